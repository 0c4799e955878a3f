"""Aggregates covered by an earlier one: the fixpoint check.

An aggregate (:func:`.aggregation.interval_hull`) is a box cut by rows over the model's states.
A later aggregate ``S`` entering the same mode whose states, the clock included, lie in an
earlier one ``S'`` (its box inside the box of ``S'`` in every coordinate, and every row of
``S'`` holding on ``S``) adds no run: every run from ``S`` is a run from ``S'``, whose runs are
explored to the horizon. It is not explored (SpaceEx's and PHAVer's fixpoint check). This
holds for any automaton whose future is decided by its mode and state alone, the clock being
one of its coordinates (outward rounding would move each later aggregate's clock start down
a little; since time only runs forward, the explorer keeps it at the start of the aggregate it
descends from, ``_Explorer._clock_from``); it is off with abort windows (a path's first switch in a window dates
its later ones) and when the explored sets are kept for pictures.

A model without a global clock gets a stronger check (``shift``). The explorer adds its own
clock (:class:`.transitions._LinearModel`, ``added_clock``), and nothing in the automaton or
the property depends on time itself: flows, invariants, guards, resets and unsafe pieces are
rows over the model's states, and a time-varying input may take any value of its box at any
instant. A run that enters mode ``m`` in state ``x`` at time ``t`` is then the run entering
``m`` in ``x`` at any ``t' <= t``, shifted by ``t - t'``; its states are the same, and the
earlier run reaches the horizon later. Since an aggregate's box is the product of a set of
states ``X'`` with its whole clock interval ``[t'_lo, t'_hi]``, a later aggregate whose states
lie in ``X'`` and whose clock starts no earlier (``t_lo >= t'_lo``) is covered, whatever its
clock's upper end: every ``(x, t)`` of ``S`` has ``(x, t'_lo)`` in the earlier aggregate.

The sets computed along two paths that reach the same states differ by rounding (about
1e-9 relative), so an aggregate is explored enlarged by :data:`MARGIN` where that decides
nothing (a check that fails under the enlarged hull is redone under the exact one).

One exception to "its runs are explored": an aggregate whose runs all entered by a jump ``J1``
that a jump ``J2`` of the mode undoes does not take ``J2`` from its first cell
(:mod:`.returns`), since its runs would be back where and when they left. That holds for runs
that came by ``J1``, not for a later aggregate inside it that came by another jump (it would
be back at states its source never held). Such an aggregate is recorded with ``J1``
(``entry``) and covers only aggregates that came by ``J1`` too; a chain's block end (runs that
have flowed in the mode) is covered by untagged aggregates only.

Either argument holds while the earlier aggregate's exploration stands: an aggregate refined
back into its members (:meth:`.explorer._Explorer._aggregate`) is forgotten with everything
recorded after it (explored depth first, so those are its descendants, whose exploration is
redone from the members).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from reach import lp
from reach.backends.star.aggregation import one_coordinate
from reach.sets import Box, Star


def applies(model) -> bool:
    """Whether the fixpoint check applies: the model has no abort window (windows date
    switches)."""
    return not any(t.window is not None for t in model.transitions)


def time_invariant(model) -> bool:
    """Whether the check may also shift runs in time (``shift``, module docstring): it applies
    and the model has no global clock (the explorer adds its own, which nothing reads)."""
    return applies(model) and model.global_clock is None


#: relative margin by which a recorded aggregate is enlarged (box and jump rows): a later
#: aggregate's bounds carry LP and rounding errors of about 1e-9 (1 + |x|), and one inside
#: the earlier set up to those errors is then inside the enlarged one exactly
MARGIN = 1e-8

#: the same for a row that reads one coordinate (a bound at an invariant, ``T <= 22``): hulls
#: take such a bound exactly (:func:`.aggregation.interval_hull`), and the enlarged hull stays
#: within the touch tolerance (1e-9) of a property bounded there
AXIS_MARGIN = 5e-10


def enlarged(hull: Star, invariant, rows, ranges: Box | None = None) -> tuple[Star, tuple]:
    """``(star, rows)``: the aggregate ``hull`` (a box star cut by the mode's ``invariant`` and
    the jump's ``rows``, each ``(H, g)``) with its box and ``rows`` pushed out by
    :data:`MARGIN` ``(1 + |.|)`` (rows reading one coordinate by :data:`AXIS_MARGIN`), the
    box then clipped to ``ranges`` (a box every reachable state lies in, see
    :func:`.aggregation.interval_hull`). It contains every reachable state
    of ``hull``, so exploring it in its place is sound, and a later aggregate equal to it up to
    rounding lies inside it exactly (in a clipped coordinate both hold the range: the margin
    does not accumulate from one aggregate to the next)."""
    box = hull.box_bound()
    pad = MARGIN * (1.0 + np.maximum(np.abs(box.low), np.abs(box.high)))
    low, high = box.low - pad, box.high + pad
    if ranges is not None:
        low, high = np.maximum(low, ranges.low), np.minimum(high, ranges.high)
    H, g = np.asarray(rows[0], float), np.asarray(rows[1], float)
    margin = np.where(one_coordinate(H), AXIS_MARGIN, MARGIN) if H.size else np.zeros(0)
    g = g + margin * (1.0 + np.abs(g)) * np.linalg.norm(H, axis=1)
    star = Star.from_box(Box(low, high)).intersect_halfspaces(
        np.vstack([invariant[0], H]), np.concatenate([invariant[1], g]))
    return star, (H, g)


@dataclass
class _Explored:
    """A recorded aggregate's states: its box (every explored coordinate), the rows
    ``H x <= g`` it has besides the box and its mode's invariant, and ``start``, the lower end
    of its clock interval."""

    mode: str
    low: np.ndarray
    high: np.ndarray
    H: np.ndarray
    g: np.ndarray
    start: float
    entry: str | None = None        # the jump its runs came by, where it skips their returns


@dataclass
class Covered:
    """The explored aggregates, in the order they were entered; ``shift``: a later aggregate
    is covered whatever the upper end of its clock (the time-invariant argument of the module
    docstring), else only within the earlier one's clock interval."""

    clock: int
    shift: bool = True
    entries: list[_Explored] = field(default_factory=list)
    pruned: int = 0

    def mark(self) -> int:
        """A point to :meth:`forget` back to."""
        return len(self.entries)

    def forget(self, mark: int) -> None:
        """Drop every aggregate recorded since ``mark`` (an aggregate refined into its members,
        and its descendants)."""
        del self.entries[mark:]

    def record(self, mode: str, star: Star, rows, entry: str | None = None) -> None:
        """Record the aggregate ``star`` entering ``mode``: a box star cut by the mode's
        invariant and the jump's ``rows = (H, g)``; ``entry``: the jump all its runs came by,
        where one of the mode's jumps undoes it (module docstring), else None."""
        box = star.box_bound()
        self.entries.append(_Explored(mode, box.low, box.high, np.asarray(rows[0], float),
                                      np.asarray(rows[1], float), float(box.low[self.clock]), entry))

    def covers(self, mode: str, hull: Star, count_lps, entry: str | None = None) -> bool:
        """Whether an earlier aggregate of ``mode`` holds every state of ``hull`` (a star inside
        the mode's invariant), the clock within its interval or, with ``shift``, starting no
        earlier (module docstring); each jump row not settled by the boxes costs one LP over
        ``hull`` (reported to ``count_lps``). ``entry``: the jump every run of ``hull`` came by
        (None: several, or runs that have flowed in the mode); an aggregate recorded with
        another covers nothing of it."""
        box = hull.box_bound()
        low, high, start = box.low, box.high, float(box.low[self.clock])
        if np.isnan(low).any() or np.isnan(high).any():     # NaN fails every test below: not covered
            return False
        states = np.arange(low.size) != self.clock if self.shift else np.ones(low.size, dtype=bool)
        for explored in self.entries:
            if explored.mode != mode or explored.start > start or explored.entry not in (None, entry):
                continue
            if np.any(low[states] < explored.low[states]) or np.any(high[states] > explored.high[states]):
                continue
            if self._rows_hold(explored, hull, count_lps):
                self.pruned += 1
                return True
        return False

    @staticmethod
    def _rows_hold(entry: _Explored, hull: Star, count_lps) -> bool:
        """``H x <= g`` of ``entry`` on all of ``hull``: by the box bound where it settles a row,
        else by the row's support over ``hull`` (an LP; a failed LP settles nothing)."""
        if not entry.g.size:
            return True
        open_rows = hull.support_bounds(entry.H) > entry.g
        if not np.any(open_rows):
            return True
        H, g = entry.H[open_rows], entry.g[open_rows]
        count_lps(len(g))
        support = lp.maximize_many(H @ hull.basis, hull.predicate.A, hull.predicate.b,
                                   (hull.box.low, hull.box.high)) + H @ hull.center
        return bool(np.all(support <= g))          # a failed LP (nan) settles nothing
