"""The lint of invariant faces where runs stop (reach.model.lint.blocking_faces): a run that
reaches its mode's invariant boundary with no transition enabled ends there, so nothing after
is checked. Held against the simulator (the runs really stop) and against dense sampling of the
faces (a sampled point of an exit face in no guard must be reported; no report, no such point)."""

from __future__ import annotations

import json

import numpy as np
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.cli import main as cli
from reach.model import load_model
from reach.model.lint import blocking_faces


def write(tmp_path, doc, name="m"):
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return load_model(path)


def one_mode(invariant, flow, transitions=(), horizon=10, box=None, inputs=None, state=("x", "t")):
    doc = {"name": "m", "state": list(state), "horizon": horizon,
           "modes": {"go": {"flow": flow, "invariant": list(invariant)}, "out": {"flow": {s: int(s == "t") for s in state}}},
           "transitions": list(transitions),
           "initial": {"mode": "go", "box": box or {"x": [0, 1], "t": 0}}}
    if inputs:
        doc["bounded_inputs"] = inputs
    return doc


def test_a_run_stopped_by_its_invariant_is_reported_and_warned_of_on_check(tmp_path, capsys):
    """x' = 1 under x <= 5 with no transition: every run ends at x = 5, by t = 5 of a horizon
    of 10. The lint says so, a check warns of it, and Monte Carlo's runs all stop early."""
    model = write(tmp_path, one_mode(["x <= 5"], {"x": 1, "t": 1}))
    findings = blocking_faces(model)
    assert len(findings) == 1 and not findings[0][1]
    assert "runs of mode 'go' that reach the boundary of x <= 5 stop there (no transition out of it is " \
           "enabled there)" in findings[0][0]
    assert model.warnings == [findings[0][0]]
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "xmax", "kind": "safety", "modes": ["go"], "require": ["x <= 6"]}]}))
    code = cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "montecarlo",
                "-o", "samples=200", "-o", "optimise=false"])
    out = capsys.readouterr()
    assert code == 3
    assert "warning:" in out.err and "x <= 5 stop there" in out.err
    assert "runs stopped before the horizon" in out.out
    code = cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "star", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert code == 0 and row["status"] == "safe" and row["model_warnings"] == model.warnings


def test_a_guard_on_the_face_clears_it(tmp_path):
    """The thermostat's pattern: the invariant's boundary is the guard of the way out."""
    doc = one_mode(["x <= 5"], {"x": 1, "t": 1}, [{"from": "go", "to": "out", "guard": ["x >= 5"], "urgent": True}])
    assert blocking_faces(write(tmp_path, doc)) == []


def test_a_face_the_flow_never_crosses_is_no_finding(tmp_path):
    """x' = 1 under x >= -3: a run only moves away from that boundary."""
    assert blocking_faces(write(tmp_path, one_mode(["x >= -3"], {"x": 1, "t": 1}))) == []


def test_guards_covering_the_face_together_clear_it_and_a_gap_is_partly(tmp_path):
    """Two guards split the face x = 5 at y = 0 between them: covered. With a gap between
    y <= -1 and y >= 1 the runs that reach x = 5 with |y| < 1 stop: a finding, but one that a
    guard meets in part, so only `reach lint` lists it (a check does not warn)."""
    box = {"x": [0, 1], "y": [-2, 2], "t": 0}
    flow = {"x": 1, "y": 0, "t": 1}
    state = ("x", "y", "t")
    split = [{"from": "go", "to": "out", "guard": ["x >= 5", "y <= 0"]},
             {"from": "go", "to": "out", "guard": ["x >= 5", "y >= 0"]}]
    assert blocking_faces(write(tmp_path, one_mode(["x <= 5"], flow, split, box=box, state=state))) == []
    gap = [{"from": "go", "to": "out", "guard": ["x >= 5", "y <= -1"]},
           {"from": "go", "to": "out", "guard": ["x >= 5", "y >= 1"]}]
    model = write(tmp_path, one_mode(["x <= 5"], flow, gap, box=box, state=state))
    findings = blocking_faces(model)
    assert len(findings) == 1 and findings[0][1]
    assert "on part of that boundary" in findings[0][0]
    assert model.warnings == [] and model.lints == [findings[0][0]]


def test_the_end_of_time_a_model_sets_itself_is_no_finding(tmp_path):
    """t <= 3 on the global clock (SpaceEx's usual way to stop time) stops every run at 3 by
    the model's own wish."""
    assert blocking_faces(write(tmp_path, one_mode(["t <= 3"], {"x": 1, "t": 1}))) == []


def test_inputs_pushing_out_are_a_finding_and_pulling_back_are_not(tmp_path):
    """x' = u under x <= 5: with u in [-1, 1] some runs reach x = 5 and stop; with u in
    [-1, -0.5] none moves towards it. Likewise for a constant input with those ranges."""
    both = one_mode(["x <= 5"], {"x": "u", "t": 1}, inputs={"u": {"range": [-1, 1], "varying": True}})
    assert len(blocking_faces(write(tmp_path, both))) == 1
    back = one_mode(["x <= 5"], {"x": "u", "t": 1}, inputs={"u": {"range": [-1, -0.5], "varying": True}})
    assert blocking_faces(write(tmp_path, back)) == []
    constant = one_mode(["x <= 5"], {"x": "u", "t": 1}, inputs={"u": {"range": [-1, 1]}})
    assert len(blocking_faces(write(tmp_path, constant))) == 1
    constant_back = one_mode(["x <= 5"], {"x": "u", "t": 1}, inputs={"u": {"range": [-1, -0.5]}})
    assert blocking_faces(write(tmp_path, constant_back)) == []


@settings(max_examples=40, deadline=None)
@given(a=st.sampled_from([-1.0, -0.5, 0.0, 0.5, 1.0]), b=st.sampled_from([-1.0, 0.0, 1.0]),
       cut=st.lists(st.tuples(st.sampled_from([-3.0, -1.0, 0.0, 1.5]), st.sampled_from([-1.0, 0.5, 2.0, 3.0])),
                    min_size=0, max_size=3))
def test_findings_agree_with_sampled_faces(tmp_path_factory, a, b, cut):
    """Invariant: the box |x| <= 2, |y| <= 2; flow x' = a y + b, y' = -x; the ways out are
    guards x >= 2, lo <= y <= hi (one per ``cut``). On the face x = 2 the flow points out
    where a y + b >= 0. Dense samples of that face (y on a grid of 4001 points) tell whether
    some point of it with the flow strictly out lies strictly in no guard: the lint must
    report mode 'go' exactly then (the other three faces are left with no guard, so they are
    reported whenever the flow crosses them, which it does: y' = -x points out of y = 2 at x < 0)."""
    tmp_path = tmp_path_factory.mktemp("faces")
    transitions = [{"from": "go", "to": "out", "guard": ["x >= 2", f"y >= {lo}", f"y <= {hi}"]}
                   for lo, hi in cut if lo <= hi]
    doc = {"name": "m", "state": ["x", "y"], "horizon": 5,
           "modes": {"go": {"flow": {"x": f"{a}*y + {b}", "y": "-x"}, "invariant": ["x <= 2", "x >= -2", "y <= 2", "y >= -2"]},
                     "out": {"flow": {"x": 0, "y": 0}}},
           "transitions": transitions, "initial": {"mode": "go", "box": {"x": [0, 0.5], "y": [0, 0.5]}}}
    model = write(tmp_path, doc)
    reported = {text for text, _ in blocking_faces(model)}
    face_reported = any("x <= 2" in text for text in reported)
    y = np.linspace(-2, 2, 4001)
    out = a * y + b > 1e-9
    inside = np.zeros_like(y, bool)
    for lo, hi in cut:
        if lo <= hi:
            inside |= (y >= lo - 1e-12) & (y <= hi + 1e-12)
    sampled_gap = bool(np.any(out & ~inside))
    if sampled_gap:
        assert face_reported
    else:
        # the lint works with strict slack: a gap narrower than the grid could still be real,
        # but none of these cuts leave one (their ends sit on the grid)
        assert not face_reported


def test_a_jump_into_a_target_whose_invariant_fails_after_it_leaves_the_face_open(tmp_path, capsys):
    """x' = 1, y' = 1 under x <= 5, left at x >= 5 for `out`, whose invariant y <= 3 fails after
    the jump for the runs from y in [4, 5]: the jump is not taken (the automaton's semantics),
    so those runs stop at x = 5 -- the simulator's runs do -- and the lint names the target's
    row. A reset y := 0 makes the row hold after every jump: no finding; nor where the mode keeps
    y (whether it holds was settled before the mode, a matter of reachability)."""
    flow = {"x": 1, "y": 1, "t": 1}
    tr = {"from": "go", "to": "out", "guard": ["x >= 5"], "urgent": True}
    doc = one_mode(["x <= 5"], flow, [tr], box={"x": [0, 1], "y": [0, 5], "t": 0}, state=("x", "y", "t"))
    doc["modes"]["out"]["invariant"] = ["y <= 3"]
    model = write(tmp_path, doc)
    (finding, partly), = blocking_faces(model)
    assert partly and "boundary of x <= 5" in finding and "'out': y <= 3" in finding
    assert model.warnings == []                   # a guard meets the face: `reach lint` only
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "ymax", "kind": "safety", "modes": ["go", "out"], "require": ["y <= 20"]}]}))
    code = cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "montecarlo",
                "-o", "samples=200", "-o", "optimise=false"])
    assert code == 3 and "runs stopped before the horizon" in capsys.readouterr().out
    doc["transitions"][0]["reset"] = {"y": 0}
    assert blocking_faces(write(tmp_path, doc, "reset")) == []
    doc["transitions"][0].pop("reset")
    doc["modes"]["go"]["flow"]["y"] = 0     # y held since the mode was entered: reachability's matter
    assert blocking_faces(write(tmp_path, doc, "kept")) == []


def test_both_faces_of_an_absolute_bound_are_stop_faces(tmp_path):
    """abs(x) <= 1 under x' = v, v in [-1, 1] held, with no way out: runs stop at x = 1 and at
    x = -1. Both faces are kept (star tests each), and the lint names the row once."""
    doc = one_mode(["abs(x) <= 1"], {"x": "v", "v": 0, "t": 1}, box={"x": [0, 0.5], "v": [-1, 1], "t": 0},
                   state=("x", "v", "t"))
    model = write(tmp_path, doc)
    assert len([f for f in model.stop_faces if f.mode == "go"]) == 2
    (finding, _), = blocking_faces(model)
    assert finding.count("abs(x) <= 1") == 1


def test_looser_copies_of_an_invariant_row_are_not_faces_of_their_own(tmp_path):
    """``x <= 5`` and 2999 looser ``x <= k``: only ``x <= 5`` has an exit face (the others lie
    beyond it), and only it is examined; each of the 3000 rows took two LPs of 3000 rows (40 s
    for the lint, a check never started)."""
    rows = ["x <= 5"] + [f"x <= {k}" for k in range(6, 3005)]
    findings = blocking_faces(write(tmp_path, one_mode(rows, {"x": 1, "t": 1})))
    assert len(findings) == 1
    assert "boundary of x <= 5 stop there" in findings[0][0]
