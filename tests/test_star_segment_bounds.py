"""Star segment bounds (reach.backends.star.flowpipe) against closed forms and brute force.

- the curvature bound ``M >= sup |x''|`` on a cell: for a diagonal ``A`` every run's
  ``x_i''(t) = a_i^2 x_i(t) + a_i b_i`` is monotone in ``t`` (``x_i(t) = e^{a_i t}
  (x_i(0) + b_i / a_i) - b_i / a_i``), so its supremum over the cell and the start box is
  attained at a box corner and a cell end, and the segment error is exactly the documented
  ``h^2/8 M_i / (1 - delta^2 a_i^2 / 8)`` (``delta = h / q`` the sub-step); for a general
  ``A`` the error is at least ``h^2/8`` times the sampled supremum of ``|x''|`` (dense grid
  over the exact runs from the box corners, where the convex ``|x''|`` peaks);
- the chain bounds against the box corners (support of a box star, ``max |D x + d|``);
- the constant-flow segment and the input box against brute-force supports.
"""

from __future__ import annotations

import importlib
import itertools

import numpy as np
from scipy.integrate import quad
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from reach.backends.star.flowpipe import (AffineFlow, _chain_abs_bounds, _chain_bounds, _drift_segment,
                                          _plus_box, _segment)
from reach.sets import Box, HPolytope, Star

flowpipe = importlib.import_module("reach.backends.star.flowpipe")    # the package also has a function of that name

SEEDS = st.integers(0, 2**32 - 1)


def corners(box: Box) -> np.ndarray:
    return np.array(list(itertools.product(*zip(box.low, box.high))))


def runs(A, b, X0, times):
    """Exact states ``x(t)`` (times, corners, n) of ``x' = A x + b`` via the augmented expm."""
    n = A.shape[0]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = A, b
    out = []
    for t in times:
        E = expm(aug * t)
        out.append(X0 @ E[:n, :n].T + E[:n, n])
    return np.array(out)


def random_box(rng, n):
    low = rng.normal(size=n)
    return Box(low, low + rng.uniform(0.1, 1.5, n))


@given(SEEDS, st.floats(0.05, 3.0))
@settings(max_examples=30, deadline=None)
def test_diagonal_flow_segment_error_is_the_closed_form(seed, h):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-2.0, 1.0, 3)
    b = rng.normal(size=3)
    box = random_box(rng, 3)
    A = np.diag(a)
    seg, end, error = _segment(AffineFlow(A, b), Star.from_box(box), h)
    X0 = corners(box)
    X = runs(A, b, X0, [0.0, h])
    M = np.max(np.abs(X * a ** 2 + a * b), axis=(0, 1))          # sup |x''| at the cell ends
    rho = np.max(a ** 2)
    q = max(1, int(np.ceil(h / np.sqrt(2.0 / rho))))            # sub-steps: delta^2 rho / 8 <= 1/4
    delta = h / q
    assert delta ** 2 * rho / 8 <= 0.25 + 1e-12
    assert error == pytest.approx(h * h / 8 * M / (1 - delta ** 2 * a ** 2 / 8), rel=1e-9, abs=1e-12)
    # the end star is the exact image of the start box
    for x1 in X[1]:
        assert end.contains(x1)
    assert np.allclose(end.box_bound().low, X[1].min(axis=0)) and np.allclose(end.box_bound().high, X[1].max(axis=0))


@given(SEEDS, st.floats(0.05, 2.0))
@settings(max_examples=25, deadline=None)
def test_segment_error_bounds_the_curvature_of_every_run(seed, h):
    """General ``A``: ``error >= h^2/8 sup |x''|``, which the interpolation error bound
    needs (the tightness is checked on the diagonal flows above)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(2, 2))
    b = rng.normal(size=2)
    box = random_box(rng, 2)
    _, _, error = _segment(AffineFlow(A, b), Star.from_box(box), h)
    X = runs(A, b, corners(box), np.linspace(0.0, h, 401))
    M = np.max(np.abs(X @ (A @ A).T + A @ b), axis=(0, 1))
    assert np.all(error >= h * h / 8 * M * (1 - 1e-9))


@given(SEEDS)
@settings(max_examples=25, deadline=None)
def test_chain_bounds_are_the_box_corner_extremes(seed):
    """Box stars ``Y_j = c_j + V_j a``, ``a`` in a box: the support in ``w`` and
    ``max |D_l x + d_l|`` are attained at a corner of the coefficient box."""
    rng = np.random.default_rng(seed)
    J, n, m, L = 3, 2, 3, 2
    centers, bases = rng.normal(size=(J, n)), rng.normal(size=(J, n, m))
    box = random_box(rng, m)
    W = rng.normal(size=(4, n))
    D, d = rng.normal(size=(L, n, n)), rng.normal(size=(L, n))
    points = centers[:, None, :] + np.einsum("jnm,km->jkn", bases, corners(box))      # (J, corners, n)
    assert _chain_bounds(centers, bases, box, W) == pytest.approx(np.max(points @ W.T, axis=1))
    values = np.abs(np.einsum("lin,jkn->jkli", D, points) + d[None, None])
    assert _chain_abs_bounds(centers, bases, box, D, d) == pytest.approx(np.max(values, axis=1))


@given(SEEDS)
@settings(max_examples=25, deadline=None)
def test_hull_curvature_bound_is_the_interval_hulls_extreme(seed):
    """The cheap bound of the chain's screening is ``max |D_l x + d_l|`` over the interval hull
    of each ``Y_j`` (brute force over the hull's corners): never below the exact one, equal to it
    where ``V_j`` is diagonal. The exact one, formed a grid star at a time, is unchanged."""
    rng = np.random.default_rng(seed)
    J, n, L = 4, 2, 3
    centers, bases = rng.normal(size=(J, n)), rng.normal(size=(J, n, n))
    bases[0] = np.diag(rng.normal(size=n))
    box = random_box(rng, n)
    D, d = rng.normal(size=(L, n, n)), rng.normal(size=(L, n))
    mid, radius = centers + bases @ box.center, np.abs(bases) @ box.radius
    hull = mid[:, None, :] + np.array(list(itertools.product((-1, 1), repeat=n)))[None] * radius[:, None, :]
    values = np.abs(np.einsum("lin,jkn->jkli", D, hull) + d[None, None])
    loose = flowpipe._hull_abs_bounds(centers, bases, box, D, d)
    assert loose == pytest.approx(np.max(values, axis=1))
    exact = _chain_abs_bounds(centers, bases, box, D, d)
    assert np.all(loose >= exact * (1 - 1e-12))
    assert loose[0] == pytest.approx(exact[0])
    old, flowpipe.PRODUCT_BYTES = flowpipe.PRODUCT_BYTES, 1         # one grid star at a time
    try:
        assert _chain_abs_bounds(centers, bases, box, D, d) == pytest.approx(exact)
    finally:
        flowpipe.PRODUCT_BYTES = old


def cut_star(rng):
    """A 2-D star with a coefficient box and one predicate row through a point of the box,
    and the brute-force vertices of its coefficient polygon."""
    box = random_box(rng, 2)
    a, w = rng.uniform(box.low, box.high), rng.normal(size=2)
    star = Star(rng.normal(size=2), rng.normal(size=(2, 2)) + 2 * np.eye(2), HPolytope(w[None], [w @ a]), box)
    polygon = star.predicate.intersection(box.to_hpolytope()).vertices_2d()
    return star, star.center + polygon @ star.basis.T


@given(SEEDS, st.floats(0.1, 5.0))
@settings(max_examples=25, deadline=None)
def test_constant_flow_segment_is_the_swept_set(seed, h):
    """``x' = b``: the segment is ``start + [0, h] b``; its support is the larger of the
    start's and the end's (brute force over the vertices), and it is the flowpipe's
    constant-flow branch (zero error, exact end)."""
    rng = np.random.default_rng(seed)
    b = rng.normal(size=2)
    start, X0 = cut_star(rng)
    seg = _drift_segment(start, b, h)
    via, end, error = _segment(AffineFlow(np.zeros((2, 2)), b), start, h)
    assert np.all(error == 0.0)
    for _ in range(4):
        w = rng.normal(size=2)
        reference = max(np.max(X0 @ w), np.max((X0 + h * b) @ w))
        assert seg.support(w) == pytest.approx(reference, abs=1e-9)
        assert via.support(w) == pytest.approx(reference, abs=1e-9)
        assert end.support(w) == pytest.approx(np.max((X0 + h * b) @ w), abs=1e-9)


@given(SEEDS)
@settings(max_examples=25, deadline=None)
def test_input_box_adds_its_radius_to_every_support(seed):
    """``star + [-r, r]``: ``h(w) = h_star(w) + |w| . r`` (brute-force vertices of the
    star), one coefficient per positive ``r_i`` (a zero radius adds none)."""
    rng = np.random.default_rng(seed)
    star, X = cut_star(rng)
    radius = rng.uniform(0.0, 1.0, 2) * (rng.uniform(size=2) < 0.7)
    out = _plus_box(star, radius)
    assert out.nvars == star.nvars + int(np.count_nonzero(radius))
    for _ in range(4):
        w = rng.normal(size=2)
        assert out.support(w) == pytest.approx(np.max(X @ w) + np.abs(w) @ radius, abs=1e-9)


def test_input_deviation_bound_covers_the_bang_bang_input_and_is_tight():
    """``x' = a x + u``, ``|u| <= 1``, ``a < 0``: the largest deviation ``sup |d(t)|`` up to
    ``t`` is ``(1 - e^{a t}) / |a|`` (constant ``u = 1``). The bound ``R_j`` covers it at
    every grid point and is within the documented ``h e^{|a| h}`` sum, i.e. within a
    factor ``e^{2 |a| h}`` of the true value for small ``h``."""
    a, h, count = -0.5, 0.1, 20
    flow = AffineFlow(np.array([[a]]), np.zeros(1), np.array([[1.0]]), np.array([1.0]))
    R = flow.deviation(h, count)[:, 0]
    t = h * np.arange(count + 1)
    exact = (1 - np.exp(a * t)) / abs(a)
    assert R[0] == 0.0
    assert np.all(R >= exact - 1e-12)
    assert np.all(R[1:] <= exact[1:] * np.exp(2 * abs(a) * h))
    assert AffineFlow(np.array([[a]]), np.zeros(1)).deviation(h, count) is None


def test_deviation_bound_grows_with_the_horizon_asked():
    """Asking for more grid points after fewer (the bound is cached per step) gives the same
    rows as a fresh flow, and every row bounds the exact support of the input effect,
    ``R(t) = int_0^t |e^{A tau} B| u_r dtau`` (the class doc; scipy ``quad``), from above, within 10 % in
    each entry and 1 % in sum, here for a three-state chain driven through its first state."""
    A = np.array([[-0.3, 0.0, 0.0], [1.0, -0.2, 0.0], [0.0, 1.0, -0.1]])
    B, u_r, h = np.array([[1.0], [0.0], [0.0]]), np.array([0.5]), 0.2
    exact = np.zeros((8, 3))
    for j in range(1, 8):
        for row in range(3):
            exact[j, row] = u_r[0] * quad(lambda tau: abs((expm(A * tau) @ B)[row, 0]), 0.0, j * h,
                                          epsabs=1e-14, epsrel=1e-12)[0]
    fresh = AffineFlow(A, np.zeros(3), B, u_r).deviation(h, 7)
    assert np.all(fresh >= exact - 1e-14)
    assert np.all(fresh[1:] <= exact[1:] * 1.1)            # the curvature term, O(delta^2)
    assert fresh[1:].sum() <= exact[1:].sum() * 1.01
    flow = AffineFlow(A, np.zeros(3), B, u_r)
    for count in (1, 2, 3, 7, 4):
        assert flow.deviation(h, count) == pytest.approx(fresh[:count + 1], rel=1e-12, abs=1e-15)


def test_directed_deviation_is_the_exact_support_along_a_row_not_the_boxs():
    """``x' = v, v' = -x - 0.4 v + u``, ``|u| <= 1``: along ``c = (1, -0.5)`` the input's exact
    support at ``t`` is ``int_0^t |c^T e^{A s} B| ds`` (scipy quad, an independent reference).
    The directed bound covers it at every grid point, within ``O(h^2)``, and lies well below
    what the box gives along ``c`` (``|c| R``, each component's worst signal at once)."""
    A, B, c = np.array([[0.0, 1.0], [-1.0, -0.4]]), np.array([[0.0], [1.0]]), np.array([[1.0, -0.5]])
    h, count = 0.05, 80
    flow = AffineFlow(A, np.zeros(2), B, np.array([1.0]))
    directed = flow.deviation(h, count, c)[:, 0]
    box = np.abs(c) @ flow.deviation(h, count).T
    for j in (10, 40, 80):
        exact = quad(lambda s: abs((c @ expm(A * s) @ B)[0, 0]), 0, j * h, limit=200)[0]
        assert exact - 1e-9 <= directed[j] <= exact + 1e-3 * h
    assert directed[80] < 0.8 * box[0, 80]
    assert np.array_equal(flow.deviation(h, count)[:, 0], flow.deviation(h, count, np.array([[1.0, 0.0]]))[:, 0])
