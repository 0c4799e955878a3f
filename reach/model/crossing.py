"""Urgent guards a run jumps over between two grid points.

The simulator finds an urgent guard where a grid state lies in it. A guard with two opposite
rows, ``h x <= c_hi`` and ``-h x <= -c_lo`` (a slab ``c_lo <= h x <= c_hi``; an equality such as
SpaceEx's ``x == 2`` when ``c_lo = c_hi``), can hold at no grid state of a run that crosses it:
``h x`` above ``c_hi`` at one grid point and below ``c_lo`` at the next (or the other way up).
By continuity ``h x`` lies in the slab at some instant between them, so the run must jump
there if the guard's other rows hold too.

That instant is located as a guard entry is: by bisection on the row violated at the earlier
point (it holds at the later one), to the entry search's resolution ``h 2^-40``. The state
found lies within that resolution of the slab (the row's partner crossed it in the last
halving); it is the guard's entry where every other row of the guard holds there, to
``INVARIANT_TOLERANCE (1 + |x|_inf)``. A crossing whose other rows do not hold at that state
is not an entry (a run that meets them only further inside a wide slab, between grid points,
is not followed), nor is a brief visit to a guard of one row between grid points.
"""

from __future__ import annotations

import numpy as np

PARALLEL = 1e-12        # two rows are opposite where their unit normals sum to at most this


class _Row:
    """One guard row ``H_i x <= g_i`` as a guard of its own: ``X -> X H_i^T - g_i`` (R, 1),
    with ``rows`` for the closed-form entry of a scalar flow."""

    def __init__(self, H: np.ndarray, g: np.ndarray, i: int):
        self.rows = (H[i:i + 1], g[i:i + 1])

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return X @ self.rows[0].T - self.rows[1]


def opposite_rows(H: np.ndarray, g: np.ndarray) -> list:
    """The pairs ``(i, j)``, ``i < j``, of rows of ``H x <= g`` with opposite normals (``H_i /
    |H_i| + H_j / |H_j|`` at most :data:`PARALLEL`) that bound a slab that is not empty (its
    width ``g_i / |H_i| + g_j / |H_j|`` at least 0)."""
    norms = np.linalg.norm(H, axis=1)
    pairs = []
    for i in range(H.shape[0]):
        for j in range(i + 1, H.shape[0]):
            if not (norms[i] > 0 and norms[j] > 0):
                continue
            opposite = np.abs(H[i] / norms[i] + H[j] / norms[j]).max() <= PARALLEL
            width = g[i] / norms[i] + g[j] / norms[j]
            if opposite and width >= 0:
                pairs.append((i, j))
    return pairs


class SlabCrossings:
    """The slabs of one mode's urgent guards (``urgent``, ``(transition, margins)`` pairs) and
    their crossings between grid points (see the module docstring)."""

    def __init__(self, model, urgent: list):
        self.guards = []
        for tr, _ in urgent:
            rows = model.guard_halfspaces(tr)
            pairs = opposite_rows(*rows) if rows is not None else []
            self.guards.append((rows, pairs, {i: _Row(*rows, i) for pair in pairs for i in pair}) if pairs else None)

    def __bool__(self) -> bool:
        return any(g is not None for g in self.guards)

    def earliest(self, index: int, start_t, start_x, grid_t, states, valid, entry, propagate) -> np.ndarray:
        """The instant each run enters urgent guard ``index`` by crossing one of its slabs
        between two successive points of ``start`` (``start_t`` (R,), ``start_x`` (R, n)) and its
        grid states (``grid_t`` (R, K), ``states`` (R, K, n); the later point ``valid`` (R, K)),
        ``inf`` where it does not. ``entry(X, h, row)`` locates the first instant in ``(0, h]``
        where ``row`` holds (it holds at ``h``), ``propagate(X, h)`` advances states."""
        from reach.model.simulate import INVARIANT_TOLERANCE

        R = start_t.shape[0]
        when = np.full(R, np.inf)
        guard = self.guards[index]
        if guard is None or R == 0:
            return when
        (H, g), pairs, single = guard
        points = np.concatenate([start_x[:, None, :], states], axis=1)      # (R, K+1, n)
        margins = points @ H.T - g                                         # (R, K+1, m)
        K = states.shape[1]
        first = np.full(R, K)
        enter = np.zeros(R, dtype=int)
        partner = np.zeros(R, dtype=int)
        for i, j in pairs:
            for a, b in ((i, j), (j, i)):        # above row a's bound, then below row b's
                jumped = (margins[:, :-1, a] > 0) & (margins[:, 1:, b] > 0) & valid
                k = np.where(jumped.any(axis=1), jumped.argmax(axis=1), K)
                better = k < first
                first[better], enter[better], partner[better] = k[better], a, b
        times = np.concatenate([start_t[:, None], grid_t], axis=1)
        for a in np.unique(enter[first < K]):
            sel = np.flatnonzero((first < K) & (enter == a))
            k = first[sel]
            x0, t_lo = points[sel, k], times[sel, k]
            s = entry(x0, times[sel, k + 1] - t_lo, single[a])
            x_s = propagate(x0, s)
            m_s = x_s @ H.T - g
            m_s[np.arange(sel.size), partner[sel]] = -np.inf     # met within the resolution
            holds = np.all(m_s <= INVARIANT_TOLERANCE * (1.0 + np.abs(x_s).max(axis=1))[:, None], axis=1)
            when[sel[holds]] = t_lo[holds] + s[holds]
        return when
