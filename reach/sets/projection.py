"""Outer polygons of sets projected onto two coordinates.

A convex set ``S`` in ``R^n`` projected onto coordinates ``(i, j)`` is the convex set
``P = {(x_i, x_j) : x in S}``, whose support function in a plane direction ``d`` is the support
function of ``S`` in the lifted direction ``w = d_0 e_i + d_1 e_j``:

    h_P(d) = h_S(w).

So any upper bounds ``u_k >= h_S(w_k)`` for directions ``d_1..d_K`` give the outer polygon

    P  subset of  Q = { p : d_k . p <= u_k, k = 1..K },

which is exact at the directions (``Q`` touches ``P`` wherever ``u_k = h_S(w_k)``). The directions
are spread evenly in angle after scaling each axis by the extent of ``S`` along it, so a set that
is long in metres and thin in metres per second still gets its corners cut. ``Q`` is built by
clipping its bounding rectangle (the four axis directions) with each further half-plane
(Sutherland-Hodgman on a convex polygon), which copes with degenerate sets (segments, points).
"""

from __future__ import annotations

import numpy as np

#: directions per outer polygon (a multiple of 4: the axis directions are among them)
DIRECTIONS = 16


def plane_directions(count: int = DIRECTIONS, scale=(1.0, 1.0)) -> np.ndarray:
    """``count`` unit-angle directions (rows) in the plane, axis ``k`` divided by ``scale[k]``:
    even in angle once the axes are scaled to the set's extent."""
    theta = 2 * np.pi * np.arange(count) / count
    d = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    d[np.abs(d) < 1e-15] = 0.0
    return d / np.asarray(scale, dtype=float)


def outer_polygon(support, count: int = DIRECTIONS) -> np.ndarray:
    """Vertices (rows, counter-clockwise) of the outer polygon of a convex plane set given by
    ``support(D) -> upper bounds of h(d)`` for the rows ``d`` of ``D`` (see the module doc).
    An empty set gives no vertices; an unbounded one raises ValueError."""
    axes = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    box = np.asarray(support(axes), dtype=float)
    if np.any(box == -np.inf) or box[0] < -box[2] or box[1] < -box[3]:
        return np.zeros((0, 2))
    if not np.all(np.isfinite(box)):
        raise ValueError("the set is unbounded in the plotted variables")
    x0, y0, x1, y1 = -box[2], -box[3], box[0], box[1]
    polygon = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    scale = (max(x1 - x0, 1e-12 * max(1.0, abs(x0), abs(x1))),
             max(y1 - y0, 1e-12 * max(1.0, abs(y0), abs(y1))))
    D = plane_directions(count, scale)
    keep = np.all(D != 0.0, axis=1)                 # the axis directions are the rectangle
    D = D[keep]
    if D.shape[0]:
        for d, u in zip(D, np.asarray(support(D), dtype=float)):
            polygon = clip(polygon, d, u)
            if polygon.shape[0] == 0:
                break
    return polygon


def clip(polygon: np.ndarray, d: np.ndarray, u: float) -> np.ndarray:
    """The convex polygon cut by the half-plane ``d . p <= u`` (Sutherland-Hodgman).

    A slack of ``1e-12`` of the polygon's size keeps a half-plane that only touches a degenerate
    polygon (a segment, a point) from removing it."""
    if polygon.shape[0] == 0:
        return polygon
    size = float(np.max(np.abs(polygon @ d))) if polygon.size else 1.0
    value = polygon @ d - u - 1e-12 * max(1.0, size)
    out = []
    k = polygon.shape[0]
    for a in range(k):
        b = (a + 1) % k
        pa, pb, va, vb = polygon[a], polygon[b], value[a], value[b]
        if va <= 0:
            out.append(pa)
        if (va < 0 < vb) or (vb < 0 < va):
            out.append(pa + (pb - pa) * (va / (va - vb)))
    return np.array(out).reshape(-1, 2)


def star_support(star, W: np.ndarray, exact: bool = True) -> np.ndarray:
    """Upper bounds of ``h_S(w)`` for the rows of ``W``: one LP each when ``exact`` and the
    star's predicate has rows, else the coefficient-box bound (exact for a box predicate)."""
    if not exact or star.predicate.A.shape[0] == 0:
        return star.support_bounds(W)
    return np.array([star.support(w) for w in W])
