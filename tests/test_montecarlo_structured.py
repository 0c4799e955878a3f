"""The structured runs of Monte Carlo: held to what the user asked for, stopped by the time budget,
counted honestly in the result's details (counts only: no test reads a clock)."""

from __future__ import annotations

import numpy as np
import pytest

from reach.backends.montecarlo import sampling
from reach.backends.montecarlo.options import Options
from reach.backends.montecarlo.sampling import Batches, spread, structured_cap
from reach.checking import check_files
from reach.result import Status
from reach.stats import clopper_pearson_upper

QUIET = {"search_rounds": 0, "optimise": False, "dt": 0.1}
STATES = 8 + 2                  # four masses (position, velocity) and the two inputs, carried as states
STEPS = 300                     # horizon 30 / dt 0.1


def _chain(tmp_path, invariant: bool = False):
    """A damped chain of four masses driven at its ends by two bounded varying forces, from a
    box of eight free coordinates: a plan of 3385 structured runs (corners, faces and centre with
    constant, bang-bang and one-switch input signals). ``invariant``: a mode invariant no run
    reaches, which puts the runs on the simulator's general path (stopped under way by a
    deadline) instead of its one-linear-mode path."""
    inv = '\n    invariant: ["x1 <= 1000"]' if invariant else ""
    box = ", ".join(f"{s}{i}: [-0.1, 0.1]" for i in range(1, 5) for s in "xv")
    (tmp_path / "chain.yaml").write_text(f"""name: chain
state: [x1, v1, x2, v2, x3, v3, x4, v4]
bounded_inputs:
  u1: {{range: [-0.1, 0.1], varying: true}}
  u2: {{range: [-0.1, 0.1], varying: true}}
modes:
  run:{inv}
    flow:
      x1: v1
      v1: "-2*x1 + x2 - 0.1*v1 + u1"
      x2: v2
      v2: "x1 - 2*x2 + x3 - 0.1*v2"
      x3: v3
      v3: "x2 - 2*x3 + x4 - 0.1*v3"
      x4: v4
      v4: "x3 - 2*x4 - 0.1*v4 + u2"
initial:
  mode: run
  box: {{{box}}}
horizon: 30
""")
    (tmp_path / "props.yaml").write_text(
        "properties:\n"
        "  - {id: bounded, kind: safety, modes: [run], require: ['abs(x1) <= 10', 'abs(x4) <= 10']}\n"
        "  - {id: peak, kind: event, modes: [run], maximize: x1, require: '<= 10'}\n")
    return tmp_path / "chain.yaml", tmp_path / "props.yaml"


def _check(paths, options, prop="bounded"):
    (result,) = check_files(*paths, "montecarlo", options, only=[prop])
    return result


PLANNED = 3385


def test_a_plan_of_cheap_runs_runs_whole_whatever_the_samples(tmp_path):
    """3385 runs of 300 steps on 10 states are 1e7 state-steps, within STRUCTURED_WORK: all run,
    with one sample asked for, and nothing is said to be left out."""
    r = _check(_chain(tmp_path), {**QUIET, "samples": 1})
    assert r.status == Status.UNKNOWN
    assert r.details["structured_runs"] == r.details["structured_planned"] == PLANNED
    assert "structured_left_out" not in r.details and "structured_note" not in r.details
    assert r.details["random_runs"] == 1
    # the violation bound counts the one i.i.d. sample, not the thousands of structured runs
    assert r.details["violation_probability_upper_95"] == pytest.approx(clopper_pearson_upper(0, 1))


def test_one_sample_of_long_runs_gets_the_documented_number_of_structured_runs(tmp_path, monkeypatch):
    """Where the structured runs are long (here a work allowance of 20 runs' worth), ``samples=1``
    runs at most ``max(8 x samples, runs that fit in STRUCTURED_WORK)`` of them, spread over the
    plan, and the details say how many were planned, run and left out by the cap, and why."""
    monkeypatch.setattr(sampling, "STRUCTURED_WORK", 20 * STEPS * STATES)
    opts = {**QUIET, "samples": 1}
    cap = structured_cap(Options.from_dict(opts), STEPS, STATES)
    assert cap == max(sampling.STRUCTURED_PER_SAMPLE * 1, 20) == 20
    r = _check(_chain(tmp_path), opts)
    d = r.details
    assert d["structured_runs"] == cap and d["structured_planned"] == PLANNED
    assert d["structured_left_out"] == {"cap": PLANNED - cap, "time_budget": 0}
    assert f"{cap} of {PLANNED} planned structured runs" in d["structured_note"]
    assert "option structured" in d["structured_note"] and "random runs only" in d["structured_note"]
    assert d["random_runs"] == 1
    assert d["violation_probability_upper_95"] == pytest.approx(clopper_pearson_upper(0, 1))
    # more samples, more structured runs: 8 per sample
    (more,) = check_files(*_chain(tmp_path), "montecarlo", {**QUIET, "samples": 40}, only=["bounded"])
    assert more.details["structured_runs"] == 8 * 40


@pytest.mark.parametrize("asked", [0, 7, PLANNED, 10 * PLANNED])
def test_the_structured_option_caps_the_plan(tmp_path, asked):
    """``-o structured=N`` runs at most N structured runs (0: none, and no aimed input signals,
    which start from them), safety and event properties alike."""
    paths = _chain(tmp_path)
    for prop in ("bounded", "peak"):
        r = _check(paths, {**QUIET, "samples": 3, "structured": asked}, prop)
        assert r.status == Status.UNKNOWN
        ran = min(asked, PLANNED)
        assert r.details["structured_runs"] == ran and r.details["structured_planned"] == PLANNED
        if ran < PLANNED:
            assert r.details["structured_left_out"] == {"cap": PLANNED - ran, "time_budget": 0}
            assert "option structured" in r.details["structured_note"]
        else:
            assert "structured_left_out" not in r.details
    assert r.details["runs"] == min(asked, PLANNED) + 3 and r.details["iid_runs"] == 3


@pytest.mark.parametrize("invariant", [False, True])
@pytest.mark.parametrize("prop", ["bounded", "peak"])
def test_a_spent_time_budget_stops_the_structured_runs(tmp_path, monkeypatch, invariant, prop):
    """With the budget spent before the runs begin, only the first batch of structured runs
    starts; the others are left out by the time budget (counted and named), no i.i.d. run is
    sampled and the violation bound is 1. On the simulator's general path the first batch's
    runs stop at once (cut, left out of the bound); on its one-linear-mode path it runs to
    its end."""
    monkeypatch.setattr(sampling, "FIRST_BATCH_WORK", 10 * STEPS * STATES)
    r = _check(_chain(tmp_path, invariant), {**QUIET, "samples": 50, "max_seconds": 1e-9}, prop)
    d = r.details
    assert r.status == Status.UNKNOWN
    assert d["structured_runs"] == 10 and d["structured_planned"] == PLANNED
    assert d["structured_left_out"] == {"cap": 0, "time_budget": PLANNED - 10}
    assert "by the time budget" in d["structured_note"]
    assert f"ended the structured runs after 10 of {PLANNED}" in d["note"]
    assert "after 0 of 50 random runs" in d["note"]
    assert d["violation_probability_upper_95"] == 1.0
    if invariant:
        assert d["cut_runs"] == 10 and "cut short" in d["note"]
    else:
        assert "cut_runs" not in d
    if prop == "bounded":
        assert d["random_runs"] == 0
    else:
        assert d["iid_runs"] == 0 and d["runs"] == 10


def test_a_structured_violation_is_still_found_with_one_sample():
    """The thrust bound of SRA01 is broken at a corner of the initial box at t = 0: its plan is
    cheap, so it runs whole with one sample asked for, and the structured runs find it."""
    (r,) = check_files("models/SRA01.yaml", "properties/thrust_7N.yaml", "montecarlo",
                       {"samples": 1, "search_rounds": 0, "optimise": False})
    assert r.status == Status.UNSAFE and r.details["found_in"] == "structured+random"
    assert r.details["structured_runs"] == r.details["structured_planned"]
    assert r.counterexample.violation_time == 0.0


def test_spread_takes_one_run_in_each_stretch():
    for total, count in [(10, 10), (3385, 66), (7, 1), (1000, 999)]:
        pick = spread(total, count, seed=0)
        edges = np.floor(np.linspace(0, total, count + 1)).astype(int)
        assert pick.size == count and np.all((pick >= edges[:-1]) & (pick < edges[1:]))
        assert np.array_equal(pick, spread(total, count, seed=0))
    assert not np.array_equal(spread(3385, 66, 0), spread(3385, 66, 1))


def test_batches_depend_on_the_plan_only_without_a_budget(monkeypatch):
    """Sizes: all at once up to BATCH_WORK; else a first batch of FIRST_BATCH_WORK, then four
    times larger up to BATCH_WORK, covering every run once. With a spent budget only the first
    starts."""
    monkeypatch.setattr(sampling, "FIRST_BATCH_WORK", 1000.0)
    monkeypatch.setattr(sampling, "BATCH_WORK", 50_000.0)
    small = list(Batches(40, 100, 10))          # 40 runs x 1000 state-steps <= 50000
    assert small == [(0, 40)]
    runs = list(Batches(200, 100, 10))
    sizes = [b - a for a, b in runs]
    assert sizes == [1, 4, 16, 50, 50, 50, 29]
    assert [a for a, _ in runs] == list(np.cumsum([0] + sizes[:-1]))
    assert list(Batches(200, 100, 10)) == runs
    assert list(Batches(200, 100, 10, deadline=0.0)) == [(0, 1)]
    assert list(Batches(0, 100, 10)) == []


BUSY = """name: busy
state: [x, t, c]
modes:
  start:
    flow: {x: '0', t: '1', c: '0'}
    invariant: [t <= 0]
  calm:
    flow: {x: '0', t: '1', c: '0'}
  busy:
    flow: {x: '0', t: '1', c: '1'}
initial:
  mode: start
  constraints: [x >= 0, x <= 1, t == 0, c == 0]
transitions:
  to_calm: {from: start, to: calm, guard: [x <= 0.6], urgent: true}
  to_calm2: {from: start, to: calm, guard: [x >= 0.8], urgent: true}
  to_busy: {from: start, to: busy, guard: [x >= 0.6, x <= 0.8], urgent: true}
  tick: {from: busy, to: busy, guard: [c >= 0.01], reset: {c: '0'}, urgent: true}
horizon: 20
"""


@pytest.mark.parametrize("kind,body", [("safety", "avoid: [t >= 19.9]"),
                                       ("event", "maximize: t\n    require: '<= 19.9'")])
def test_runs_a_budget_cuts_count_as_violating_in_the_bound(tmp_path, kind, body):
    """The runs from x in [0.6, 0.8] (P = 0.2) enter 'busy', jump every 0.01 and violate at
    t = 19.9; the others idle in 'calm' and finish at once. A budget cuts the slow, violating
    runs: left out of the bound, they would leave only clean runs behind it (a bound of 0.004
    against a probability of 0.2). Counted as violating, the bound is at least the one of the
    same runs without a budget, whatever the machine's speed (the one block of random runs starts
    at once, or none does and the bound is 1)."""
    (tmp_path / "m.yaml").write_text(BUSY)
    (tmp_path / "p.yaml").write_text(f"properties:\n  - id: late\n    kind: {kind}\n    modes: [busy]\n    {body}\n")
    options = {"dt": 0.005, "search_rounds": 0, "optimise": False, "structured": 4}
    free = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo", options)[0]
    cut = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo", {**options, "max_seconds": 0.05})[0]
    assert free.status is Status.UNSAFE
    assert cut.status is not Status.SAFE
    if kind == "safety" and cut.details.get("cut_runs"):       # said as cut short, not as stopped runs
        from reach.checking import load_bound
        from reach.report import line
        model, props = load_bound(tmp_path / "m.yaml", tmp_path / "p.yaml")
        text = line(cut, props[0], model)
        assert "cut short before the horizon" in text and "runs stopped before the horizon" not in text, text
    if cut.status is Status.UNKNOWN:
        bound = cut.details["violation_probability_upper_95"]
        violating = free.details.get("violating_runs", free.details.get("iid_violations"))
        assert bound >= clopper_pearson_upper(violating or 0, 1000) - 1e-12, cut.details
