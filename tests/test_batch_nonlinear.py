"""The batched RK4 of nonlinear modes (reach.model.batch_nonlinear).

References: ``scipy.integrate.solve_ivp`` (DOP853 at ``rtol = 1e-12``) on the SRNA01 flow for
the accuracy the module docstring states; the mode's own sympy right-hand side
(``Mode.rhs``) for the split flow (hypothesis); ``Simulator.propagate`` (the general path's
RK4) for one grid step; a replayed counterexample of a thin SRNA01 bound on the general path.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.model import load_model
from reach.model.batch_nonlinear import RK4Blocks, SplitFlow
from reach.model.simulate import Simulator

MODEL = load_model("models/SRNA01.yaml")


def _states(seed, count):
    rng = np.random.default_rng(seed)
    box_low = np.array([-1000.0, -500.0, -5.0, -5.0, 0.0])
    box_high = np.array([1000.0, 500.0, 5.0, 5.0, 240.0])
    return box_low + (box_high - box_low) * rng.random((count, MODEL.n))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from(["approach", "rendezvous"]))
def test_split_flow_equals_the_modes_right_hand_side(seed, mode):
    X = _states(seed, 7)
    split = SplitFlow(MODEL.modes[mode].flow, MODEL.symbols)
    got = split(np.ascontiguousarray(X.T)).T
    want = MODEL.modes[mode].rhs(X)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9 * np.abs(want).max())
    assert split.rows == [2, 3]              # only the accelerations have nonlinear terms


def test_one_grid_step_is_the_general_paths_rk4():
    sim = Simulator(MODEL)
    X = _states(3, 50)
    steps = RK4Blocks(SplitFlow(MODEL.modes["approach"].flow, MODEL.symbols), sim, "approach")
    np.testing.assert_allclose(steps.step(np.ascontiguousarray(X.T)).T, sim.propagate("approach", X, sim.dt),
                               rtol=1e-13, atol=1e-10)


def test_grid_states_against_solve_ivp_over_the_horizon():
    """From three corners of the initial box, every grid state of the 2400-step horizon is
    within 1e-7 of the DOP853 solution at rtol 1e-12, relative to ``1 + |x|_inf`` (measured
    3.0e-8: the RK4 truncation error of the fast closed-loop velocity modes, ``h lambda`` about
    0.15)."""
    sim = Simulator(MODEL)
    low, high = MODEL.initial.low, MODEL.initial.high
    X0 = np.array([low, high, [low[0], high[1], 0, 0, 0]])
    flow = SplitFlow(MODEL.modes["approach"].flow, MODEL.symbols)
    S = RK4Blocks(flow, sim, "approach").block(np.ascontiguousarray(X0.T), sim.steps + 1)   # (K, n, R)
    grid = np.arange(sim.steps + 1) * sim.dt
    rhs = MODEL.modes["approach"].rhs
    worst = 0.0
    for r, x0 in enumerate(X0):
        ref = solve_ivp(lambda t, z: rhs(z[None, :])[0], (0, grid[-1]), x0, method="DOP853", t_eval=grid,
                        rtol=1e-12, atol=1e-12)
        scale = np.abs(ref.y).max(axis=0)                       # per grid point
        worst = max(worst, float(np.max(np.abs(S[:, :, r] - ref.y.T).max(axis=1) / (1.0 + scale))))
    assert worst < 1e-7


def test_a_violation_found_on_the_block_path_replays_and_matches_solve_ivp(tmp_path):
    """Every SRNA01 run climbs from y < -375 m towards the target, so ``y <= -200 m`` fails mid-
    approach: the block path finds it, the general path replays it (UNSAFE only then), and the
    state at the reported instant is the DOP853 solution's (rtol 1e-12) to 1e-6 relative."""
    from reach.checking import check_files
    from reach.result import Status

    spec = tmp_path / "y.yaml"
    spec.write_text("properties:\n  - id: y_low\n    kind: safety\n    modes: [approach]\n"
                    "    require: [\"y <= -200[m]\"]\n")
    (result,) = check_files("models/SRNA01.yaml", str(spec), "montecarlo",
                            {"samples": 40, "search_rounds": 0, "optimise": False})
    assert result.status == Status.UNSAFE
    cex = result.counterexample
    assert cex.violation_time > 1.0 and cex.violation_state[1] > -200.0
    rhs = MODEL.modes["approach"].rhs
    ref = solve_ivp(lambda t, z: rhs(z[None, :])[0], (0, cex.violation_time), cex.initial_state,
                    method="DOP853", rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(cex.violation_state, ref.y[:, -1], rtol=1e-6, atol=1e-6)
