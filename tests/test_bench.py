"""The benchmark runner and its cross-checks."""

import json

from reach.bench.crosscheck import cross_check
from reach.bench.runner import run_suite
from reach.bench.tables import compare_runs


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
