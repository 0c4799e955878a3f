"""Files reach names itself are never written through a symbolic link (``reach plot``'s default
picture, everything ``reach bench`` writes), ``reach compare`` reads results files defensively
(escaped cells, checked numbers, a size cap, duplicates said), a tiny ``--time-limit`` is a
timeout, and a crowded run picture says nothing on stderr."""

import json
import os
import shutil
import signal
import warnings
from pathlib import Path

import pytest

import reach.bench.runner as runner
from reach.cli import main

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def thermostat(tmp_path, monkeypatch):
    """The thermostat model and its properties in the (working) folder ``tmp_path``, a victim
    file and a suite of one quick Monte Carlo instance, ``thermostat``."""
    shutil.copy(ROOT / "models" / "thermostat.yaml", tmp_path / "thermostat.yaml")
    shutil.copy(ROOT / "properties" / "thermostat.yaml", tmp_path / "thermostat_props.yaml")
    (tmp_path / "victim.txt").write_text("victim\n")
    (tmp_path / "suite.yaml").write_text(
        "backends:\n  montecarlo: {samples: 5, search_rounds: 0, optimise: false}\ninstances:\n"
        "  - id: thermostat\n    model: thermostat.yaml\n    properties: thermostat_props.yaml\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


# 1. reach plot MODEL PROPS -b B without --out

def test_plot_default_file_is_not_written_through_a_link(thermostat, capsys):
    link = thermostat / "thermostat_star_t_T.png"
    link.symlink_to(thermostat / "victim.txt")
    code = main(["plot", "thermostat.yaml", "thermostat_props.yaml", "-b", "star", "-p", "band"])
    out, err = capsys.readouterr()
    assert code == 2
    assert _one_line(err) == ("reach: --out: thermostat_star_t_T.png is a symbolic link: "
                              "not written through")
    assert (thermostat / "victim.txt").read_text() == "victim\n"
    assert link.is_symlink()
    assert "star:" not in out                  # refused before the check ran


# 2. reach bench: every file it writes

@pytest.mark.parametrize("name", ["results.md", "results.json", ".results.lock", "plots/thermostat_runs.png"])
def test_bench_refuses_a_link_at_each_of_its_files(thermostat, capsys, name):
    (thermostat / "bs" / "plots").mkdir(parents=True)
    (thermostat / "bs" / name).symlink_to(thermostat / "victim.txt")
    code = main(["bench", "--suite", "suite.yaml", "--instance", "thermostat", "-j", "1", "--out", "bs"])
    out, err = capsys.readouterr()
    assert code == 2
    assert _one_line(err) == f"reach: --out: bs/{name} is a symbolic link: not written through"
    assert (thermostat / "victim.txt").read_text() == "victim\n"
    assert "[  1/1]" not in out                  # refused before any unit ran
    assert not (thermostat / "bs" / "results.json").is_file() or name == "results.json"


def test_bench_refuses_a_link_in_the_default_results_folder(thermostat, capsys):
    (thermostat / "results").mkdir()
    (thermostat / "results" / "results.md").symlink_to(thermostat / "victim.txt")
    assert main(["bench", "--suite", "suite.yaml", "--instance", "thermostat", "-j", "1"]) == 2
    assert _one_line(capsys.readouterr().err) == ("reach: --out: results/results.md is a symbolic link: "
                                                  "not written through")
    assert (thermostat / "victim.txt").read_text() == "victim\n"


@pytest.mark.parametrize("name", ["results.md", "plots/thermostat_runs.png"])
def test_bench_checks_each_file_again_when_it_writes_it(thermostat, capsys, monkeypatch, name):
    """A link planted after the first check (here: the first check skipped) is refused too."""
    monkeypatch.setattr(runner, "check_outputs", lambda *args: None)
    (thermostat / "bs" / "plots").mkdir(parents=True)
    (thermostat / "bs" / name).symlink_to(thermostat / "victim.txt")
    code = main(["bench", "--suite", "suite.yaml", "--instance", "thermostat", "-j", "1", "--out", "bs"])
    assert code == 2
    assert _one_line(capsys.readouterr().err) == f"reach: --out: bs/{name} is a symbolic link: not written through"
    assert (thermostat / "victim.txt").read_text() == "victim\n"


def test_bench_pictures_are_named_inside_the_plots_folder():
    assert runner.subdomain_picture(Path("o/plots"), "../../x", "p/q") == Path("o/plots/x_p_q_subdomains.png")
    assert runner.runs_picture(Path("o/plots"), "../evil") == Path("o/plots/evil_runs.png")


# 3. reach compare

def _results(path: Path, *rows) -> Path:
    path.write_text(json.dumps({"rows": [{"instance": "i", "property": "p", "backend": "b", "status": "safe",
                                          "seconds": 1.0, **row} for row in rows]}))
    return path


def test_compare_escapes_every_cell(tmp_path, capsys):
    old = _results(tmp_path / "old.json", {})
    new = _results(tmp_path / "new.json", {"instance": "a\x1b[31mred\nrow|x\u2028y"}, {"status": "unsafe|z"})
    assert main(["compare", str(old), str(new)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    lines = out.splitlines()
    assert lines[2] == "| a\\x1b[31mred\\nrow\\|x\\u2028y | p | b | new: safe | 1.00 | |"
    assert lines[3] == "| i | p | b | safe -> unsafe\\|z | 1.00 -> 1.00 | 1.00 |"
    assert len(lines) == 6 and lines[-1] == "2 rows now, 1 before: 1 new, 0 gone"


@pytest.mark.parametrize("text, shown", [
    ("1" + "0" * 4000, "an integer of 4001 digits"), ("NaN", "nan"), ("1e999", "inf"), ("-5", "-5"),
    ("true", "true"), ('"abc"', "'abc'"), ("[1]", "a list"), ("1e10", "10000000000.0")])
def test_compare_refuses_seconds_out_of_range(tmp_path, capsys, text, shown):
    bad = tmp_path / "bad.json"
    bad.write_text('{"rows": [{"instance": "i", "property": "p", "backend": "b", "status": "safe", '
                   f'"seconds": {text}}}]}}')
    assert main(["compare", str(_results(tmp_path / "ok.json", {})), str(bad)]) == 2
    assert _one_line(capsys.readouterr().err) == (f"reach: {bad}: rows[0].seconds: expected a number of "
                                                  f"seconds in [0, 1e+09] ({shown})")


def test_compare_refuses_a_bad_probability(tmp_path, capsys):
    bad = _results(tmp_path / "bad.json", {}, {"backend": "c", "probability": [0.5, 2]})
    assert main(["compare", str(bad), str(bad)]) == 2
    assert _one_line(capsys.readouterr().err) == (f"reach: {bad}: rows[1].probability: expected an interval "
                                                  "[low, high] within [0, 1] (a list)")


def test_compare_caps_the_size_of_a_results_file(tmp_path, capsys):
    big = tmp_path / "big.json"
    with open(big, "wb") as handle:                 # sparse: no disk, no memory
        handle.truncate(runner.MAX_RESULTS_BYTES + 1)
    assert runner.MAX_RESULTS_BYTES == 64 * 2 ** 20
    assert main(["compare", str(big), str(_results(tmp_path / "ok.json", {}))]) == 2
    assert _one_line(capsys.readouterr().err) == (f"reach: {big}: file larger than {runner.MAX_RESULTS_BYTES} "
                                                  f"bytes ({runner.MAX_RESULTS_BYTES + 1})")


def test_compare_warns_of_duplicate_rows_and_compares_the_last(tmp_path, capsys):
    old = _results(tmp_path / "old.json", {})
    new = _results(tmp_path / "new.json", {}, {"status": "unsafe", "seconds": 2.0})
    assert main(["compare", str(old), str(new)]) == 0
    out, err = capsys.readouterr()
    assert _one_line(err) == (f"warning: {new}: 1 duplicate row (instance/property/back-end seen before; "
                              "the last one is compared): rows[1] i/p/b")
    assert out.splitlines()[2:] == ["| i | p | b | safe -> unsafe | 1.00 -> 2.00 | 2.00 |", "",
                                    "1 rows now, 1 before: 0 new, 0 gone"]


# 4. a --time-limit so short the alarm comes during setitimer

def test_a_tiny_time_limit_is_a_timeout(thermostat, capsys):
    before = signal.getsignal(signal.SIGALRM)
    code = main(["bench", "--suite", "suite.yaml", "--instance", "thermostat", "-j", "1",
                 "--time-limit", "1e-6", "--out", "bo"])
    err = capsys.readouterr().err
    assert code == 1, err                           # a timeout is a failed cross-check, not an internal error
    assert err == ""
    report = json.loads((thermostat / "bo" / "results.json").read_text())
    assert [(r["status"], r["seconds"]) for r in report["rows"]] == [("timeout", 1e-6)]
    assert [c["message"] for c in report["cross_checks"]] == ["thermostat with montecarlo: timeout: "
                                                             "stopped after 1e-06 s"]
    assert signal.getsignal(signal.SIGALRM) == before and signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_a_guarded_unit_survives_an_alarm_before_it_starts(monkeypatch):
    """The alarm raised as setitimer returns (as a limit of 1e-6 s does) is still a timeout."""
    from reach.executors import guarded

    real = signal.setitimer

    def fire_at_once(which, seconds, *rest):
        real(which, seconds, *rest)
        if seconds:
            signal.getsignal(signal.SIGALRM)(signal.SIGALRM, None)
    monkeypatch.setattr(signal, "setitimer", fire_at_once)
    assert guarded(lambda: "ran", (), 0.5) == ("timeout", None)


# 5. a run picture of a model of a hundred modes

def test_a_crowded_run_picture_says_nothing_on_stderr(tmp_path, capsys):
    modes = "".join(f"  m{k}:\n    flow: {{x: 1, c: 1}}\n    invariant: [\"c <= 0.1\"]\n" for k in range(100))
    jumps = "".join(f"  - {{from: m{k}, to: m{k + 1}, guard: [\"c >= 0.1\"], reset: {{c: 0}}, urgent: true}}\n"
                    for k in range(99))
    model = tmp_path / "chain.yaml"
    model.write_text(f"name: chain\nstate: [x, c]\nmodes:\n{modes}transitions:\n{jumps}"
                     "initial: {mode: m0, box: {x: [0, 0.1], c: 0}}\nhorizon: 10\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # any warning left would fail here
        assert main(["plot", str(model), "--runs", "2", "--out", str(tmp_path / "x.png")]) == 0
    out, err = capsys.readouterr()
    assert err == "" and out.strip() == f"wrote {tmp_path / 'x.png'}"
    assert (tmp_path / "x.png").stat().st_size > 10_000


# 3. a FIFO (or any other non-regular file) at an output path: refused, never opened (a FIFO
#    would block the write for ever)

@pytest.mark.parametrize("command,name", [
    (["plot", "thermostat.yaml", "thermostat_props.yaml", "-b", "star", "-p", "band", "--out", "pic.png"], "pic.png"),
    (["bench", "--suite", "suite.yaml", "--instance", "thermostat", "-j", "1", "--out", "bs"], "bs/results.json"),
    (["bench", "--suite", "suite.yaml", "--instance", "thermostat", "-j", "1", "--out", "bs"],
     "bs/plots/thermostat_runs.png"),
])
def test_a_fifo_at_an_output_path_is_bad_input(thermostat, capsys, command, name):
    (thermostat / name).parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(thermostat / name)
    assert main(command) == 2
    assert _one_line(capsys.readouterr().err) == f"reach: --out: {name} is not a regular file: not written"


def test_a_fifo_where_a_counterexample_goes_is_bad_input(thermostat, capsys):
    (thermostat / "props.yaml").write_text(
        "properties:\n  - {id: hot, kind: safety, modes: [heating, \"off\"], require: [\"T <= 20.5\"]}\n")
    (thermostat / "counterexamples").mkdir()
    os.mkfifo(thermostat / "counterexamples" / "thermostat_hot_star.json")
    assert main(["check", "thermostat.yaml", "props.yaml", "-b", "star"]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "--counterexamples: counterexamples/thermostat_hot_star.json is not a regular file: not written")
