"""Witnesses: LP points of over-approximated segments inside unsafe pieces, and how they
map back to an initial state, switch time and the transitions of their path (through
aggregates by nearest member points)."""

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
    x0, switch, transitions = explorer.initial_point(w)
    return {"mode": w.mode, "piece": w.piece, "depth": w.depth, "state": w.state[:explorer.model.n].tolist(),
            "initial_state": x0.tolist(), "switch_time": switch, "transitions": transitions}


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
    fails). Members are tried nearest box bound first; one whose box bound is no nearer than
    the best point found cannot hold a nearer point and is skipped (no LP)."""
    entries = [(e, alpha) for e in path.entries]
    while path.origin is not None:
        agg = path.origin
        target = agg.star.point(alpha[:agg.star.nvars])
        best = None
        for gap, star, member_path in sorted(((_box_gap(star, target), star, member_path)
                                             for star, member_path in agg.members), key=lambda m: m[0]):
            if best is not None and gap >= best[0]:
                break
            found = nearest(star, target)
            if found is not None and (best is None or found[0] < best[0]):
                best = (found[0], found[1], member_path)
        if best is None:
            break
        _, alpha, path = best
        entries = [(e, alpha) for e in path.entries] + entries
    return alpha, entries


def _box_gap(star: Star, x) -> float:
    """The max-norm distance from ``x`` to the box bound of ``star``: no point of ``star`` is
    nearer."""
    box = star.box_bound()
    return float(np.max(np.maximum(np.maximum(box.low - x, x - box.high), 0.0), initial=0.0))


#: pieces of the extremal input signal over ``[0, t]`` (:func:`extremal_signal`), at most
SIGNAL_PIECES = 1000

#: a piece of the extremal signal is at least the replay grid step over this factor, so that
#: the replay (whose grid must divide the pieces) stays within 100 times its usual grid
SIGNAL_GRID_FACTOR = 100

#: quadrature sub-samples per piece of the extremal input signal
SIGNAL_SUBSAMPLES = 8


def signal_pieces(t: float, replay_step: float) -> int:
    """Pieces of the extremal signal over ``[0, t]``: :data:`SIGNAL_PIECES`, fewer where a
    piece would be shorter than ``replay_step / SIGNAL_GRID_FACTOR`` (an early instant on a
    long horizon), at least one."""
    return int(min(SIGNAL_PIECES, max(1, np.floor(t * SIGNAL_GRID_FACTOR / replay_step))))


def extremal_signal(flow, c, t: float, u_low, u_high, pieces: int = SIGNAL_PIECES, earlier=()):
    """``(step, values (pieces, p))``: the piecewise-constant input on ``pieces`` equal pieces
    of ``[0, t]`` that maximises ``c^T x(t)`` for the flow ``x' = A x + b + B (u - u_c)``
    (:class:`.flowpipe.AffineFlow`), any initial state; ``earlier``: the path before, as
    ``(flow_k, tau_k, R_k)`` in time order (the run flows by ``flow_k`` up to ``tau_k``, where
    a reset ``x+ = R_k x + r_k`` takes it to the next flow, ``flow`` after the last).

    ``c^T x(t) = c^T x_free(t) + int_0^t g(s) (u(s) - u_c) ds`` with ``g(s) = lambda(s)^T B(s)``,
    the adjoint ``lambda(t) = c``, ``lambda' = -A^T lambda`` along each flow and
    ``lambda(tau-) = R^T lambda(tau+)`` at a jump (the maximum principle for the path's modes
    and jump instants held fixed; without jumps ``g(s) = c^T e^{A (t - s)} B``). Over inputs
    constant on each piece ``P_k`` the maximum takes, per input ``i``,
    ``u_i = u_c,i + u_r,i sign(int_{P_k} g_i)`` -- the bang-bang signal that attains the
    input's exact support ``int_0^t |g| u_r`` (:meth:`.flowpipe.AffineFlow.deviation`) as the
    pieces shrink; it switches where ``g_i`` changes sign. The integrals are composite Simpson
    sums of ``SIGNAL_SUBSAMPLES`` sub-intervals per piece (``lambda`` carried back one
    sub-interval at a time, one matrix-vector product per sample). The jump instants of the
    run the signal drives may differ from the path's: a candidate, which only a replay decides."""
    u_low, u_high = np.asarray(u_low, float), np.asarray(u_high, float)
    centre, radius = (u_low + u_high) / 2, (u_high - u_low) / 2
    step = t / pieces
    sub = SIGNAL_SUBSAMPLES
    delta = step / sub
    flows = [f for f, _, _ in earlier] + [flow]
    jumps = [(tau, R) for _, tau, R in earlier]
    k = len(flows) - 1                                      # the segment of the current sample
    row, s = np.asarray(c, dtype=float), t
    samples = np.empty((pieces * sub + 1, flow.B.shape[1]))
    for l in range(samples.shape[0]):                       # g at t - l delta
        target = t - l * delta
        if l and not (k > 0 and jumps[k - 1][0] > target):
            row = row @ flows[k].step(delta)[0]             # no jump since the last sample
        elif l:
            while k > 0 and jumps[k - 1][0] > target:       # back through a jump in (target, s]
                tau, R = jumps[k - 1]
                row = row @ flows[k].step(max(s - tau, 0.0))[0] @ R
                s, k = tau, k - 1
            row = row @ flows[k].step(max(s - target, 0.0))[0]
        s = target
        samples[l] = row @ flows[k].B
    samples = samples[::-1]                                 # g at s = l delta
    weights = np.ones(sub + 1)
    weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0
    blocks = np.lib.stride_tricks.sliding_window_view(samples, sub + 1, axis=0)[::sub]
    integrals = delta / 3 * blocks @ weights                # (pieces, p)
    values = np.clip(centre + radius * np.sign(integrals), u_low, u_high)
    return step, values
