"""Inputs read and outputs written only in their places, and overflowing numbers as answers,
not crashes: a template outside the model's and the working folder, a symbolic link where the
import writes its models/ folder, a suite expectation of a property that does not exist, a
flow too large for double precision (star), a flow taylor's nominal run cannot follow, a requirement that overflows."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from reach.cli import main

ROOT = Path(__file__).resolve().parent.parent
TANK = (ROOT / "tests/data/tank.yaml").read_text()
LEVEL = ROOT / "tests/data/tank_level.yaml"


def test_a_template_outside_the_model_and_working_folders_is_not_read(tmp_path, capsys, monkeypatch):
    """The foreign file's contents never reach the message; a template beside the model is read."""
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "secret.yaml").write_text('state: ["sk-live-ABCDEF123"]\n')
    work, models = tmp_path / "work", tmp_path / "models"
    work.mkdir()
    models.mkdir()
    (models / "m.yaml").write_text(f"extends: {foreign / 'secret.yaml'}\nname: m\n")
    monkeypatch.chdir(work)
    assert main(["check", str(models / "m.yaml"), str(LEVEL), "-b", "star"]) == 2
    err = capsys.readouterr().err
    assert "lies outside the folder of the model file and the working folder" in err and "sk-live" not in err
    (models / "_base.yaml").write_text(TANK)
    (models / "child.yaml").write_text("extends: _base.yaml\nname: child\n")
    assert main(["check", str(models / "child.yaml"), str(LEVEL), "-b", "star"]) in (0, 1, 3)


def test_a_linked_models_folder_below_an_absolute_out_is_not_written_through(tmp_path, capsys):
    victim, out = tmp_path / "victim", tmp_path / "imp"
    victim.mkdir()
    out.mkdir()
    os.symlink(victim, out / "models")
    xml = ROOT / "models/spaceex/BouncingBall/bball.xml"
    cfg = ROOT / "models/spaceex/BouncingBall/bball-height.cfg"
    assert main(["import", str(xml), str(cfg), "--out", str(out.resolve())]) == 2
    assert "models is a symbolic link: not written through" in capsys.readouterr().err
    assert list(victim.iterdir()) == []


def test_a_suite_expecting_a_property_the_file_lacks_is_bad_input(tmp_path, capsys):
    (tmp_path / "tank.yaml").write_text(TANK)
    (tmp_path / "level.yaml").write_text(LEVEL.read_text())
    suite = {"backends": {"star": {}},
             "instances": [{"id": "T", "model": "tank.yaml", "properties": "level.yaml", "expect": {"nosuch": "safe"}}]}
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump(suite))
    assert main(["bench", "--suite", str(tmp_path / "suite.yaml"), "--out", str(tmp_path / "out"), "-j", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "expects a verdict of 'nosuch', which is no property" in err
    assert err.startswith(f"reach: {tmp_path / 'suite.yaml'}:") and ": instances[0].expect: " in err   # file and line


def test_an_instance_with_no_back_end_is_bad_input_at_its_line(tmp_path, capsys):
    (tmp_path / "tank.yaml").write_text(TANK)
    (tmp_path / "level.yaml").write_text(LEVEL.read_text())
    suite = {"backends": {"star": {}},
             "instances": [{"id": "T", "model": "tank.yaml", "properties": "level.yaml", "backends": []}]}
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump(suite))
    assert main(["bench", "--suite", str(tmp_path / "suite.yaml"), "--out", str(tmp_path / "out"), "-j", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"reach: {tmp_path / 'suite.yaml'}:") and \
        err.endswith("instances[0].backends: expected a non-empty list of the suite's back-ends")


def test_a_transition_from_no_mode_is_bad_input(tmp_path, capsys):
    (tmp_path / "m.yaml").write_text(TANK.replace("from: fill", "from: []", 1))
    assert "from: []" in (tmp_path / "m.yaml").read_text()
    assert main(["lint", str(tmp_path / "m.yaml")]) == 2
    assert "from: expected a mode name or a non-empty list of mode names" in capsys.readouterr().err


def overflowing(tmp_path, flow: str) -> Path:
    """A one-state model whose flow is ``flow`` and its property file ``p.yaml`` (h <= 2)."""
    doc = {"name": "over", "state": ["h"], "horizon": 10,
           "modes": {"fill": {"flow": {"h": flow}}}, "initial": {"mode": "fill", "box": {"h": [0.9, 1.0]}}}
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "level", "kind": "safety", "modes": ["fill"], "require": ["h <= 2"]}]}))
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_flow_beyond_double_precision_is_undecided_not_a_crash(tmp_path, capsys):
    """star: UNSUPPORTED naming the overflow (exit 3, no 'internal error')."""
    path = overflowing(tmp_path, "1e300*h*h + 0.01")
    assert main(["check", str(path), str(tmp_path / "p.yaml"), "-b", "star"]) == 3
    out = capsys.readouterr()
    assert "numbers beyond double precision" in out.out and "internal error" not in out.err


def test_taylors_nominal_run_gives_up_on_a_flow_it_cannot_follow(tmp_path, capsys):
    """sin(1e300 h) needs steps at the spacing of the numbers: the nominal run stops after its
    step budget (UNKNOWN naming it) instead of running on past any time budget."""
    from reach.backends.taylor.nominal import MAX_STEPS

    path = overflowing(tmp_path, "0.02 - 0.01*h + sin(1e300*h)")
    assert main(["check", str(path), str(tmp_path / "p.yaml"), "-b", "taylor"]) == 3
    assert f"more than {MAX_STEPS} steps" in capsys.readouterr().out


def test_a_bad_input_line_is_cut_at_two_thousand_characters(tmp_path, capsys):
    """A property naming a mode of 10000 characters is refused quoting it, in one readable line."""
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"properties": [
        {"id": "long", "kind": "safety", "modes": ["a" * 10000], "require": ["h <= 2[m]"]}]}))
    (tmp_path / "m.yaml").write_text(TANK)
    assert main(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "star"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert len(line) == 2000 and line.endswith("...") and "p.yaml:" in line


def test_lint_of_a_folder_does_not_read_through_links(tmp_path, capsys):
    (tmp_path / "tank.yaml").write_text(TANK)
    os.symlink("/etc/passwd", tmp_path / "pw.yaml")
    assert main(["lint", str(tmp_path)]) == 0
    assert "no findings (1 model)" in capsys.readouterr().out


def test_a_suite_option_out_of_range_is_named(tmp_path, capsys):
    (tmp_path / "tank.yaml").write_text(TANK)
    (tmp_path / "level.yaml").write_text(LEVEL.read_text())
    suite = {"backends": {"star": {"step": -1}},
             "instances": [{"id": "T", "model": "tank.yaml", "properties": "level.yaml"}]}
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump(suite))
    assert main(["bench", "--suite", str(tmp_path / "suite.yaml"), "--out", str(tmp_path / "out"), "-j", "1"]) == 2
    assert "backends.star: step: expected a number > 0, got -1" in capsys.readouterr().err


def test_a_counterexample_with_a_byte_order_mark_replays(tmp_path, capsys):
    """An editor's UTF-8 byte-order mark in front of a saved counterexample is not part of it."""
    model = tmp_path / "tank.yaml"
    model.write_text(TANK)
    folder = tmp_path / "cex"
    assert main(["check", str(model), str(LEVEL), "-b", "montecarlo", "-p", "tight",
                 "--counterexamples", str(folder)]) == 1
    (saved,) = folder.glob("*.json")
    saved.write_text("\ufeff" + saved.read_text(), encoding="utf-8")
    capsys.readouterr()
    assert main(["replay", str(saved)]) == 1
    assert "violates 'tight'" in capsys.readouterr().out


def test_an_integer_too_long_to_read_is_bad_input_at_its_line(tmp_path, capsys):
    """A 5000-digit integer is past Python's int conversion limit (4300 digits): bad input at
    its line and field, not a bare 'ValueError'."""
    text = (Path("tests/data/tank.yaml").read_text().replace("horizon:", "horizon_was:")
            + "horizon: " + "9" * 5000 + "\n")
    (tmp_path / "m.yaml").write_text(text)
    line = text.count("\n")
    assert main(["check", str(tmp_path / "m.yaml"), "tests/data/tank_level.yaml", "-b", "star"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"m.yaml:{line}: horizon: invalid YAML: a number too long to read" in err[0]


def test_file_names_keep_letters_of_any_script_and_never_a_path():
    """A model named in another script keeps its name in the files written from it; a separator
    or a leading dot never survives (the name stays one component inside its folder)."""
    from reach.paths import safe_name
    assert safe_name("水槽") == "水槽"
    assert safe_name("../../x") == "x" and safe_name("a/b") == "a_b" and safe_name("ｘ／y") == "ｘ_y"
    assert safe_name(".hidden") == "hidden" and safe_name("///") == "unnamed"
    long_a, long_b = "m_" + "b" * 100 + "_one_star", "m_" + "b" * 100 + "_two_star"
    assert len(safe_name(long_a)) == 80 and safe_name(long_a) != safe_name(long_b)   # no two files in one


def test_taylors_expansion_of_a_stiff_flow_stops_at_the_budget(tmp_path, capsys):
    """x' = -1000 (x - 1) + y^2 over 24 s: thousands of DA steps per run. The expansion looks at
    the budget as it steps, so the check ends near max_seconds, UNKNOWN naming the budget (it
    ran past 180 s with max_seconds=20)."""
    import time
    model = {"name": "stiff", "state": ["x", "y", "t"], "horizon": 24,
             "modes": {"go": {"flow": {"x": "-1000*(x - 1) + y**2", "y": 0, "t": 1}}},
             "initial": {"mode": "go", "box": {"x": [0, 0.5], "y": [0, 0.01], "t": 0}}}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "low", "kind": "safety", "modes": ["go"], "require": ["x <= 0.9"]}]}))
    start = time.perf_counter()
    assert main(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "taylor",
                 "-o", "max_seconds=3"]) == 3
    assert "time budget of 3 s (option max_seconds) exhausted" in capsys.readouterr().out
    assert time.perf_counter() - start < 60


def test_linting_a_folder_without_models_is_bad_input(tmp_path, capsys):
    """``reach lint /`` said "no findings (0 models)", exit 0: a clean bill for nothing."""
    (tmp_path / "props.yaml").write_text("properties:\n  - {id: p, kind: safety, modes: [a], require: [\"x <= 1\"]}\n")
    assert main(["lint", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip().endswith(f"{tmp_path} holds no model file (*.yaml)")


@pytest.mark.parametrize("value,kind", [("!!binary aGVsbG8=", "bytes"), ("2001-12-14t21:59:43.10-05:00", "a date"),
                                        ("12", "a number")])
def test_a_name_yaml_reads_as_no_text_says_what_it_read(tmp_path, capsys, value, kind):
    (tmp_path / "m.yaml").write_text(TANK.replace("name: tank", f"name: {value}", 1))
    assert f"name: {value}" in (tmp_path / "m.yaml").read_text()
    assert main(["lint", str(tmp_path / "m.yaml")]) == 2
    assert capsys.readouterr().err.strip().endswith(f"name: expected a name in text, got {kind} (quote it)")


def clock_model(tmp_path, requirements: list, events: list = ()) -> tuple[Path, Path]:
    """A clock ``t`` over 7 s (``exp(exp(t))`` passes the largest float at t = 6.566) and a
    property file of safety ``requirements`` (ids r0, r1, ...) and event properties ``events``."""
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "clock", "units": {"time": "s"}, "state": {"x": "1", "t": "s"}, "horizon": 7,
        "modes": {"run": {"flow": {"x": 0, "t": 1}}}, "initial": {"mode": "run", "box": {"x": [1, 1.1], "t": 0}}}))
    props = [{"id": f"r{i}", "kind": "safety", "modes": ["run"], "require": [text]} for i, text in enumerate(requirements)]
    props += [{"id": f"e{i}", "kind": "event", "modes": ["run"], **event} for i, event in enumerate(events)]
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"properties": props}))
    return tmp_path / "m.yaml", tmp_path / "p.yaml"


def test_enclosures_that_overflow_are_unbounded_not_dropped():
    """A candidate whose series holds ``inf - inf`` (NaN) encloses nothing: both ends unbounded,
    so the extremum over it and a finite candidate is unbounded on its outer side instead of
    being the finite candidate's value (``max(1, nan)`` is 1)."""
    from reach.backends.taylor.bound import enclose, extremum_bound, overflows
    from reach.backends.taylor.da import DA, algebra

    alg = algebra(3, 1)
    finite = DA(alg, np.array([1.0, 0.5, 0.0, 0.0]))
    blown = DA(alg, np.array([np.inf, np.nan, np.nan, 0.0]))
    assert not overflows(finite) and overflows(blown)
    lo, hi = enclose(blown, np.array(0.0))
    assert (float(lo), float(hi)) == (-np.inf, np.inf)
    ends = {"start": tuple(float(v) for v in enclose(finite, np.array(0.0))), "end": (float(lo), float(hi))}
    assert extremum_bound(ends, "max") == (0.5, np.inf)
    assert extremum_bound(ends, "min") == (-np.inf, 1.5)


@pytest.mark.parametrize("remainder", ["estimated", "rigorous"])
def test_a_requirement_that_overflows_says_so_and_is_never_safe(tmp_path, capsys, remainder):
    """``exp(exp(t)) >= 1`` holds, but its margin overflows before the horizon: its bound is not
    the finite start's ``[1.718, 1.718]`` (the overflowed end dropped) but unbounded below, and
    the result says that the margin overflows (exit 3, not SAFE)."""
    import json

    model, props = clock_model(tmp_path, ["exp(exp(t/(1[s]))) >= 1"])
    code = main(["check", str(model), str(props), "-b", "taylor", "-o", f"remainder={remainder}"])
    out = capsys.readouterr().out
    assert code == 3, out
    assert "smallest margin in [-inf, 1.718]" in out and "[1.718, 1.718]" not in out
    assert "overflows (is not finite) at run:horizon: the bound's lower end is unbounded" in out
    assert "refine" not in out                  # halving the initial set does not undo an overflow
    main(["check", str(model), str(props), "-b", "taylor", "-o", f"remainder={remainder}", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert row["status"] == "unknown" and float(row["details"]["margin_bound"][0]) == -np.inf


def test_overflowing_requirements_are_violations_or_open_never_the_overflow_sentinel(tmp_path, capsys):
    """``exp(exp(t)) <= 1e300`` is passed at t = 6.538: with the estimated remainder the margin
    was the finite start's ``[1e+300, 1e+300]`` and the maximum of ``exp(exp(t))`` the start's
    2.718; now both reach the overflow, and the replayed run is the counterexample (exit 1). A
    ratio that is NaN past the overflow (``inf / inf``) is open, exit 3, naming the overflow."""
    model, props = clock_model(tmp_path, ["exp(exp(t/(1[s]))) <= 1e300"],
                               [{"maximize": "exp(exp(t/(1[s])))", "require": "<= 1e300"}])
    code = main(["check", str(model), str(props), "-b", "taylor", "--counterexamples", str(tmp_path / "cx")])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "1e+300, 1e+300]" not in out and "smallest margin in [-inf, 1e+300]" in out
    assert "max exp(exp(t/(1[s]))) in [2.718, inf]" in out
    assert out.count("UNSAFE") == 2 and "violated at t=" in out
    ratio = "exp(exp(t/(1[s])))/(1e306 + exp(exp(t/(1[s]))))"       # passes 0.999 only past the overflow
    model, props = clock_model(tmp_path, [f"{ratio} <= 0.999"])
    for remainder in ("estimated", "rigorous"):
        code = main(["check", str(model), str(props), "-b", "taylor", "-o", f"remainder={remainder}"])
        out = capsys.readouterr().out
        assert code == 3, out
        assert "smallest margin in [-inf, 0.999]" in out and "overflows (is not finite)" in out
