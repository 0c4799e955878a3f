"""taylor on an event property whose bound reaches past the requirement: a subdomain point is
replayed, and a run that breaks it makes the answer UNSAFE with a counterexample that replays."""

from __future__ import annotations

import numpy as np

from reach.backends.montecarlo import replay
from reach.backends.taylor import BACKEND
from reach.result import Status
from model_files import load_files

# x'' = -x from x0 in [0.9, 1.1], v0 = 0: v = -x0 sin t, min v = -x0 (at t = pi / 2)
OSCILLATOR = """
name: osc
state: [x, v]
modes:
  run: {flow: {x: v, v: "-x"}}
initial: {mode: run, box: {x: [0.9, 1.1], v: 0}}
horizon: 3
"""


def test_a_broken_event_bound_is_unsafe_with_a_replayed_run(tmp_path):
    """min v >= -1.05 fails for x0 > 1.05; the estimated and the rigorous check both answer UNSAFE
    (before: UNKNOWN, with the bound past the requirement and no run), and the counterexample's
    initial state is one whose closed-form minimum breaks the bound."""
    model, props = load_files(tmp_path, OSCILLATOR, """
        properties:
          - {id: vmin, kind: event, modes: [run], minimize: v, require: ">= -1.05"}
    """)
    for options in ({}, {"remainder": "rigorous"}):
        result = BACKEND.check(model, props["vmin"], options)
        assert result.status is Status.UNSAFE
        x0 = result.counterexample.initial_state
        assert -x0[0] < -1.05
        assert replay(model, props["vmin"], np.array(x0), None).violated


def test_a_bound_met_by_every_run_finds_no_witness(tmp_path):
    """min v >= -1.2 holds (min v = -1.1): no replay breaks it, so no UNSAFE."""
    model, props = load_files(tmp_path, OSCILLATOR, """
        properties:
          - {id: vmin, kind: event, modes: [run], minimize: v, require: ">= -1.2"}
    """)
    for options in ({}, {"remainder": "rigorous"}):
        assert BACKEND.check(model, props["vmin"], options).status is not Status.UNSAFE
