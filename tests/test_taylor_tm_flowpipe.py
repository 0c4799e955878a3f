"""Taylor-model flowpipes (reach/backends/taylor/tm_flowpipe.py): the enclosures contain the exact
solutions of linear flows and the sampled runs of the CW SIREN closed loop, a remainder smaller
than the Picard image is rejected, and the first-order remainder symbols enclose the field."""

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from reach.backends.taylor.da import DA
from reach.backends.taylor.flow import compile_expressions, compile_numeric
from reach.backends.taylor.tm_flowpipe import LinearTM, TMFlow, prove_minimum_at_most, validate
from reach.model import load_model


def oscillator(x):
    """``x'' = -x`` with a clock."""
    return [x[1], -x[0], x[0].const_like(1.0)]


def sample_xi(rng, count: int, m: int) -> np.ndarray:
    """Random points of ``[-1, 1]^m`` and its corners."""
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * m)).reshape(m, -1).T
    return np.vstack([rng.uniform(-1, 1, (count, m)), corners])


def test_oscillator_encloses_the_exact_solution():
    flow = TMFlow(oscillator, [1.0, 0.0, 0.0], [0.1, 0.1, 0.0], order=4, exact=[2], tol=[1e-7, 1e-7, 1.0])
    pipe = flow.run(2 * np.pi, 0.2)
    assert pipe.status == "horizon"
    assert abs(pipe.t_end - 2 * np.pi) < 1e-12
    assert np.max(pipe.error_radius[-1]) < 1e-6          # the carried error stays small
    rng = np.random.default_rng(1)
    for seg in pipe.segments[::4]:
        T = seg.t0 + seg.h
        for xi in sample_xi(rng, 4, 2):
            x0, v0 = 1.0 + 0.1 * xi[0], 0.1 * xi[1]
            exact = np.array([x0 * np.cos(T) + v0 * np.sin(T), -x0 * np.sin(T) + v0 * np.cos(T), T])
            lo, hi = seg.box_at(xi, 2)
            assert np.all(lo <= exact) and np.all(exact <= hi)
            assert np.all(hi[:2] - lo[:2] < 1e-5)


def test_linear_cw_drift_encloses_the_matrix_exponential():
    """The CW drift of the model's ``arrived`` mode, ``x(T) = expm(A T) x0``, over half an hour."""
    model = load_model("models/cw_siren.yaml")
    flow_exprs = model.modes["arrived"].flow
    f = compile_expressions(flow_exprs, model.symbols)
    n = 7.2921e-5
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [3 * n ** 2, 0, 0, 2 * n], [0, 0, -2 * n, 0]])
    center, half = np.array([500.0, -500.0, 0.01, -0.02, 0.0]), np.array([5.0, 5.0, 0.0, 0.0, 0.0])
    flow = TMFlow(f, center, half, order=4, exact=[4], tol=[1e-8, 1e-8, 1e-11, 1e-11, 1.0])
    pipe = flow.run(1800.0, 100.0)
    assert pipe.status == "horizon"
    rng = np.random.default_rng(2)
    for seg in pipe.segments:
        T = seg.t0 + seg.h
        for xi in sample_xi(rng, 3, 2):
            x0 = center[:4] + np.r_[half[:2] * xi, 0.0, 0.0]
            exact = scipy.linalg.expm(A * T) @ x0
            lo, hi = seg.box_at(xi, 2)
            slack = 1e-12 * (1 + np.abs(exact))          # expm's own rounding
            assert np.all(lo[:4] - slack <= exact) and np.all(exact <= hi[:4] + slack)
            assert np.all(hi[:2] - lo[:2] < 1e-4)


@pytest.fixture(scope="module")
def siren():
    model = load_model("models/cw_siren.yaml")
    flow_exprs = model.modes["transfer"].flow
    return compile_expressions(flow_exprs, model.symbols), compile_numeric(flow_exprs, model.symbols)


def test_cw_siren_closed_loop_contains_sampled_runs(siren):
    """Every run of a 1 m box, integrated by scipy at 1e-12, lies in its enclosure at every step
    end of the first 120 s, and in the whole-step enclosure at the middle of every step."""
    f, f_numeric = siren
    center, half = np.array([500.0, -500.0, 0.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0, 0.0, 0.0])
    flow = TMFlow(f, center, half, order=4, exact=[4], tol=[1e-7, 1e-7, 1e-9, 1e-9, 1.0])
    pipe = flow.run(120.0, 10.0)
    assert pipe.status == "horizon"
    ends = np.array([s.t0 + s.h for s in pipe.segments])
    rng = np.random.default_rng(3)
    for xi in sample_xi(rng, 4, 2):
        x0 = center + half * np.r_[xi, 0.0, 0.0, 0.0]
        middles = np.array([s.t0 + 0.5 * s.h for s in pipe.segments])
        run = solve_ivp(lambda t, x: [float(v) for v in f_numeric(list(x))], (0, ends[-1]), x0,
                        method="DOP853", rtol=1e-12, atol=1e-13, t_eval=np.sort(np.r_[ends, middles]))
        states = run.y.T.reshape(len(ends), 2, -1)     # (middle, end) of each step
        for seg, (middle, state) in zip(pipe.segments, states):
            lo, hi = seg.box_at(xi, 2)
            slack = 1e-10 * (1 + np.abs(state))       # scipy's own error
            assert np.all(lo - slack <= state) and np.all(state <= hi + slack)
            whole = np.array([x.bound() for x in seg.tm()])
            assert np.all(whole[:, 0] - slack <= middle) and np.all(middle <= whole[:, 1] + slack)


def test_a_remainder_smaller_than_the_picard_image_is_rejected():
    flow = TMFlow(oscillator, [1.0, 0.0, 0.0], [0.1, 0.1, 0.0], order=3, exact=[2])
    X0 = flow.start_polynomials(flow.initial_frame())
    seg = flow.step(X0, 0.0, 0.5)
    assert seg is not None
    assert validate(oscillator, X0, seg.poly, seg.lo, seg.hi, 0.5, flow.errors)
    assert not validate(oscillator, X0, seg.poly, 0.2 * seg.lo, 0.2 * seg.hi, 0.5, flow.errors)
    assert not validate(oscillator, X0, seg.poly, np.zeros(3), np.zeros(3), 0.5, flow.errors)


def test_first_order_remainder_symbols_enclose_the_network_field(siren):
    """``f(P + J)`` in :class:`LinearTM` arithmetic contains the field at points ``P(xi) + d``,
    ``d`` in ``J``, on a 1 m box of the transfer (sine layers and the normalisation's power)."""
    f, f_numeric = siren
    flow = TMFlow(f, [300.0, -300.0, 0.05, 0.03, 3000.0], [1.0, 1.0, 1e-3, 1e-3, 0.0], order=3, exact=[4])
    P = flow.start_polynomials(flow.initial_frame())
    lo = -np.array([1e-3, 2e-3, 1e-6, 1e-6, 0.0])
    hi = np.array([2e-3, 1e-3, 2e-6, 1e-6, 0.0])
    F = [Fi.enclose() for Fi in f(LinearTM.seed(P, lo, hi, flow.errors))]
    rng = np.random.default_rng(4)
    vars_ = flow.alg.nvars
    for _ in range(20):
        point = np.zeros(vars_)
        point[:flow.m] = rng.uniform(-1, 1, flow.m)
        x = np.array([p(point[None, :])[0] for p in P]) + rng.uniform(lo, hi)
        value = np.array(f_numeric(list(x)), dtype=float)
        for Fi, v in zip(F, value):
            centre = Fi.poly(point[None, :])[0]
            slack = 1e-12 * (1 + abs(v))
            assert centre + Fi.lo - slack <= v <= centre + Fi.hi + slack


def test_closest_approach_is_proved_only_when_every_run_gets_close():
    """Distance squared to ``(0, -1)`` of the oscillator: every run from the box passes within
    ``0.005`` near ``t = pi/2`` (proved below 0.02), while the corner runs never get within 1e-4."""
    flow = TMFlow(oscillator, [1.0, 0.0, 0.0], [0.05, 0.05, 0.0], order=4, exact=[2], tol=[1e-6, 1e-6, 1.0])

    def q(x):
        return x[0] * x[0] + (x[1] + 1.0) * (x[1] + 1.0)

    proof = prove_minimum_at_most(flow, q, 0.02, 4.0, 0.1)
    assert proof.status == "proved" and proof.fraction == 1.0
    assert all(1.0 < t < 2.2 for *_, t in proof.proved)
    proof = prove_minimum_at_most(flow, q, 1e-4, 4.0, 0.1, max_depth=2)
    assert proof.status == "horizon" and proof.fraction < 1.0
