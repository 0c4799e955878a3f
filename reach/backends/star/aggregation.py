"""Aggregation of successor stars: one box star standing for many, refined back into its
members on demand (see :meth:`reach.backends.star.explorer._Explorer._aggregate`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from reach import lp
from reach.sets import Box, Star
from reach.sets.hpolytope import HPolytope

if TYPE_CHECKING:
    from reach.backends.star.explorer import _Path


@dataclass
class _Aggregate:
    """One star standing for ``members`` (successor stars with their paths), all entering
    ``mode``; ``star`` contains every member. Explored in their place until a check under it
    fails; then the members are explored instead (``refined``)."""

    mode: str
    star: Star
    members: list[tuple[Star, _Path]]
    refined: bool = False
    #: the leading coefficients of ``star`` that its descendants' shapes keep: all of an interval
    #: hull's (fresh ones), those of the aggregate a shaped hull descends from
    #: (:meth:`.explorer._Explorer._shaped`)
    base: int = 0


def interval_hull(members, invariant, count_lps, ranges: Box | None = None):
    """``(hull, kept)``: the interval hull of the member stars (LPs reported to
    ``count_lps``; every bound pushed out by a relative 1e-9 against rounding, :func:`_outward`) intersected
    with ``invariant = (H, g)`` and with ``ranges`` (a box every reachable state lies in: the
    bounded inputs' ranges), a box star with fresh coefficients, and the non-empty
    members. ``hull`` is None when a member is unbounded. The hull contains every reachable
    state of every member: everything reachable from them is reachable from it, and its LPs
    stay small however many jumps and cells came before. Clipped to ``ranges``, a coordinate
    that no flow moves (a bounded input) keeps its range exactly through any number of
    aggregations, instead of gaining the outward rounding at each.

    Each bound ``max_k h_k(w)`` over the members ``k`` (``w = +-e_i``) is exact, with fewer LPs
    than ``2 n`` per member (:func:`_supports`): members are taken largest box bound first, and
    a member's LP along ``w`` is skipped where its box bound (no LP) is already at most the
    best value found, since its support cannot raise the maximum."""
    n = members[0][0].dim if members else 0
    W = np.vstack([np.eye(n), -np.eye(n)])
    best = np.full(2 * n, -np.inf)
    bounds = [star.support_bounds(W) for star, _ in members]
    nonempty = []
    for k in sorted(range(len(members)), key=lambda k: -np.sum(np.minimum(bounds[k], 1e300))):
        values = _supports(members[k][0], W, bounds[k], bounds[k] > best, count_lps)
        if values is not None:                                 # else an empty member
            nonempty.append(k)
            best = np.maximum(best, values)
    kept = [members[k] for k in sorted(nonempty)]
    if not kept or not np.all(np.isfinite(best)):
        return None, kept
    low, high = _axis_clipped(*_outward(-best[n:], best[:n]), *invariant)
    if ranges is not None:
        low, high = np.maximum(low, ranges.low), np.minimum(high, ranges.high)
        if np.any(low > high):                      # no member holds a reachable state
            return None, []
    return Star.from_box(Box(low, high)).intersect_halfspaces(*invariant), kept


def one_coordinate(H) -> np.ndarray:
    """Which rows of ``H`` read exactly one coordinate (``a x_i <= g``: a bound on one state)."""
    return np.count_nonzero(H, axis=1) == 1


def _axis_clipped(low, high, H, g):
    """``[low, high]`` cut by the rows of ``H x <= g`` that read one coordinate (``a x_i <= g``,
    bounds rounded outward): the hull is cut by those rows anyway, so its states stay, and
    a bound at an invariant (``T <= 22``) is the row's exact value instead of an LP's
    rounded one, which the fixpoint check can compare exactly (:mod:`.fixpoint`)."""
    H, g = np.asarray(H, float).reshape(-1, low.size), np.asarray(g, float).reshape(-1)
    single = one_coordinate(H)
    if not np.any(single):
        return low, high
    low, high = low.copy(), high.copy()
    for row, bound in zip(H[single], g[single]):
        i = int(np.flatnonzero(row)[0])
        value = bound / row[i]
        if row[i] > 0:
            high[i] = min(high[i], np.nextafter(value, np.inf))
        else:
            low[i] = max(low[i], np.nextafter(value, -np.inf))
    return low, high


def _outward(low, high):
    """``[low, high]`` pushed out by a relative 1e-9 against rounding, then onto a grid of
    steps ``2^(e - 30)`` (``2^e <= 1 + |x| < 2^(e+1)``; about 1e-9 relative, every operation
    exact): hulls of the same states whose LP bounds differ in the last digits (another
    basis, another order of sums) come out equal, so that the fixpoint check
    (:mod:`.fixpoint`) can find one inside the other."""
    size = 1.0 + np.maximum(np.abs(low), np.abs(high))
    step = np.exp2(np.floor(np.log2(size)) - 30)
    return np.floor((low - 1e-9 * size) / step) * step, np.ceil((high + 1e-9 * size) / step) * step


def _supports(star: Star, W, bound, need, count_lps):
    """Upper bounds of the supports of ``star`` along the rows of ``W``, exact where ``need``:
    ``bound`` (its box bounds, no LP) elsewhere; None if the star is empty. The exact values
    come from one LP model (:func:`reach.lp.maximize_many`), except along a row ``w`` with
    ``w^T V = 0``, where the support is ``w^T c`` and the box bound already is that; without
    predicate rows the box is the whole coefficient set and its bounds are exact. A direction
    whose LP fails keeps the box bound (it contains the star's support)."""
    values = bound.copy()
    G = W @ star.basis
    need = need & np.any(G != 0, axis=1)
    if not star.predicate.A.shape[0] or not np.any(need):
        return values
    count_lps(int(need.sum()))
    exact = lp.maximize_many(G[need], star.predicate.A, star.predicate.b,
                             (star.box.low, star.box.high)) + W[need] @ star.center
    if np.all(exact == -np.inf):
        return None
    values[need] = np.where(np.isnan(exact), bound[need], exact)
    return values


def shared_shape_hull(members, keep: int, count_lps) -> Star | None:
    """A hull of member stars of one shape -- the same first ``keep`` coefficients, their
    centres and those columns of their bases equal up to rounding (the successors of one jump
    taken at its instant from two cells that share that instant) -- that keeps the shape:
    ``c_0 + V_0 a + e``, ``a`` in the interval hull of the members' ranges of those coefficients
    (LPs reported to ``count_lps``) and in every predicate row on them alone that all members
    share, ``|e| <= r`` with ``r`` the largest ``|c_i - c_0| + |V_i - V_0| |a|_max`` plus the
    reach of member ``i``'s other columns (tiny spreads), padded against rounding. Every point
    of member ``i`` is ``c_0 + V_0 a`` plus such an ``e``, so the hull holds every member. None
    where the members differ in shape (``r`` above 1e-6 of the set's size) or one is
    unbounded."""
    stars = [star for star, _ in members]
    first = stars[0]
    k = keep
    if any(s.nvars < k for s in stars) or not all(np.all(np.isfinite(s.box.low)) and np.all(np.isfinite(s.box.high))
                                                 for s in stars):
        return None
    reach = np.max([np.maximum(np.abs(s.box.low[:k]), np.abs(s.box.high[:k])) for s in stars], axis=0)
    size = np.abs(first.basis[:, :k]) @ reach + np.abs(first.center)
    gap = np.max([np.abs(s.center - first.center) + np.abs(s.basis[:, :k] - first.basis[:, :k]) @ reach
                  + np.abs(s.basis[:, k:]) @ np.maximum(np.abs(s.box.low[k:]), np.abs(s.box.high[k:]))
                  for s in stars], axis=0)
    if np.any(gap > 1e-6 * (1.0 + size.max())):
        return None
    low, high = np.full(k, np.inf), np.full(k, -np.inf)
    W = np.hstack([np.vstack([np.eye(k), -np.eye(k)]), np.zeros((2 * k, 0))])
    for s in stars:
        count_lps(2 * k)
        C = np.hstack([W, np.zeros((2 * k, s.nvars - k))])
        values = lp.maximize_many(C, s.predicate.A, s.predicate.b, (s.box.low, s.box.high))
        if np.all(values == -np.inf):                 # an empty member
            continue
        values = np.where(np.isnan(values), np.concatenate([s.box.high[:k], -s.box.low[:k]]), values)
        high, low = np.maximum(high, values[:k]), np.minimum(low, -values[k:])
    if not np.all(low <= high):
        return None
    low, high = _outward(low, high)
    eps = np.finfo(float).eps
    radius = gap * (1 + 1e-9) + 8 * eps * size
    own = [i for i, row in enumerate(first.predicate.A) if not np.any(row[k:])]
    shared = [i for i in own
              if all(any(np.array_equal(first.predicate.A[i], r) and first.predicate.b[i] >= b
                         for r, b in zip(s.predicate.A, s.predicate.b)) for s in stars[1:])]
    free = np.flatnonzero(radius > 0)
    E = np.zeros((first.dim, free.size))
    E[free, np.arange(free.size)] = radius[free]
    rows = np.hstack([first.predicate.A[shared][:, :k], np.zeros((len(shared), free.size))])
    box = Box(np.append(low, -np.ones(free.size)), np.append(high, np.ones(free.size)))
    return Star(first.center, np.hstack([first.basis[:, :k], E]), HPolytope(rows, first.predicate.b[shared]), box)
