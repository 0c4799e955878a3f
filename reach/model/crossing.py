"""Urgent guards a run meets between two grid points.

The simulator finds an urgent guard ``G(x) <= 0`` where a grid state lies in it. A run can meet
it between two grid points without any grid state in it; this module finds three cases:

* **a slab crossed**: two opposite rows, ``p(x) <= c_hi`` and ``-p(x) <= -c_lo`` (a slab ``c_lo <=
  p <= c_hi``; an equality such as SpaceEx's ``x == 2`` when ``c_lo = c_hi``; ``p`` linear, or any
  expression when the rows' sum is a number, as ``x^2 == 1``), with ``p`` above ``c_hi`` at one
  grid point and below ``c_lo`` at the next (or the other way up). By continuity ``p`` lies in
  the slab at some instant between them;
* **a linear row dipped into**: a row's margin ``m = H_i x - g_i`` positive at both grid points,
  falling at the first (``m' < 0``) and rising at the second, with the two tangents meeting
  below 0 (``m0 + m0' s = m1 + m1' (s - dt)`` at a value at most 0: where ``m`` is convex
  between the points, as near a smooth minimum, its least value is at least that, so a dip
  whose tangents meet above 0 cannot reach the guard). The minimum is located by bisection
  on the sign of ``m'``; the row holds there only if the dip reaches it;
* **a grid point in the guard** by the margins computed here, which the caller's own margins
  (another rounding: a block product) put just outside, as ``t == 2`` at ``t = 2``.

The instant is located as a guard entry is, by bisection on the row the run enters by (the
whole guard for a grid point in it), which holds at the right end, to the entry search's
resolution ``dt 2^-40``. The state found is the guard's entry where every other row of the
guard holds there, each to ``INVARIANT_TOLERANCE (1 + m)``, ``m`` the magnitude the row
combines, as in the simulator's guard test (a slab's partner row is met within
the resolution: it was crossed in the last halving, or, after a dip into one row of a slab, it
holds where that row is met). Each run's candidates are tried in time order; one that fails
(a dip whose lowest point misses, other rows that do not hold) is dropped and the next one
tried. A run that meets the other rows only elsewhere in the slab, a dip whose tangents meet
above 0 or a nonlinear row dipped into is not followed.
"""

from __future__ import annotations

import weakref

import numpy as np

from reach.model.constraints import opposite_pairs

PARALLEL = 1e-12        # two rows are opposite where their unit normals sum to at most this


class _Row:
    """Row ``i`` of a guard's margins ``G(X)`` (R, m) as a guard of its own (R, 1)."""

    def __init__(self, margins, i: int):
        self.margins, self.i = margins, i

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return self.margins(X)[:, self.i:self.i + 1]


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
            if opposite and g[i] / norms[i] + g[j] / norms[j] >= 0:
                pairs.append((i, j))
    return pairs


class Crossings:
    """The urgent guards of mode ``name`` of the simulator ``sim`` and the instants runs meet
    them between grid points (see the module docstring)."""

    def __init__(self, sim, name: str):
        self.sim, self.name = weakref.proxy(sim), name     # the simulator holds this: no cycle
        model = sim.model
        self.guards = []
        for tr, margins in sim.urgent[name]:
            rows = model.guard_halfspaces(tr)
            pairs = (opposite_rows(*rows) if rows is not None else      # a nonlinear slab: sum a number <= 0
                     [(i, j) for i, j, total, strict in opposite_pairs(tr.guard) if not strict and total <= 0])
            # the guards an entry is located on: each row alone, then all of them
            entries = [_Row(margins, i) for i in range(len(tr.guard))] + [margins]
            scale = sim._scale(("guard", tr.name), tr.guard)       # the rows' own tolerances
            self.guards.append((margins, rows, pairs, entries, self._rates(rows), scale))

    def _rates(self, rows):
        """``X -> (H f(X))`` (R, m): the rates of change of a linear guard's margins along the
        mode's flow ``f`` (one product ``X (H A)^T + H b`` for a linear flow), or None."""
        if rows is None:
            return None
        H = rows[0]
        if self.name in self.sim.generators:
            M, n = self.sim.generators[self.name], self.sim.n
            HA, Hb = np.ascontiguousarray((H @ M[:n, :n]).T), H @ M[:n, n]
            return lambda X: X @ HA + Hb
        rhs = self.sim.model.modes[self.name].rhs
        return lambda X: rhs(X) @ H.T

    def __bool__(self) -> bool:
        return bool(self.guards)

    def earliest(self, index: int, start_t, start_x, grid_t, states, valid, before) -> np.ndarray:
        """The instant each run meets urgent guard ``index`` between two successive points of
        ``start`` (``start_t`` (R,), ``start_x`` (R, n)) and its grid states (``grid_t`` (R, K),
        ``states`` (R, K, n); the later point ``valid`` (R, K)), ``inf`` where it does not or
        not before its event already known at ``before`` (R,): only the intervals that start
        before it are searched, and a point in the guard only where it lies before it (the
        caller found the entry at that point itself)."""
        R = start_t.shape[0]
        when = np.full(R, np.inf)
        if R == 0:
            return when
        guard_margins, _, pairs, entries, rates_of, scale = self.guards[index]
        points = np.concatenate([start_x[:, None, :], states], axis=1)      # (R, K+1, n)
        times = np.concatenate([start_t[:, None], grid_t], axis=1)
        margins = guard_margins(points.reshape(-1, points.shape[-1])).reshape(R, points.shape[1], -1)
        K, m = states.shape[1], margins.shape[-1]
        # candidates: (intervals (R, K), row entered by (m: the whole guard), its partner met
        # within the resolution or -1, a dip)
        valid = valid & (times[:, :-1] < before[:, None])
        # a grid point in the guard by these margins (the caller's, of other rounding, may
        # have put it just outside): an entry before it, located on the whole guard
        candidates = [(np.all(margins[:, 1:] <= 0, axis=2) & valid & (times[:, 1:] < before[:, None]), m, -1, False)]
        partner_of = {}
        for i, j in pairs:
            partner_of.setdefault(i, j)
            partner_of.setdefault(j, i)
            for a, b in ((i, j), (j, i)):        # above row a's bound, then below row b's
                candidates.append(((margins[:, :-1, a] > 0) & (margins[:, 1:, b] > 0) & valid, a, b, False))
        outside = (margins[:, :-1] > 0) & (margins[:, 1:] > 0) & valid[:, :, None]     # (R, K, m)
        if rates_of is not None and outside.any():
            rates = rates_of(points.reshape(-1, points.shape[-1])).reshape(margins.shape)
            d0, d1, m0, m1 = rates[:, :-1], rates[:, 1:], margins[:, :-1], margins[:, 1:]
            h = np.diff(times, axis=1)[:, :, None]
            with np.errstate(divide="ignore", invalid="ignore"):
                meet = m0 + d0 * (m1 - m0 - d1 * h) / (d0 - d1)          # the tangents' meeting value
            dipped = outside & (d0 < 0) & (d1 > 0) & (meet <= 0)
            # a dip into a slab's row meets its partner at the entry too (the slab is not empty)
            candidates += [(dipped[:, :, a], a, partner_of.get(a, -1), True) for a in range(m)
                           if dipped[:, :, a].any()]
        pending = np.ones(R, dtype=bool)
        while True:             # each run's earliest candidate; one that fails is dropped
            firsts = np.stack([np.where(c.any(axis=1), c.argmax(axis=1), K) for c, *_ in candidates])
            which = firsts.argmin(axis=0)
            first = firsts[which, np.arange(R)]
            active = pending & (first < K)
            if not active.any():
                return when
            for c_index in np.unique(which[active]):
                mask, a, b, dip = candidates[c_index]
                sel = np.flatnonzero(active & (which == c_index))
                k = first[sel]
                found = self._locate(guard_margins, scale, entries, rates_of, a, b, dip, points[sel, k],
                                     times[sel, k], times[sel, k + 1] - times[sel, k])
                hit = np.isfinite(found)
                when[sel[hit]], pending[sel[hit]] = found[hit], False
                mask[sel[~hit], k[~hit]] = False

    def _locate(self, guard_margins, scale, entries, rates_of, a, b, dip, x0, t0, h) -> np.ndarray:
        """The entry instants (``inf`` where none) of runs at ``x0`` at ``t0`` into the guard in
        ``(0, h]``, by row ``a`` (``m``: the whole guard), ``b`` its partner met within the
        resolution (or -1), after a dip of row ``a`` (whose lowest point must reach it); the
        other rows must hold there to ``INVARIANT_TOLERANCE (1 + m)``, ``m`` the magnitude each
        combines (``scale``, as the simulator's own guard test)."""
        from reach.model.simulate import INVARIANT_TOLERANCE, _holds

        when = np.full(t0.shape, np.inf)
        go = np.ones(t0.shape, dtype=bool)
        if dip:                                 # the row holds at the dip's lowest point, or never
            _, bottom, _ = self.sim._bisect(self.name, x0, h, lambda Z: rates_of(Z)[:, a] >= 0)
            go = entries[a](self.sim.propagate(self.name, x0, bottom))[:, 0] <= 0
            h = bottom
        if not go.any():
            return when
        s = self.sim._first_entry(self.name, x0[go], h[go], entries[a])
        x_s = self.sim.propagate(self.name, x0[go], s)
        m_s = guard_margins(x_s)
        if b >= 0:
            m_s[:, b] = -np.inf                     # met within the resolution
        holds = _holds(m_s, INVARIANT_TOLERANCE, scale, x_s)
        found = np.full(int(go.sum()), np.inf)
        found[holds] = t0[go][holds] + s[holds]
        when[go] = found
        return when
