"""The matrices of a linear hybrid automaton as the exploration reads them: flows (with an
added clock and the time-varying inputs taken apart), normalised invariants, guards and
resets of the transitions worth firing, the initial star and the unsafe pieces."""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from reach import lp
from reach.backends.star.flowpipe import AffineFlow
from reach.backends.star.polygons import SIDES, polygon_pieces
from reach.model.constraints import affine_coefficients, halfspaces
from reach.sets import Box, Star
from reach.sets.hpolytope import HPolytope


@dataclass
class _Piece:
    """One convex unsafe piece ``H x <= g`` (rows normalised); ``strict`` if every row is;
    ``inradius``: radius of the largest ball inside it (``inf`` if unbounded)."""

    H: np.ndarray
    g: np.ndarray
    strict: bool
    label: str

    @cached_property
    def inradius(self) -> float:
        n = self.H.shape[1]
        res = lp.maximize(np.eye(n + 1)[n], np.hstack([self.H, np.ones((len(self.g), 1))]), self.g)
        return res.value if res.optimal else (np.inf if res.unbounded else -np.inf)


@dataclass
class _Jump:
    """An outgoing transition: guard rows, reset ``x+ = R x + r``, window (clock, lo, hi)."""

    name: str
    target: str
    H: np.ndarray
    g: np.ndarray
    R: np.ndarray
    r: np.ndarray
    window: tuple[int, float, float] | None


_CACHE: dict[tuple[int, str], tuple[weakref.ref, object]] = {}


def _cached(obj, build):
    """``build(obj)``, computed once per live object and kind of build (symbolic extraction is
    slow); the kind is the builder's qualified name, so several builders may cache one object."""
    key = (id(obj), build.__qualname__)
    ref, value = _CACHE.get(key, (None, None))
    if ref is None or ref() is not obj:
        value = build(obj)
        _CACHE[key] = (weakref.ref(obj, lambda _: _CACHE.pop(key, None)), value)
    return value


def _unsafe_pieces(prop) -> dict[str, list[_Piece] | None]:
    """The property's unsafe pieces per mode, rows normalised; a piece with quadratic
    constraints is replaced by polygons that hold it (:mod:`.polygons`, closed, labelled so);
    None for a mode with another nonlinear constraint."""
    def build(prop):
        out = {}
        for mode in prop.modes:
            halfspaces = prop.halfspace_pieces(mode)
            if halfspaces is None:
                out[mode] = _polygon_pieces(prop, mode)
                continue
            out[mode] = []
            for k, ((H, g), constraints) in enumerate(zip(halfspaces, prop.pieces[mode])):
                label = " and ".join(dict.fromkeys(c.text for c in constraints)) or f"piece {k}"
                out[mode].append(_Piece(*_normalised(H, g), all(c.strict for c in constraints), label))
        return out
    return _cached(prop, build)


class _LinearModel:
    """The matrices of a linear hybrid automaton, extracted once per model object (the
    symbolic extraction costs more than a small check): flows, normalised invariants,
    outgoing jumps, and whether the model is linear at all.

    The exploration needs a global clock (it bounds the horizon and dates the switches).
    A model without one (no state of rate 1 in every mode) gets its own: state ``n`` with
    rate 1 everywhere, 0 initially, never reset and absent from every guard, invariant
    and property, so the reachable states of the model are the projections of the
    extended ones (``n`` is then ``model.n + 1`` and ``added_clock`` is True).

    ``timeless``: the modes where no time may pass (SpaceEx ``flow false``; every state has
    rate 0 there, so such a model always gets its own clock); ``zero_dwell``: whether the
    model may have a zero-dwell cycle (:mod:`reach.model.lint`); ``ranges``: a box every
    reachable state lies in: the range of each bounded input on its coordinate (flow 0 in
    every mode, never reset, so the value a run starts with), the clock at least 0 (it
    starts at 0 and never decreases), unbounded elsewhere."""

    def __init__(self, model):
        from reach.model.lint import zero_dwell_cycles

        clock = model.global_clock
        self.added_clock = clock is None
        self.n = model.n + self.added_clock
        self.clock = model.n if clock is None else clock
        self.jumps = {name: [self._jump(model, tr) for tr in model.outgoing(name)]
                      for name in model.modes}
        self.linear = (all(m.linear is not None and m.invariant_halfspaces is not None
                           for m in model.modes.values())
                       and all(j is not None for js in self.jumps.values() for j in js))
        self.varying = [u for u in getattr(model, "bounded_inputs", []) if u.varying]
        self.timeless = {name for name, mode in model.modes.items() if mode.timeless}
        low, high = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        for u in getattr(model, "bounded_inputs", []):
            low[u.index], high[u.index] = u.low, u.high
        low[self.clock] = 0.0
        self.ranges = Box(low, high)
        self.zero_dwell = bool(zero_dwell_cycles(model)[0])        # a search with LPs: once
        if self.linear:
            self.flows = {name: self._flow(*self._with_clock(*mode.linear))
                          for name, mode in model.modes.items()}
            self.invariants = {name: _normalised(*self.widen(*mode.invariant_halfspaces))
                               for name, mode in model.modes.items()}
            self.fired = {name: _unsubsumed(js, *self.invariants[name])
                          for name, js in self.jumps.items()}

    def widen(self, H, g):
        """Rows over the model's states as rows over the explored ones (a zero clock column)."""
        g = np.atleast_1d(np.asarray(g, dtype=float))
        H = np.asarray(H, dtype=float).reshape(g.size, self.n - self.added_clock)
        if self.added_clock:
            H = np.hstack([H, np.zeros((g.size, 1))])
        return H, g

    def _with_clock(self, A, b):
        if not self.added_clock:
            return A, b
        n = self.n
        A2 = np.zeros((n, n))
        A2[:n - 1, :n - 1] = A
        return A2, np.append(b, 1.0)

    def _flow(self, A, b) -> AffineFlow:
        """The mode's flow with its time-varying inputs taken out of ``A``: their columns
        ``B`` act through the input set (centre in ``b``, radius bounded per step); the input
        coordinates themselves keep their interval for properties that name them."""
        if not self.varying:
            return AffineFlow(A, b)
        cols = [u.index for u in self.varying]
        low = np.array([u.low for u in self.varying], dtype=float)
        high = np.array([u.high for u in self.varying], dtype=float)
        A = A.copy()
        B = A[:, cols].copy()
        A[:, cols] = 0.0
        return AffineFlow(A, b + B @ ((low + high) / 2), B, (high - low) / 2)

    def initial_star(self, initial) -> Star:
        """The initial set as a star: its bounding box, cut by its polytope if it has one
        (inequalities ``A x <= b`` and equalities ``E x = f`` as two inequalities)."""
        star = Star.from_box(self.initial_box(initial.low, initial.high))
        poly = getattr(initial, "polytope", None)
        if poly is None:
            return star
        E, f = np.atleast_2d(poly.E).reshape(-1, self.n - self.added_clock), np.atleast_1d(poly.f)
        H = np.vstack([np.atleast_2d(poly.A).reshape(-1, E.shape[1]), E, -E])
        g = np.concatenate([np.atleast_1d(poly.b), f, -f])
        return star.intersect_halfspaces(*self.widen(H, g))

    def initial_box(self, low, high) -> Box:
        """The initial box over the explored states (the added clock starts at 0)."""
        if self.added_clock:
            low, high = np.append(low, 0.0), np.append(high, 0.0)
        return Box(low, high)

    @classmethod
    def of(cls, model) -> "_LinearModel":
        return _cached(model, cls)

    def _jump(self, model, tr) -> _Jump | None:
        """The transition as matrices, or None if its guard or reset is nonlinear."""
        guard = model.guard_halfspaces(tr)
        if guard is None:
            return None
        R, r = np.eye(self.n), np.zeros(self.n)
        for index, expr in tr.reset.items():
            coeffs = affine_coefficients(expr, model.symbols)
            if coeffs is None:
                return None
            R[index, :model.n], r[index] = coeffs
        return _Jump(tr.name, tr.target, *_normalised(*self.widen(*guard)), R, r, tr.window)


def _polygon_pieces(prop, mode: str) -> list[_Piece] | None:
    """The unsafe pieces of ``mode`` with each quadratic constraint's polygons
    (:func:`.polygons.polygon_pieces`); None if a piece has none."""
    out = []
    for k, constraints in enumerate(prop.pieces[mode]):
        found = polygon_pieces(constraints, prop.symbols)
        if found is None:
            return None
        label = " and ".join(dict.fromkeys(c.text for c in constraints)) or f"piece {k}"
        exact = halfspaces(constraints, prop.symbols) is not None
        for H, g in found:
            out.append(_Piece(*_normalised(H, g), exact and all(c.strict for c in constraints),
                              label if exact else f"{label} (as polygons of {SIDES} sides)"))
    return out


def _normalised(H, g):
    """Rows scaled to unit norm (zero rows dropped if satisfied, kept as 0 <= g if not)."""
    H = np.atleast_2d(np.asarray(H, dtype=float))
    g = np.atleast_1d(np.asarray(g, dtype=float))
    norms = np.linalg.norm(H, axis=1)
    keep = (norms > 0) | (g < 0)
    norms = np.where(norms > 0, norms, 1.0)
    return (H / norms[:, None])[keep], (g / norms)[keep]


def _unsubsumed(jumps: list[_Jump], H_inv, g_inv) -> list[_Jump]:
    """The jumps worth firing: ``j`` is dropped when an earlier kept jump ``k`` has the same
    target and reset and ``guard_j and invariant`` implies every row of ``guard_k`` (one LP
    per row over the state space); the successors of ``j`` are then contained in those of
    ``k``, whatever the segment. A row of ``guard_k`` is implied when ``guard_j`` or the
    invariant holds it as stored (bound no larger), else by the LP's maximum at most its bound,
    with no allowance: a state of ``guard_j`` outside ``guard_k`` by a hair takes ``j``, and
    the successors of ``k`` would not hold it. A jump whose guard misses the invariant is
    dropped too."""
    def implies(region: HPolytope, k: _Jump) -> bool:
        return all(np.any(np.all(region.A == row, axis=1) & (region.b <= bound))
                   or ((res := region.maximize(row)).optimal and res.value <= bound)
                   for row, bound in zip(k.H, k.g))

    kept = []
    for j in jumps:
        H = np.vstack([j.H, H_inv]) if H_inv.shape[0] else j.H
        if not H.shape[0]:                       # no guard, no invariant: nothing to compare
            kept.append(j)
            continue
        region = HPolytope(H, np.concatenate([j.g, g_inv]))
        if region.maximize(np.zeros(region.dim)).infeasible:     # only a proved emptiness drops it
            continue
        if not any(k.target == j.target and np.array_equal(k.R, j.R) and np.array_equal(k.r, j.r)
                   and implies(region, k) for k in kept):
            kept.append(j)
    return kept


def misses(piece: _Piece, H, g, tolerance: float) -> bool:
    """Whether ``piece`` and ``{x : H x <= g}`` (a mode's invariant; rows of both normalised)
    are disjoint by a two-row certificate: a piece row ``h x <= p`` and an invariant row
    ``-h x <= q`` (exactly opposite as stored) with ``p < -q - tolerance max(1, |p|, |q|)``.
    On the invariant ``h x >= -q``, beyond the piece's ``p`` by more than the touch tolerance
    the depth LP would grant (:class:`.options.StarOptions`), so no state of the mode is in
    the piece. Exact in floating point (only a comparison of stored rows); no LP. A deadband
    ``|th| <= 0.02`` against the requirement ``|th| <= 0.05`` is such a pair."""
    if not piece.H.shape[0] or not H.shape[0]:
        return False
    opposite = np.all(piece.H[:, None, :] == -H[None, :, :], axis=2)
    p, q = piece.g[:, None], g[None, :]
    apart = p < -q - tolerance * np.maximum(1.0, np.maximum(np.abs(p), np.abs(q)))
    return bool(np.any(opposite & apart))


def _modes_leading_to(model, targets: set[str]) -> set[str]:
    """Modes from which some mode in ``targets`` can be reached (targets included)."""
    reach = set(targets)
    changed = True
    while changed:
        changed = False
        for tr in model.transitions:
            if tr.target in reach and tr.source not in reach:
                reach.add(tr.source)
                changed = True
    return reach


def kept_rows(jump: _Jump, H_src, g_src, frozen=(), tolerance: float = 1e-9, size=None):
    """``(K, k)``: rows every successor ``y = R x + r`` of the jump satisfies, from the rows
    ``h x <= g`` of its guard and of ``(H_src, g_src)`` (rows every state that takes it meets:
    the source's invariant and the rows its chain was cut by), an aggregate keeping what a
    guard pins down (``T = 21`` from ``T >= 21`` and ``T <= 21``; with ``v := 0.8 v``, the
    switching line ``x + v = -0.2`` as ``x + 1.25 v = -0.2``).

    A row over states the reset leaves alone (``x+ = x``) is kept as it is (``a = h``, exact).
    Any other row ``h`` is written ``h = a R + e`` (``a`` by least squares, kept where ``|e| <=
    1e-12 |h|``): ``a y = h x - e x + a r <= g + a r + |e| s`` with ``s`` a bound of ``|x|``
    over the states that took the jump (``size``, per coordinate; without it, no such row).
    ``e`` is computed, so the slack adds four roundings of ``|a| |R| + |h|`` to ``|e|``, and
    ``tolerance * max(1, |g|, |a r|)`` for the rounding of ``a r``. A row over a state the
    reset overwrites (``x := 0``) is not in the row space, and is dropped. So is a row that
    reads, or would constrain, a coordinate in ``frozen`` (the time-varying inputs the reset
    reads: it takes any value of their ranges, and after the jump their coordinates are
    independent of what they were, :meth:`.explorer._Explorer._fresh_inputs`)."""
    H = np.vstack([jump.H, H_src]) if H_src.shape[0] else jump.H
    g = np.concatenate([jump.g, g_src])
    n = jump.R.shape[0]
    free = np.setdiff1d(np.arange(n), list(frozen))         # a is 0 on the frozen coordinates
    if not H.shape[0] or not free.size:
        return H[:0], g[:0]
    alone = np.all(jump.R == np.eye(n), axis=1) & (jump.r == 0)
    exact = np.all((H == 0) | alone[None, :], axis=1)       # a = h, no rounding
    unfrozen = np.all(H[:, list(frozen)] == 0, axis=1)      # rows reading no frozen coordinate
    if size is None or not np.all(np.isfinite(size)):
        keep = exact & unfrozen
        return H[keep], g[keep]
    A = H.copy()
    A[~exact] = 0.0
    A[np.ix_(~exact, free)] = np.linalg.lstsq(jump.R[free].T, H[~exact].T, rcond=None)[0].T
    e = A @ jump.R - H
    E = np.abs(e) + 4 * np.finfo(float).eps * (np.abs(A) @ np.abs(jump.R) + np.abs(H))
    keep = np.all(np.isfinite(A), axis=1) & (np.linalg.norm(e, axis=1) <= 1e-12 * np.linalg.norm(H, axis=1))
    keep &= unfrozen
    A, g, E, exact = A[keep], g[keep], E[keep], exact[keep]
    shift = A @ jump.r
    slack = np.where(exact, 0.0, E @ np.abs(size) + tolerance * np.maximum(1.0, np.maximum(np.abs(g), np.abs(shift))))
    return A, g + shift + slack
