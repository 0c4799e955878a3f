"""Convex polyhedra in half-space form ``P = {x : A x <= b}``.

Everything that needs an optimisation goes through :mod:`reach.lp`:

* support function ``h_P(d) = max {d^T x : A x <= b}`` (``+inf`` if unbounded in ``d``),
* emptiness (an LP with a zero objective),
* interval hull, ``2 n`` support evaluations along ``+-e_i``.

Intersection is exact and free: stack the rows. In two dimensions :meth:`vertices_2d`
enumerates the vertices by brute force (every pair of lines, kept when feasible), which is
slow but independent of any LP and so serves as a reference in tests.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from reach import lp
from reach.sets.box import Box


class HPolytope:
    """``{x in R^n : A x <= b}``; ``A`` is ``(k, n)`` (``k`` may be 0: all of ``R^n``)."""

    def __init__(self, A, b):
        A = np.asarray(A, dtype=float)
        b = np.asarray(b, dtype=float).reshape(-1)
        if A.ndim != 2 or A.shape[0] != b.size:
            raise ValueError(f"A must be (k, n) with k = len(b); got {A.shape} and {b.size}")
        self.A, self.b = A, b

    @classmethod
    def universe(cls, n: int) -> "HPolytope":
        return cls(np.zeros((0, n)), np.zeros(0))

    @property
    def dim(self) -> int:
        return self.A.shape[1]

    def __repr__(self) -> str:
        return f"HPolytope(dim={self.dim}, constraints={self.A.shape[0]})"

    def contains(self, x, tol: float = 1e-9) -> bool:
        x = np.asarray(x, dtype=float)
        return bool(np.all(self.A @ x <= self.b + tol * (1 + np.abs(self.b))))

    def intersection(self, other: "HPolytope") -> "HPolytope":
        return HPolytope(np.vstack([self.A, other.A]), np.concatenate([self.b, other.b]))

    def intersect_halfspaces(self, H, g) -> "HPolytope":
        """``P intersected with {x : H x <= g}``."""
        return self.intersection(HPolytope(np.atleast_2d(H), np.atleast_1d(g)))

    def feasible_point(self):
        """A point of ``P`` or None if ``P`` is empty."""
        return lp.feasible_point(self.A, self.b, n=self.dim)

    def is_empty(self) -> bool:
        return self.feasible_point() is None

    def maximize(self, direction) -> lp.LPResult:
        """The LP ``max d^T x`` over ``P`` (status, value, maximiser)."""
        return lp.maximize(direction, self.A, self.b)

    def support(self, direction) -> float:
        """``h_P(d)``; ``-inf`` for an empty ``P``, ``+inf`` if unbounded along ``d``."""
        return self.maximize(direction).support_value()

    def bounding_box(self) -> Box:
        """The interval hull ``[-h_P(-e_i), h_P(e_i)]`` (infinite where unbounded)."""
        eye = np.eye(self.dim)
        high = np.array([self.support(e) for e in eye])
        low = np.array([-self.support(-e) for e in eye])
        return Box(low, high)

    def vertices_2d(self, tol: float = 1e-9) -> np.ndarray:
        """Vertices of a bounded 2-D polytope, counter-clockwise (brute-force enumeration).

        Every pair of constraint lines is intersected; intersection points satisfying all
        constraints (to ``tol``) are vertices. Duplicates are merged.
        """
        if self.dim != 2:
            raise ValueError("vertices_2d needs a 2-D polytope")
        points = []
        for i, j in combinations(range(self.A.shape[0]), 2):
            M = self.A[[i, j]]
            if abs(np.linalg.det(M)) < 1e-12 * (1 + np.abs(M).max() ** 2):
                continue
            x = np.linalg.solve(M, self.b[[i, j]])
            if np.all(self.A @ x <= self.b + tol * (1 + np.abs(self.b))):
                points.append(x)
        if not points:
            return np.zeros((0, 2))
        points = np.array(points)
        unique = [points[0]]
        for p in points[1:]:
            if min(np.linalg.norm(p - q) for q in unique) > 1e-7 * (1 + np.linalg.norm(p)):
                unique.append(p)
        unique = np.array(unique)
        centre = unique.mean(axis=0)
        order = np.argsort(np.arctan2(unique[:, 1] - centre[1], unique[:, 0] - centre[0]))
        return unique[order]


class LazyHPolytope(HPolytope):
    """An :class:`HPolytope` over ``dim`` variables whose rows ``build() -> (A, b)`` are formed
    on first use: a flowpipe segment's predicate (:func:`reach.sets.star.chord_hull`) is large
    and dense, and most segments are cleared by their coefficient box alone, without it."""

    def __init__(self, dim: int, build):
        self._dim, self._build, self._rows = dim, build, None

    def _formed(self) -> tuple[np.ndarray, np.ndarray]:
        if self._rows is None:
            self._rows = HPolytope(*self._build())
            if self._rows.dim != self._dim:
                raise ValueError(f"rows over {self._rows.dim} variables, expected {self._dim}")
            self._build = None
        return self._rows.A, self._rows.b

    @property
    def A(self) -> np.ndarray:
        return self._formed()[0]

    @property
    def b(self) -> np.ndarray:
        return self._formed()[1]

    @property
    def dim(self) -> int:
        return self._dim
