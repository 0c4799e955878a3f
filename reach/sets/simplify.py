"""Fewer, larger sets for export and pictures: consecutive pieces merged into their hull.

Merging never loses a state: the interval hull of boxes contains each box, and the convex hull
of polygons contains each polygon. Pieces are merged in runs of ``ceil(count / cap)`` consecutive
ones (consecutive in time within one mode, as a back-end emits them), so about ``cap`` remain.
"""

from __future__ import annotations

import math

import numpy as np


def _runs(count: int, cap: int) -> list[range]:
    size = max(1, math.ceil(count / max(1, cap)))
    return [range(k, min(k + size, count)) for k in range(0, count, size)]


def piece_box(piece) -> tuple[np.ndarray, np.ndarray]:
    """An interval hull of a set piece over its ``names`` (for stars from the coefficient box)."""
    eye = np.eye(len(piece.names))
    return -piece.support(-eye, exact=False), piece.support(eye, exact=False)


def merged_boxes(pieces: list, cap: int) -> list[tuple[float, float, list, list]]:
    """``(t0, t1, low, high)`` of at most ``cap`` interval hulls of consecutive pieces."""
    boxes = [piece_box(p) for p in pieces]
    out = []
    for run in _runs(len(pieces), cap):
        low = np.min([boxes[k][0] for k in run], axis=0)
        high = np.max([boxes[k][1] for k in run], axis=0)
        out.append((min(pieces[k].t0 for k in run), max(pieces[k].t1 for k in run),
                    low.tolist(), high.tolist()))
    return out


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of plane points, counter-clockwise (Andrew's monotone chain);
    collinear and repeated points are dropped."""
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)
    if pts.shape[0] <= 2:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def merged_polygons(polygons: list[np.ndarray], cap: int) -> list[np.ndarray]:
    """About ``cap`` polygons: convex hulls of runs of consecutive ones (empty ones skipped). A run
    also ends where the next polygon's bounding box does not meet the run's (pieces of another
    flowpipe branch: their hull would bridge empty space), so a few more than ``cap`` may remain."""
    polygons = [p for p in polygons if p.shape[0]]
    if len(polygons) <= cap:
        return polygons
    size = max(1, math.ceil(len(polygons) / max(1, cap)))
    out, run, low, high = [], [], None, None
    for p in polygons:
        lo, hi = p.min(axis=0), p.max(axis=0)
        if run and (len(run) >= size or np.any(lo > high) or np.any(hi < low)):
            out.append(convex_hull(np.vstack(run)))
            run = []
        if not run:
            low, high = lo, hi
        run.append(p)
        low, high = np.minimum(low, lo), np.maximum(high, hi)
    out.append(convex_hull(np.vstack(run)))
    return out
