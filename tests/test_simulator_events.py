"""Urgent transitions that hold right after a jump (reach.model.simulate, ``Simulator._urgent_now``)
against the closed form of a three-mode model.

Model (state ``x, y``): in ``a`` the clock ``x`` runs (``x' = 1``); the urgent ``go`` (guard
``x >= 1``) jumps to ``b`` with ``x := 2, y := y + 1``; in ``b`` the urgent ``land`` (guard ``x >= 2``)
holds at once, exactly on its boundary, and jumps to ``c`` with ``x := 0, y := 10 y``; in ``c``
``x' = 1`` again. ``b``'s flow ``x' = -100`` leaves ``land``'s guard at once, so the jump is taken
only if the simulator tests the guard right after the jump: no grid point ever sees it.

A run from ``(x_0, y_0)`` reaches ``go`` at ``t_1 = max(0, 1 - x_0)`` (at once when it starts
inside the guard, also exactly on its boundary ``x_0 = 1``), then ends in ``c`` with
``x(T) = T - t_1`` and ``y(T) = 10 (y_0 + 1)``, never spending time in ``b``.
"""

from __future__ import annotations

import functools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.model import load_model
from reach.model.simulate import Simulator

HORIZON = 2.0
MODEL = f"""name: chain_after_jump
state: [x, y]
modes:
  a: {{flow: {{x: 1, y: 0}}}}
  b: {{flow: {{x: -100, y: 0}}}}
  c: {{flow: {{x: 1, y: 0}}}}
transitions:
  go: {{from: a, to: b, urgent: true, guard: ["x >= 1"], reset: {{x: "2", y: "y + 1"}}}}
  land: {{from: b, to: c, urgent: true, guard: ["x >= 2"], reset: {{x: "0", y: "10*y"}}}}
initial: {{mode: a, box: {{x: [0, 2], y: [-1, 1]}}}}
horizon: {HORIZON}
"""


@functools.cache
def simulator(directory) -> Simulator:
    path = directory / "chain_after_jump.yaml"
    path.write_text(MODEL)
    return Simulator(load_model(path))


@given(x0=st.lists(st.floats(0.0, 2.0), min_size=1, max_size=6), y0=st.floats(-1.0, 1.0))
@settings(max_examples=15)
def test_a_guard_that_holds_after_a_jump_is_taken_at_once(tmp_path_factory, x0, y0):
    """Runs below, on and inside ``go``'s guard in one batch (the boundary run always in)."""
    sim = simulator(tmp_path_factory.getbasetemp())
    x0 = np.array([*x0, 1.0])
    y = y0 + 0.1 * np.arange(x0.size)
    traj = sim.run(np.column_stack([x0, y]), record=True)
    t1 = np.maximum(0.0, 1.0 - x0)
    c = sim.mode_names.index("c")
    np.testing.assert_array_equal(traj.final_mode, c)
    np.testing.assert_allclose(traj.final_state[:, 0], HORIZON - t1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(traj.final_state[:, 1], 10.0 * (y + 1.0), rtol=0, atol=1e-12)
    for i in range(x0.size):
        t, mode, X = traj.path[i]
        arrived = int(np.flatnonzero(mode == c)[0])
        assert abs(t[arrived] - t1[i]) <= 1e-9
        np.testing.assert_array_equal(X[arrived], [0.0, 10.0 * (y[i] + 1.0)])
        assert np.all(t[mode != c] <= t1[i] + 1e-9)       # no time in a after t_1, none in b
