"""Aggregation of successor stars: one box star standing for many, refined back into its
members on demand (see :meth:`reach.backends.star.explorer._Explorer._aggregate`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from reach import lp
from reach.sets import Box, Star

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


def interval_hull(members, invariant, count_lps):
    """``(hull, kept)``: the interval hull of the member stars (``2 n`` supports each, reported to
    ``count_lps``; every bound pushed out by a relative 1e-9 against rounding) intersected with
    ``invariant = (H, g)``, a box star with fresh coefficients, and the non-empty members.
    ``hull`` is None when a member is unbounded. The hull contains every member: everything
    reachable from them is reachable from it, and its LPs stay small however many jumps and
    cells came before."""
    bounds, kept = [], []
    for star, path in members:
        low, high = _interval(star, count_lps)
        if np.any(high == -np.inf):
            continue                                           # an empty member
        kept.append((star, path))
        if bounds is not None and np.all(np.isfinite(high)) and np.all(np.isfinite(low)):
            bounds.append((low, high))
        else:
            bounds = None
    if not kept or bounds is None:
        return None, kept
    low = np.min([b[0] for b in bounds], axis=0)
    high = np.max([b[1] for b in bounds], axis=0)
    if not np.all(np.isfinite(low)):
        return None, kept
    pad = 1e-9 * (1.0 + np.maximum(np.abs(low), np.abs(high)))
    return Star.from_box(Box(low - pad, high + pad)).intersect_halfspaces(*invariant), kept


def _interval(star: Star, count_lps):
    """``(low, high)``: the exact interval hull of ``star``, ``2 n`` supports on one LP model
    (:func:`reach.lp.maximize_many`); from the coefficient box alone, with no LP, when the
    star has no predicate rows (the box then is the whole coefficient set), and for a
    direction whose LP fails (the box bound contains the star's support). All ``-inf`` in
    ``high`` if the star is empty."""
    eye = np.eye(star.dim)
    W = np.vstack([eye, -eye])
    if not star.predicate.A.shape[0]:
        values = star.support_bounds(W)
    else:
        count_lps(2 * star.dim)
        values = lp.maximize_many(W @ star.basis, star.predicate.A, star.predicate.b,
                                  (star.box.low, star.box.high)) + W @ star.center
        undecided = np.isnan(values)                  # the LP failed: the box's bound (outer)
        values[undecided] = star.support_bounds(W[undecided])
    return -values[star.dim:], values[:star.dim]
