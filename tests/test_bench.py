"""The benchmark runner and its cross-checks."""

import json
from pathlib import Path

import pytest

from reach.bench.crosscheck import cross_check
from reach.bench.runner import run_suite
from reach.bench.tables import compare_runs
from reach.errors import InputError


def _row(backend, status, **extra):
    row = {"instance": "I", "property": "p", "backend": backend, "status": status, "seconds": 1.0,
           "details": {}, "expected": None, "probability": None, "bound": None, "counterexample": None}
    row.update(extra)
    return row


def test_runner_writes_tables_and_checks_expectations(tmp_path):
    suite = tmp_path / "suite.yaml"
    root = __import__("pathlib").Path.cwd()
    suite.write_text(f"""backends:
  montecarlo: {{samples: 60, search_rounds: 0}}
instances:
  - id: SRA01-7N
    model: {root}/models/SRA01.yaml
    properties: {root}/properties/thrust_7N.yaml
    expect: {{thrust_7N: unsafe}}
  - id: SRA01-7N-wrong
    model: {root}/models/SRA01.yaml
    properties: {root}/properties/thrust_7N.yaml
    expect: {{thrust_7N: safe}}
""")
    log = tmp_path / "log.txt"
    with open(log, "w") as stream:
        code = run_suite(suite, out=tmp_path / "out", jobs=1, stream=stream)
    assert code == 1                                   # the wrong expectation must fail the run
    report = json.loads((tmp_path / "out" / "results.json").read_text())
    assert {r["status"] for r in report["rows"]} == {"unsafe"}
    failures = [c["message"] for c in report["cross_checks"] if c["level"] == "fail"]
    assert len(failures) == 1 and "SRA01-7N-wrong/thrust_7N" in failures[0]
    table = (tmp_path / "out" / "results.md").read_text()
    assert "| SRA01-7N | thrust_7N | unsafe | UNSAFE" in table
    assert "[  2/2]" in log.read_text()
    assert (tmp_path / "out" / "plots" / "SRA01_runs.png").stat().st_size > 10_000
    assert "| SRA01-7N | thrust_7N | montecarlo | unsafe |" in compare_runs(tmp_path / "out" / "results.json",
                                                                         tmp_path / "out" / "results.json")


def test_cross_check_flags_disagreements():
    assert cross_check([_row("a", "safe"), _row("b", "unknown")]) == []
    unreplayable = cross_check([_row("a", "unsafe")])
    assert unreplayable[0]["level"] == "fail" and "without a counterexample" in unreplayable[0]["message"]
    apart = cross_check([_row("fsr", "unknown", probability=[0.60, 0.62]),
                         _row("montecarlo", "unknown", probability=[0.63, 0.66])])
    assert apart[0]["level"] == "fail" and "do not overlap" in apart[0]["message"]
    overlapping = cross_check([_row("fsr", "unknown", probability=[0.60, 0.64]),
                               _row("montecarlo", "unknown", probability=[0.63, 0.66])])
    assert overlapping == []
    bound = cross_check([_row("taylor", "safe", bound=[0.0, 1.0]),
                         _row("montecarlo", "unknown", details={"sampled_range": [0.2, 1.3]})])
    assert bound[0]["level"] == "fail" and "excludes sampled" in bound[0]["message"]


def test_sweep_writes_the_abort_map(tmp_path):
    import subprocess
    import sys
    out = tmp_path / "map.png"
    run = subprocess.run([sys.executable, "-m", "reach", "sweep", "SRA02", "properties/rendezvous.yaml",
                          "-p", "collision", "--cells", "2", "-j", "1", "--out", str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    rows = [line for line in run.stdout.splitlines() if line.startswith("| 2")]
    assert len(rows) == 2 and all(row.endswith("| 125.00 |") for row in rows)   # window end: all safe
    assert out.stat().st_size > 10_000



ABORT_LINE = """
name: abort_line
state: [x, y, v, t]
modes:
  approach: {flow: {x: "v", y: "0", v: "0", t: "1"}, invariant: ["x >= 20", "t <= 100"]}
  passive: {flow: {x: "v", y: "0", v: "0", t: "1"}}
transitions:
  - {from: approach, to: passive, guard: ["t >= 50", "t <= 100"]}
initial: {mode: approach, box: {x: [100, 110], y: [0, 0], v: [-0.5, -0.5], t: [0, 0]}}
horizon: 200
"""

WITHOUT_Y = ABORT_LINE.replace("[x, y, v, t]", "[x, v, t]").replace('y: "0", ', "").replace("y: [0, 0], ", "")


@pytest.mark.parametrize("model, message", [(ABORT_LINE, "lie outside the invariant of the initial mode"),
                                            (WITHOUT_Y, "no state named y")])
def test_a_sweep_that_would_say_nothing_is_bad_input(tmp_path, model, message):
    """A sweep draws its initial cells on an arc in (x, y): a model without those states was an
    internal error (exit 3), and cells wholly outside the initial mode's invariant (the default
    arc, radius 1000 from 180 to 270 degrees, has x < 0 < 20: no run starts there) all read
    "latest safe abort at the window's end", exit 0, though runs of the model's own initial set
    violate. Both are bad input now, one line naming the model file."""
    import subprocess
    import sys
    (tmp_path / "m.yaml").write_text(model)
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: low, kind: safety, require: ['x >= 0']}\n")
    run = subprocess.run([sys.executable, "-m", "reach", "sweep", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"),
                          "--cells", "2", "-j", "1", "--out", str(tmp_path / "map.png")],
                         capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 2, run.stdout + run.stderr
    assert message in run.stderr and "m.yaml" in run.stderr and len(run.stderr.strip().splitlines()) == 1


def test_an_expected_verdict_no_back_end_reached_is_undecided(tmp_path):
    """Monte Carlo never proves SAFE: the thermostat's expected-safe band stays unproved, a
    note, and the run exits 3 (undecided) instead of 0, though the expected violation is found.
    A filter that selects no unit is bad input before anything runs."""
    root = __import__("pathlib").Path.cwd()
    suite = tmp_path / "suite.yaml"
    suite.write_text(f"""backends:
  montecarlo: {{samples: 5, search_rounds: 0, optimise: false}}
  star: {{}}
instances:
  - id: thermo
    model: {root}/models/thermostat.yaml
    properties: {root}/properties/thermostat.yaml
    backends: [montecarlo]
    expect: {{band: safe, below_20p5: unsafe}}
""")
    with open(tmp_path / "log.txt", "w") as stream:
        assert run_suite(suite, out=tmp_path / "out", jobs=1, stream=stream) == 3
    report = json.loads((tmp_path / "out" / "results.json").read_text())
    notes = sorted(c["message"] for c in report["cross_checks"] if c["level"] == "note")
    assert [n.split(":")[0] for n in notes] == ["thermo/band"]
    assert "expected safe, but no back-end proved it (montecarlo UNKNOWN)" in notes[0]
    with pytest.raises(InputError, match="no unit to run: star runs on none of the chosen instances"):
        run_suite(suite, out=tmp_path / "out2", jobs=1, backends=["star"])


def thermostat_suite(tmp_path, instances: dict):
    """A suite of thermostat instances on a quick Monte Carlo (``instances``: id -> its
    ``expect`` as YAML text, or None)."""
    root = Path.cwd()
    text = "backends:\n  montecarlo: {samples: 5, search_rounds: 0, optimise: false}\ninstances:\n"
    for name, expect in instances.items():
        text += (f"  - id: {name}\n    model: {root}/models/thermostat.yaml\n"
                 f"    properties: {root}/properties/thermostat.yaml\n")
        if expect is not None:
            text += f"    expect: {expect}\n"
    suite = tmp_path / "suite.yaml"
    suite.write_text(text)
    return suite


def test_two_filtered_runs_into_one_folder_keep_each_others_rows(tmp_path, monkeypatch):
    """Two filtered runs (one instance each) that finish together into the same --out: each
    merges its rows under a lock, so neither overwrites the other's (both instances' rows end
    in results.json). Reading the earlier rows is slowed down so that, unlocked, both runs would
    read before either writes."""
    import threading
    import time

    import reach.bench.runner as runner
    read = runner.previous_rows

    def slow_read(*args, **kwargs):
        rows = read(*args, **kwargs)
        time.sleep(0.5)
        return rows
    monkeypatch.setattr(runner, "previous_rows", slow_read)
    suite = thermostat_suite(tmp_path, {"one": None, "two": None})
    import io
    threads = [threading.Thread(target=run_suite, args=(suite,),
                                kwargs={"instances": [i], "out": tmp_path / "out", "jobs": 1, "stream": io.StringIO()})
               for i in ("one", "two")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    report = json.loads((tmp_path / "out" / "results.json").read_text())
    assert {r["instance"] for r in report["rows"]} == {"one", "two"}


def test_a_filtered_run_is_gated_on_its_own_instances_only(tmp_path):
    """An earlier run left a note on `thermo` (its expected-safe band unproved by Monte Carlo);
    a run filtered to `clean` (nothing expected, nothing to note) exits 0: the kept rows'
    checks are written to the report, not gated on. Run on `thermo` again, it exits 3."""
    suite = thermostat_suite(tmp_path, {"thermo": "{band: safe}", "clean": None})
    out = tmp_path / "out"
    with open(tmp_path / "log.txt", "w") as stream:
        assert run_suite(suite, out=out, jobs=1, stream=stream) == 3
        assert run_suite(suite, out=out, jobs=1, stream=stream, instances=["clean"]) == 0
        report = json.loads((out / "results.json").read_text())
        assert [c["instance"] for c in report["cross_checks"]] == ["thermo"]   # still reported
        assert run_suite(suite, out=out, jobs=1, stream=stream, instances=["thermo"]) == 3
