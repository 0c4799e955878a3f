"""Batched nominal runs (reach.backends.taylor.nominal): each run of a batch is the run on its own,
and follows scipy's solve_ivp (DOP853: the same steps; dense 1e-12 solutions and terminal events)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.integrate import solve_ivp

from reach.backends.taylor.nominal import DENSE_TOL, dop853, nominal, nominal_batch, _rows
from reach.backends.taylor.units import problem
from reach.model import load_model
from reach.spec import bind, load_properties


@pytest.fixture(scope="module")
def siren():
    model = load_model("models/cw_siren.yaml")
    prop = bind(load_properties("properties/cw_siren.yaml")[0], model)
    return model, problem(model, prop).code("transfer")


def _starts(model, count, seed):
    low, high = model.initial.low, model.initial.high
    return low + (high - low) * np.random.default_rng(seed).random((count, model.n))


def _scipy(code, x0, T, rtol, **kw):
    fun = lambda t, x: np.array(code.f_numeric(list(x)), dtype=float)
    return solve_ivp(fun, (0.0, T), x0, method="DOP853", rtol=rtol, atol=rtol * np.maximum(1.0, np.abs(x0)), **kw)


def test_batched_runs_are_the_single_runs_and_follow_solve_ivp(siren):
    """Five CW SIREN starts, stopped at the docking guard: the batch gives each run exactly its own
    nodes and dense solution; the coarse steps and the stop time are solve_ivp's with a terminal
    event, and the dense solution is solve_ivp's 1e-12 solution to 1e-9."""
    model, code = siren
    X = _starts(model, 5, 1)
    stops = [code.stop(x) for x in X]
    batch = nominal_batch(code.f_numeric, X, np.full(5, model.horizon), 1e-9, stops)
    for x, stop, run in zip(X, stops, batch):
        alone = nominal(code.f_numeric, x, model.horizon, 1e-9, stop=stop)
        np.testing.assert_array_equal(run.nodes, alone.nodes)
        np.testing.assert_array_equal(run.grid(), alone.grid())
        event = lambda t, y: stop(y[None, :])[0]
        event.terminal, event.direction = True, -1
        ref = _scipy(code, x, model.horizon, 1e-9, events=event)
        assert ref.status == 1
        coarse = run.nodes[: 2 * len(ref.t) - 1: 2]
        np.testing.assert_allclose(coarse, ref.t, rtol=1e-9)
        assert run.nodes[-1] > ref.t[-1]                      # one step past the crossing
        dense = _scipy(code, x, run.nodes[-1], DENSE_TOL, dense_output=True)
        times = np.linspace(0.0, run.nodes[-1], 301)
        np.testing.assert_allclose(run.solution(times), dense.sol(times), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(run.solution(float(times[77])), dense.sol(times[77]), rtol=1e-9, atol=1e-9)


def test_steps_are_scipys(siren):
    """Over the first hour (no stop), the accepted steps of each batched run are solve_ivp's.

    The batch evaluates the field row-wise (vectorised numpy and BLAS kernels) where solve_ivp
    calls it per state, so the two differ in the last bits of each evaluation; the step control
    carries that over some hundred steps, hence steps to 1e-9 and the end state to 1e-6 relative
    (a different method or error norm would differ in the first digits)."""
    model, code = siren
    X = _starts(model, 4, 2)
    runs = dop853(_rows(code.f_numeric), np.zeros(4), X, np.full(4, 3600.0), 1e-9, 1e-9 * np.maximum(1.0, np.abs(X)))
    for x, run in zip(X, runs):
        ref = _scipy(code, x, 3600.0, 1e-9)
        assert len(run.t) == len(ref.t)
        np.testing.assert_allclose(run.t, ref.t, rtol=1e-9)
        np.testing.assert_allclose(run.y, ref.y[:, -1], rtol=1e-6, atol=1e-9)


def _pendulum(values):
    theta, omega = values[0], values[1]
    return [omega, -np.sin(theta) - 0.1 * omega]


@settings(max_examples=15, deadline=None)
@given(st.lists(st.tuples(st.floats(-3.0, 3.0), st.floats(-2.0, 2.0), st.floats(0.5, 20.0)),
                min_size=1, max_size=6))
def test_any_batch_of_pendulum_runs(cases):
    """Damped pendulums from random states over random spans: every run of the batch equals its run
    alone (the same nodes, bit for bit) and the dense solution ends at solve_ivp's state."""
    X = np.array([[a, b] for a, b, _ in cases])
    T = np.array([t for _, _, t in cases])
    batch = nominal_batch(_pendulum, X, T, 1e-9, [None] * len(cases))
    for x, t, run in zip(X, T, batch):
        alone = nominal(_pendulum, x, t, 1e-9)
        np.testing.assert_array_equal(run.nodes, alone.nodes)
        assert run.nodes[0] == 0.0 and run.nodes[-1] == t
        ref = solve_ivp(lambda _, y: np.array(_pendulum(y)), (0.0, t), x, method="DOP853", rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(run.solution(t), ref.y[:, -1], rtol=1e-9, atol=1e-9)
