"""The star back-end against independent references.

* grid successors against numerically integrated sampled points (scipy ``solve_ivp``);
* continuous-time flowpipes: every sampled trajectory point of a random stable system lies in
  the segment of its cell (hypothesis over systems, boxes, points and times);
* small hybrid automata built directly with the dataclasses: the verdict agrees with the
  closed-form maximum of the run, every UNSAFE carries a counterexample that replays, and
  a violation between grid points is found in continuous time but missed in discrete time.
"""

import re

import numpy as np
import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND, AffineFlow, flowpipe, safe_abort_time
from reach.errors import Where
from reach.model.automaton import HybridAutomaton, InitialSet, Mode, Transition
from reach.model.constraints import Constraint
from reach.model.units import SI
from reach.result import Status
from reach.sets import Box, Star
from reach.spec.properties import BoundSafety

SEEDS = st.integers(0, 2**32 - 1)


def random_stable_system(rng, n):
    """``A = -(B B^T + 0.1 I) + S`` (``S`` skew): every eigenvalue has real part <= -0.1."""
    B = rng.normal(size=(n, n)) * 0.7
    S = rng.normal(size=(n, n))
    return -(B @ B.T + 0.1 * np.eye(n)) + (S - S.T), rng.normal(size=n)


def integrate(A, b, x0, t):
    if t == 0:
        return np.array(x0, dtype=float)
    sol = solve_ivp(lambda _, x: A @ x + b, (0, t), x0, rtol=1e-11, atol=1e-12)
    return sol.y[:, -1]


# ---------------------------------------------------------------------- continuous dynamics

@given(SEEDS)
@settings(max_examples=15, deadline=None)
def test_grid_successors_match_integrated_points(seed):
    rng = np.random.default_rng(seed)
    A, b = random_stable_system(rng, 3)
    flow = AffineFlow(A, b)
    h = rng.uniform(0.05, 0.5)
    Phis, psis = flow.powers(h, 6)
    star = Star.from_box(Box(rng.uniform(-2, -1, 3), rng.uniform(1, 2, 3)))
    for alpha in rng.uniform(-1, 1, (3, star.nvars)):
        x0 = star.point(alpha)
        for j in (1, 3, 6):
            successor = star.affine_map(Phis[j], psis[j])
            np.testing.assert_allclose(successor.point(alpha), integrate(A, b, x0, j * h),
                                       rtol=1e-7, atol=1e-8)


@given(SEEDS, st.integers(2, 4))
@settings(max_examples=15, deadline=None)
def test_sampled_trajectories_lie_in_the_flowpipe(seed, n):
    """Continuous time: x(t) is in the segment of the cell containing t, for all t."""
    rng = np.random.default_rng(seed)
    A, b = random_stable_system(rng, n)
    low = rng.uniform(-3, 3, n)
    box = Box(low, low + rng.uniform(0.0, 1.5, n))
    step, duration = rng.uniform(0.2, 1.0), 3.0
    segments = flowpipe(A, b, Star.from_box(box), step, duration)
    corners = box.corners()
    starts = np.vstack([corners[rng.integers(len(corners), size=2)],
                        box.low + (box.high - box.low) * rng.uniform(size=(2, n))])
    for x0 in starts:
        for t in rng.uniform(0, duration, 2):
            cell = min(int(t / step), len(segments) - 1)
            assert segments[cell].contains(integrate(A, b, x0, t)), (x0, t)


def test_the_interpolation_error_is_needed():
    """A rotation bends every trajectory: the chord hull alone misses mid-cell points."""
    A, b = np.array([[0.0, 1.0], [-1.0, 0.0]]), np.zeros(2)
    point = Star(np.array([1.0, 0.0]), np.zeros((2, 0)))
    segment = flowpipe(A, b, point, 1.0, 1.0)[0]
    mid = integrate(A, b, point.center, 0.5)
    assert segment.contains(mid)
    chord = Star(segment.center, segment.basis[:, :1], box=Box([0.0], [1.0]))   # lam only
    assert not chord.contains(mid)


# ---------------------------------------------------------------------- hybrid automata

X, V, T = sympy.symbols("x v t", real=True)
SYMBOLS = [X, V, T]


def c(g, strict=False):
    """The constraint ``g <= 0`` (``< 0`` when strict)."""
    return Constraint(sympy.expand(g), strict, f"{g} <= 0", Where())


def automaton(window=(1.0, 2.0), horizon=5.0, x0=(0.0, 0.1)):
    """``thrust`` (x' = v, v' = 1) then, at one instant of the window, ``coast`` (v' = -v)."""
    lo, hi = window
    thrust = Mode("thrust", SYMBOLS, [V, sympy.Integer(1), sympy.Integer(1)], {}, [c(T - hi)])
    coast = Mode("coast", SYMBOLS, [V, -V, sympy.Integer(1)], {}, [])
    abort = Transition("abort", "thrust", "coast", [c(lo - T), c(T - hi)], urgent=False,
                       window=(2, lo, hi))
    initial = InitialSet("thrust", np.array([x0[0], 0.0, 0.0]), np.array([x0[1], 0.0, 0.0]))
    return HybridAutomaton("thrust-coast", "test automaton", "(built in test)", SI, {}, ["x", "v", "t"],
                           [], {"thrust": thrust, "coast": coast}, [abort], initial, horizon, clocks=[2])


def farthest(window=(1.0, 2.0), horizon=5.0, x0=0.1):
    """Closed form of the largest x in coast: abort at the window's end from the largest x0."""
    tau = window[1]
    return x0 + tau ** 2 / 2 + tau * (1 - np.exp(-(horizon - tau)))


def x_at_most(limit, modes=("coast",)):
    return BoundSafety("reach", list(modes), {m: [[c(limit - X, strict=True)]] for m in modes},
                       SYMBOLS, file="(built in test)")


def test_two_mode_automaton_safe_with_margin():
    model = automaton()
    result = BACKEND.check(model, x_at_most(farthest() + 0.05))
    assert result.status is Status.SAFE, result.details
    assert "continuous time" in result.details["semantics"]


def test_two_mode_automaton_unsafe_replays():
    model = automaton()
    prop = x_at_most(farthest() - 0.1)
    result = BACKEND.check(model, prop)
    assert result.status is Status.UNSAFE, result.details
    cex = result.counterexample
    assert 1.0 <= cex.switch_time <= 2.0
    again = replay(model, prop, np.array(cex.initial_state), cex.switch_time)
    assert again.violated and again.state[0] > farthest() - 0.1


def test_violation_between_grid_points():
    """v = t in thrust; the band 0.55 <= v <= 0.95 lies between the grid points 0.5 and 1."""
    model = automaton(window=(1.5, 2.0), horizon=2.0)
    band = BoundSafety("band", ["thrust"], {"thrust": [[c(0.55 - V), c(V - 0.95)]]}, SYMBOLS,
                       file="(built in test)")
    discrete = BACKEND.check(model, band, {"step": 0.5, "discrete_time": True})
    assert discrete.status is Status.UNKNOWN       # Hylaa-like grid semantics miss it: no proof
    assert "no violation at the grid points" in discrete.details["reason"]
    continuous = BACKEND.check(model, band, {"step": 0.5})
    assert continuous.status is Status.UNSAFE
    assert 0.55 <= continuous.counterexample.violation_state[1] <= 0.95


def test_unsupported_models_and_properties():
    model = automaton()       # a nonlinear flow is linearised; a nonlinear invariant is not
    model.modes["coast"] = Mode("coast", SYMBOLS, [V, -V ** 3, sympy.Integer(1)], {}, [c(V ** 2 - 4)])
    result = BACKEND.check(model, x_at_most(10.0))
    assert result.status is Status.UNSUPPORTED and "nonlinear invariants" in result.details["reason"]

    class Reach:
        kind, id = "reach", "dock"

    assert "safety" in BACKEND.supports(automaton(), Reach())


def test_safe_abort_time_brackets_the_closed_form():
    """x_max(tau) = 0.1 + tau^2/2 + tau (1 - e^-(5 - tau)) grows with the abort time tau, so
    the latest safe abort for x <= L solves x_max(tau) = L; the sweep proves a time just
    below it."""
    model = automaton(window=(0.0, 2.0))
    limit = farthest(window=(0.0, 1.2))
    taus = np.linspace(0, 2, 20001)
    exact = taus[np.argmax(farthest(window=(0.0, taus)) > limit)]
    proven = safe_abort_time(model, [x_at_most(limit)], model.initial.low, model.initial.high)
    assert exact - 0.15 <= proven <= exact


def test_no_safe_abort_is_nan_not_the_window_start():
    """With the window [1, 2] the earliest abort already reaches x_max(1) = 0.1 + 1/2 + (1 - e^-4)
    = 1.58: a bound below it proves no abort safe, which is NaN, not the window's start 1."""
    model = automaton(window=(1.0, 2.0))
    assert np.isnan(safe_abort_time(model, [x_at_most(farthest(window=(1.0, 1.0)) - 0.1)],
                                    model.initial.low, model.initial.high))
    assert safe_abort_time(model, [x_at_most(farthest(window=(1.0, 2.0)) + 0.1)],
                           model.initial.low, model.initial.high) == 2.0


# ---------------------------------------------------------------------- the rendezvous family

@pytest.fixture(scope="module")
def rendezvous():
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties
    props = {p.id: p for f in ("properties/rendezvous.yaml", "properties/collision_box_0p2.yaml")
             for p in load_properties(f)}
    return lambda name, pid: (lambda m: (m, bind(props[pid], m)))(load_model(f"models/{name}.yaml"))


def test_rendezvous_abort_window_safe(rendezvous):
    model, prop = rendezvous("SRA02", "collision")
    result = BACKEND.check(model, prop)
    assert result.status is Status.SAFE, result.details


def test_rendezvous_late_abort_hits_the_0p2_box(rendezvous):
    model, prop = rendezvous("SRU01", "collision_0p2")
    result = BACKEND.check(model, prop)
    assert result.status is Status.UNSAFE, result.details
    cex = result.counterexample
    assert replay(model, prop, np.array(cex.initial_state), cex.switch_time).violated


def test_a_cell_far_longer_than_a_large_flows_time_scale_is_refused_before_its_samples_fill_memory():
    """A dense 300-state flow (time scale 4.7) over cells of 16667 (a horizon of 1e6 in 60
    cells) asked for 3540 sub-samples of 300 x 300 matrices: 2.6 GB each for the samples and
    the chain's products, 10 GB held. The sub-samples are now capped by their bytes as well
    (SUBSAMPLE_BYTES), with a step that fits named; a step under it is taken."""
    from reach.backends.star.flowpipe import SUBSAMPLE_BYTES

    n = 300
    flow = AffineFlow(-0.001 * np.ones((n, n)), np.zeros(n))
    with pytest.raises(ArithmeticError, match=r"at most (\d+) sub-samples at 300 states.*-o step=") as err:
        flow.curvature(1e6 / 60)
    most = int(re.search(r"at most (\d+) sub-samples", str(err.value)).group(1))
    assert most * 8 * n * n <= SUBSAMPLE_BYTES
    step = float(re.search(r"-o step=([0-9.e+-]+)", str(err.value)).group(1))
    assert flow.curvature(step * 0.999)[3] <= most
