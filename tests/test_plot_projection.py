"""Outer polygons of projected sets against an independent exact projection.

Reference: the vertices of a star's coefficient polytope by brute-force enumeration (every choice
of ``m`` active constraints, solved and kept when feasible), mapped through ``c + V a`` and
projected, then scipy's convex hull. The outer polygon must contain the reference and, with exact
supports in ``K`` directions spread evenly once the axes are scaled to the set's extent, lie within
``(D / 2) tan(pi / K)`` of it in those scaled coordinates (``D`` the scaled diameter): a vertex of
the outer polygon sits between two supporting lines ``2 pi / K`` apart, both touching the set.
"""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial import ConvexHull

from reach.result import SetPiece
from reach.sets import Box, HPolytope, Star
from reach.sets.projection import DIRECTIONS, clip, outer_polygon
from reach.sets.simplify import convex_hull, merged_polygons


def random_star(seed: int, n: int = 4, m: int = 3, rows: int = 3) -> Star:
    rng = np.random.default_rng(seed)
    center = rng.normal(size=n) * 10
    basis = rng.normal(size=(n, m)) * rng.uniform(0.1, 5.0, size=(n, 1))
    A = rng.normal(size=(rows, m))
    b = np.abs(rng.normal(size=rows)) + 0.2             # a = 0 stays feasible
    return Star(center, basis, HPolytope(A, b), Box(-np.ones(m), np.ones(m)))


def exact_projection(star: Star, i: int, j: int) -> np.ndarray:
    m = star.nvars
    A = np.vstack([star.predicate.A, np.eye(m), -np.eye(m)])
    b = np.concatenate([star.predicate.b, star.box.high, -star.box.low])
    vertices = []
    for rows in itertools.combinations(range(A.shape[0]), m):
        M = A[list(rows)]
        if abs(np.linalg.det(M)) < 1e-10:
            continue
        a = np.linalg.solve(M, b[list(rows)])
        if np.all(A @ a <= b + 1e-9):
            vertices.append(star.point(a)[[i, j]])
    pts = np.array(vertices)
    return pts[ConvexHull(pts).vertices]


def inside(polygon: np.ndarray, points: np.ndarray, slack: float) -> np.ndarray:
    """Points in the convex counter-clockwise polygon, up to ``slack``. Edges shorter than 1e-12 of
    the polygon's extent (repeated vertices up to rounding) have no meaningful normal and are
    skipped."""
    ok = np.ones(len(points), dtype=bool)
    extent = np.ptp(polygon, axis=0).max()
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        edge = b - a
        if np.linalg.norm(edge) <= 1e-12 * extent:
            continue
        normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        ok &= (points - a) @ normal <= slack
    return ok


def distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance of each point to the convex polygon (0 inside)."""
    out = np.zeros(len(points))
    inner = inside(polygon, points, 0.0)
    for k, p in enumerate(points):
        if inner[k]:
            continue
        best = np.inf
        for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
            e = b - a
            s = 0.0 if not e.any() else np.clip((p - a) @ e / (e @ e), 0.0, 1.0)
            best = min(best, np.linalg.norm(p - (a + s * e)))
        out[k] = best
    return out


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([(0, 1), (1, 3), (2, 0)]))
def test_star_polygon_contains_and_is_tight(seed, axes):
    star = random_star(seed)
    i, j = axes
    names = ("a", "b", "c", "d")
    piece = SetPiece("m", 0.0, 1.0, "star", names, (star,))
    poly = piece.polygon(names[i], names[j], exact=True)
    exact = exact_projection(star, i, j)
    scale = exact.max(axis=0) - exact.min(axis=0)
    assert np.all(inside(poly, exact, 1e-7 * scale.max()))
    P, E = poly / scale, exact / scale                   # the scaled coordinates of the bound
    diameter = max(np.linalg.norm(p - q) for p in E for q in E)
    bound = diameter / 2 * np.tan(np.pi / DIRECTIONS) + 1e-7
    assert distance_to_polygon(P, E).max() <= bound


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000))
def test_box_bound_polygon_contains_the_exact_one(seed):
    star = random_star(seed)
    names = ("a", "b", "c", "d")
    bloat = np.array([0.5, 0.0, 2.0, 0.1])
    piece = SetPiece("m", 0.0, 1.0, "star", names, (star,), bloat)
    loose = piece.polygon("a", "c", exact=False)
    exact = exact_projection(star, 0, 2)
    assert np.all(inside(loose, exact, 1e-7 * np.abs(exact).max()))
    # the bloat box around every exact vertex: its corners are states of the piece too
    corners = np.array([[sx * 0.5, sy * 2.0] for sx in (-1, 1) for sy in (-1, 1)])
    grown = (exact[:, None, :] + corners[None]).reshape(-1, 2)
    assert np.all(inside(loose, grown, 1e-7 * np.abs(grown).max()))


def test_segment_hull_contains_both_stars_and_functional_axes():
    """A two-star piece holds both members; an axis given as a functional ``w . x + c`` is the
    image of the states under it (checked on random points of the members)."""
    s0, s1 = random_star(1), random_star(2)
    piece = SetPiece("m", 0.0, 1.0, "star", ("a", "b", "c", "d"), (s0, s1))
    w, c = np.array([1.0, -2.0, 0.0, 0.5]), 3.0
    poly = piece.polygon((w, c), "b")
    rng = np.random.default_rng(0)
    for star in (s0, s1):
        alpha = rng.uniform(-1, 1, size=(4000, 3))
        alpha = alpha[np.all(alpha @ star.predicate.A.T <= star.predicate.b, axis=1)]
        X = star.center + alpha @ star.basis.T
        pts = np.stack([X @ w + c, X[:, 1]], axis=1)
        assert np.all(inside(poly, pts, 1e-7 * np.abs(pts).max()))


def test_time_axis_and_box_pieces():
    low, high = np.array([0.0, -1.0, 2.0]), np.array([1.0, 1.0, 3.0])
    piece = SetPiece("m", 5.0, 6.0, "box", ("x", "y", "z"), low=low, high=high)
    rect = piece.polygon("time", "z")
    assert np.allclose(rect.min(axis=0), [5.0, 2.0]) and np.allclose(rect.max(axis=0), [6.0, 3.0])
    rect = piece.polygon("y", "time")
    assert np.allclose(rect.min(axis=0), [-1.0, 5.0]) and np.allclose(rect.max(axis=0), [1.0, 6.0])
    # a box projected on x + y and z: the hexagon-free parallelogram, exact support
    poly = piece.polygon((np.array([1.0, 1.0, 0.0]), 0.0), "z")
    assert np.isclose(poly[:, 0].min(), -1.0) and np.isclose(poly[:, 0].max(), 2.0)


def test_empty_and_degenerate_sets():
    star = Star(np.zeros(2), np.eye(2), HPolytope(np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([-1.0, -1.0])),
                Box(-np.ones(2), np.ones(2)))                    # a1 <= -1 and a1 >= 1: empty
    piece = SetPiece("m", 0.0, 1.0, "star", ("x", "y"), (star,))
    assert piece.polygon("x", "y").shape == (0, 2)
    point = Star(np.array([2.0, 3.0]), np.zeros((2, 1)), box=Box(np.zeros(1), np.zeros(1)))
    poly = SetPiece("m", 0.0, 1.0, "star", ("x", "y"), (point,)).polygon("x", "y")
    assert poly.shape[0] >= 1 and np.allclose(poly, [2.0, 3.0])
    line = outer_polygon(lambda D: D @ np.array([1.0, 1.0]) + np.abs(D @ np.array([1.0, 0.0])))
    assert np.allclose(line[:, 1], 1.0) and np.isclose(line[:, 0].min(), 0.0) and np.isclose(line[:, 0].max(), 2.0)


def test_clip_and_merge_keep_every_point():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    half = clip(square, np.array([1.0, 1.0]), 1.0)
    x, y = half[:, 0], half[:, 1]
    area = abs(x @ np.roll(y, -1) - y @ np.roll(x, -1)) / 2             # shoelace
    assert np.isclose(area, 0.5) and np.all(half @ [1.0, 1.0] <= 1.0 + 1e-9)
    rng = np.random.default_rng(3)
    chain = [convex_hull(rng.normal(size=(8, 2)) + 0.2 * k) for k in range(30)]      # overlapping
    merged = merged_polygons(chain, 7)
    assert len(merged) <= 7
    for p in chain:
        assert any(np.all(inside(m, p, 1e-9)) for m in merged)
    apart = [convex_hull(rng.normal(size=(8, 2)) + 100.0 * (k % 2)) for k in range(30)]  # two branches
    merged = merged_polygons(apart, 7)
    assert all(np.ptp(m, axis=0).max() < 50 for m in merged)      # no hull bridges the two
