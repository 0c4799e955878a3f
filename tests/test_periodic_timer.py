"""A periodic timer: a clock reset by the transition its own guard enables, the sampled-data
pattern of SpaceEx files (``t == 1`` to ``t := 0``, not urgent, the invariant ``t <= 1`` forcing
the tick). Such a guard is no window of the run's time (a once-only switch instant): every
tick is taken. Closed form from ``c(0) = c0``: ticks at ``k - c0`` (k = 1, 2, ...), ``x(T) = T``
and ``c(T) = (c0 + T) mod 1``."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND as STAR
from reach.model.simulate import Simulator
from reach.result import Status
from model_files import load_files

HORIZON = 3.0


def _timer(c0: str) -> str:
    return f"""
name: periodic_timer
state: [c, x]
modes:
  run: {{flow: {{c: 1, x: 1}}, invariant: ["c <= 1"]}}
transitions:
  - {{from: run, to: run, guard: ["c >= 1", "c <= 1"], reset: {{c: "0"}}}}
initial: {{mode: run, box: {{c: {c0}, x: 0}}}}
horizon: {HORIZON}
"""


PROPERTY = "properties:\n  - {id: below, kind: safety, require: ['x <= 2.5']}\n"


@settings(max_examples=15, deadline=None)
@given(c0=st.floats(0.01, 0.9))          # (from 0 the last tick falls on the horizon)
def test_every_tick_is_taken_at_its_closed_form_instant(tmp_path_factory, c0):
    model, _ = load_files(tmp_path_factory.mktemp("timer"), _timer(repr(c0)), PROPERTY)
    assert all(tr.window is None for tr in model.transitions)
    traj = Simulator(model).run(np.array([[c0, 0.0]]), record=True)
    assert np.isnan(traj.blocked_at[0])
    t, _, states = traj.path[0]
    ticks = t[1:][np.diff(states[:, 0]) < -0.5]                 # c falls back to 0
    want = np.arange(1, HORIZON + 1) - c0
    np.testing.assert_allclose(ticks, want[want < HORIZON - 1e-9], atol=1e-9)
    np.testing.assert_allclose(states[-1], [(c0 + HORIZON) % 1.0, HORIZON], atol=1e-9)


def test_a_timer_from_zero_is_no_window_and_both_backends_find_the_violation(tmp_path):
    """From ``c = 0`` the clock was once read as the run's time, the guard as a window
    ``[1, 1]`` taken once: every run was blocked at the second tick (t = 2), and x <= 2.5,
    violated at t = 2.5, came out UNKNOWN from both back-ends."""
    model, props = load_files(tmp_path, _timer("0"), PROPERTY)
    assert all(tr.window is None for tr in model.transitions)
    for backend in (STAR, MONTECARLO):
        result = backend.check(model, props["below"], {})
        assert result.status is Status.UNSAFE, (backend, result.details)
        c = result.counterexample
        rep = replay(model, props["below"], c.initial_state, c.switch_time)
        assert rep.violated and abs(rep.time - 2.5) < 0.01
