"""Generalized star sets (Duggirala & Viswanathan, CAV 2016).

A star is a centre ``c in R^n``, a basis ``V in R^{n x m}`` and a predicate over the
coefficients ``a in R^m``:

    S = { c + V a  :  C a <= d,  lo <= a <= hi }.

The predicate is an :class:`~reach.sets.hpolytope.HPolytope` ``C a <= d`` together with a
coefficient box ``[lo, hi]`` that is part of it (and doubles as a cheap bound).

Operations
----------
* affine map ``M S + t = <M c + t, M V, same predicate>`` -- exact, a matrix product;
* intersection with ``{x : H x <= g}`` -- exact, adds ``H V a <= g - H c`` to the predicate;
* support function ``h_S(w) = w^T c + max { (V^T w)^T a : a in predicate }`` -- one LP;
* cheap support bound from the box alone, ``w^T (c + V a_c) + |V^T w|^T a_r`` with box
  centre ``a_c`` and radius ``a_r`` -- an upper bound, no LP, vectorised over many ``w``;
* :meth:`depth` -- how deep the star reaches into a polytope (negative when disjoint);
* :func:`chord_hull` -- the convex hull of a star and its image under a second
  (centre, basis) pair with the *same* coefficients, plus an error term that vanishes at
  both ends; this is the flowpipe segment of :mod:`reach.backends.star`.
"""

from __future__ import annotations

import numpy as np

from reach import lp
from reach.sets.box import Box
from reach.sets.hpolytope import HPolytope, LazyHPolytope


class Star:
    """``{c + V a : C a <= d, lo <= a <= hi}``."""

    def __init__(self, center, basis, predicate: HPolytope | None = None, box: Box | None = None):
        c = np.asarray(center, dtype=float).reshape(-1)
        V = np.asarray(basis, dtype=float).reshape(c.size, -1)
        m = V.shape[1]
        self.center, self.basis = c, V
        self.predicate = predicate if predicate is not None else HPolytope.universe(m)
        self.box = box if box is not None else Box(np.full(m, -np.inf), np.full(m, np.inf))
        if self.predicate.dim != m or self.box.dim != m:
            raise ValueError(f"predicate/box must be over {m} coefficients")

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_box(cls, box: Box) -> "Star":
        """The box as a star with one generator per non-degenerate side, ``a in [-1, 1]^m``."""
        r = box.radius
        free = np.flatnonzero(r > 0)
        V = np.zeros((box.dim, free.size))
        V[free, np.arange(free.size)] = r[free]
        return cls(box.center, V, box=Box(-np.ones(free.size), np.ones(free.size)))

    @property
    def dim(self) -> int:
        return self.center.size

    @property
    def nvars(self) -> int:
        return self.basis.shape[1]

    def __repr__(self) -> str:
        return f"Star(dim={self.dim}, vars={self.nvars}, constraints={self.predicate.A.shape[0]})"

    def point(self, alpha) -> np.ndarray:
        """``c + V a``."""
        return self.center + self.basis @ np.asarray(alpha, dtype=float)

    # ------------------------------------------------------------------ exact operations

    def affine_map(self, M, t=None) -> "Star":
        """``{M x + t : x in S}``."""
        M = np.atleast_2d(np.asarray(M, dtype=float))
        c = M @ self.center + (0.0 if t is None else np.asarray(t, dtype=float))
        return Star(c, M @ self.basis, self.predicate, self.box)

    def intersect_halfspaces(self, H, g) -> "Star":
        """``S intersected with {x : H x <= g}``: rows ``H V a <= g - H c`` join the predicate,
        except those the coefficient box already implies (their largest value over the box is
        within the bound): the set is the same, the LPs smaller."""
        H = np.atleast_2d(np.asarray(H, dtype=float))
        g = np.atleast_1d(np.asarray(g, dtype=float))
        needed = ~(self.support_bounds(H) <= g)
        if not np.any(needed):
            return self
        H, g = H[needed], g[needed]
        pred = self.predicate.intersect_halfspaces(H @ self.basis, g - H @ self.center)
        return Star(self.center, self.basis, pred, self.box)

    def intersect(self, polytope: HPolytope) -> "Star":
        return self.intersect_halfspaces(polytope.A, polytope.b)

    # ------------------------------------------------------------------ LP queries

    def _lp_bounds(self):
        return (self.box.low, self.box.high)

    def feasible_alpha(self):
        """Coefficients of some point of ``S``, or None if ``S`` is empty."""
        return lp.feasible_point(self.predicate.A, self.predicate.b, bounds=self._lp_bounds(),
                                 n=self.nvars)

    def is_empty(self) -> bool:
        return self.feasible_alpha() is None

    def maximize(self, direction) -> lp.LPResult:
        """``max w^T x`` over ``S``; ``x`` of the result holds the coefficients ``a``."""
        w = np.asarray(direction, dtype=float)
        res = lp.maximize(self.basis.T @ w, self.predicate.A, self.predicate.b,
                          bounds=self._lp_bounds())
        if res.optimal:
            res.value += float(w @ self.center)
        return res

    def support(self, direction) -> float:
        """``h_S(w)``: ``-inf`` if ``S`` is empty, ``+inf`` if unbounded along ``w``."""
        return self.maximize(direction).support_value()

    def bounding_box(self) -> Box:
        """Exact interval hull (``2 n`` LPs)."""
        eye = np.eye(self.dim)
        return Box(np.array([-self.support(-e) for e in eye]), np.array([self.support(e) for e in eye]))

    def contains(self, x) -> bool:
        """Is ``x`` in ``S``? (LP with ``V a = x - c``.)"""
        x = np.asarray(x, dtype=float)
        alpha = lp.feasible_point(self.predicate.A, self.predicate.b, A_eq=self.basis,
                                  b_eq=x - self.center, bounds=self._lp_bounds(), n=self.nvars)
        return alpha is not None

    def depth(self, H, g, cap: float = np.inf, tolerance: float | None = None) -> tuple[float, np.ndarray | None]:
        """How far ``S`` reaches into ``Q = {x : H x <= g}`` (rows of ``H`` normalised).

        Solves ``max s  s.t.  x in S,  H_r x + s ||H_r|| <= g_r,  s <= cap``. The value is
        negative exactly when ``S`` and ``Q`` are disjoint (it is then minus a lower bound
        of their Chebyshev-like separation), zero when they only touch, and positive when
        ``S`` enters the interior of ``Q``. Returns ``(-inf, None)`` for an empty ``S``,
        ``(inf, None)`` if the depth is unbounded (an unbounded ``S`` and no cap), otherwise
        the optimal value and the coefficients ``a`` of the deepest point. ``tolerance``: the
        LP's primal feasibility tolerance (None: the solver's default).

        Where the coefficient box is bounded, the value returned is the weak-duality bound
        of the LP's duals (:func:`reach.lp.variable_bound`): at least the true depth
        whatever the solver's tolerances, and equal to its optimum up to them.
        """
        H = np.atleast_2d(np.asarray(H, dtype=float))
        g = np.atleast_1d(np.asarray(g, dtype=float))
        norms = np.linalg.norm(H, axis=1)
        norms[norms == 0] = 1.0
        m = self.nvars
        A = np.vstack([np.hstack([self.predicate.A, np.zeros((self.predicate.A.shape[0], 1))]),
                       np.hstack([H @ self.basis, norms[:, None]])])
        b = np.concatenate([self.predicate.b, g - H @ self.center])
        bounds = (np.append(self.box.low, -np.inf), np.append(self.box.high, cap))
        objective = np.zeros(m + 1)
        objective[-1] = 1.0
        res = lp.maximize(objective, A, b, bounds=bounds, tolerance=tolerance)
        if res.infeasible:
            return -np.inf, None
        if res.unbounded:
            return np.inf, None
        bound = lp.variable_bound(m, A, b, *bounds, res.duals)
        return (bound if np.isfinite(bound) else res.value), res.x[:m]

    # ------------------------------------------------------------------ cheap bounds

    def support_bounds(self, directions) -> np.ndarray:
        """Upper bounds of ``h_S(w)`` for each row ``w`` of ``directions`` (box only, no LP)."""
        W = np.atleast_2d(np.asarray(directions, dtype=float))
        G = W @ self.basis
        if self.box.bounded:
            return W @ self.center + G @ self.box.center + np.abs(G) @ self.box.radius
        finite = np.isfinite(self.box.radius)
        ac, ar = self.box.center[finite], self.box.radius[finite]
        value = W @ self.center + G[:, finite] @ ac + np.abs(G[:, finite]) @ ar
        value[np.any(G[:, ~finite] != 0, axis=1)] = np.inf
        return value

    def box_bound(self) -> Box:
        """An interval enclosure from the coefficient box alone (no LP): the support bounds
        along ``+-e_i``, ``c_i + V_i a_c +- |V_i| a_r``."""
        if not np.all(np.isfinite(self.box.radius)):
            eye = np.eye(self.dim)
            return Box(-self.support_bounds(-eye), self.support_bounds(eye))
        mid = self.center + self.basis @ self.box.center
        rad = np.abs(self.basis) @ self.box.radius
        return Box(mid - rad, mid + rad)


# ---------------------------------------------------------------------- the segment

#: tangent points of the concave tent ``4 lam (1 - lam)``; its tangents at these points
#: bound it from above, so ``|g| <= 4 (a^2 + (1 - 2a) lam)`` for each ``a`` is implied by
#: ``|g| <= 4 lam (1 - lam)`` (a = 1/2 gives the box ``|g| <= 1``). The ends (a = 0, 1)
#: make the error vanish at both grid points.
TENT_POINTS = (0.0, 1.0)


def chord_hull(start: Star, end_center, end_basis, error=None) -> Star:
    """A star containing ``(1 - lam) x0(a) + lam x1(a) + e`` for every ``lam in [0, 1]``,
    every ``a`` in the predicate of ``start`` and every ``|e_i| <= 4 lam (1 - lam) r_i``.

    ``x0(a) = c0 + V0 a`` is ``start``; ``x1(a) = c1 + V1 a`` uses the same coefficients
    (typically ``start`` advanced by one time step); ``r = error`` is the error radius at
    mid-segment. New coefficients ``(a, b, lam, g)``:

        x = c0 + V0 a + (V1 - V0) b + lam (c1 - c0) + diag(r) g,

    where ``b`` stands for ``lam a``. The predicate is the homogenisation
    ``P b <= lam q``, ``P (a - b) <= (1 - lam) q`` of ``P a <= q`` (box rows included),
    ``0 <= lam <= 1`` and the tent rows on ``g``; without the error term the set is exactly
    ``conv(start, {x1(a)})``. The first ``m`` coefficients are the original ``a``: a point
    of the hull keeps its coefficients, so a witness maps back to ``start``'s predicate.
    """
    m = start.nvars
    c0, V0 = start.center, start.basis
    c1 = np.asarray(end_center, dtype=float)
    V1 = np.asarray(end_basis, dtype=float)
    r = np.zeros(start.dim) if error is None else np.asarray(error, dtype=float)
    if not np.all(np.isfinite(r)):        # NaN would read as "no error" below
        raise lp.LPError("a non-finite error radius (the flow overflows)")
    err = np.flatnonzero(r > 0)
    k = err.size
    lo, hi = start.box.low, start.box.high

    def rows():
        """The homogenised predicate and the tent rows (formed only when an LP needs them)."""
        eye = np.eye(m)
        up, down = np.isfinite(hi), np.isfinite(lo)
        P = np.vstack([start.predicate.A, eye[up], -eye[down]])     # P a <= q, finite box rows included
        q = np.concatenate([start.predicate.b, hi[up], -lo[down]])
        count = P.shape[0]
        zeros_k = np.zeros((count, k))
        A_blocks = [
            np.hstack([np.zeros((count, m)), P, -q[:, None], zeros_k]),      # P b - lam q <= 0
            np.hstack([P, -P, q[:, None], zeros_k]),                         # P (a - b) + lam q <= q
        ]
        b_blocks = [np.zeros(count), q]
        for a in TENT_POINTS if k else ():
            for sign in (1.0, -1.0):
                block = np.zeros((k, 2 * m + 1 + k))
                block[:, 2 * m] = -4.0 * (1 - 2 * a)
                block[:, 2 * m + 1:] = sign * np.eye(k)
                A_blocks.append(block)
                b_blocks.append(np.full(k, 4.0 * a * a))
        return np.vstack(A_blocks), np.concatenate(b_blocks)

    predicate = LazyHPolytope(2 * m + 1 + k, rows)
    box = Box(np.concatenate([lo, np.minimum(lo, 0.0), [0.0], -np.ones(k)]),
              np.concatenate([hi, np.maximum(hi, 0.0), [1.0], np.ones(k)]))
    E = np.zeros((start.dim, k))
    E[err, np.arange(k)] = r[err]
    basis = np.hstack([V0, V1 - V0, (c1 - c0)[:, None], E])
    return Star(c0, basis, predicate, box)
