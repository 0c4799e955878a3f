"""Aggregation of successor stars: one box star standing for many, refined back into its
members on demand (see :meth:`reach.backends.star.explorer._Explorer._aggregate`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

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
    """``(hull, kept)``: the interval hull of the member stars (``2 n`` LPs each, reported to
    ``count_lps``; every bound pushed out by a relative 1e-9 against rounding) intersected with
    ``invariant = (H, g)``, a box star with fresh coefficients, and the non-empty members.
    ``hull`` is None when a member is unbounded. The hull contains every member: everything
    reachable from them is reachable from it, and its LPs stay small however many jumps and
    cells came before."""
    bounds, kept = [], []
    for star, path in members:
        eye = np.eye(star.dim)
        count_lps(2 * star.dim)
        high = np.array([star.support(e) for e in eye])
        if np.any(high == -np.inf):
            continue                                           # an empty member
        kept.append((star, path))
        if bounds is not None and np.all(np.isfinite(high)):
            bounds.append((np.array([-star.support(-e) for e in eye]), high))
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
