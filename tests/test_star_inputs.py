"""star with bounded time-varying inputs and polytopic initial sets.

The model objects follow the model layer's interface for these features (a bounded input is a
state coordinate with flow 0, listed in ``model.bounded_inputs``; a polytopic initial set is
``initial.polytope`` with ``A x <= b``, ``E x = f``), built here directly.

References: for ``x' = -x + u``, ``|u| <= 1`` from ``x = 0`` the reachable values at time ``t``
are exactly ``|x| <= 1 - e^{-t}`` (bang-bang input); sampled piecewise-constant input signals
integrated by ``solve_ivp`` must lie in the flowpipe; a linear bound over a segment of initial
states is extremal at a vertex.
"""

from types import SimpleNamespace

import numpy as np
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.star import BACKEND, flowpipe
from reach.errors import Where
from reach.model.automaton import HybridAutomaton, InitialSet, Mode
from reach.model.constraints import Constraint
from reach.model.units import SI
from reach.result import Status
from reach.sets import Box, Star
from reach.spec.properties import BoundSafety

X, Y, U, T = sympy.symbols("x y u t", real=True)


def c(g, strict=False):
    return Constraint(sympy.expand(g), strict, f"{g} <= 0", Where())


def leaky(horizon=3.0, varying=True):
    """``x' = -x + u``, ``u in [-1, 1]``, ``t' = 1``, from ``x = 0``."""
    mode = Mode("run", [X, U, T], [-X + U, sympy.Integer(0), sympy.Integer(1)], {}, [])
    initial = InitialSet("run", np.array([0.0, -1.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    model = HybridAutomaton("leaky", "x' = -x + u", "(built in test)", SI, {}, ["x", "u", "t"], [],
                            {"run": mode}, [], initial, horizon, clocks=[2])
    model.bounded_inputs = [SimpleNamespace(name="u", index=1, low=-1.0, high=1.0, varying=varying)]
    return model


def x_at_most(limit):
    return BoundSafety("x_max", ["run"], {"run": [[c(limit - X, strict=True)]]}, [X, U, T],
                       file="(built in test)")


def test_varying_input_bound_is_proved_and_not_much_beyond():
    exact = 1 - np.exp(-3.0)
    model = leaky()
    safe = BACKEND.check(model, x_at_most(exact * 1.1), {"step": 0.05})
    assert safe.status is Status.SAFE, safe.details
    # below the true maximum nothing may be proved (bang-bang u = 1 reaches it)
    for limit in (exact * 0.98, exact * 0.5):
        assert BACKEND.check(model, x_at_most(limit), {"step": 0.05}).status is not Status.SAFE


def test_constant_input_is_a_frozen_state():
    """A constant input is a state with zero derivative: u = 1 reaches the same maximum,
    and a violation replays (the input value is part of the initial state)."""
    model = leaky(varying=False)
    exact = 1 - np.exp(-3.0)
    assert BACKEND.check(model, x_at_most(exact * 1.05), {"step": 0.05}).status is Status.SAFE
    result = BACKEND.check(model, x_at_most(exact * 0.9), {"step": 0.05})
    assert result.status is Status.UNSAFE, result.details
    assert result.counterexample.initial_state[1] > 0.9 * 0.9


def piecewise(values, duration):
    """``u(t)``: ``values[k]`` on the k-th of ``len(values)`` equal pieces of ``[0, duration]``."""
    return lambda t: values[min(int(t / duration * len(values)), len(values) - 1)]


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=10, deadline=None)
def test_runs_under_sampled_input_signals_lie_in_the_flowpipe(seed):
    rng = np.random.default_rng(seed)
    n = 2
    B0 = rng.normal(size=(n, n)) * 0.6
    A = -(B0 @ B0.T + 0.2 * np.eye(n)) + np.array([[0, 1], [-1, 0]]) * rng.uniform(0, 1)
    B = rng.normal(size=(n, 1))
    lo, hi = np.array([-0.5]), np.array([rng.uniform(0, 1)])
    box = Box(rng.uniform(-1, 0, n), rng.uniform(0, 1, n))
    step, duration = rng.uniform(0.2, 0.6), 2.0
    segments = flowpipe(A, np.zeros(n), Star.from_box(box), step, duration, B, lo, hi)
    for _ in range(3):
        x0 = box.low + (box.high - box.low) * rng.uniform(size=n)
        u = piecewise(rng.choice([lo[0], hi[0]], size=7), duration)
        t_end = rng.uniform(0, duration)
        sol = solve_ivp(lambda t, x: A @ x + B[:, 0] * u(t), (0, t_end), x0, rtol=1e-10, atol=1e-12,
                        max_step=duration / 50)
        cell = min(int(t_end / step), len(segments) - 1)
        assert segments[cell].contains(sol.y[:, -1]), (x0, t_end)


def segment_start():
    """``x' = 0, y' = 1``; initial set the segment ``x + y = 1``, ``0 <= x <= 1`` (a polytope:
    its bounding box is the unit square)."""
    mode = Mode("go", [X, Y, T], [sympy.Integer(0), sympy.Integer(1), sympy.Integer(1)], {}, [])
    initial = InitialSet("go", np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0]))
    initial.polytope = SimpleNamespace(A=np.array([[1.0, 0, 0], [-1.0, 0, 0]]), b=np.array([1.0, 0.0]),
                                       E=np.array([[1.0, 1.0, 0.0]]), f=np.array([1.0]))
    return HybridAutomaton("segment", "x' = 0, y' = 1", "(built in test)", SI, {}, ["x", "y", "t"], [],
                           {"go": mode}, [], initial, 1.0, clocks=[2])


def test_polytopic_initial_set_is_used_exactly():
    """x + y = 1 + t on every run, so x + y <= 2 holds (met at t = 1), while the bounding
    box alone (x = y = 1 at t = 1: x + y = 3) would not prove it; x + y <= 1.9 fails."""
    model = segment_start()
    bound = lambda limit: BoundSafety("sum", ["go"], {"go": [[c(limit - X - Y, strict=True)]]}, [X, Y, T],
                                      file="(built in test)")
    assert BACKEND.check(model, bound(2.0)).status is Status.SAFE
    result = BACKEND.check(model, bound(1.9))
    assert result.status is Status.UNSAFE, result.details
    x0 = np.array(result.counterexample.initial_state)
    assert abs(x0[0] + x0[1] - 1) < 1e-6


def test_input_driven_runs_that_stay_inside_the_invariant_are_kept():
    """``x' = -x + u``, ``u in [0, 2]``: with u at its centre the run crosses the invariant
    ``x <= 0.5`` at t = ln 2 and must leave ``run``, but with u near 0 a run stays in ``run``
    until the horizon, so ``t <= 1.5`` in ``run`` is violated; cutting the input-free grid
    stars with the exact invariant would lose those runs and prove it."""
    run = Mode("run", [X, U, T], [-X + U, sympy.Integer(0), sympy.Integer(1)], {}, [c(X - 0.5)])
    hold = Mode("hold", [X, U, T], [sympy.Integer(0), sympy.Integer(0), sympy.Integer(1)], {}, [])
    from reach.model.automaton import Transition
    leave = Transition("leave", "run", "hold", [c(0.5 - X)], urgent=True)
    initial = InitialSet("run", np.array([0.0, 0.0, 0.0]), np.array([0.0, 2.0, 0.0]))
    model = HybridAutomaton("leaky-hold", "x' = -x + u", "(built in test)", SI, {}, ["x", "u", "t"], [],
                            {"run": run, "hold": hold}, [leave], initial, 3.0, clocks=[2])
    model.bounded_inputs = [SimpleNamespace(name="u", index=1, low=0.0, high=2.0, varying=True)]
    prop = BoundSafety("leaves", ["run"], {"run": [[c(1.5 - T, strict=True)]]}, [X, U, T],
                       file="(built in test)")
    assert BACKEND.check(model, prop, {"step": 0.1}).status is not Status.SAFE
