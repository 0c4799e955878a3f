"""The command-line contract (DESIGN.md): exit 0 every property SAFE, 1 a violation, 2 bad input
as one line ``file:line: field: message``, 3 undecided; never a traceback, a hang, code execution
or a file written outside its folder.

* ``tests/data/cli_cases.yaml``: the table of cases (what is wrong, the command line, the exit
  code, the first line of stderr), each run in-process from a fresh working directory.
* Property-based: command lines assembled from pools of good and bad parts, and model files
  with random fields replaced, must end in a code of the contract with no traceback and write
  nothing outside the working directory.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import os
import re
import warnings
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reach.cli import main

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"
CASES = yaml.safe_load((DATA / "cli_cases.yaml").read_text())["cases"]
CONTRACT = {0, 1, 2, 3}


def _fill(value, tmp: Path):
    if isinstance(value, str):
        return value.replace("{repo}", str(REPO)).replace("{tmp}", str(tmp))
    if isinstance(value, list):
        return [_fill(v, tmp) for v in value]
    if isinstance(value, dict):
        return {k: _fill(v, tmp) for k, v in value.items()}
    return value


def _special(value):
    """``.nan`` / ``.inf`` in the table stand for the floats."""
    if isinstance(value, str) and value in (".nan", ".inf", "-.inf"):
        return {".nan": math.nan, ".inf": math.inf, "-.inf": -math.inf}[value]
    if isinstance(value, list):
        return [_special(v) for v in value]
    return value


def patched_model(case: dict) -> str:
    """tests/data/tank.yaml with the case's ``set`` and ``drop`` applied, as YAML text."""
    doc = copy.deepcopy(yaml.safe_load((DATA / "tank.yaml").read_text()))
    for path, value in (case.get("set") or {}).items():
        *parents, last = path.split(".")
        node = doc
        for key in parents:
            node = node.setdefault(key, {})
        node[last] = _special(value)
    for path in case.get("drop") or []:
        *parents, last = path.split(".")
        node = doc
        for key in parents:
            node = node[key]
        del node[last]
    return yaml.safe_dump(doc, allow_unicode=False)


def run(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    """``reach ARGV`` in-process from ``cwd``: (exit code, stdout, stderr). Warnings count as
    stderr lines, as a user's terminal shows them."""
    out, err = io.StringIO(), io.StringIO()
    before = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
                warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                code = main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 2
    finally:
        os.chdir(before)
    shown = "".join(warnings.formatwarning(w.message, w.category, w.filename, w.lineno, "")
                    for w in caught)
    return code, out.getvalue(), shown + err.getvalue()


def prepare(case: dict, tmp: Path) -> list[str]:
    """Write the case's files into ``tmp``; its command line."""
    if "set" in case or "drop" in case:
        (tmp / "model.yaml").write_text(patched_model(case))
    if "model_text" in case:
        (tmp / "model.yaml").write_text(case["model_text"])
    if "model_padding" in case:                    # a comment line of that many bytes
        (tmp / "model.yaml").write_text("name: tank\n#" + "x" * case["model_padding"] + "\n")
    if "model_bytes" in case:
        (tmp / "model.yaml").write_bytes(bytes.fromhex(case["model_bytes"]))
    if "props_text" in case:
        (tmp / "props.yaml").write_text(case["props_text"])
    for name, text in (case.get("files") or {}).items():
        (tmp / name).write_text(_fill(text, tmp))
    for name, target in (case.get("links") or {}).items():
        os.symlink(target, tmp / name)
    return _fill(case["argv"], tmp)


def _snapshot(folder: Path) -> set:
    return {p.name for p in folder.iterdir()}


def test_the_table_has_at_least_100_cases_and_unique_names():
    names = [c["case"] for c in CASES]
    assert len(names) >= 100 and len(set(names)) == len(names)
    assert {c["exit"] for c in CASES} == CONTRACT


@pytest.mark.parametrize("case", CASES, ids=[c["case"] for c in CASES])
def test_case(case, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    argv = prepare(case, work)
    outside = _snapshot(tmp_path), _snapshot(REPO)
    code, out, err = run(argv, work)
    assert "Traceback" not in err and "Traceback" not in out
    assert code == case["exit"], f"exit {code}, stderr: {err!r}"
    first = err.splitlines()[0] if err else ""
    assert re.search(case["first_line"], first), f"first line {first!r}"
    if code == 2:
        assert err.count("\n") == 1, f"bad input is one line: {err!r}"
        assert "\x1b" not in err                       # control characters are escaped
    assert (_snapshot(tmp_path), _snapshot(REPO)) == outside, "wrote outside the working directory"
    assert not (work / "pwned").exists()


# ------------------------------------------------------------------ generated command lines

GOOD_MODEL = str(DATA / "tank.yaml")
GOOD_PROPS = str(DATA / "tank_level.yaml")
TEXT = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12)
NUMBERS = st.sampled_from(["0", "-1", "1e12", "nan", "inf", "-inf", "1e-300", "3", "0.5", "true", "[]", "{", "x"])
OPTIONS = st.builds(lambda k, v: f"{k}={v}", st.sampled_from(
    ["samples", "dt", "seed", "search_rounds", "step", "max_refinements", "order", "e_tol", "method", "bogus"]), NUMBERS)
PATHS = st.sampled_from([GOOD_MODEL, GOOD_PROPS, "/dev/zero", "/dev/null", "/etc/passwd", "/", "nope.yaml",
                         "../outside.yaml", str(REPO / "suite.yaml"), "-"]) | TEXT


@st.composite
def command_lines(draw):
    command = draw(st.sampled_from(["check", "replay", "compare", "lint", "plot", "sweep", "bench", "bogus"]))
    if command == "check":
        argv = ["check", draw(PATHS | st.just(GOOD_MODEL)), draw(PATHS | st.just(GOOD_PROPS))]
        argv += ["-b", draw(st.sampled_from(["montecarlo", "star", "fsr", "taylor", "nope"]))]
        for option in draw(st.lists(OPTIONS, max_size=3)):
            argv += ["-o", option]
        argv += ["-o", "samples=10", "-o", "search_rounds=0"] if argv[4] == "montecarlo" and draw(st.booleans()) else []
        return argv
    if command in ("replay", "lint"):
        return [command, draw(PATHS)]
    if command == "compare":
        return [command, draw(PATHS), draw(PATHS)]
    if command == "plot":
        return [command, draw(PATHS), "--runs", draw(NUMBERS), "--out", draw(st.sampled_from(["a.png", "a.xyz", "/proc/x.png", "a"]))]
    if command == "sweep":
        return [command, draw(PATHS), draw(PATHS), "--radius", draw(NUMBERS), "--cells", draw(NUMBERS)]
    if command == "bench":
        return [command, "--suite", draw(PATHS), "--time-limit", draw(NUMBERS), "--instance", "NOPE"]
    return [command] + draw(st.lists(TEXT, max_size=3))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(argv=command_lines())
def test_generated_command_lines_keep_the_contract(argv, tmp_path_factory):
    work = tmp_path_factory.mktemp("argv")
    outside = _snapshot(work.parent), _snapshot(REPO)
    code, out, err = run(argv, work)
    assert code in CONTRACT, (argv, code, err)
    assert "Traceback" not in err and "internal error" not in err, (argv, err)
    if code == 2:
        assert err.count("\n") == 1, (argv, err)
    assert (_snapshot(work.parent), _snapshot(REPO)) == outside


# ------------------------------------------------------------------ generated model files

FIELDS = ["name", "state", "state.h", "units", "units.time", "modes", "modes.fill", "modes.fill.flow",
          "modes.fill.flow.h", "modes.fill.invariant", "modes.drain.control", "transitions", "initial",
          "initial.mode", "initial.box", "initial.box.h", "horizon", "constants", "constants.k", "extends",
          "description", "disturbance", "inputs"]
VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6),
                   st.floats(allow_nan=True, allow_infinity=True), TEXT,
                   st.lists(st.integers(-5, 5) | TEXT, max_size=3),
                   st.dictionaries(TEXT, st.integers(0, 3) | TEXT, max_size=2),
                   st.sampled_from(["h**2", "h <= 1", "1[m]", "1[N]", "__import__('os')", "h.real", "x" * 300,
                                    "/dev/zero", "../../etc/passwd", "on", "[1, 2]", "(" * 200]))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.dictionaries(st.sampled_from(FIELDS), VALUES, min_size=1, max_size=3),
       command=st.sampled_from(["lint", "check"]))
def test_generated_models_keep_the_contract(changes, command, tmp_path_factory):
    """Loading, binding and linting a damaged model (the back-ends run on the table's cases; here
    ``check`` uses fsr, which answers at once on a deterministic model once it has loaded)."""
    work = tmp_path_factory.mktemp("model")
    doc = yaml.safe_load((DATA / "tank.yaml").read_text())
    for path, value in changes.items():
        *parents, last = path.split(".")
        node = doc
        for key in parents:
            if not isinstance(node.get(key), dict):
                node[key] = {}
            node = node[key]
        node[last] = value
    (work / "model.yaml").write_text(yaml.safe_dump(doc))
    outside = _snapshot(work.parent), _snapshot(REPO)
    argv = ["lint", "model.yaml"] if command == "lint" else ["check", "model.yaml", GOOD_PROPS, "-b", "fsr"]
    code, out, err = run(argv, work)
    assert code in CONTRACT, (changes, code, err)
    assert "Traceback" not in err and "internal error" not in err, (changes, err)
    if code == 2:
        assert err.count("\n") == 1, (changes, err)
    assert (_snapshot(work.parent), _snapshot(REPO)) == outside


def test_an_event_counterexample_replays_from_the_command_line(tmp_path):
    """``x' = v, v' = -x`` from x0 in [0.9, 1.1], v0 = 0: x(t) = x0 cos t, so the largest x is
    1.1 (at t = 0 and 2 pi), above the required 1.05. Monte Carlo's counterexample file replays:
    exit 1 and the extremum of the run it names, which the closed form gives."""
    (tmp_path / "m.yaml").write_text(
        "name: spring\nstate: [x, v]\nmodes:\n  m:\n    flow: {x: v, v: -x}\n"
        "initial: {mode: m, box: {x: [0.9, 1.1], v: 0}}\nhorizon: 7\n")
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: peak, kind: event, modes: [m], maximize: x, require: '<= 1.05'}\n")
    code, out, err = run(["check", "m.yaml", "p.yaml", "-b", "montecarlo", "--counterexamples", "cex"], tmp_path)
    assert code == 1, out + err
    path = next((tmp_path / "cex").glob("*.json"))
    x0 = json.loads(path.read_text())["initial_state"][0]
    code, out, err = run(["replay", str(path)], tmp_path)
    assert code == 1 and not err, out + err
    value = float(out.split("max x = ")[1].split()[0])
    assert value == pytest.approx(x0, abs=1e-4) and value > 1.05
    assert "required <= 1.05" in out


KICKED_DRIFT = """
name: kicked_drift
state: [x, v]
modes:
  coast: {flow: {x: v, v: 0}}
initial: {mode: coast, box: {x: 0, v: 0.1}}
horizon: 100
disturbance:
  gaussian: {mean: [0], cov: [1.0e-6]}
  enters: [v]
  step: 10
"""


@pytest.mark.parametrize("low, high, code, violated", [(20, 21, 1, True), (9, 11, 0, False)])
def test_a_probability_wholly_below_its_threshold_reads_as_a_violation(tmp_path, capsys, low, high, code,
                                                                      violated):
    """x(100) = 10 up to kicks of standard deviation 1e-3 m/s: P(x in [20, 21]) is 0 (below 0.9: a
    violation with no run to show, status UNKNOWN, exit 1, shown as VIOLATED and ``violated:
    true`` in --json), P(x in [9, 11]) is 1 (SAFE, exit 0)."""
    (tmp_path / "m.yaml").write_text(KICKED_DRIFT)
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: there, kind: reach, at: 100, target: "
                                     f"{{box: {{x: [{low}, {high}]}}}}, probability: {{at_least: 0.9}}}}\n")
    files = [str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "fsr"]
    assert main(["check", *files]) == code
    text = capsys.readouterr().out
    assert ("VIOLATED" in text) == violated and ("SAFE" in text) == (not violated)
    assert main(["check", *files, "--json"]) == code
    (row,) = json.loads(capsys.readouterr().out)
    assert row["violated"] is violated and row["status"] == ("unknown" if violated else "safe")


def test_a_reader_that_goes_away_ends_the_run_quietly(tmp_path):
    """``reach check ... | head`` whose reader has gone: no "internal error", and exit 3
    (nothing is claimed that the reader did not see)."""
    import subprocess
    import sys

    repo = Path(__file__).resolve().parent.parent
    proc = subprocess.Popen([sys.executable, "-m", "reach", "check", str(repo / "tests/data/tank.yaml"),
                             str(repo / "tests/data/tank_level.yaml"), "-b", "star"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    proc.stdout.close()                 # before reach has written anything
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 3 and "error" not in err, err


def test_a_check_where_no_property_applies_proves_nothing(capsys):
    """SRNA01 has no Passive mode, so the optional collision property does not apply: with it
    alone nothing is checked, which is undecided (3), not "every property SAFE" (0); beside a
    property that applies and holds, it is left out (0)."""
    args = ["check", "SRNA01", "properties/rendezvous.yaml", "-b", "star"]
    assert main([*args, "-p", "collision"]) == 3
    assert "not applicable" in capsys.readouterr().out
    assert main([*args, "-p", "collision", "-p", "velocity"]) == 0


def test_replay_shows_the_margin_in_the_requirements_unit(tmp_path, capsys):
    """th' = 0.01 rad/s from 0 over 2 s reaches 0.02 rad = 1.1459 deg; against th <= 1[deg] the
    replay's margins are in degrees as check's are: -0.1459 deg at the end (1 - 1.1459), not
    -0.002546 rad unlabelled."""
    (tmp_path / "m.yaml").write_text("name: slew\nunits: {length: m, time: s, mass: kg}\n"
                                     "state: {th: rad}\nmodes:\n  go: {flow: {th: '0.01[rad/s]'}}\n"
                                     "initial: {mode: go, box: {th: 0}}\nhorizon: 2\n")
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: cap, kind: safety, require: ['th <= 1[deg]']}\n")
    cex = tmp_path / "cx"
    assert main(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "star",
                 "--counterexamples", str(cex)]) == 1
    capsys.readouterr()
    (saved,) = cex.glob("*.json")
    assert main(["replay", str(saved)]) == 1
    out = capsys.readouterr().out
    assert "deg there" in out and "deepest -0.1459 deg along the run" in out
