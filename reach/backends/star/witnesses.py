"""Witnesses: LP points of over-approximated segments inside unsafe pieces, and how they
map back to an initial state and switch time (through aggregates by nearest member points)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from reach import lp
from reach.sets import Star

if TYPE_CHECKING:
    from reach.backends.star.explorer import _Entry, _Path


@dataclass
class _Witness:
    """A point of an over-approximated segment inside an unsafe piece."""

    mode: str
    piece: str
    depth: float
    alpha: np.ndarray
    state: np.ndarray
    path: _Path

    @property
    def history(self) -> tuple[_Entry, ...]:
        return self.path.entries


def witness_details(explorer, w: _Witness) -> dict:
    x0, switch = explorer.initial_point(w)
    return {"mode": w.mode, "piece": w.piece, "depth": w.depth, "state": w.state[:explorer.model.n].tolist(),
            "initial_state": x0.tolist(), "switch_time": switch}


def nearest_point(star: Star, x):
    """``(distance, coefficients)`` of the point of ``star`` nearest to ``x`` in the max norm
    (an LP over ``(a, t)``: ``|c + V a - x| <= t``), or None if ``star`` is empty."""
    m, n = star.nvars, star.dim
    ones = np.ones((n, 1))
    A = np.vstack([np.hstack([star.basis, -ones]), np.hstack([-star.basis, -ones]),
                   np.hstack([star.predicate.A, np.zeros((star.predicate.A.shape[0], 1))])])
    b = np.concatenate([x - star.center, star.center - x, star.predicate.b])
    objective = np.zeros(m + 1)
    objective[-1] = 1.0
    res = lp.minimize(objective, A, b, bounds=(np.append(star.box.low, 0.0),
                                               np.append(star.box.high, np.inf)))
    return (res.value, res.x[:m]) if res.optimal else None


def trace(alpha, path, nearest):
    """The coefficients of the initial star behind the point ``alpha`` of a star reached
    along ``path``, and the path's entries, each with the coefficients it reads.

    Through an aggregate the point of the member nearest to the aggregate's point
    (``nearest(star, x)``, as :func:`nearest_point`) stands for it: exact when that point lies
    in a member, a candidate otherwise (the replay decides; the aggregate is refined if it
    fails)."""
    entries = [(e, alpha) for e in path.entries]
    while path.origin is not None:
        agg = path.origin
        target = agg.star.point(alpha[:agg.star.nvars])
        best = None
        for star, member_path in agg.members:
            found = nearest(star, target)
            if found is not None and (best is None or found[0] < best[0]):
                best = (found[0], found[1], member_path)
        if best is None:
            break
        _, alpha, path = best
        entries = [(e, alpha) for e in path.entries] + entries
    return alpha, entries
