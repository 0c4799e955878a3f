"""Paths of hundreds of jumps: star follows them (the search runs with a deep stack,
:mod:`reach.deep`) and aggregates the successors of constant-flow modes on long paths, so a
counter ticking 400 times is decided with memory that does not grow with the square of the
path. The reference is the closed form: from ``x0`` in ``[0, 0.5]`` the counter ``c`` steps at
``t = k - x0``, so it reaches ``k`` first at ``t = k - 0.5`` and is ``400`` at most by the horizon
400 (``399`` at least)."""

from __future__ import annotations

import signal
import sys
import threading

import pytest

from reach.backends.star import BACKEND
from reach.deep import FRAMES, call_deep
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties
from model_files import load_files

TICK = """
name: tick
state: [x, c, t]
modes:
  run:
    flow: {x: "1", c: "0", t: "1"}
    invariant: ["x <= 1"]
transitions:
  - {from: run, to: run, guard: ["x >= 1"], reset: {x: "0", c: "c + 1"}, urgent: true}
initial: {mode: run, box: {x: [0, 0.5], c: [0, 0], t: [0, 0]}}
horizon: 400
"""


PROPERTIES = """
properties:
  - {id: at_most, kind: safety, require: ['c <= 400.2']}
  - {id: below, kind: safety, require: ['c <= 399.5']}
"""


def loaded(folder, horizon: float):
    (folder / f"m{horizon:g}.yaml").write_text(TICK.replace("horizon: 400", f"horizon: {horizon:g}"))
    (folder / "p.yaml").write_text(PROPERTIES)
    model = load_model(folder / f"m{horizon:g}.yaml")
    return model, {p.id: bind(p, model) for p in load_properties(folder / "p.yaml")}


@pytest.fixture(scope="module")
def tick(tmp_path_factory):
    return loaded(tmp_path_factory.mktemp("tick"), 400)


def test_four_hundred_jumps_are_proved(tick):
    model, props = tick
    result = BACKEND.check(model, props["at_most"])
    assert result.status is Status.SAFE, result.details.get("reason")
    assert result.details["jumps"] >= 399


def test_the_four_hundredth_tick_is_found_and_replayed(tick):
    """``c = 400`` first at ``t = 399.5``, from ``x0 = 0.5``."""
    model, props = tick
    result = BACKEND.check(model, props["below"])
    assert result.status is Status.UNSAFE, result.details.get("reason")
    assert result.counterexample is not None
    assert result.details["witness"]["initial_state"][0] == pytest.approx(0.5, abs=1e-6)


def test_drift_aggregation_is_what_keeps_the_stars_small(tmp_path):
    """Without it every level of a 300-jump path holds a star of one more coefficient; with it
    the successors become aggregates once their stars hold more than 256, with the same verdict."""
    model, props = loaded(tmp_path, 300)
    plain = BACKEND.check(model, props["at_most"], {"aggregate_drift_coefficients": None})
    merged = BACKEND.check(model, props["at_most"], {})
    assert plain.status is Status.SAFE and merged.status is Status.SAFE
    assert plain.details["aggregates"] == 0 < merged.details["aggregates"]


def test_a_deep_recursion_runs_and_a_deeper_one_ends_cleanly():
    def depth(k):
        return 0 if k == 0 else 1 + depth(k - 1)

    assert call_deep(lambda: depth(FRAMES // 2), threading.Event()) == FRAMES // 2
    with pytest.raises(RecursionError):
        call_deep(lambda: depth(2 * FRAMES), threading.Event())
    assert sys.getrecursionlimit() < FRAMES          # restored


class _Interrupted(Exception):
    pass


def _interrupt(signum, frame):
    raise _Interrupted()


@pytest.mark.skipif(not hasattr(signal, "SIGALRM"), reason="needs SIGALRM")
def test_an_interrupted_caller_stops_the_search_before_going_on():
    """The time limit of a bench unit arrives as an exception in the waiting thread: the search
    is told to stop (``cancel``) and has ended when the exception reaches the caller."""
    cancel, ended = threading.Event(), threading.Event()

    def search():
        while not cancel.wait(0.01):
            pass
        ended.set()

    previous = signal.signal(signal.SIGALRM, _interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.2)
        with pytest.raises(_Interrupted):
            call_deep(search, cancel)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert cancel.is_set() and ended.is_set()


def test_a_time_budget_ends_a_long_chain_in_unknown(tmp_path):
    """``max_seconds`` is checked at every invariant step and LP, not only between chains."""
    model, props = loaded(tmp_path, 400)
    result = BACKEND.check(model, props["at_most"], {"step": 1e-3, "max_seconds": 0.2, "finer_retry": False})
    assert result.status is Status.UNKNOWN
    assert "time budget of 0.2 s exhausted" in result.details["reason"]


OSCILLATOR = """
name: spring
state: [x, v]
modes:
  free: {flow: {x: "v", v: "-x"}}
initial: {mode: free, box: {x: [0.9, 1.1], v: [0, 0]}}
horizon: 10
"""


@pytest.mark.parametrize("bound,status", [(1.1 + 1e-6, Status.SAFE), (-1.1 - 1e-6, Status.SAFE),
                                          (1.09, Status.UNSAFE), (-1.09, Status.UNSAFE)])
def test_a_chain_too_long_to_hold_is_explored_in_blocks_with_the_same_verdicts(tmp_path, monkeypatch, bound,
                                                                                status):
    """``x = x0 cos t``: its extremes are ``+-1.1`` (at ``t = 0, pi, 2 pi, 3 pi``). With room for
    only 13 grid stars at a time, the chain of 600 cells runs in blocks, each from the last grid
    star of the one before, and proves and refutes the same bounds."""
    import reach.backends.star.explorer as explorer
    (tmp_path / "m.yaml").write_text(OSCILLATOR)
    require = f"x <= {bound}" if bound > 0 else f"x >= {bound}"
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: b, kind: safety, require: ['{require}']}}\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    options = {"step": 10 / 600, "finer_retry": False}
    whole = BACKEND.check(model, prop, options)
    monkeypatch.setattr(explorer, "MAX_CHAIN_BYTES", 8 * 3 * 3 * 4 * 14)    # n = 3 (clock), m = 3
    blocks = BACKEND.check(model, prop, options)
    assert whole.status is status and blocks.status is status, (whole.details.get("reason"),
                                                                 blocks.details.get("reason"))
    if status is Status.SAFE:                    # (a violation is found in the first block)
        assert "explored in blocks" in blocks.details["semantics"]
        assert "explored in blocks" not in whole.details["semantics"]


def test_a_long_quiet_exploration_says_once_that_it_is_still_going(tmp_path, monkeypatch, caplog):
    import logging

    import reach.backends.star.explorer as explorer
    monkeypatch.setattr(explorer, "QUIET_HINT_SECONDS", 0.0)
    model, props = loaded(tmp_path, 20)
    with caplog.at_level(logging.WARNING, logger="reach"):
        BACKEND.check(model, props["at_most"], {})
    hints = [r.getMessage() for r in caplog.records if "still exploring" in r.getMessage()]
    assert len(hints) == 1 and "-o max_seconds" in hints[0]


DOCK = """
name: dock
state: [x, v]
bounded_inputs:
  u: {range: [-0.1, 0.1], varying: true}
modes:
  approach: {flow: {x: v, v: u}, invariant: ["x <= 0"]}
  recoil: {flow: {x: v, v: u}}
transitions:
  - {from: approach, to: recoil, guard: ["x >= 0"], reset: {v: "-0.5*v", x: "x - 0.02"}, urgent: true}
initial: {mode: approach, box: {x: [-1, -0.9], v: [0.2, 0.3]}}
horizon: 10
"""


@pytest.mark.parametrize("budget", [2.0, 6.0])
def test_one_time_budget_bounds_every_pass_of_a_check(tmp_path, budget):
    """A clockless model with a time-varying input whose bound star cannot settle quickly (it
    holds: the largest x in recoil is about 1.82, from bang-bang inputs): the first pass, the
    clockless model's second pass and the finer passes share one budget, which the reason
    names as given."""
    import time

    model, props = load_files(tmp_path, DOCK, "properties:\n  - {id: far, kind: safety, modes: [recoil], "
                                              "require: ['x <= 2.0']}\n")
    prop = props["far"]
    started = time.perf_counter()
    result = BACKEND.check(model, prop, {"max_seconds": budget})
    elapsed = time.perf_counter() - started
    assert result.status is not Status.UNSAFE
    if result.status is Status.UNKNOWN:
        assert f"time budget of {budget:g} s exhausted (option max_seconds)" in result.details["reason"]
    assert elapsed < 1.5 * budget + 2.0
