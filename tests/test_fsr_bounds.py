"""fsr's intervals are bounds or say they are not: a uniform initial box integrated with the kicks,
the Fourier truncation bounded by the Gaussian kicks' spread (against closed forms and the
omitted terms summed), an estimate that decides nothing, a row far smaller than another read
both ways, a polytope initial set refused."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.integrate import quad
from scipy.special import ndtr

from reach.backends.fsr import BACKEND
from reach.backends.fsr import fourier as F
from reach.result import Status
from model_files import load_files

# x uniform on [-1, 1] (the initial box, no drift) plus one Gaussian kick of sd S at t = 0
KICKED = """
name: kicked
state: [x]
modes:
  m: {{flow: {{x: "0"}}}}
initial: {{mode: m, box: {{x: [-1, 1]}}}}
horizon: 1
disturbance:
  gaussian: {{mean: [0], cov: [{var}]}}
  enters: [x]
  step: 1
"""


def _uniform_plus_normal(low: float, high: float, sd: float) -> float:
    """P(low <= u + n <= high), u ~ U[-1, 1], n ~ N(0, sd^2), by quadrature over u."""
    value, _ = quad(lambda u: 0.5 * (ndtr((high - u) / sd) - ndtr((low - u) / sd)), -1, 1,
                    epsabs=1e-13, epsrel=1e-13, points=[low, high])
    return value


def test_a_uniform_box_with_a_gaussian_kick_holds_the_truth_by_both_methods(tmp_path):
    """At a target edge, where the uniform's slow sinc decay matters most, the default interval
    (randomised QMC over the box and the kick) and the Fourier one (its truncation bounded: the
    kick spreads x) both hold the closed form."""
    sd = 0.02
    model, props = load_files(tmp_path, KICKED.format(var=sd ** 2), """
        properties:
          - {id: edge, kind: reach, at: 1, target: {box: {x: [0.95, 1.5]}}, probability: {at_least: 0.01}}
    """)
    truth = _uniform_plus_normal(0.95, 1.5, sd)
    for options in ({}, {"method": "fourier"}):
        result = BACKEND.check(model, props["edge"], options)
        low, high = result.probability
        assert low <= truth <= high
        assert high - low < 2e-3
        assert result.status is Status.SAFE and truth >= 0.01
    assert result.details["error"].endswith("truncation bound")


def test_without_a_gaussian_spread_the_fourier_estimate_decides_nothing(tmp_path):
    """x ~ U[-1, 1] and a kick on another state only: P(x in [1, 1.5]) = 0, but the truncated
    Fourier sum gives about 8e-4; that must not be a SAFE against 3e-4, nor P(x in [-1, 1]) = 1 a
    violation of 0.9995. The default method integrates over the box: both exact."""
    model, props = load_files(tmp_path, """
        name: unif
        state: [x, y]
        modes:
          m: {flow: {x: "0", y: "0"}}
        initial: {mode: m, box: {x: [-1, 1], y: 0}}
        horizon: 1
        disturbance:
          gaussian: {mean: [0], cov: [1]}
          enters: [y]
          step: 1
    """, """
        properties:
          - {id: none, kind: reach, at: 1, target: {box: {x: [1, 1.5]}}, probability: {at_least: 0.0003}}
          - {id: all, kind: reach, at: 1, target: {box: {x: [-1, 1]}}, probability: {at_least: 0.9995}}
    """)
    for pid, truth in (("none", 0.0), ("all", 1.0)):
        result = BACKEND.check(model, props[pid], {"method": "fourier"})
        assert result.status is Status.UNKNOWN
        assert result.probability == (0.0, 1.0)
        assert result.details["verdict"] == "undecided"
        assert abs(result.details["estimate"] - truth) < 0.01
        low, high = BACKEND.check(model, props[pid]).probability
        assert low <= truth <= high and high - low < 1e-9


@settings(max_examples=40, deadline=None)
@given(st.floats(0.05, 3.0), st.floats(0.5, 20.0), st.floats(0.05, 2.0), st.integers(1, 30))
def test_the_truncation_bound_exceeds_the_omitted_terms(lam, L, width, count):
    """1-D: sum over |k| > K of exp(-lam w_k^2 / 2) |box transform| / L, summed far out, is at most
    the bound (the worst case of the Gaussian factor, the box transform at its largest)."""
    omega = 2 * np.pi * np.arange(count + 1, count + 200_000) / L
    transform = np.abs(2 * np.sin(omega * width / 2) / omega)
    omitted = 2 * np.sum(np.exp(-0.5 * lam * omega ** 2) * transform) / L
    bound = F.truncation_bound(lam, [width], [L], [count])
    assert omitted <= bound[0] * (1 + 1e-9) + 1e-300


def test_a_row_far_smaller_than_another_is_read_both_ways(tmp_path):
    """s spreads by 1e5 m, th by 1e-8 rad: P(|s| <= 1e7 and th >= 0) = 0.5. Read against s alone,
    th looked deterministic (at 0, meeting th >= 0) and the probability 1: a false SAFE."""
    model, props = load_files(tmp_path, """
        name: scales
        state: [s, th]
        modes:
          m: {flow: {s: "0", th: "-0.01*th"}}
        initial: {mode: m, box: {s: 0, th: 0}}
        horizon: 10
        disturbance:
          gaussian: {mean: [0, 0], cov: [1e10, 1e-16]}
          enters: [s, th]
          step: 10
    """, """
        properties:
          - {id: both, kind: reach, at: 10, target: ["s <= 1e7", "s >= -1e7", "th >= 0"],
             probability: {at_least: 0.9}}
    """)
    result = BACKEND.check(model, props["both"])
    assert result.status is not Status.SAFE
    low, high = result.probability
    assert low <= 0.5 <= high


def test_a_polytope_initial_set_is_refused(tmp_path):
    """The segment x + y = 1 is no box: taking its bounding box as uniform gave P(x + y in
    [0.99, 1.01]) = 0.02 where it is about 1."""
    model, props = load_files(tmp_path, """
        name: seg
        state: [x, y]
        modes:
          m: {flow: {x: "0", y: "0"}}
        initial: {mode: m, box: {x: [0, 1], y: [0, 1]}, constraints: ["x + y == 1"]}
        horizon: 1
        disturbance:
          gaussian: {mean: [0, 0], cov: [1e-6, 1e-6]}
          enters: [x, y]
          step: 1
    """, """
        properties:
          - {id: onseg, kind: reach, at: 1, target: ["x + y <= 1.01", "x + y >= 0.99"],
             probability: {at_least: 0.9}}
    """)
    assert "polytope" in BACKEND.supports(model, props["onseg"])


def test_the_uniform_shift_integral_holds_quadratures_of_its_closed_form():
    """P(lo <= z + d v <= hi), z ~ N(0, C) correlated, v ~ U[-1, 1]: against Gauss-Legendre over v of
    scipy's bivariate normal box probabilities; and with a row that has no Gaussian spread (met
    or not given v), against a 1-D quadrature."""
    from scipy.stats import multivariate_normal

    from reach.sets.gaussian import uniform_shift_probability

    C = np.array([[1.0, 0.6], [0.6, 2.0]]) * 0.01
    d = np.array([1.0, 0.5])
    lo, hi = np.array([-0.2, -0.3]), np.array([0.5, 0.4])
    nodes, weights = np.polynomial.legendre.leggauss(200)
    normal = multivariate_normal(np.zeros(2), C)
    exact = sum(w / 2 * normal.cdf(hi - d * v, lower_limit=lo - d * v) for v, w in zip(nodes, weights))
    p = uniform_shift_probability(np.zeros(2), C, lo, hi, d[:, None], [1.0], abs_error=1e-4)
    assert p.low <= exact <= p.high and p.high - p.low <= 2e-4
    flat = np.diag([0.01, 0.0])                 # z2 = 0.5 v exactly: v in [-0.6, 0.8]
    exact, _ = quad(lambda v: 0.5 * (ndtr((0.5 - v) / 0.1) - ndtr((-0.2 - v) / 0.1)), -0.6, 0.8, epsabs=1e-13)
    p = uniform_shift_probability(np.zeros(2), flat, lo, hi, d[:, None], [1.0], abs_error=1e-4)
    assert p.low <= exact <= p.high and p.high - p.low <= 2e-4
