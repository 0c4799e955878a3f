"""Gaussian polytope probabilities (reach/sets/gaussian.py) against independent references."""

import numpy as np
import pytest
from scipy.special import ndtr
from scipy.stats import multivariate_normal

from reach.sets.gaussian import Gaussian, box_probability, interval_form, polytope_probability


def polar_probability(H, g, radii=2_000_000):
    """``P(H u <= g)`` for ``u ~ N(0, I_2)`` and a polygon containing 0, by integrating the
    radial law ``P(|u| <= r) = 1 - exp(-r^2/2)`` over the angle (an independent 1-D quadrature)."""
    theta = (np.arange(radii) + 0.5) * 2 * np.pi / radii
    directions = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    proj = directions @ np.asarray(H, float).T
    with np.errstate(divide="ignore"):
        r = np.where(proj > 0, np.asarray(g, float) / proj, np.inf).min(axis=1)
    return float(np.mean(1 - np.exp(-r ** 2 / 2)))


def test_interval_form_merges_opposite_rows():
    H = np.array([[1.0, 0], [-2.0, 0], [0, 1.0], [3.0, 0]])
    g = np.array([2.0, 2.0, 5.0, 3.0])
    T, lo, hi = interval_form(H, g)
    assert T.shape == (2, 2)
    assert np.allclose(T, [[1, 0], [0, 1]])
    assert np.allclose(lo, [-1, -np.inf]) and np.allclose(hi, [1, 5])


def test_one_dimensional_closed_form():
    p = box_probability([1.0], [[4.0]], [-1.0], [2.0])
    exact = ndtr(0.5) - ndtr(-1.0)
    assert p.dimension == 0
    assert p.low <= exact <= p.high and p.width < 1e-11


def test_far_upper_tail_keeps_relative_precision():
    p = box_probability([0.0], [[1.0]], [8.0], [np.inf])
    assert p.value == pytest.approx(ndtr(-8.0), rel=1e-10)


@pytest.mark.parametrize("d", [2, 3, 5])
def test_box_against_scipy(d):
    rng = np.random.default_rng(d)
    A = rng.normal(size=(d, d))
    cov = A @ A.T + 0.2 * np.eye(d)
    mean = rng.normal(size=d)
    sd = np.sqrt(np.diag(cov))
    lower, upper = mean - 1.2 * sd, mean + 0.8 * sd
    lower[0] = -np.inf
    p = box_probability(mean, cov, lower, upper, abs_error=2e-4)
    reference = multivariate_normal.cdf(upper, mean, cov, lower_limit=lower, abseps=1e-7, releps=0,
                                        maxpts=5_000_000)
    assert p.low - 2e-6 <= reference <= p.high + 2e-6
    assert p.width <= 2 * 2e-4 + 1e-9


def test_singular_covariance_against_polar_quadrature():
    rng = np.random.default_rng(1)
    B = rng.normal(size=(3, 2))                     # rank-2 covariance in R^3
    H = np.vstack([np.eye(3), -np.eye(3)])
    g = np.ones(6)
    p = polytope_probability(np.zeros(3), B @ B.T, H, g, abs_error=1e-5)
    assert p.low - 1e-6 <= polar_probability(H @ B, g) <= p.high + 1e-6


def test_polytope_with_more_faces_than_dimensions():
    H = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1], [1, 0.0]])
    g = np.array([1, 1, 1, 1, 0.5])
    cov = np.array([[1.0, 0.3], [0.3, 0.5]])
    L = np.linalg.cholesky(cov)
    p = polytope_probability(np.zeros(2), cov, H, g, abs_error=1e-5)
    assert p.low - 1e-6 <= polar_probability(H @ L, g) <= p.high + 1e-6


def test_point_distributions_and_empty_sets():
    zero = np.zeros((2, 2))
    assert box_probability([0.5, 0.5], zero, [0, 0], [1, 1]).value == 1.0
    assert box_probability([1.5, 0.5], zero, [0, 0], [1, 1]).value == 0.0
    assert box_probability([0, 0], np.eye(2), [1, 0], [0, 1]).high == 0.0


def test_deterministic_coordinate_is_checked_not_integrated():
    cov = np.diag([1.0, 0.0])
    inside = box_probability([0, 3], cov, [-1, 2], [1, 4])
    outside = box_probability([0, 3], cov, [-1, 4], [1, 5])
    assert inside.low <= ndtr(1) - ndtr(-1) <= inside.high
    assert outside.high == 0.0


def test_gaussian_set_operations():
    g = Gaussian([1.0, 2.0], [[2.0, 0.5], [0.5, 1.0]])
    image = g.affine([[1.0, 1.0]], [3.0])
    assert np.allclose(image.mean, [6.0]) and np.allclose(image.cov, [[4.0]])
    assert np.allclose(g.marginal([1]).cov, [[1.0]])
    X = g.sample(200_000, rng=3)
    assert np.allclose(X.mean(axis=0), g.mean, atol=0.02)
    assert np.allclose(np.cov(X.T), g.cov, atol=0.03)
    p = g.probability([[1.0, 1.0]], [6.0])          # P(x + y <= 6) for x + y ~ N(3, 4)
    assert p.low <= ndtr(1.5) <= p.high


def test_a_non_finite_law_bounds_no_probability():
    """A NaN mean or variance must not make rows look fixed and satisfied (which gave 1)."""
    for mean, cov in (([np.nan, 0.0], np.eye(2)), ([0.0, 0.0], np.diag([np.nan, 1.0])),
                      ([np.inf, -np.inf], np.eye(2))):
        p = box_probability(mean, cov, [-1.0, -1.0], [1.0, 1.0])
        assert (p.low, p.high) == (0.0, 1.0)
