"""``reach plot``: exit codes, one-line errors, the picture written where asked; result tables
with the formal agreement columns (small reports, no bench run)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reach.bench.tables import agreement, markdown_table
from reach.cli import main

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / "models" / "spaceex" / "BouncingBall"


def run(args, cwd):
    proc = subprocess.run([sys.executable, "-m", "reach.cli", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.parametrize("extra, message", [
    (["--vars", "T,zz"], "--vars: no state or input 'zz'"),
    (["--vars", "T"], "--vars: expected two names"),
    (["-b", "nope"], "--backend: unknown back-end 'nope'"),
    (["-o", "star.bogus=1"], "options.star.bogus: unknown star option"),
    (["--out", "pic.xyz"], "--out: unknown picture format"),
    (["-p", "nothere"], "--property: no property 'nothere'"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, extra, message):
    code, out, err = run(["plot", str(ROOT / "models" / "thermostat.yaml"), str(ROOT / "properties" / "thermostat.yaml"),
                          "-b", "star", *extra], tmp_path)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert not list(tmp_path.iterdir())


def test_star_sets_of_a_spaceex_model_written_in_the_working_folder(tmp_path):
    """The bouncing ball is SAFE by star (exit 0); the default picture lands in the working folder,
    and every sampled run of the simulator lies in the star's outer polygons (x against time)."""
    code, out, err = run(["plot", str(BALL / "bball.xml"), str(BALL / "bball-height.cfg"), "-b", "star",
                          "-b", "montecarlo", "-o", "montecarlo.samples=20", "-o", "montecarlo.optimise=false",
                          "-o", "montecarlo.search_rounds=0"], tmp_path)
    assert code == 3, err            # montecarlo never says SAFE: undecided overall
    pictures = list(tmp_path.glob("*.png"))
    assert len(pictures) == 1 and pictures[0].stat().st_size > 10_000
    assert "wrote" in out and err == ""


def test_samples_lie_in_star_sets(tmp_path):
    from reach.checking import check_spaceex

    star, model, _, _ = check_spaceex(BALL / "bball.xml", BALL / "bball-height.cfg", "star", {"keep_sets": True})
    sampled, _, _, _ = check_spaceex(BALL / "bball.xml", BALL / "bball-height.cfg", "montecarlo",
                                     {"keep_sets": True, "samples": 20, "optimise": False, "search_rounds": 0})
    pieces = star[0].sets
    assert pieces and sampled[0].sets
    names = list(model.state)
    for run_piece in sampled[0].sets[:10]:
        for t, x in zip(run_piece.times[::7], run_piece.points[::7]):
            covering = [p for p in pieces if p.mode == run_piece.mode and p.t0 - 1e-9 <= t <= p.t1 + 1e-9]
            up = [p.support(np.vstack([np.eye(len(p.names))[:len(names)], -np.eye(len(p.names))[:len(names)]]),
                            exact=False) for p in covering]
            n = len(names)
            assert any(np.all(x <= u[:n] + 1e-6) and np.all(-x <= u[n:] + 1e-6) for u in up), (t, x)


def test_plot_without_properties_keeps_the_run_picture(tmp_path):
    out = tmp_path / "runs.png"
    assert main(["plot", str(ROOT / "models" / "thermostat.yaml"), "--runs", "3", "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000
    assert main(["plot", str(ROOT / "models" / "thermostat.yaml"), "--vars", "T,t"]) == 2


def row(backend, status, seconds, instance="I", prop="p"):
    return {"instance": instance, "property": prop, "backend": backend, "status": status, "seconds": seconds,
            "details": {}, "model": "M"}


def test_agreement_and_ratio():
    assert agreement({"star": row("star", "safe", 1.0), "taylor": row("taylor", "safe", 4.0)}) == \
        ("yes", "taylor/star 4.0x")
    assert agreement({"star": row("star", "safe", 1.0), "taylor": row("taylor", "unsafe", 2.0)})[0] == "NO"
    assert agreement({"star": row("star", "safe", 1.0), "taylor": row("taylor", "unknown", 2.0)}) == \
        ("open (taylor undecided)", "")
    assert agreement({"star": row("star", "safe", 1.0), "montecarlo": row("montecarlo", "unknown", 2.0)}) == \
        ("one formal", "")
    assert agreement({"star": row("star", "unsupported", 0.0), "taylor": row("taylor", "safe", 2.0)})[0] == \
        "one formal"


def test_results_table_links_plots_and_embeds_pictures(tmp_path):
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "M_runs.png").write_bytes(b"png")
    (tmp_path / "plots" / "SRA08_abort_map.png").write_bytes(b"png")
    report = {"suite": "s.yaml", "started": "now", "machine": {"platform": "x"}, "executor": "local",
              "wall_seconds": 1.0, "backends": ["star", "taylor"], "cross_checks": [],
              "rows": [row("star", "safe", 0.5), row("taylor", "safe", 1.5)]}
    text = markdown_table(report, tmp_path)
    assert "![Safe-abort map" in text and "(plots/SRA08_abort_map.png)" in text
    line = next(l for l in text.splitlines() if l.startswith("| I | p |"))
    assert "| yes | taylor/star 3.0x | [runs](plots/M_runs.png) |" in line
    json.dumps(report)


@pytest.mark.parametrize("name", ["x.png/", "x.png/.", "sub/x.png/"])
def test_out_written_as_a_folder_is_refused_and_nothing_is_written(tmp_path, capsys, name):
    """``--out x.png/`` names a folder: bad input (one line naming the option and the name), never
    the file ``x.png`` that the name without its slash would be."""
    out = f"{tmp_path}/{name}"
    code = main(["plot", str(ROOT / "models" / "thermostat.yaml"), "--runs", "2", "--out", out])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith(f"reach: --out: {out} names a folder (it ends in '/"), err
    assert "thermostat_runs.png" in err                  # the file name it suggests
    assert not list(tmp_path.iterdir()), "nothing is written (no x.png, no folder)"


def test_out_that_is_an_existing_folder_is_refused_and_a_file_path_still_works(tmp_path, capsys):
    code = main(["plot", str(ROOT / "models" / "thermostat.yaml"), "--runs", "2", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and f"--out: {tmp_path} is a folder (give a file name such as {tmp_path}/thermostat_runs.png)" in err
    assert not list(tmp_path.iterdir())
    assert main(["plot", str(ROOT / "models" / "thermostat.yaml"), "--runs", "2",
                 "--out", str(tmp_path / "x.png")]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"]
