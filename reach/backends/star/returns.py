"""Zero-dwell returns: a jump straight back to the mode a run has just left, at the same state.

A saturated controller written as three modes (``lin`` and ``sat`` on either side of
``|k x| = 1``), with closed guards on the shared boundary, lets a run that reaches the boundary
switch ``sat -> lin -> sat -> lin ...`` at one instant without end: both guards hold there. Each
round the over-approximated successors grow by the interpolation error of the cell they come
from, so no fixpoint closes and the exploration stops undecided.

Claim. Let every run of a chain's start star ``S`` in mode ``M`` have entered ``M`` by a jump
``J1`` from mode ``P`` (reset ``x -> R1 x + r1``), and let ``J2: M -> P`` (reset ``R2, r2``)
undo it: ``R2 R1 = I`` and ``R2 r1 + r2 = 0``. Let one row ``h x <= g`` of ``J2``'s guard satisfy

(a) ``h x >= g`` for every run at its entry: ``M``'s invariant holds the row ``-h x <= c`` with
    ``c <= -g`` (rows normalised; exactly opposite, as rows from one expression are), or ``S``
    reaches no deeper than 0 into ``h x <= g`` (the weak-duality bound of :meth:`.Star.depth`);
(b) ``h x`` strictly increases along every run while it is in the segment ``Q`` of the chain's
    first cell: ``d/dt (h x) = h (A x + b) + h B (u - u_c) >= min_Q h A x + h b - |h B| u_r > 0``
    (the minimum by the coefficient box, else by :meth:`.Star.depth` against
    ``h A x <= -h b + |h B| u_r``, whose bound below 0 proves ``Q`` misses it).

Then ``h x(tau) > h x(0) >= g`` for ``0 < tau <= `` the cell's length, so no run of ``S`` meets
``J2``'s guard in the first cell except at ``tau = 0``. A run that takes ``J2`` there is back in
``P`` at the state and instant at which it left ``P``: it is the run that stayed in ``P``,
which the exploration of ``P`` already follows (flow, checks and jumps). So ``J2`` need not be
taken from the first cell (nor from its halves, whose runs are the cell's), and every run is
still covered. Later cells take ``J2`` as any jump.
"""
from __future__ import annotations

import numpy as np

def undone(first, second) -> bool:
    """Whether jump ``second`` undoes the reset of jump ``first``: ``R2 R1 = I``, ``R2 r1 + r2 = 0``."""
    R = second.R @ first.R
    r = second.R @ first.r + second.r
    return bool(np.array_equal(R, np.eye(R.shape[0])) and not np.any(r))


def entry_rows(jump, invariant, start) -> list[int]:
    """The rows of ``jump``'s guard that every run of ``start`` meets from outside, (a) above."""
    H, g = invariant
    rows = []
    for k, (a, b) in enumerate(zip(jump.H, jump.g)):
        kept = any(np.array_equal(H[i], -a) and g[i] <= -b for i in range(H.shape[0]))
        if kept or (start.box.bounded and start.depth(a[None], np.array([b]))[0] <= 0.0):
            rows.append(k)
    return rows


def rising(flow, jump, rows, segment) -> bool:
    """Whether ``h x`` strictly increases over ``segment`` for one of ``rows`` of ``jump``'s
    guard, (b) above, for every input in the flow's box."""
    for k in rows:
        h = jump.H[k]
        w = h @ flow.A
        floor = -float(h @ flow.b)              # the rise is positive where w x > floor
        if flow.inputs:
            floor += float(np.abs(h @ flow.B) @ flow.u_radius)
        if -float(segment.support_bounds(-w[None])[0]) > floor:
            return True
        if np.any(w) and segment.box.bounded and segment.depth(w[None], np.array([floor]))[0] < 0.0:
            return True
    return False
