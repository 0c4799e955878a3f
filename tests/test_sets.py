"""The LP layer and the set types against independent references.

References: closed-form box formulas, brute-force vertex enumeration in 2-D (pairs of
constraint lines, no LP), and direct evaluation of sampled points.
"""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from reach import lp
from reach.sets import Box, HPolytope, Star, chord_hull

SEEDS = st.integers(0, 2**32 - 1)


def random_polygon(rng, k=6):
    """A bounded 2-D polytope: ``k`` random half-planes around a point plus a bounding box."""
    angles = rng.uniform(0, 2 * np.pi, k)
    A = np.column_stack([np.cos(angles), np.sin(angles)])
    b = rng.uniform(0.5, 2.0, k)
    box = Box([-3, -3], [3, 3]).to_hpolytope()
    return HPolytope(A, b).intersection(box)


# ---------------------------------------------------------------------- LP layer

def test_lp_statuses():
    A = np.array([[1.0, 0.0], [-1.0, 0.0]])
    assert lp.maximize([1, 0], A, [1, 0]).value == pytest.approx(1.0)
    assert lp.minimize([0, 1], A, [1, 0]).unbounded
    assert lp.minimize([1, 0], A, [-1, 0]).infeasible
    assert lp.feasible_point(A, [-1, 0]) is None
    x = lp.feasible_point(A, [1, 0])
    assert 0 <= x[0] <= 1
    # variables are free by default (scipy's default would be x >= 0)
    assert lp.minimize([1], np.array([[-1.0]]), [5.0]).value == pytest.approx(-5.0)


# ---------------------------------------------------------------------- Box

@given(SEEDS)
@settings(max_examples=30, deadline=None)
def test_box_support_and_affine_hull(seed):
    rng = np.random.default_rng(seed)
    low = rng.uniform(-2, 0, 3)
    box = Box(low, low + rng.uniform(0, 2, 3))
    corners = box.corners()
    d = rng.normal(size=3)
    assert box.support(d) == pytest.approx(np.max(corners @ d))
    M, t = rng.normal(size=(2, 3)), rng.normal(size=2)
    hull = box.affine_map(M, t)
    images = corners @ M.T + t
    np.testing.assert_allclose(hull.low, images.min(axis=0), atol=1e-12)
    np.testing.assert_allclose(hull.high, images.max(axis=0), atol=1e-12)


# ---------------------------------------------------------------------- HPolytope

@given(SEEDS)
@settings(max_examples=30, deadline=None)
def test_hpolytope_support_against_vertices(seed):
    rng = np.random.default_rng(seed)
    P = random_polygon(rng)
    V = P.vertices_2d()
    assert len(V) >= 3
    for _ in range(4):
        d = rng.normal(size=2)
        assert P.support(d) == pytest.approx(np.max(V @ d), abs=1e-7)
    box = P.bounding_box()
    np.testing.assert_allclose(box.low, V.min(axis=0), atol=1e-7)
    np.testing.assert_allclose(box.high, V.max(axis=0), atol=1e-7)
    assert all(P.contains(v) for v in V)
    assert not P.contains(V.max(axis=0) + 0.1)


@given(SEEDS)
@settings(max_examples=30, deadline=None)
def test_hpolytope_intersection_emptiness_against_vertices(seed):
    rng = np.random.default_rng(seed)
    P, Q = random_polygon(rng), random_polygon(rng)
    Q = HPolytope(Q.A, Q.b - Q.A @ rng.uniform(-4, 4, 2))       # shifted copy
    both = P.intersection(Q)
    assert both.is_empty() == (len(both.vertices_2d()) == 0)


# ---------------------------------------------------------------------- Star

def star_as_polygon(star: Star) -> HPolytope:
    """A 2-D star with an invertible basis, rewritten in x: ``a = V^-1 (x - c)``."""
    Vinv = np.linalg.inv(star.basis)
    pred = star.predicate.intersection(star.box.to_hpolytope())
    return HPolytope(pred.A @ Vinv, pred.b + pred.A @ Vinv @ star.center)


def star_predicate_polygon(star: Star) -> HPolytope:
    """The coefficients ``a`` of a star: its predicate together with its box."""
    return star.predicate.intersection(star.box.to_hpolytope())


def random_star(rng) -> Star:
    basis = rng.normal(size=(2, 2)) + 2 * np.eye(2)
    star = Star(rng.normal(size=2), basis, box=Box([-1, -1], [1, 1]))
    return star.intersect_halfspaces(rng.normal(size=(1, 2)), [0.5])


@given(SEEDS)
@settings(max_examples=30, deadline=None)
def test_star_intersection_against_vertex_enumeration(seed):
    """Star predicates after exact intersections: LP support vs brute-force vertices."""
    rng = np.random.default_rng(seed)
    star = random_star(rng)
    H = rng.normal(size=(2, 2))
    g = H @ star.center + rng.uniform(-0.5, 1.0, 2)
    cut = star.intersect_halfspaces(H, g)
    V = star_as_polygon(star).intersect_halfspaces(H, g).vertices_2d()
    assert cut.is_empty() == (len(V) == 0)
    if len(V):
        for _ in range(3):
            d = rng.normal(size=2)
            assert cut.support(d) == pytest.approx(np.max(V @ d), abs=1e-6)
            assert cut.support_bounds(d)[0] >= np.max(V @ d) - 1e-9     # the cheap bound is an upper bound


@given(SEEDS)
@settings(max_examples=30, deadline=None)
def test_star_affine_map_of_sampled_points(seed):
    rng = np.random.default_rng(seed)
    star = Star.from_box(Box(rng.uniform(-1, 0, 3), rng.uniform(0, 1, 3)))
    M, t = rng.normal(size=(3, 3)), rng.normal(size=3)
    image = star.affine_map(M, t)
    for alpha in rng.uniform(-1, 1, (5, star.nvars)):
        x = star.point(alpha)
        assert image.contains(M @ x + t)
        np.testing.assert_allclose(image.point(alpha), M @ x + t)
    outside = star.box_bound().high + 1.0
    assert not star.contains(outside)


@given(SEEDS)
@settings(max_examples=25, deadline=None)
def test_depth_sign_matches_disjointness(seed):
    rng = np.random.default_rng(seed)
    star = random_star(rng)
    H = rng.normal(size=(3, 2))
    g = H @ rng.uniform(-3, 3, 2) + rng.uniform(0.1, 1.0, 3)
    depth, alpha = star.depth(H, g)
    meet = star_as_polygon(star).intersect_halfspaces(H, g).vertices_2d()
    assert (depth >= -1e-7) == (len(meet) > 0)
    if alpha is not None and depth >= 0:
        assert np.all(H @ star.point(alpha) <= g + 1e-7)


@given(SEEDS)
@settings(max_examples=25, deadline=None)
def test_chord_hull_contains_interpolants_and_is_the_convex_hull(seed):
    rng = np.random.default_rng(seed)
    start = random_star(rng)
    M = rng.normal(size=(2, 2))
    c1, V1 = M @ start.center + 1.0, M @ start.basis
    error = rng.uniform(0, 0.3, 2)
    seg = chord_hull(start, c1, V1, error)
    # coefficients drawn as convex combinations of the brute-force vertices of the predicate
    # (with its box): always inside, with no rejection loop; an empty star has nothing to check
    corners = star_predicate_polygon(start).vertices_2d()
    assume(len(corners) > 0)
    weights = rng.dirichlet(np.ones(len(corners)), 5)
    for a in weights @ corners:
        lam = rng.uniform()
        e = rng.uniform(-1, 1, 2) * 4 * lam * (1 - lam) * error
        x = (1 - lam) * start.point(a) + lam * (c1 + V1 @ a) + e
        assert seg.contains(x)
    # support equals the brute-force convex hull of both polygons, plus the mid-cell error
    V0 = star_as_polygon(start).vertices_2d()
    Vend = V0 @ M.T + 1.0
    for _ in range(3):
        d = rng.normal(size=2)
        hull = max(np.max(V0 @ d), np.max(Vend @ d))
        assert hull - 1e-6 <= seg.support(d) <= hull + np.abs(d) @ error + 1e-6
    # the first coefficients of a hull point are the start's coefficients
    res = seg.maximize(rng.normal(size=2))
    assert start.predicate.contains(res.x[:2], tol=1e-6)


def _offset_star(rng) -> Star:
    """A 2-D star whose coefficient box need not contain 0 (``low`` in [-1, 1]), its
    predicate a half-plane just beyond a random point of the box: never empty."""
    low = rng.uniform(-1, 1, 2)
    high = low + rng.uniform(0.2, 2.0, 2)
    a = rng.uniform(low, high)
    w = rng.normal(size=2)
    return Star(rng.normal(size=2), rng.normal(size=(2, 2)) + 2 * np.eye(2), HPolytope(w[None], [w @ a + 0.1]),
                Box(low, high))


def _at_weight(seg: Star, m: int, lam: float) -> Star:
    """The points of a chord hull with the chord weight (coefficient ``2 m``) fixed to ``lam``."""
    low, high = seg.box.low.copy(), seg.box.high.copy()
    low[2 * m] = high[2 * m] = lam
    return Star(seg.center, seg.basis, seg.predicate, Box(low, high))


@given(SEEDS, st.sampled_from([0.0, 0.1, 0.3, 0.5, 0.8, 1.0]))
@settings(max_examples=40, deadline=None)
def test_chord_hull_at_each_weight_is_the_interpolant_plus_the_tent(seed, lam):
    """At chord weight ``lam`` the hull is exactly ``(1 - lam) X0 + lam X1 + E(lam)`` (Minkowski
    sums; ``X0`` the start, ``X1 = {x1(a)}``), which holds every interpolant
    ``(1 - lam) x0(a) + lam x1(a)``, with ``E(lam) = {|e_i| <= t(lam) r_i}``,
    ``t = min(1, 4 lam, 4 (1 - lam))``: the two tangent lines of the error parabola
    ``4 lam (1 - lam)`` at the grid points, capped at its peak. Reference support:
    ``(1 - lam) h0 + lam h1 + t(lam) |d| . r`` with ``h0, h1`` the maxima over the brute-force
    vertices of the coefficient polygon. A component with zero error adds no coefficient."""
    rng = np.random.default_rng(seed)
    start = _offset_star(rng)
    M = rng.normal(size=(2, 2))
    c1, V1 = M @ start.center + rng.normal(size=2), M @ start.basis
    error = np.array([rng.uniform(0.05, 0.5), 0.0])[rng.permutation(2)]
    seg = chord_hull(start, c1, V1, error)
    assert seg.nvars == 2 * 2 + 1 + 1
    corners = star_predicate_polygon(start).vertices_2d()
    tent = min(1.0, 4 * lam, 4 * (1 - lam))
    assert tent >= 4 * lam * (1 - lam)              # the parabola lies under the tangent lines
    sliced = _at_weight(seg, 2, lam)
    for _ in range(4):
        d = rng.normal(size=2)
        h0, h1 = np.max((start.center + corners @ start.basis.T) @ d), np.max((c1 + corners @ V1.T) @ d)
        reference = (1 - lam) * h0 + lam * h1 + tent * np.abs(d) @ error
        assert sliced.support(d) == pytest.approx(reference, abs=1e-6)


@given(SEEDS, st.booleans())
@settings(max_examples=25, deadline=None)
def test_chord_hull_without_error_is_the_convex_hull_of_the_ends(seed, point):
    """No error: the hull is ``conv(start, end)`` and its support the larger end support
    (brute-force vertices), also for a start that is a single point (the hull is then the
    segment from ``x0`` to ``x1``, nothing beyond ``x1``)."""
    rng = np.random.default_rng(seed)
    if point:                       # the center alone: all coefficients pinned to 0
        start = Star(rng.normal(size=2), rng.normal(size=(2, 2)), box=Box(np.zeros(2), np.zeros(2)))
        corners = np.zeros((1, 2))
    else:
        start = _offset_star(rng)
        corners = star_predicate_polygon(start).vertices_2d()
    M = rng.normal(size=(2, 2))
    c1, V1 = M @ start.center + rng.normal(size=2), M @ start.basis
    seg = chord_hull(start, c1, V1)
    assert seg.nvars == 2 * 2 + 1
    ends = np.vstack([start.center + corners @ start.basis.T, c1 + corners @ V1.T])
    for _ in range(4):
        d = rng.normal(size=2)
        assert seg.support(d) == pytest.approx(np.max(ends @ d), abs=1e-6)
