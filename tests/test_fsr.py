"""The fsr back-end: moments, reach and reach-avoid probabilities, the Fourier path and the
eccentric-orbit transition matrix, each against an independent reference."""

import copy
from math import comb

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp
from scipy.special import ndtr

from reach.backends.fsr import fourier as F
from reach.backends.base import run
from reach.backends.fsr import BACKEND, GaussianProblem, reach, reach_avoid
from reach.backends.fsr import leave_bound as fsr_leave_bound
from reach.backends.montecarlo import BACKEND as MC
from reach.model.constraints import halfspaces
from reach.model.loader import load_model
from reach.model.ltv import (KickedLinearSystem, cwh_matrix, eccentric_orbit_system, kick_times,
                             mean_anomaly, true_anomaly, yamanaka_ankersen)
from reach.result import Status
from reach.sets.gaussian import interval_form
from reach.spec.properties import bind, load_properties

MU = 398600.4418          # km^3/s^2
A_ORBIT = 7000.0          # km


def cwh_transition(n, t):
    """Closed-form CWH transition matrix (Clohessy-Wiltshire solution), x radial, y along-track."""
    s, c = np.sin(n * t), np.cos(n * t)
    return np.array([
        [4 - 3 * c, 0, 0, s / n, 2 * (1 - c) / n, 0],
        [6 * (s - n * t), 1, 0, -2 * (1 - c) / n, (4 * s - 3 * n * t) / n, 0],
        [0, 0, c, 0, 0, s / n],
        [3 * n * s, 0, 0, c, 2 * s, 0],
        [-6 * n * (1 - c), 0, 0, -2 * s, 4 * c - 3, 0],
        [0, 0, -n * s, 0, 0, c]])


def velocity_kicks():
    G = np.zeros((6, 3))
    G[3:] = np.eye(3)
    return G


def load(model, properties):
    m = load_model(f"models/{model}.yaml")
    return m, {p.id: bind(p, m) for p in load_properties(f"properties/{properties}.yaml")}


# ------------------------------------------------------------------ discretisation and moments

def test_kick_times_match_the_simulator_convention():
    assert np.allclose(kick_times(10.0, 30.0), [0, 10, 20, 30])
    assert np.allclose(kick_times(10.0, 25.0), [0, 10, 20, 25])
    assert np.allclose(kick_times(10.0, 0.0), [0])


def test_exact_discretisation_of_cwh():
    n = np.sqrt(MU / A_ORBIT ** 3)
    system = KickedLinearSystem.from_continuous(cwh_matrix(n), None, velocity_kicks(), 7.0, 70.0)
    assert np.allclose(system.Phi[3], cwh_transition(n, 7.0), rtol=1e-12, atol=1e-15)


def test_moments_equal_the_controllability_form():
    """Recursion against eqs. (13)-(14): C = [B, AB, ...], B = Phi G, mean A^tau x0 + C (1 (x) mu)."""
    rng = np.random.default_rng(0)
    A = 0.05 * rng.normal(size=(4, 4)) - 0.02 * np.eye(4)
    G = rng.normal(size=(4, 2))
    system = KickedLinearSystem.from_continuous(A, None, G, 0.5, 6.0)
    x0, mu = rng.normal(size=4), rng.normal(size=2)
    Sigma = np.array([[0.3, 0.1], [0.1, 0.2]])
    means, covs = system.moments(x0, None, mu, Sigma)
    Phi = system.Phi[0]
    for tau in (1, 5, system.steps):
        C = np.hstack([np.linalg.matrix_power(Phi, j) @ Phi @ G for j in range(tau - 1, -1, -1)])
        mean = np.linalg.matrix_power(Phi, tau) @ x0 + C @ np.tile(mu, tau)
        cov = C @ np.kron(np.eye(tau), Sigma) @ C.T
        assert np.allclose(means[tau], mean, rtol=1e-12, atol=1e-12)
        assert np.allclose(covs[tau], cov, rtol=1e-12, atol=1e-14)


def test_moments_time_varying_recursion():
    rng = np.random.default_rng(1)
    Phi = np.eye(3) + 0.1 * rng.normal(size=(5, 3, 3))
    G = rng.normal(size=(3, 1))
    system = KickedLinearSystem(Phi, np.zeros((5, 3)), G, np.arange(6.0))
    means, covs = system.moments(np.ones(3), 0.1 * np.eye(3), [0.5], [[2.0]])
    B = [Phi[k] @ G for k in range(5)]
    cov = system.propagator(5, 0) @ (0.1 * np.eye(3)) @ system.propagator(5, 0).T
    mean = system.propagator(5, 0) @ np.ones(3)
    for k in range(5):
        M = system.propagator(5, k + 1) @ B[k]
        cov = cov + 2.0 * M @ M.T
        mean = mean + 0.5 * M[:, 0]
    assert np.allclose(means[5], mean) and np.allclose(covs[5], cov)


def test_moments_against_sampled_trajectories():
    """Sampled from the closed-form CWH solution (not the matrix exponential)."""
    n = np.sqrt(MU / A_ORBIT ** 3)
    G = velocity_kicks()
    system = KickedLinearSystem.from_continuous(cwh_matrix(n), None, G, 60.0, 600.0)
    x0 = np.array([0.1, -1.0, 0.05, 0.0, 1e-4, 0.0])
    mu, Sigma = np.array([1e-5, 0, -1e-5]), np.diag([4e-8, 1e-8, 9e-8])
    means, covs = system.moments(x0, None, mu, Sigma)
    rng = np.random.default_rng(2)
    N = 200_000
    Phi = cwh_transition(n, 60.0)
    X = np.tile(x0, (N, 1))
    for _ in range(10):
        X = (X + rng.multivariate_normal(mu, Sigma, size=N) @ G.T) @ Phi.T
    sd = np.sqrt(np.diag(covs[-1]))
    assert np.all(np.abs(X.mean(axis=0) - means[-1]) < 5 * sd / np.sqrt(N))
    corr = np.cov(X.T) / np.outer(sd, sd)
    assert np.allclose(corr, covs[-1] / np.outer(sd, sd), atol=0.015)


# ------------------------------------------------------------------ probabilities with exact answers

def scalar_problem(a, step, at, x0, mu, var):
    system = KickedLinearSystem.from_continuous([[a]], None, [[1.0]], step, at)
    return GaussianProblem(system, np.array([x0]), np.zeros((1, 1)), np.array([mu]), np.array([[var]]))


def test_one_dimensional_reach_is_analytic():
    """x' = a x with N(mu, var) kicks: x[K] = r^K x0 + sum_{j=1..K} r^j w, r = exp(a step)."""
    a, step, K, x0, mu, var = -0.3, 1.0, 8, 2.0, 0.1, 0.25
    problem = scalar_problem(a, step, K * step, x0, mu, var)
    r = np.exp(a * step)
    mean = r ** K * x0 + mu * sum(r ** j for j in range(1, K + 1))
    sd = np.sqrt(var * sum(r ** (2 * j) for j in range(1, K + 1)))
    p = reach(problem, np.array([[1.0], [-1.0]]), np.array([0.6, 0.2]))
    exact = ndtr((0.6 - mean) / sd) - ndtr((-0.2 - mean) / sd)
    assert p.low <= exact <= p.high and p.width < 1e-11


@pytest.mark.parametrize("method", ["genz", "markov"])
@pytest.mark.parametrize("steps", [2, 10])
def test_reach_avoid_random_walk_is_sparre_andersen(method, steps):
    """P(S_1 >= 0, ..., S_n >= 0) = C(2n, n) / 4^n for a symmetric continuous random walk."""
    problem = scalar_problem(0.0, 1.0, float(steps), 0.0, 0.0, 1.0)
    positive = (np.array([[-1.0]]), np.array([0.0]))
    p, info = reach_avoid(problem, positive, positive, abs_error=2e-4, method=method, drop_budget=0.0)
    exact = comb(2 * steps, steps) / 4 ** steps
    assert p.low <= exact <= p.high
    assert info["kept"] == steps                       # x[0] = 0 is checked, not integrated


def test_boole_dropping_keeps_the_interval_rigorous():
    """A corridor far from the mean is dropped; the interval still contains the exact value."""
    problem = scalar_problem(0.0, 1.0, 6.0, 0.0, 0.0, 1.0)
    target = (np.array([[-1.0]]), np.array([0.0]))
    wide = (np.array([[-1.0]]), np.array([3.0]))     # x >= -3 at every step
    p, info = reach_avoid(problem, target, wide, abs_error=1e-4, drop_budget=0.02)
    exact_plain, _ = reach_avoid(problem, target, wide, abs_error=1e-5, drop_budget=0.0)
    assert info["dropped"] > 0 and 0 < info["boole"] <= 0.02
    assert p.low <= exact_plain.value <= p.high


def test_deterministic_violation_gives_zero():
    problem = scalar_problem(0.0, 1.0, 3.0, -1.0, 0.0, 1.0)
    positive = (np.array([[-1.0]]), np.array([0.0]))
    p, info = reach_avoid(problem, positive, positive)
    assert p.high == 0.0 and info["reason"]


# ------------------------------------------------------------------ the Fourier path

def test_fourier_equals_gaussian_closed_form_on_cwh():
    n = np.sqrt(MU / A_ORBIT ** 3)
    G = velocity_kicks()
    system = KickedLinearSystem.from_continuous(cwh_matrix(n), None, G, 10.0, 600.0)
    x0 = np.array([0.1, -2, 0.1, 0, -5e-4, 0])
    Sigma = 2e-13 * np.eye(3)
    problem = GaussianProblem(system, x0, np.zeros((6, 6)), np.zeros(3), Sigma)
    means, _ = problem.moments()
    T = np.eye(3, 6)
    lower, upper = T @ means[-1] - 0.004, T @ means[-1] + 0.006
    gaussian = reach(problem, np.vstack([T, -T]), np.concatenate([upper, -lower]), abs_error=1e-6)
    z = F.ProjectedSum.of(system, T, F.point_law(x0), F.GaussianLaw(np.zeros(3), Sigma))
    fourier = F.box_probability(z, lower, upper, tol=1e-7)
    assert abs(fourier.value - gaussian.value) < 2e-6
    assert fourier.low <= gaussian.high and gaussian.low <= fourier.high


def test_fourier_density_is_the_gaussian_density():
    """FFT inversion (eq. 8) against eq. (15) for a correlated 2-D Gaussian sum."""
    G = np.array([[1.0, 0.0], [0.5, 1.0]])
    system = KickedLinearSystem(np.repeat(np.eye(2)[None], 3, axis=0), np.zeros((3, 2)), G,
                                np.arange(4.0))
    Sigma = np.diag([1.0, 0.5])
    z = F.ProjectedSum.of(system, np.eye(2), F.point_law([0.3, -0.2]), F.GaussianLaw(np.zeros(2), Sigma))
    axes, density = F.density_on_grid(z, points=64)
    X, Y = np.meshgrid(*axes, indexing="ij")
    P = 3 * G @ Sigma @ G.T
    d = np.stack([X - 0.3, Y + 0.2], axis=-1)
    pdf = np.exp(-0.5 * np.einsum("...i,ij,...j->...", d, np.linalg.inv(P), d)) / (2 * np.pi * np.sqrt(np.linalg.det(P)))
    assert np.max(np.abs(density - pdf)) < 1e-8 * pdf.max()


def sum_of_two(law):
    """x = w0 + w1 (no dynamics), the law of the 1-D sum of two kicks."""
    system = KickedLinearSystem(np.ones((2, 1, 1)), np.zeros((2, 1)), np.ones((1, 1)), np.arange(3.0))
    return F.ProjectedSum.of(system, np.ones((1, 1)), F.point_law([0.0]), law)


def test_fourier_uniform_sum_is_triangular():
    """U(-1, 1) + U(-1, 1) is triangular on [-2, 2]: P(-0.5 <= x <= 1) = 1 - 1/8 - 1.5^2/8."""
    p = F.box_probability(sum_of_two(F.UniformLaw([-1.0], [1.0])), [-0.5], [1.0], tol=1e-6)
    exact = 1 - 1 / 8 - 1.5 ** 2 / 8
    assert p.low <= exact <= p.high and p.width < 2e-6


def test_fourier_laplace_sum_has_its_closed_form():
    """Laplace(1) + Laplace(1): P(|x| > t) = (2 + t) exp(-t) / 2; its window is sized by Chernoff."""
    p = F.box_probability(sum_of_two(F.LaplaceLaw([0.0], [1.0])), [-1.0], [1.0], tol=1e-6)
    exact = 1 - 1.5 * np.exp(-1.0)
    assert p.low <= exact <= p.high and p.width < 2e-6


def test_fourier_mixture_against_sampling():
    law = F.MixtureLaw(np.array([0.7, 0.3]), (F.GaussianLaw(np.array([-1.0]), np.array([[0.2]])),
                                              F.UniformLaw(np.array([0.5]), np.array([2.5]))))
    z = sum_of_two(law)
    p = F.box_probability(z, [-1.0], [1.5], tol=1e-5)
    rng = np.random.default_rng(4)
    X = law.sample(rng, 400_000) + law.sample(rng, 400_000)
    hit = np.mean((X >= -1.0) & (X <= 1.5))
    assert abs(hit - p.value) < 4 * np.sqrt(hit * (1 - hit) / 400_000) + p.width


# ------------------------------------------------------------------ eccentric orbits

def test_yamanaka_ankersen_equals_cwh_at_zero_eccentricity():
    n = np.sqrt(MU / A_ORBIT ** 3)
    for theta0 in (0.0, 1.0, 4.0):
        for dt in (10.0, 1000.0, 7000.0):
            reference = scipy.linalg.expm(cwh_matrix(n) * dt)
            Phi = yamanaka_ankersen(0.0, A_ORBIT, MU, theta0, dt)
            assert np.max(np.abs(Phi - reference)) <= 1e-13 * np.max(np.abs(reference))


def test_eccentric_trajectory_equals_cwh_at_zero_eccentricity():
    """The seed's Fig. 8 check: from (0, -2, 0) km with -0.5 m/s along-track, no control, no noise."""
    n = np.sqrt(MU / A_ORBIT ** 3)
    G = velocity_kicks()
    ltv = eccentric_orbit_system(0.0, A_ORBIT, MU, 0.3, G, 60.0, 6000.0)
    lti = KickedLinearSystem.from_continuous(cwh_matrix(n), None, G, 60.0, 6000.0)
    x0 = np.array([0, -2, 0, 0, -5e-4, 0])
    a, _ = ltv.moments(x0, None, np.zeros(3), np.zeros((3, 3)))
    b, _ = lti.moments(x0, None, np.zeros(3), np.zeros((3, 3)))
    assert np.max(np.abs(a - b)) <= 1e-13 * np.max(np.abs(b))


def test_yamanaka_ankersen_against_integrated_tschauner_hempel():
    """Time-domain linearised relative motion about a Keplerian orbit, integrated numerically."""
    e, theta0, dt = 0.3, 0.7, 3000.0
    p = A_ORBIT * (1 - e ** 2)
    h = np.sqrt(MU * p)
    n = np.sqrt(MU / A_ORBIT ** 3)

    def rhs(t, X):
        theta = true_anomaly(mean_anomaly(theta0, e) + n * t, e)
        r = p / (1 + e * np.cos(theta))
        w, wdot = h / r ** 2, -2 * h * np.sqrt(MU / p) * e * np.sin(theta) / r ** 3
        x, y, z, vx, vy, vz = X
        k = MU / r ** 3
        return [vx, vy, vz, 2 * w * vy + wdot * y + w ** 2 * x + 2 * k * x,
                -2 * w * vx - wdot * x + w ** 2 * y - k * y, -k * z]

    columns = [solve_ivp(rhs, [0, dt], np.eye(6)[i], rtol=1e-12, atol=1e-14, method="DOP853").y[:, -1]
               for i in range(6)]
    reference = np.array(columns).T
    Phi = yamanaka_ankersen(e, A_ORBIT, MU, theta0, dt)
    assert np.max(np.abs(Phi - reference)) <= 1e-9 * np.max(np.abs(reference))


# ------------------------------------------------------------------ the back-end on the scenario models

SCENARIOS = [("fsr_lqr1_reach", "fsr_lqr1_reach", "dock"),
             ("fsr_lqr1_reach_avoid", "fsr_lqr1_reach_avoid", "corridor"),
             ("fsr_lqr2_reach", "fsr_lqr2_reach", "dock"),
             ("fsr_burn", "fsr_burn", "arrive")]


@pytest.mark.parametrize("model,properties,pid", SCENARIOS)
def test_targets_are_centred_at_the_nominal_position(model, properties, pid):
    m, props = load(model, properties)
    prop = props[pid]
    means, _ = GaussianProblem.from_model(m, prop.at).moments()
    T, lower, upper = interval_form(*halfspaces(prop.target, prop.symbols))
    centre = 0.5 * (lower + upper)
    assert np.max(np.abs(centre - T @ means[-1])) < 1e-6       # km: within a millimetre


def test_lqr1_design_matches_the_documented_behaviour():
    m, _ = load("fsr_lqr1_reach", "fsr_lqr1_reach")
    means, _ = GaussianProblem.from_model(m, 2110.0).moments()
    assert 1.4 < np.linalg.norm(means[-1, :3]) < 1.6            # "~1.5 km from the chief"
    assert -2.15 < means[:, 1].min() < -2.13                    # the seed's corridor holds nominally


def test_burn_reach_is_one_dimensional_closed_form():
    """One scalar kick: position = p + d w, so P is a normal interval probability."""
    m, props = load("fsr_burn", "fsr_burn")
    prop = props["arrive"]
    result = BACKEND.check(m, prop, {})
    A, _ = m.modes["coast"].linear
    d = scipy.linalg.expm(A * 500.0)[:3, 4] * np.sqrt(m.disturbance.cov[0, 0])
    w = np.min(0.025 / np.abs(d[:2]))                            # |d_i w| <= 25 m on x and y
    exact = ndtr(w) - ndtr(-w)
    assert result.probability[0] <= exact <= result.probability[1]
    assert result.status is Status.SAFE


def test_verdicts_follow_the_interval():
    m, props = load("fsr_lqr1_reach", "fsr_lqr1_reach")
    holds = BACKEND.check(m, props["dock"], {})
    fails = BACKEND.check(m, props["dock_strict"], {})
    assert holds.status is Status.SAFE and holds.probability[0] >= 0.6
    assert fails.status is Status.UNKNOWN and fails.details["verdict"] == "violated"
    assert fails.probability[1] < 0.9


def test_tight_corridor_methods_agree():
    m, props = load("fsr_lqr1_reach_avoid", "fsr_lqr1_reach_avoid")
    genz = BACKEND.check(m, props["corridor_tight"], {"method": "genz", "abs_error": 3e-3})
    markov = BACKEND.check(m, props["corridor_tight"], {"method": "markov", "abs_error": 3e-3})
    reach_only = BACKEND.check(m, props["box5"], {})
    assert genz.probability[0] <= markov.probability[1] and markov.probability[0] <= genz.probability[1]
    assert genz.probability[1] < reach_only.probability[0]      # the corridor costs probability
    assert genz.details["dropped"] > 0 and genz.details["boole"] <= 3e-4


def test_uniform_initial_box_matches_the_quadrature_of_its_closed_form():
    """Uniform burn error and Gaussian kicks: the position at 500 s is ``d vy0 + g`` with ``vy0``
    uniform (the initial box) and ``g ~ N(0, S)``, ``S = sum_k G_k Q G_k^T`` over the kicks at
    ``0, 10, ..., 490`` s. P(box) is the average over ``vy0`` (Gauss-Legendre) of scipy's normal
    box probabilities, about 0.698; fsr's interval (randomised QMC over the initial box and the
    kicks' Genz variables together) must contain it and be no wider than twice the requested
    error. The Fourier path (on request) must contain it too; its truncation bound does not close
    at the frequency cap here (the kicks spread 0.3 m against a window of kilometres), so its
    estimate goes to the details and its interval stays the honest, wide one."""
    from scipy.stats import multivariate_normal

    m, props = load("fsr_burn_uniform", "fsr_burn")
    result = BACKEND.check(m, props["arrive"], {"abs_error": 1e-2})
    assert result.details["method"] == "genz"
    by_fourier = BACKEND.check(m, props["arrive"], {"abs_error": 1e-2, "method": "fourier"})
    A, _ = m.modes["coast"].linear
    d = scipy.linalg.expm(A * 500.0)[:3, 4]
    S = sum(G @ m.disturbance.cov @ G.T for G in
            (scipy.linalg.expm(A * (500.0 - t))[:3, 3:] for t in np.arange(0.0, 500.0, 10.0)))
    centre = np.array([-125.3607, -206.7841, 0.0]) * 1e-3                 # km, the property's box
    lo, hi = centre - 0.025, centre + 0.025
    a, b = m.initial.low[4], m.initial.high[4]
    nodes, weights = np.polynomial.legendre.leggauss(64)
    xy = multivariate_normal(np.zeros(2), S[:2, :2])
    pz = ndtr(0.025 / np.sqrt(S[2, 2])) - ndtr(-0.025 / np.sqrt(S[2, 2]))
    exact = sum(w / 2 * pz * xy.cdf(hi[:2] - d[:2] * v, lower_limit=lo[:2] - d[:2] * v)
                for v, w in zip((a + b) / 2 + (b - a) / 2 * nodes, weights))
    assert 0.69 < exact < 0.71
    assert result.probability[0] <= exact <= result.probability[1]
    assert result.probability[1] - result.probability[0] <= 2e-2
    assert result.status is Status.SAFE                                  # at least 0.6
    assert by_fourier.probability[0] <= exact <= by_fourier.probability[1]
    low, high = by_fourier.details["estimated_interval"]
    assert low <= exact <= high and high - low <= 2e-2
    assert run(BACKEND, m, props["arrive_safe"]).status is Status.UNSUPPORTED


def test_unsupported_models_and_properties_say_why():
    m, props = load("fsr_burn", "fsr_burn")
    deterministic = copy.copy(m)
    deterministic.disturbance = None
    assert "deterministic" in BACKEND.supports(deterministic, props["arrive"])
    arch = load_model("models/SRA01.yaml")
    safety = [bind(p, arch) for p in load_properties("properties/rendezvous.yaml")][0]
    assert "safety" in BACKEND.supports(arch, safety)
    arch.disturbance = m.disturbance
    reach_prop = props["arrive"]
    assert BACKEND.supports(arch, reach_prop) is not None
    result = run(BACKEND, arch, safety)
    assert result.status is Status.UNSUPPORTED and result.details["reason"]


# ------------------------------------------------------------------ intervals: Boole terms and verdicts

def _walk_sides(steps, level):
    """``P(S_k < level)`` for the standard random walk ``S_k`` (variance ``k``), ``k = 1..steps``."""
    return ndtr(level / np.sqrt(np.arange(1, steps + 1)))


def test_default_drop_budget_is_a_tenth_of_the_error_and_drops_the_smallest_sides():
    """A corridor ``x >= -3`` around a random walk: the rows dropped are the smallest tail
    masses ``P(S_k < -3) = Phi(-3 / sqrt k)`` while their running sum stays within
    ``abs_error / 10``, and the Boole term is that sum (closed form)."""
    steps, abs_error = 6, 0.04
    problem = scalar_problem(0.0, 1.0, float(steps), 0.0, 0.0, 1.0)
    target = (np.array([[-1.0]]), np.array([10.0]))             # x[K] >= -10: one more, tiny side
    wide = (np.array([[-1.0]]), np.array([3.0]))
    p, info = reach_avoid(problem, target, wide, abs_error=abs_error)
    sides = np.sort(np.append(_walk_sides(steps - 1, -3.0), ndtr(-10.0 / np.sqrt(steps))))
    count = int(np.sum(np.cumsum(sides) <= abs_error / 10))
    assert 0 < count < steps
    assert info["dropped"] == count + 1                          # and x[0] = 0, fixed
    assert info["boole"] == pytest.approx(np.sum(sides[:count]), rel=1e-9)
    exact, _ = reach_avoid(problem, target, wide, abs_error=1e-4, drop_budget=0.0)
    assert p.low <= exact.value <= p.high


def test_row_cap_keeps_the_first_and_last_rows_and_charges_the_rest_to_boole():
    """Random walk, ``S_k >= 0`` for ``k = 1..3`` capped at two rows: the rows kept are
    ``k = 1`` and ``k = 3`` (first and last in time), whose joint probability is the orthant
    probability ``1/4 + asin(rho) / (2 pi)`` with ``rho = 1 / sqrt 3``; the cut row costs
    ``P(S_2 < 0) = 1/2`` in the lower end. With one row the value is ``P(S_1 >= 0) = 1/2``."""
    problem = scalar_problem(0.0, 1.0, 3.0, 0.0, 0.0, 1.0)
    positive = (np.array([[-1.0]]), np.array([0.0]))
    p, info = reach_avoid(problem, positive, positive, abs_error=1e-4, drop_budget=0.0, max_rows=2)
    orthant = 0.25 + np.arcsin(1 / np.sqrt(3)) / (2 * np.pi)
    assert info["capped"] == 1 and info["kept"] == 2
    assert info["boole"] == pytest.approx(0.5)
    assert p.value == pytest.approx(orthant, abs=3e-4) and p.high >= orthant - 1e-12
    assert p.low == pytest.approx(max(0.0, p.value - 0.5), abs=3e-4)
    exact = comb(6, 3) / 4 ** 3                                  # Sparre Andersen, all three rows
    assert p.low <= exact <= p.high
    one, info = reach_avoid(problem, positive, positive, abs_error=1e-4, drop_budget=0.0, max_rows=1)
    assert info["capped"] == 2 and one.value == pytest.approx(0.5, abs=1e-9) and one.low == 0.0
    none, info = reach_avoid(problem, positive, positive, abs_error=1e-4, drop_budget=0.0, max_rows=3)
    assert info["capped"] == 0 and none.low <= exact <= none.high


def test_leave_bound_is_the_boole_sum_of_post_kick_exceedances():
    """``x[k+1] = r (x[k] + w[k])``, ``w ~ N(mu, var)``: the post-kick state ``x[k] + w[k]``
    is normal with mean ``r^k x0 + mu (1 + r + ... + r^k)`` and variance
    ``var (1 + r^2 + ... + r^2k)``; the bound is the sum over the kicks and rows of the
    closed-form exceedance probabilities."""
    a, K, x0, mu, var = -0.3, 6, 0.5, 0.1, 0.25
    problem = scalar_problem(a, 1.0, float(K), x0, mu, var)
    r = np.exp(a)
    k = np.arange(K)
    mean = r ** k * x0 + mu * np.array([sum(r ** j for j in range(i + 1)) for i in k])
    sd = np.sqrt(var * np.array([sum(r ** (2 * j) for j in range(i + 1)) for i in k]))
    H, g = np.array([[1.0], [-1.0]]), np.array([1.6, 1.0])
    exact = np.sum(ndtr((mean - 1.6) / sd)) + np.sum(ndtr((-mean - 1.0) / sd))
    assert 0.05 < exact < 1
    assert fsr_leave_bound(problem, H, g) == pytest.approx(exact, rel=1e-12)
    assert fsr_leave_bound(problem, H, np.array([-5.0, 1.0])) == 1.0          # capped at 1


def test_leave_bound_without_noise_is_the_indicator_of_reaching_the_face():
    """No kick noise: the state stays at ``x0``; leaving ``x < g`` is certain when
    ``x0 >= g`` (the face counts as outside) and impossible otherwise."""
    problem = scalar_problem(0.0, 1.0, 3.0, 1.0, 0.0, 0.0)
    H = np.array([[1.0]])
    assert fsr_leave_bound(problem, H, np.array([1.0])) == 1.0
    assert fsr_leave_bound(problem, H, np.array([1.0 + 1e-9])) == 0.0


@pytest.mark.parametrize("low,high,at_least,status,verdict", [
    (0.6, 0.7, 0.6, Status.SAFE, "holds"),               # the lower end meets the threshold
    (0.5, 0.7, 0.6, Status.UNKNOWN, "undecided"),
    (0.5, 0.6, 0.6, Status.UNKNOWN, "undecided"),        # the threshold is still reachable
    (0.5, 0.59, 0.6, Status.UNKNOWN, "violated"),
    (0.9, 1.0, None, Status.UNKNOWN, "no threshold"),
])
def test_verdict_reads_the_interval_against_the_threshold(low, high, at_least, status, verdict):
    """SAFE only when the whole interval is at least the threshold; a violation is only
    reported (never as SAFE or UNSAFE) when the whole interval is below it."""
    from reach.backends.fsr import _verdict
    from reach.sets.gaussian import Probability
    assert _verdict(Probability(0.5 * (low + high), low, high), at_least) == (status, verdict)


def test_overflowing_moments_are_undecided_never_safe():
    """A spiral (x' = x - y, y' = x + y) over 800 s: the mean overflows to inf and then to
    inf - inf = NaN at kick 71. NaN rows once read as satisfied constraints (probability 1, SAFE,
    while Monte Carlo gives P <= 0.02); both properties must be UNKNOWN with the whole [0, 1]."""
    model = load_model("tests/data/fsr_spiral.yaml")
    for prop in load_properties("tests/data/fsr_spiral_props.yaml"):
        result = BACKEND.check(model, bind(prop, model), {})
        assert result.status is Status.UNKNOWN
        assert result.probability == (0.0, 1.0)
        assert "overflows" in result.details["reason"]


DRIVEN_KICKS = """
name: driven
state: [x, v]
bounded_inputs: {p: {range: RANGE}}
modes:
  run: {flow: {x: v, v: "-0.1*v + p"}}
initial: {mode: run, box: {x: 0, v: 0}}
horizon: 10
disturbance: {gaussian: {mean: [0], cov: [0.01]}, enters: [v], step: 1}
"""


@pytest.mark.parametrize("low, high", [(0.05, 0.1), (0.1, 0.1)])
def test_a_bounded_constant_with_a_range_is_not_averaged_over(tmp_path, low, high):
    """P(|x(10)| <= 1) is 0.25 at p = 0.05 and 0.025 at p = 0.1: averaged over p (as a uniform
    law) it would meet 0.08 and read SAFE though p = 0.1 breaks it. A ranged bounded input is
    unsupported (it is any value, not a distribution); fixed to one value, the check runs."""
    from model_files import load_files

    model, props = load_files(tmp_path, DRIVEN_KICKS.replace("RANGE", f"[{low}, {high}]"), """
        properties:
          - {id: near, kind: reach, at: 10, target: {box: {x: [-1, 1]}}, probability: {at_least: 0.08}}
    """)
    reason = BACKEND.supports(model, props["near"])
    if low < high:
        assert reason is not None and "p may take any value" in reason
    else:
        assert reason is None
        result = BACKEND.check(model, props["near"])
        assert result.probability[1] < 0.08 and result.details["verdict"] == "violated"


@pytest.mark.parametrize("method", ["genz", "markov"])
def test_a_clock_on_its_bound_meets_it_whatever_the_rounding(tmp_path, method):
    """``x' = -0.3 x`` kicked by N(0, 1) every 0.3 and a clock ``z``: at 0.9 the clock is
    0.9000000000000001 in floating point (0.3 is not a binary number), yet it meets ``z <= 0.9``
    and ``z <= 0.6`` at 0.6: ``P(|x(0.9)| <= 1) = 2 Phi(1 / sigma) - 1``, ``sigma^2 = sum_k
    e^(-0.6 (0.9 - 0.3 k))`` (closed form), for a reach target with ``z <= 0.9`` and a
    reach-avoid with ``z <= 0.6`` while it waits (it was 0: 'a deterministic constraint fails');
    Monte Carlo's interval holds the same value."""
    (tmp_path / "m.yaml").write_text(
        "name: clk\nstate: [x, z]\nmodes:\n  run: {flow: {x: \"-0.3*x\", z: 1}}\n"
        "initial: {mode: run, box: {x: 0, z: 0}}\nhorizon: 10\n"
        "disturbance: {gaussian: {mean: [0], cov: [1]}, enters: [x], step: 0.3}\n")
    (tmp_path / "p.yaml").write_text(
        "properties:\n"
        "  - {id: reach_z, kind: reach, at: 0.9, target: [\"x >= -1\", \"x <= 1\", \"z <= 0.9\"]}\n"
        "  - {id: avoid_z, kind: reach_avoid, at: 0.9, target: {box: {x: [-1, 1]}}, safe: [\"z <= 0.6\"]}\n")
    model = load_model(tmp_path / "m.yaml")
    sigma = np.sqrt(sum(np.exp(-0.6 * (0.9 - 0.3 * k)) for k in range(3)))
    exact = 2 * ndtr(1 / sigma) - 1
    for prop in load_properties(tmp_path / "p.yaml"):
        bound = bind(prop, model)
        low, high = BACKEND.check(model, bound, {"method": method}).probability
        assert low - 1e-9 <= exact <= high + 1e-9 and high - low < 1e-3
        low, high = MC.check(model, bound, {"samples": 4000}).probability
        assert low <= exact <= high


def test_the_method_reported_is_the_one_that_ran():
    """``-o method=genz`` on a point initial state: a reach and a reach-avoid probability, both
    by Genz's QMC of a Gaussian box, both say so (the reach one said 'gaussian')."""
    from reach.checking import check_files
    results = check_files("models/fsr_burn.yaml", "properties/fsr_burn.yaml", "fsr", {"method": "genz"})
    assert [r.details["method"] for r in results] == ["genz", "genz"]


@pytest.mark.parametrize("mean, cov", [("[0]", '["(0.05[m/s])**2"]'),
                                       ("[0, 0]", '["(0.05[m/s])**2", "(0.05[m/s])**2"]')])
def test_a_state_entered_twice_is_bad_input_naming_it(tmp_path, capsys, mean, cov):
    """``enters: [vy, vy]`` is one state listed twice: bad input at the ``enters`` line naming
    ``vy``, whether the mean and covariance have one entry (it was read as a mean of the wrong
    length) or two (it was accepted, and the kick counted twice)."""
    from pathlib import Path

    from reach.cli import main

    root = Path(__file__).resolve().parents[1]
    text = (root / "models" / "fsr_burn.yaml").read_text()
    for old, new in (("enters: [vy]", "enters: [vy, vy]"), ("mean: [0]", f"mean: {mean}"),
                     ('cov: ["(0.05[m/s])**2"]', f"cov: {cov}")):
        assert old in text
        text = text.replace(old, new)
    model = tmp_path / "burn.yaml"
    model.write_text(text)
    line = text.splitlines().index("  enters: [vy, vy]") + 1
    assert main(["check", str(model), str(root / "properties" / "fsr_burn.yaml"), "-b", "fsr"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (f"reach: {model}:{line}: disturbance.enters[1]: 'vy' is listed twice "
                            f"(list each state the kicks enter once)\n")
