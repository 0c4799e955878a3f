"""The ``star`` back-end: generalized-star-set reachability of linear hybrid automata.

Method
------
Each mode has affine dynamics ``x' = A x + b``. A star ``S`` advances by one step ``h`` as
``e^{Ah} S + psi(h)`` (``[Phi psi; 0 1] = expm([A b; 0 0] h)``: the affine term by state
augmentation), so a whole chain of grid stars ``Y_0, Y_1, ...`` is a stack of matrix
products. Between grid points every run is covered by the **segment** of its cell
``[t_j, t_j + h]``: the exact convex hull of ``Y_j`` and ``Y_{j+1}`` with a shared
predicate (:func:`reach.sets.star.chord_hull`) plus the linear-interpolation error

    |x_i(t_j + lam h) - chord_i(lam)| <= lam (1 - lam) h^2 / 2 * M_i,   M_i >= sup |x_i''|

on the cell. ``x'' = A^2 x + A b`` is an affine function of the state; ``M`` comes from
``q + 1`` sub-samples at spacing ``delta = h / q`` (support bounds of ``Y_j`` in the
directions of ``A^2 e^{A s}``) and the closure argument ``y := x''``, ``y'' = A^2 y``:

    sup |y| <= max_samples |y| + delta^2/8 |A^2| sup |y|
    =>  M = (I - delta^2/8 |A^2|)^{-1} max_samples |y|,

valid because ``q`` is chosen so that the spectral radius of ``delta^2/8 |A^2|`` is at
most 1/4 (the inverse is then a non-negative Neumann series).

Transitions -- urgent ones (the octagon entry) and may-transitions over a clock window
(the abort) alike -- fire from a segment intersected with the guard and the source
invariant: that set contains the state at every switching instant inside the cell, so the
continuum of switching times is covered without aggregation; each such set starts a
successor star that carries the global clock, so no alignment of time grids is assumed.
Invariants are intersected exactly (predicate rows). Every unsafe convex piece of the
property is checked per segment: cheap support bounds first (vectorised over the chain),
an LP on the segment only where they do not exclude the piece.

Refinement. Each cell's segment adds a block of coefficients (hull weights, chord weight,
error terms) to its star, and successors keep their ancestors' blocks. When a piece is
met, the block with the largest spread along the piece is blamed and only the cell that
owns it is bisected (halved step, a quarter of the error), with everything downstream of
it; up to ``max_refinements`` times per cell. A witness -- an LP point of a segment inside a
piece -- maps back through the coefficients (the original ones are kept in every derived
star) to an initial state and abort time; it is replayed with the Monte Carlo simulator
when nothing is left to refine or when it lies deeper in the piece than all refinable
spread. UNSAFE only if the replay violates; otherwise UNKNOWN.

Timed modes. In a mode whose flow is a constant (``A = 0``: clocks, counters, stopwatches
of a timed or linear hybrid automaton) every run is the ray ``x + s b``; the cell
``[0, h]`` from ``S`` is then exactly ``S + [0, h] b`` -- one new coefficient ``s in [0, 1]``
instead of a chord hull, no interpolation error, nothing to refine -- so coefficient counts
grow by one per mode visit and hundreds of jumps stay cheap. A transition whose guard,
within the source invariant, lies inside the guard of another transition with the same
target and reset is *subsumed* (its successors are contained in the other's) and is not
fired separately (an urgent time-out at the end of a window, for example).

Jumps. ``max_jumps`` bounds the jumps along a path (none by default). When the model may
have a zero-dwell cycle (:mod:`reach.model.lint`), at most ``STALL_JUMPS`` jumps in a row may
leave the earliest clock where it was; beyond, UNKNOWN. A witness whose path takes more
than one window switch, or a window on a clock other than the global one, is replayed
without a switch time (the simulator takes one switch at a global time): if that run does
not violate, the answer stays UNKNOWN.

Clock. The horizon and the switch times are read off a global clock (rate 1 everywhere,
0 initially, never reset). A model without one gets its own, an extra explored state that
no guard, invariant, reset or property mentions (:class:`_LinearModel`).

Aggregation. Each segment of a non-constant flow doubles a star's coefficients (the chord
hull keeps ``a`` and ``lam a``), so a path with many jumps -- a thermostat switching every
few minutes -- would need LPs of exponential size. Past the first ``aggregate_after`` jumps
of a path, the successors one chain sends through one transition (the stars entering a
mode in that chain's time window) are replaced by their interval hull, a box star with
fresh coefficients intersected with the target invariant; it contains every member, so a
proof under it covers them. When a check under an aggregate fails, its witness is traced
back through the nearest point of a member (one LP per member, per aggregate level) to an
initial state and replayed; if that run does not violate, the aggregate is refined into
its members, explored with their exact histories. Star, coefficient and memory budgets end
a check in UNKNOWN with the reason, and progress goes to the ``reach.star`` logger.

Strict and non-strict bounds. With piece rows of unit norm, the depth LP (HiGHS, primal
feasibility 1e-10) is trusted to ``tol = touch_tolerance * max(1, |g|, |h . c|)``: a piece
of strict inequalities (the negation of ``x >= -100``) counts as entered only above
``tol`` (a set that meets ``x = -100`` only touches it), a piece with a non-strict row as met
from ``-tol``; the details state the largest ``tol`` used. An LP failure answers UNKNOWN.

``discrete_time=True`` checks and switches at grid points only (Hylaa's semantics): no
segments, no error terms -- not a proof for continuous time, so it answers UNSAFE (replayed)
or UNKNOWN ("no violation at the grid points"), never SAFE.

:func:`safe_abort_time` / :func:`safe_abort_map` sweep initial cells for the latest abort
time up to which every abort is proven safe (Fig. 5 of the rendezvous benchmark).
"""

from __future__ import annotations

import logging
import time
import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.linalg import expm

from reach import lp
from reach.backends.options import parse_options
from reach.result import Result, Status
from reach.sets import Box, Star, chord_hull
from reach.sets.hpolytope import HPolytope
from reach.model.constraints import affine_coefficients

NAME = "star"

LOG = logging.getLogger("reach.star")

#: a cell is bisected before any check while its interpolation error exceeds this fraction
#: of the state's magnitude (fast transients, e.g. right after a controller switch)
ERROR_RATIO = 0.25

#: primal feasibility tolerance of the depth LPs (HiGHS's default is 1e-7): a depth is
#: then exact to well below the touch tolerance of :class:`StarOptions`
DEPTH_LP_TOLERANCE = 1e-10

#: in a model that may have a zero-dwell cycle, this many jumps in a row without the
#: earliest clock advancing end the check (UNKNOWN)
STALL_JUMPS = 10

#: the grid stacks of one chain may take at most this many bytes (memory guard)
MAX_CHAIN_BYTES = 1 << 30

#: seconds between two progress lines (logger ``reach.star``, shown under ``-v``)
PROGRESS_SECONDS = 1.0

#: a witness is replayed at once when the spread refinement could still remove is below
#: this fraction of the unsafe piece's inradius: the over-approximation is already tight
TIGHT_RATIO = 0.1


@dataclass
class StarOptions:
    """Settings of the star back-end (the problem -- model, property -- is separate).

    step: base time step in model time units (default: horizon / 60; cells that need it are
        bisected).
    discrete_time: check and switch at grid points only (Hylaa-like; not a proof).
    max_refinements: how many times a failing cell may be bisected.
    replay: replay LP witnesses with the Monte Carlo simulator.
    max_replays: at most this many replays per check.
    max_unresolved: stop (UNKNOWN) after this many cells that refinement cannot clear.
    max_lps: LP budget; when exhausted the answer is UNKNOWN.
    max_jumps: bound on discrete jumps along a path; UNKNOWN beyond. None (default): no
        bound, but at most ``STALL_JUMPS`` jumps in a row without time passing when the
        model may have a zero-dwell cycle (:mod:`reach.model.lint`).
    aggregate_after: successors of the jumps after the first ``aggregate_after`` ones on a
        path, out of a mode whose flow is not constant, are aggregated: the stars one chain
        sends through one transition become one star, their interval hull (see
        :meth:`_Explorer._aggregate`); refined back into the members when a check under it
        fails. None: never aggregate.
    max_stars: UNKNOWN once this many stars (chains) have been explored.
    max_coefficients: UNKNOWN when a segment needs more coefficients than this (each
        segment of a non-constant flow doubles them: LPs and grid stacks would grow without
        bound; aggregation keeps the count down).
    max_deaggregations: at most this many aggregates are refined back into their members.
    touch_tolerance: relative LP tolerance. With piece rows of unit norm, the depth LP's
        answer counts as exact up to ``tol = touch_tolerance * max(1, |g_r|, |h_r . c|)``
        (largest over the piece's rows ``h_r x <= g_r``, ``c`` the segment's centre): a
        piece made only of strict inequalities is entered when the depth exceeds ``tol``;
        a piece with a non-strict row is met when the depth is at least ``-tol``.
    replay_dt: simulator step for replays (None: the simulator's default).
    """

    step: float | None = None
    discrete_time: bool = False
    max_refinements: int = 8
    replay: bool = True
    max_replays: int = 20
    max_unresolved: int = 8
    max_lps: int = 50_000
    max_jumps: int | None = None
    aggregate_after: int | None = 2
    max_stars: int = 20_000
    max_coefficients: int = 2_000
    max_deaggregations: int = 50
    touch_tolerance: float = 1e-9
    replay_dt: float | None = None

    @classmethod
    def from_dict(cls, options: dict | None) -> "StarOptions":
        if isinstance(options, StarOptions):
            return options
        return cls(**parse_options(cls, options, "star"))


# ---------------------------------------------------------------------- dynamics

class AffineFlow:
    """``x' = A x + b + B (u - u_c)`` of one mode: step maps, stacked powers, the curvature
    data and, with a bounded input ``|u - u_c| <= u_r`` (componentwise, any measurable
    signal), the bound of its effect.

    Input effect. Split every run as ``x = x_free + d`` with ``x_free`` the run of
    ``x' = A x + b`` (``b`` holds ``B u_c``) from the same state and
    ``d(t) = int_0^t e^{A (t - s)} B (u(s) - u_c) ds``. Then ``|d(t)| <= R(t) =
    int_0^t |e^{A tau} B| u_r dtau``, non-decreasing in ``t``, and since
    ``e^{A tau} = Phi^i e^{A sigma}`` with ``|e^{A sigma}| <= e^{|A| sigma}`` entrywise,
    ``R((j + 1) h) <= sum_{i <= j} |Phi^i| w`` with ``w = h e^{|A| h} |B| u_r``
    (:meth:`deviation`)."""

    def __init__(self, A: np.ndarray, b: np.ndarray, B: np.ndarray | None = None,
                 u_radius: np.ndarray | None = None):
        self.A, self.b = A, b
        self.B, self.u_radius = B, u_radius
        self.inputs = B is not None and B.size > 0 and bool(np.any(np.abs(B) @ u_radius > 0))
        self.n = A.shape[0]
        self.A2 = A @ A
        self.Ab = A @ b
        self.drift = not np.any(A)          # constant flow: exact segments, no refinement
        self.rho = float(np.max(np.abs(np.linalg.eigvals(np.abs(self.A2))))) if self.n else 0.0
        self._steps: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._powers: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._curvature: dict[float, tuple] = {}
        self._deviation: dict[float, np.ndarray] = {}

    def deviation(self, h: float, count: int) -> np.ndarray | None:
        """``R_j >= sup_{t <= j h} |d(t)|`` for ``j = 0..count`` (``(count + 1, n)``), or None
        without inputs (see the class doc)."""
        if not self.inputs:
            return None
        R = self._deviation.get(h)
        if R is None or R.shape[0] <= count:
            Phis, _ = self.powers(h, count)
            w = h * expm(np.abs(self.A) * h) @ (np.abs(self.B) @ self.u_radius)
            steps = np.abs(Phis[:count]) @ w                     # |Phi^i| w, i < count
            R = np.vstack([np.zeros(self.n), np.cumsum(steps, axis=0)])
            self._deviation[h] = R
        return R[:count + 1]

    def step(self, h: float):
        """``(Phi, psi)`` with ``x(t + h) = Phi x(t) + psi``."""
        if h not in self._steps:
            n = self.n
            aug = np.zeros((n + 1, n + 1))
            aug[:n, :n], aug[:n, n] = self.A, self.b
            E = expm(aug * h)
            self._steps[h] = (E[:n, :n], E[:n, n])
        return self._steps[h]

    def powers(self, h: float, count: int):
        """``Phi_j, psi_j`` for ``j = 0..count`` (``x(t + j h) = Phi_j x + psi_j``)."""
        Phis, psis = self._powers.get(h, (np.eye(self.n)[None], np.zeros((1, self.n))))
        if Phis.shape[0] <= count:
            Phi, psi = self.step(h)
            P, p = list(Phis), list(psis)
            while len(P) <= count:
                P.append(Phi @ P[-1])
                p.append(Phi @ p[-1] + psi)
            Phis, psis = np.array(P), np.array(p)
            self._powers[h] = (Phis, psis)
        return Phis[:count + 1], psis[:count + 1]

    def curvature(self, h: float):
        """Sub-sample data for ``M >= sup |x''|`` on a cell of length ``h``.

        Returns ``(D, d, F, q)``: ``x''(s_l) = D_l x + d_l`` at ``s_l = l h / q``, the
        closure factor ``F = (I - delta^2/8 |A^2|)^{-1}`` and ``q``, the least number of
        sub-steps with spectral radius of ``delta^2/8 |A^2|`` at most 1/4.
        """
        if h not in self._curvature:
            q = 1 if self.rho == 0 else max(1, int(np.ceil(h / np.sqrt(2.0 / self.rho))))
            delta = h / q
            Phi, psi = self.step(delta)
            D, d = [], []
            P, p = np.eye(self.n), np.zeros(self.n)
            for _ in range(q + 1):
                D.append(self.A2 @ P)
                d.append(self.A2 @ p + self.Ab)
                P, p = Phi @ P, Phi @ p + psi
            F = np.linalg.inv(np.eye(self.n) - delta ** 2 / 8 * np.abs(self.A2))
            self._curvature[h] = (np.array(D), np.array(d), F, q)
        return self._curvature[h]


def _chain_bounds(center, basis, box, W):
    """Support bounds ``max_{x in Y_j} w^T x`` for every grid star ``j`` and row ``w`` of
    ``W`` from the coefficient box: ``(J, rows)``; ``center (J, n)``, ``basis (J, n, m)``."""
    G = np.einsum("rn,jnm->jrm", W, basis)
    return center @ W.T + G @ box.center + np.abs(G) @ box.radius


def _chain_abs_bounds(center, basis, box, D, d):
    """``max |D_l x + d_l|`` over each ``Y_j``, per sample ``l`` and component: ``(J, L, n)``."""
    G = np.einsum("lin,jnm->jlim", D, basis)
    mid = np.einsum("lin,jn->jli", D, center) + d[None] + G @ box.center
    return np.abs(mid) + np.abs(G) @ box.radius


# ---------------------------------------------------------------------- problem data

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


@dataclass
class _Entry:
    """How a star was entered: the transition and the clock at the switch as an affine
    function ``offset + row . a[:len(row)]`` of the star's coefficients."""

    transition: str
    window: bool
    offset: float
    row: np.ndarray
    global_window: bool = True      # a window on the global clock (replayable switch time)


@dataclass(frozen=True)
class _Path:
    """The discrete history of a star since its origin (the initial star, or the aggregate
    it descends from): entries, and for each ancestor cell the first coefficient of its
    segment block and whether that cell may still be bisected; ``jumps`` counts every jump
    since the initial star, ``stalled`` the last jumps in a row that took no time."""

    entries: tuple[_Entry, ...] = ()
    blocks: tuple[int, ...] = ()
    open: tuple[bool, ...] = ()
    abort: float = np.inf          # earliest clock of the first window switch on the path
    jumps: int = 0
    stalled: int = 0
    origin: "_Aggregate | None" = None
    since: float = 0.0             # earliest clock of the star this path leads to

    def descend(self, entry: _Entry, block: int, can_refine: bool, clock: float) -> "_Path":
        abort = min(self.abort, clock) if entry.window and self.abort == np.inf else self.abort
        stalled = self.stalled + 1 if clock <= self.since else 0
        return _Path(self.entries + (entry,), self.blocks + (block,), self.open + (can_refine,), abort,
                     self.jumps + 1, stalled, self.origin, clock)

    def closed(self) -> "_Path":
        """The same history with no cell left to bisect."""
        return _Path(self.entries, self.blocks, (False,) * len(self.open), self.abort, self.jumps,
                     self.stalled, self.origin, self.since)


@dataclass
class _Aggregate:
    """One star standing for ``members`` (successor stars with their paths), all entering
    ``mode``; ``star`` contains every member. Explored in their place until a check under it
    fails; then the members are explored instead (``refined``)."""

    mode: str
    star: Star
    members: list[tuple[Star, "_Path"]]
    refined: bool = False


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


class _Stop(Exception):
    """Abort the exploration: a replayed counterexample, or the LP budget is spent."""

    def __init__(self, status: Status, reason: str, counterexample=None, witness=None):
        super().__init__(reason)
        self.status, self.reason = status, reason
        self.counterexample, self.witness = counterexample, witness


# ---------------------------------------------------------------------- model data

_CACHE: dict[int, tuple[weakref.ref, object]] = {}


def _cached(obj, build):
    """``build(obj)``, computed once per live object (symbolic extraction is slow)."""
    key = id(obj)
    ref, value = _CACHE.get(key, (None, None))
    if ref is None or ref() is not obj:
        value = build(obj)
        _CACHE[key] = (weakref.ref(obj, lambda _: _CACHE.pop(key, None)), value)
    return value


def _unsafe_pieces(prop) -> dict[str, list[_Piece] | None]:
    """The property's unsafe pieces per mode, rows normalised (None for a nonlinear mode)."""
    def build(prop):
        out = {}
        for mode in prop.modes:
            halfspaces = prop.halfspace_pieces(mode)
            if halfspaces is None:
                out[mode] = None
                continue
            out[mode] = []
            for k, ((H, g), constraints) in enumerate(zip(halfspaces, prop.pieces[mode])):
                label = " and ".join(c.text for c in constraints) or f"piece {k}"
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
    extended ones (``n`` is then ``model.n + 1`` and ``added_clock`` is True)."""

    def __init__(self, model):
        clock = _global_clock(model)
        self.added_clock = clock is None
        self.n = model.n + self.added_clock
        self.clock = model.n if clock is None else clock
        self.jumps = {name: [self._jump(model, tr) for tr in model.outgoing(name)]
                      for name in model.modes}
        self.linear = (all(m.linear is not None and m.invariant_halfspaces is not None
                           for m in model.modes.values())
                       and all(j is not None for js in self.jumps.values() for j in js))
        self.varying = [u for u in getattr(model, "bounded_inputs", []) if u.varying]
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


# ---------------------------------------------------------------------- the explorer

@dataclass
class _Stats:
    chains: int = 0
    cells: int = 0
    refined: int = 0
    deepest: int = 0
    lps: int = 0
    replays: int = 0
    tolerance: float = 0.0          # the largest depth tolerance used (model units)
    jumps: int = 0                  # the most jumps on one path
    reached: float = 0.0            # the latest clock a chain has started from
    aggregated: int = 0             # aggregates formed
    members: int = 0                # successor stars they stand for
    deaggregated: int = 0           # aggregates refined back into their members


class _Explorer:
    """One check of one safety property on one linear hybrid automaton."""

    def __init__(self, model, prop, options: StarOptions, initial: Star | None = None,
                 cutoff: float | None = None):
        """``cutoff`` switches to the safe-abort sweep: instead of a verdict, the explorer
        lowers ``cutoff`` to the earliest time from which a run may violate (an abort at or
        after it, or a violation before any abort at it) and skips everything later."""
        self.model, self.prop, self.opt = model, prop, options
        self.sweep = cutoff is not None
        self.cutoff = np.inf if cutoff is None else float(cutoff)
        data = _LinearModel.of(model)
        self.data = data
        self.n, self.clock = data.n, data.clock
        self.horizon = float(model.horizon)
        self.h = float(options.step) if options.step else self.horizon / 60.0
        self.flows, self.invariants, self.jumps = data.flows, data.invariants, data.fired
        self.max_jumps = np.inf if options.max_jumps is None else options.max_jumps
        from reach.model.lint import zero_dwell_cycles
        self.stall_limit = STALL_JUMPS if zero_dwell_cycles(model)[0] else np.inf
        self.aggregate_after = None if self.sweep else options.aggregate_after
        self.last_progress = time.perf_counter()
        self.pieces = {mode: [_Piece(data.widen(p.H, p.g)[0], p.g, p.strict, p.label) for p in pieces]
                       for mode, pieces in _unsafe_pieces(prop).items()} if data.added_clock \
            else _unsafe_pieces(prop)
        self.relevant = _modes_leading_to(model, set(self.pieces))
        self.stats = _Stats()
        self.unresolved: list[_Witness] = []
        self.replayed: list = []
        self.root = initial if initial is not None else data.initial_star(model.initial)
        self.root_mode = model.initial.mode

    # ---- LPs

    def _lp_budget(self):
        self.stats.lps += 1
        if self.stats.lps > self.opt.max_lps:
            raise _Stop(Status.UNKNOWN, f"LP budget of {self.opt.max_lps} exhausted")

    def _feasible(self, star: Star):
        """Coefficients of a point of ``star`` (an LP), or None if it is empty."""
        self._lp_budget()
        return star.feasible_alpha()

    # ---- exploration

    def _point(self, star: Star, guess, direction=None):
        """Coefficients of a point of ``star`` without an LP if possible: ``guess``, or the
        middle of the stretch of ``guess + s direction`` (``0 <= s <= 1``) inside the
        predicate; else an LP's point. None if ``star`` is empty."""
        if guess is not None:
            if direction is not None:
                A, b = star.predicate.A, star.predicate.b
                slope, room = A @ direction, b - A @ guess
                lo = max([0.0] + [r / k for r, k in zip(room, slope) if k < 0])
                hi = min([1.0] + [r / k for r, k in zip(room, slope) if k > 0])
                guess = guess + (lo + hi) / 2 * direction if lo <= hi else guess
            if star.box.contains(guess, 1e-12) and star.predicate.contains(guess):
                return guess
        return self._feasible(star)

    def run(self):
        start = self.root.intersect_halfspaces(*self.invariants[self.root_mode])
        self._chain(self.root_mode, start, _Path(), self.root.box.center)

    def _chain(self, mode: str, star: Star, path: _Path, guess=None, direction=None):
        """Explore ``star`` in ``mode`` up to the horizon: checks, jumps, refinement.

        ``guess`` (and ``direction``): where a point of ``star`` may be (see :meth:`_point`).
        The run of a known point proves the chain non-empty for as long as it stays inside
        the invariant, without LPs.
        """
        if mode not in self.relevant:
            return
        point = self._point(star, guess, direction)
        if point is None:
            return
        if path.jumps > self.max_jumps:
            raise _Stop(Status.UNKNOWN, f"more than {self.max_jumps} discrete jumps on a path")
        if path.stalled > self.stall_limit:
            raise _Stop(Status.UNKNOWN, f"{path.stalled} jumps in a row without time passing "
                                        f"(possible zero-dwell cycle)")
        self.stats.chains += 1
        if self.stats.chains > self.opt.max_stars:
            raise _Stop(Status.UNKNOWN, f"star budget of {self.opt.max_stars} exhausted "
                                        f"(option max_stars)")
        flow, h = self.flows[mode], self.h
        t0 = -star.support_bounds(-np.eye(self.n)[self.clock])[0]
        count = max(1, int(np.ceil((self.horizon - t0) / h - 1e-9)))
        segment_vars = star.nvars if flow.drift else 2 * star.nvars + 1 + self.n
        if segment_vars > self.opt.max_coefficients or \
                8 * 3 * (count + 1) * self.n * (star.nvars + 1) > MAX_CHAIN_BYTES:
            raise _Stop(Status.UNKNOWN, f"a segment in mode '{mode}' needs {segment_vars} coefficients "
                                        f"over {count} steps (limits: option max_coefficients = "
                                        f"{self.opt.max_coefficients}, {MAX_CHAIN_BYTES >> 20} MiB per "
                                        f"chain); aggregate sooner (option aggregate_after)")
        self.stats.jumps = max(self.stats.jumps, path.jumps)
        self.stats.reached = max(self.stats.reached, t0)
        self._progress()
        Phis, psis = flow.powers(h, count)
        dev = flow.deviation(h, count)          # input effect bound per grid point, or None
        centers = star.center @ np.swapaxes(Phis, 1, 2) + psis
        bases = np.einsum("jab,bm->jam", Phis, star.basis)
        box = star.box
        Hi, gi = self.invariants[mode]

        # invariant: the first grid star entirely outside ends the chain; rows that are not
        # implied by the coefficient box join the predicate exactly, step by step. With
        # inputs the grid stars are input-free runs x_free, |x - x_free| <= R_j: the rows are
        # relaxed to H x_free <= g + |H| R_j (every run inside the invariant satisfies them)
        last = count
        extra = {}
        if Hi.shape[0]:
            upper = _chain_bounds(centers, bases, box, Hi)
            lower = -_chain_bounds(centers, bases, box, -Hi)
            relaxed = np.broadcast_to(gi, upper.shape) + (0.0 if dev is None else dev @ np.abs(Hi).T)
            outside = np.flatnonzero(np.any(lower > relaxed + 1e-12 * (1 + np.abs(relaxed)), axis=1))
            if outside.size:
                last = min(last, int(outside[0]))
            for j in range(1, last + 1):
                active = upper[j] > relaxed[j]
                if np.any(active):
                    extra[j] = (Hi[active], relaxed[j][active])
        known_empty = last < count              # grid star `last` lies outside the invariant

        stars = {}          # grid stars with their accumulated predicate, built lazily

        def grid_star(j: int) -> Star:
            if j not in stars:
                s = Star(centers[j], bases[j], star.predicate, box)
                for i in sorted(k for k in extra if k <= j):
                    s = s.intersect_halfspaces(*extra[i])
                stars[j] = s
            return stars[j]

        for j in sorted(extra):                  # `point` stays a point of every grid star
            if j > last or (j == last and known_empty):
                break
            H, g = extra[j]
            if np.all(H @ (centers[j] + bases[j] @ point) <= g):
                continue
            found = self._feasible(grid_star(j))
            if found is None:
                last = j
                break
            point = found
        ended_inside = last == count            # by the horizon, not by the invariant
        cells = range(last + 1) if self.opt.discrete_time and ended_inside else range(last)
        if not len(cells):
            return
        self.stats.cells += len(cells)

        # cheap screening, vectorised over the chain
        candidates = set()
        if self.opt.discrete_time:
            error = np.zeros((last + 1, self.n)) if dev is None else dev[:last + 1].copy()
        else:
            D, d, F, _ = flow.curvature(h)
            samples = _chain_abs_bounds(centers[:last], bases[:last], box, D, d).max(axis=1)
            error = h * h / 8 * samples @ F.T
            if dev is not None:
                error = error + dev[1:last + 1]          # the whole cell, R non-decreasing
        for piece in self.pieces.get(mode, []):
            candidates |= self._screen(centers, bases, box, error, piece.H, piece.g, cells)
        for jump in self.jumps[mode]:
            if jump.target in self.relevant:
                candidates |= self._screen(centers, bases, box, error, jump.H, jump.g, cells)

        aggregate = (self.aggregate_after is not None and not flow.drift
                     and path.jumps >= self.aggregate_after)
        pending: dict[int, list] | None = {} if aggregate else None
        for j in sorted(candidates):
            spread = None if dev is None else dev[j] if self.opt.discrete_time else dev[j + 1]
            self._cell(mode, grid_star(j), h, path, 0, point, pending, spread)
        for index, members in (pending or {}).items():
            self._aggregate(self.jumps[mode][index].target, members)

    def _progress(self):
        now = time.perf_counter()
        if now - self.last_progress >= PROGRESS_SECONDS:
            self.last_progress = now
            s = self.stats
            LOG.info("%d stars, %d cells, %d LPs, up to %d jumps on a path, time %.6g of %.6g, "
                     "%d aggregates of %d stars (%d refined)", s.chains, s.cells, s.lps, s.jumps,
                     s.reached, self.horizon, s.aggregated, s.members, s.deaggregated)

    def _aggregate(self, mode: str, members: list[tuple[Star, _Path]]):
        """Explore the successor stars ``members`` entering ``mode`` as one star.

        The aggregate is the interval hull of the members (``2 n`` LPs each, each bound pushed
        out by a relative 1e-9) intersected with the invariant of ``mode``: it contains every
        member, so everything reachable from the members is reachable from it -- a SAFE
        under it covers them. It has fresh coefficients (a box), so its LPs stay small however
        many jumps came before. When a check under it fails and its witness does not replay,
        the members are explored instead, each with its own exact history (no cell before the
        aggregation is bisected again).
        """
        bounds = []
        kept = []
        eye = np.eye(self.n)
        for star, path in members:
            self.stats.lps += 2 * self.n
            if self.stats.lps > self.opt.max_lps:
                raise _Stop(Status.UNKNOWN, f"LP budget of {self.opt.max_lps} exhausted")
            high = np.array([star.support(e) for e in eye])
            if not np.all(np.isfinite(high)):
                if np.any(high == -np.inf):
                    continue                                   # an empty member
                bounds = None
            low = np.array([-star.support(-e) for e in eye])
            kept.append((star, path))
            if bounds is not None:
                bounds.append((low, high))
        if not kept:
            return
        if bounds is None:                                     # unbounded: explore the members
            for star, path in kept:
                self._chain(mode, star, path)
            return
        low = np.min([b[0] for b in bounds], axis=0)
        high = np.max([b[1] for b in bounds], axis=0)
        pad = 1e-9 * (1.0 + np.maximum(np.abs(low), np.abs(high)))
        hull = Star.from_box(Box(low - pad, high + pad)).intersect_halfspaces(*self.invariants[mode])
        agg = _Aggregate(mode, hull, kept)
        self.stats.aggregated += 1
        self.stats.members += len(kept)
        start = min(path.since for _, path in kept)
        jumps = max(path.jumps for _, path in kept)
        stalled = min(path.stalled for _, path in kept)
        try:
            self._chain(mode, hull, _Path(jumps=jumps, stalled=stalled, origin=agg, since=start),
                        hull.box.center)
        except _Deaggregate as failure:
            if failure.target is not agg:
                raise
            agg.refined = True
            self.stats.deaggregated += 1
            LOG.info("aggregate of %d stars entering '%s' refined into its members (%s)",
                     len(kept), mode, failure.witness.piece)
            for star, path in kept:
                self._chain(mode, star, path.closed())

    def _screen(self, centers, bases, box, error, H, g, cells) -> set[int]:
        """Cells whose segment may meet ``{H x <= g}`` by support bounds (cheap)."""
        if H.shape[0] == 0:
            return set(cells)
        lower = -_chain_bounds(centers, bases, box, -H)          # (J, rows)
        if self.opt.discrete_time:
            seg = lower[:len(cells)] - error[:len(cells)] @ np.abs(H).T
        else:
            seg = np.minimum(lower[:-1], lower[1:])[:len(cells)] - error[:len(cells)] @ np.abs(H).T
        missed = np.any(seg > g, axis=1)
        return {j for j in cells if not missed[j]}

    # ---- one cell

    def _segment(self, mode: str, start: Star, h: float, spread=None) -> tuple[Star, np.ndarray]:
        """``(segment, error)`` of the cell of length ``h`` starting at ``start``; ``spread``:
        the bound of the input effect on the cell (added as a box, then the invariant)."""
        Hi, gi = self.invariants[mode]
        if self.opt.discrete_time:
            if spread is None:
                return start, np.zeros(self.n)
            return _plus_box(start, spread).intersect_halfspaces(Hi, gi), np.zeros(self.n)
        seg, _, error = _segment(self.flows[mode], start, h)
        if spread is not None:
            seg = _plus_box(seg, spread)
        seg = seg.intersect_halfspaces(Hi, gi)
        return (_tightened(seg, len(gi)) or seg) if self.flows[mode].drift else seg, error

    def _cell(self, mode: str, start: Star, h: float, path: _Path, depth: int, point, pending=None,
              spread=None):
        """Check one cell and launch its successors; bisect when a failure is blamed on it.

        The segment's own coefficients are the block starting at ``start.nvars``; a failure
        (here or in a successor) names the block that contributes most to it, and only
        the cell owning that block is bisected. ``point``: coefficients of a point of
        ``start`` (passed on as a guess to successors). ``pending``: where successors to be
        aggregated are collected (per outgoing jump), None to explore them at once.
        ``spread``: bound of the input effect on the cell (None without inputs); halves keep
        it (it only grows with time).
        """
        if self.sweep:
            since = path.abort if path.abort < np.inf else \
                -start.support_bounds(-np.eye(self.n)[self.clock])[0]
            if since >= self.cutoff:
                return
        seg, error = self._segment(mode, start, h, spread)
        final = depth >= self.opt.max_refinements or self.opt.discrete_time or self.flows[mode].drift
        block = start.nvars
        try:
            hull = seg.box_bound()
            if not final and np.any(error > ERROR_RATIO * np.maximum(-hull.low, hull.high)):
                raise _Refine(None, block)          # a fast transient: refine before checking
            self._check_segment(mode, seg, path, block, not final)
            self._jump_from(mode, seg, path, block, not final, point, pending)
        except _Refine as failure:
            if final or failure.blame != block:
                raise
            self.stats.refined += 1
            self.stats.deepest = max(self.stats.deepest, depth + 1)
            half = h / 2
            self._cell(mode, start, half, path, depth + 1, point, pending, spread)
            mid = start.affine_map(*self.flows[mode].step(half))
            mid = mid.intersect_halfspaces(*self.invariants[mode])
            mid_point = self._point(mid, point)
            if mid_point is not None:
                self._cell(mode, mid, half, path, depth + 1, mid_point, pending, spread)

    def _check_segment(self, mode: str, seg: Star, path: _Path, block: int, own_open: bool):
        """Check every unsafe piece of ``mode`` on a segment.

        Cheap support bounds first. When they fail, the interpolation error of each cell
        along the path (its error coefficients' extent along each piece row) is compared with
        the row's deficit: an error larger than the deficit cannot be argued away by an LP,
        so that cell is refined at once. Otherwise an LP decides; on a hit the open block
        (an ancestor cell or this one) with the largest spread is blamed, and the witness is
        replayed when nothing can be refined or when it lies deeper in the piece than all
        refinable spread together.
        """
        horizon_row = np.eye(self.n)[self.clock][None]
        blocks, open_ = path.blocks + (block,), path.open + (own_open,)
        for piece in self.pieces.get(mode, []):
            lower = -seg.support_bounds(-piece.H)
            if np.any(lower > piece.g):
                continue
            spread, error = _block_spreads(seg, piece.H, blocks)     # (blocks, rows) each
            gain = np.where(np.array(open_)[:, None], error - (piece.g - lower), -np.inf)
            if gain.max(initial=-np.inf) > 0:
                raise _Refine(None, blocks[int(np.argmax(gain.max(axis=1)))])
            self._lp_budget()
            H = np.vstack([piece.H, horizon_row])
            g = np.append(piece.g, self.horizon)
            depth, alpha = _depth(seg, H, g, len(piece.g))
            tol = self.opt.touch_tolerance * max(1.0, np.abs(piece.g).max(initial=0.0),
                                                 np.abs(piece.H @ seg.center).max(initial=0.0))
            self.stats.tolerance = max(self.stats.tolerance, tol)
            if depth <= tol if piece.strict else depth < -tol:
                continue
            witness = _Witness(mode, piece.label, depth, alpha, seg.point(alpha), path)
            row = int(np.argmax(lower - piece.g))
            refinable = np.where(open_, spread[:, row], -np.inf)
            blame = blocks[int(np.argmax(refinable))] if any(open_) else None
            removable = refinable[np.isfinite(refinable)].sum()
            tight = np.isfinite(piece.inradius) and removable < TIGHT_RATIO * piece.inradius
            if blame is None or depth > removable or tight:
                self._try_replay(witness)
            if blame is not None:
                raise _Refine(witness, blame)
            if self.sweep:
                self.cutoff = min(self.cutoff, self._failure_time(witness, seg))
                continue
            if path.origin is not None and self.stats.deaggregated < self.opt.max_deaggregations:
                raise _Deaggregate(witness, path.origin)
            self.unresolved.append(witness)
            if len(self.unresolved) >= self.opt.max_unresolved:
                raise _Stop(Status.UNKNOWN, f"{len(self.unresolved)} cells still meet an unsafe "
                                            f"piece after refinement; no witness replayed",
                            witness=self.unresolved[0])

    def _failure_time(self, witness: _Witness, seg: Star) -> float:
        """Earliest time from which the runs behind a failing segment may violate: the
        earliest abort on its path, or, with no abort, the segment's earliest clock."""
        windows = [e for e in witness.history if e.window]
        if windows:
            e = windows[-1]
            box = Box(seg.box.low[:e.row.size], seg.box.high[:e.row.size])
            return e.offset - box.support(-e.row)
        return -seg.support_bounds(-np.eye(self.n)[self.clock])[0]

    def _jump_from(self, mode: str, seg: Star, path: _Path, block: int, own_open: bool, point,
                   pending=None):
        for index, jump in enumerate(self.jumps[mode]):
            if jump.target not in self.relevant:
                continue
            if self.sweep and jump.window is not None and path.abort == np.inf and \
                    -seg.support_bounds(-np.eye(self.n)[self.clock])[0] >= self.cutoff:
                continue
            if jump.H.shape[0] and np.any(-seg.support_bounds(-jump.H) > jump.g):
                continue
            entered = seg.intersect_halfspaces(jump.H, jump.g)
            if self.flows[mode].drift:
                entered = _tightened(entered, len(jump.g))
                if entered is None or np.any(-entered.support_bounds(-jump.H) > jump.g):
                    continue
            clock = _Entry(jump.name, jump.window is not None,
                           float(entered.center[self.clock]), entered.basis[self.clock].copy(),
                           jump.window is None or jump.window[0] == self.clock)
            earliest = -entered.support_bounds(-np.eye(self.n)[self.clock])[0]
            successor = entered.affine_map(jump.R, jump.r)
            successor = successor.intersect_halfspaces(*self.invariants[jump.target])
            if self.flows[mode].drift:
                successor = _tightened(successor, len(self.invariants[jump.target][1]))
                if successor is None:
                    continue
            descended = path.descend(clock, block, own_open, earliest)
            if pending is not None:
                pending.setdefault(index, []).append((successor, descended))
                continue
            # the known point's own chord: (a, lam a, lam, 0) from lam = 0 to 1, or its ray
            # (a, s) from s = 0 to 1 in a constant-flow mode
            m, pad = point.size, successor.nvars - point.size
            guess = np.concatenate([point, np.zeros(pad)])
            if self.flows[mode].drift and not self.opt.discrete_time:
                direction = np.concatenate([np.zeros(m), [1.0]]) if pad == 1 else None
            else:
                direction = np.concatenate([np.zeros(m), point, [1.0], np.zeros(pad - m - 1)]) \
                    if pad > m else None
            self._chain(jump.target, successor, descended, guess, direction)

    # ---- witnesses

    def _try_replay(self, witness: _Witness):
        if not self.opt.replay or self.stats.replays >= self.opt.max_replays:
            return
        try:
            from reach.backends.montecarlo import replay
        except ImportError:
            return
        self.stats.replays += 1
        x0, switch = self.initial_point(witness)
        run = replay(self.model, self.prop, x0, switch, self.opt.replay_dt)
        self.replayed.append({"initial_state": x0.tolist(), "switch_time": switch,
                              "violated": bool(run.violated)})
        if run.violated:
            raise _Stop(Status.UNSAFE, "replayed counterexample",
                        counterexample=run.counterexample(self.model, self.prop, NAME),
                        witness=witness)

    def initial_point(self, witness: _Witness):
        """Initial state and abort time of a witness, read off its coefficients."""
        alpha, entries = self._trace(witness.alpha, witness.path)
        m0 = self.root.nvars
        x0 = self.root.point(alpha[:m0])[:self.model.n]
        x0 = np.clip(x0, self.model.initial.low, self.model.initial.high)
        windows = [(e, a) for e, a in entries if e.window]
        if len(windows) > 1 or any(not e.global_window for e, _ in windows):
            return x0, None                  # not one switch at a global time: no switch
        if windows:
            e, a = windows[-1]
            switch = float(e.offset + e.row @ a[:e.row.size])
        else:
            switch = self._latest_abort(witness.mode)
        return x0, switch

    def _trace(self, alpha, path: _Path):
        """The coefficients of the initial star behind the point ``alpha`` of a star reached
        along ``path``, and the path's entries, each with the coefficients it reads.

        Through an aggregate the point of the member nearest (max norm, one LP per member) to
        the aggregate's point stands for it: exact when that point lies in a member, a
        candidate otherwise (the replay decides; the aggregate is refined if it fails)."""
        entries = [(e, alpha) for e in path.entries]
        while path.origin is not None:
            agg = path.origin
            target = agg.star.point(alpha[:agg.star.nvars])
            best = None
            for star, member_path in agg.members:
                found = self._nearest(star, target)
                if found is not None and (best is None or found[0] < best[0]):
                    best = (found[0], found[1], member_path)
            if best is None:
                break
            _, alpha, path = best
            entries = [(e, alpha) for e in path.entries] + entries
        return alpha, entries

    def _nearest(self, star: Star, x):
        """``(distance, coefficients)`` of the point of ``star`` nearest to ``x`` in the max
        norm (an LP over ``(a, t)``: ``|c + V a - x| <= t``), or None if ``star`` is empty."""
        self._lp_budget()
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

    def _latest_abort(self, mode: str):
        """Without an abort on the witness's path: the latest abort of its mode's windows
        (the run stays in the mode as long as possible), or None if there is none."""
        his = [j.window[2] for j in self.jumps[mode] if j.window is not None and j.window[0] == self.clock]
        return max(his) if his else None


class _Deaggregate(Exception):
    """A check under the aggregate ``target`` failed and its witness did not replay."""

    def __init__(self, witness: _Witness, target: _Aggregate):
        super().__init__("deaggregate")
        self.witness, self.target = witness, target


class _Refine(Exception):
    """A segment (or a successor of it) may meet an unsafe piece. ``blame`` is the first
    coefficient of the segment block to refine; ``witness`` is None when the cheap bounds
    alone asked for the refinement."""

    def __init__(self, witness: _Witness | None, blame: int):
        super().__init__("refine")
        self.witness, self.blame = witness, blame


# ---------------------------------------------------------------------- helpers

def _normalised(H, g):
    """Rows scaled to unit norm (zero rows dropped if satisfied, kept as 0 <= g if not)."""
    H = np.atleast_2d(np.asarray(H, dtype=float))
    g = np.atleast_1d(np.asarray(g, dtype=float))
    norms = np.linalg.norm(H, axis=1)
    keep = (norms > 0) | (g < 0)
    norms = np.where(norms > 0, norms, 1.0)
    return (H / norms[:, None])[keep], (g / norms)[keep]


def _segment(flow: AffineFlow, start: Star, h: float):
    """The segment of the cell ``[0, h]`` from ``start``: ``(segment, end star, error)``.

    ``error_i = h^2/8 M_i`` is the interpolation error at mid-cell; ``M`` bounds
    ``|x''|`` on the cell from the sub-samples of :meth:`AffineFlow.curvature`.
    """
    end = start.affine_map(*flow.step(h))
    if flow.drift:
        return _drift_segment(start, flow.b, h), end, np.zeros(flow.n)
    D, d, F, _ = flow.curvature(h)
    n = flow.n
    upper = start.support_bounds(np.concatenate([D, -D]).reshape(-1, n))
    upper = upper.reshape(2, -1) + np.concatenate([d, -d]).reshape(2, -1)
    error = h * h / 8 * (F @ upper.max(axis=0).reshape(-1, n).max(axis=0))
    return chord_hull(start, end.center, end.basis, error), end, error


def _tightened(star: Star, rows: int, rounds: int = 3) -> Star | None:
    """``star`` with its coefficient box shrunk by bound propagation over the predicate rows
    (None if that proves it empty); the set is unchanged.

    For a row ``sum_j A_ij a_j <= b_i`` with finite activity bounds, every ``a_k`` with
    ``A_ik > 0`` satisfies ``a_k <= (b_i - sum_{j != k} min(A_ij a_j)) / A_ik`` (and the mirror
    bound when ``A_ik < 0``), minima over the current box. Each bound is relaxed by a relative
    ``1e-9`` so rounding never cuts a point of the set. Cheap support bounds then see the
    guards and invariants that pin a coefficient (a dwell fixed by guard and invariant).
    Only the last ``rows`` rows (those just added by an intersection) are used: the box is
    already consistent with the older ones, and scanning them all again costs too much.
    """
    A, b = star.predicate.A[-rows:] if rows else star.predicate.A[:0], star.predicate.b[-rows:] if rows else star.predicate.b[:0]
    lo, hi = star.box.low.copy(), star.box.high.copy()
    if A.shape[0] == 0 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return star
    pos, neg = np.maximum(A, 0.0), np.minimum(A, 0.0)
    for _ in range(rounds):
        least = pos * lo + neg * hi                                   # min of A_ij a_j
        rest = b[:, None] - (least.sum(axis=1)[:, None] - least)      # room left for a_k
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            bound = rest / A
            slack = 1e-9 * (1.0 + np.abs(bound))
            upper = np.where(A > 0, bound + slack, np.inf).min(axis=0)
            lower = np.where(A < 0, bound - slack, -np.inf).max(axis=0)
        new_lo, new_hi = np.maximum(lo, lower), np.minimum(hi, upper)
        if np.any(new_lo > new_hi):
            return None
        if np.array_equal(new_lo, lo) and np.array_equal(new_hi, hi):
            break
        lo, hi = new_lo, new_hi
    return Star(star.center, star.basis, star.predicate, Box(lo, hi))


def _plus_box(star: Star, radius) -> Star:
    """``star + [-radius, radius]`` (Minkowski sum): one new coefficient in ``[-1, 1]`` per
    positive component of ``radius``."""
    radius = np.asarray(radius, dtype=float)
    free = np.flatnonzero(radius > 0)
    if not free.size:
        return star
    E = np.zeros((star.dim, free.size))
    E[free, np.arange(free.size)] = radius[free]
    A = star.predicate.A
    predicate = HPolytope(np.hstack([A, np.zeros((A.shape[0], free.size))]), star.predicate.b)
    box = Box(np.append(star.box.low, -np.ones(free.size)), np.append(star.box.high, np.ones(free.size)))
    return Star(star.center, np.hstack([star.basis, E]), predicate, box)


def _drift_segment(start: Star, b: np.ndarray, h: float) -> Star:
    """``start + [0, h] b`` exactly: every run of ``x' = b`` from ``start`` over the cell.
    One new coefficient ``s in [0, 1]`` (column ``h b``); the old ones keep their meaning."""
    A = start.predicate.A
    predicate = HPolytope(np.hstack([A, np.zeros((A.shape[0], 1))]), start.predicate.b)
    box = Box(np.append(start.box.low, 0.0), np.append(start.box.high, 1.0))
    basis = np.hstack([start.basis, (h * np.asarray(b, dtype=float))[:, None]])
    return Star(start.center, basis, predicate, box)


def flowpipe(A, b, initial: Star, step: float, duration: float, B=None, u_low=None,
             u_high=None) -> list[Star]:
    """Segments covering every trajectory of ``x' = A x + b + B u`` from ``initial`` over
    ``[0, duration]`` in continuous time (one star per cell of length ``step``), for every
    input signal with values in ``[u_low, u_high]`` (no input if ``B`` is None)."""
    A, b = np.asarray(A, dtype=float), np.asarray(b, dtype=float)
    if B is None:
        flow = AffineFlow(A, b)
    else:
        B, lo, hi = np.atleast_2d(np.asarray(B, dtype=float)), np.asarray(u_low, float), np.asarray(u_high, float)
        flow = AffineFlow(A, b + B @ ((lo + hi) / 2), B, (hi - lo) / 2)
    count = max(1, int(np.ceil(duration / step - 1e-9)))
    dev = flow.deviation(step, count)
    segments, star = [], initial
    for j in range(count):
        seg, star, _ = _segment(flow, star, step)
        segments.append(seg if dev is None else _plus_box(seg, dev[j + 1]))
    return segments


def _block_spreads(seg: Star, H: np.ndarray, blocks: tuple[int, ...]):
    """Per block ``b`` (coefficients from ``blocks[b]`` to the next start) and row ``r``:
    the spread ``sum |H_r . V_col| * radius_col`` the block is responsible for, and the
    part of it due to the block's interpolation-error coefficients. A cell block starting
    at ``s`` holds ``s`` hull coefficients, the chord weight, then the error coefficients
    (see :func:`reach.sets.star.chord_hull`)."""
    contribution = np.abs(H @ seg.basis) * seg.box.radius                # (rows, vars)
    ends = blocks[1:] + (seg.nvars,)
    spread = np.array([contribution[:, a:b].sum(axis=1) for a, b in zip(blocks, ends)])
    error = np.array([contribution[:, 2 * a + 1:b].sum(axis=1) if a else np.zeros(len(H))
                      for a, b in zip(blocks, ends)])
    return spread, error


def _depth(seg: Star, H, g, piece_rows: int):
    """``Star.depth`` on the piece rows, with further rows (the horizon) as hard limits."""
    hard = H[piece_rows:], g[piece_rows:]
    star = seg.intersect_halfspaces(*hard)
    return star.depth(H[:piece_rows], g[:piece_rows], tolerance=DEPTH_LP_TOLERANCE)


def _unsubsumed(jumps: list[_Jump], H_inv, g_inv) -> list[_Jump]:
    """The jumps worth firing: ``j`` is dropped when an earlier kept jump ``k`` has the same
    target and reset and ``guard_j and invariant`` implies every row of ``guard_k`` (one LP
    per row over the state space); the successors of ``j`` are then contained in those of
    ``k``, whatever the segment. A jump whose guard misses the invariant is dropped too."""
    def implies(region: HPolytope, k: _Jump) -> bool:
        return all((res := region.maximize(row)).optimal and res.value <= bound + 1e-9 * (1 + abs(bound))
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


def _global_clock(model) -> int | None:
    """A state that measures elapsed time: rate 1 in every mode, 0 initially, never reset."""
    for i in model.clocks:
        if model.initial.low[i] == 0 == model.initial.high[i] and \
                not any(i in tr.reset for tr in model.transitions):
            return i
    return None


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


# ---------------------------------------------------------------------- the back-end

_SOUNDNESS = (
    "continuous time: each cell [t, t+h] is covered by the exact convex hull of its two grid "
    "stars (shared predicate) plus the interpolation error lam(1-lam) h^2/2 M, "
    "M >= sup|x''| from {q} sub-samples per cell and the closure (I - delta^2/8 |A^2|)^-1; "
    "transitions (urgent and window) fire from segment-and-guard sets, so every switching "
    "instant is covered; invariants and guards are exact LP rows; depth LPs by HiGHS with primal "
    "feasibility tolerance {lp_tol:g} (other LPs ~1e-7); a piece of strict inequalities counts as "
    "entered at a depth above {rel:g} x max(1, |g|, |h.c|) (largest used: {tol:g}), a piece with a "
    "non-strict row as met at a depth of at least minus that; matrix exponentials in floating "
    "point (rounding not enclosed)")

_DISCRETE = ("discrete time: states checked and switched at grid points t = k*h only "
             "(Hylaa's semantics); behaviour between grid points is not covered")


class StarBackend:
    name = NAME
    varying_inputs = True           # time-varying bounded inputs: the input set per step

    def supports(self, model, prop) -> str | None:
        if getattr(prop, "kind", None) != "safety":
            return f"the star back-end checks safety properties only (got '{getattr(prop, 'kind', '?')}')"
        if not _LinearModel.of(model).linear:
            return ("nonlinear dynamics, invariants, guards or resets: generalized star sets need "
                    "affine flows (the taylor back-end covers nonlinear models)")
        if model.disturbance is not None:
            return "stochastic disturbance: the star back-end is deterministic (use fsr or montecarlo)"
        for mode in prop.modes:
            if _unsafe_pieces(prop).get(mode) is None:
                return f"nonlinear unsafe set in mode '{mode}': needs a polygonal approximation"
        return None

    def check(self, model, prop, options=None) -> Result:
        start = time.perf_counter()
        reason = self.supports(model, prop)
        if reason is not None:
            return Result(NAME, model.name, prop.id, Status.UNSUPPORTED, details={"reason": reason})
        opt = StarOptions.from_dict(options)
        explorer = _Explorer(model, prop, opt)
        status, counterexample = Status.SAFE, None
        details = {}
        try:
            explorer.run()
            if explorer.unresolved:
                raise _Stop(Status.UNKNOWN, f"{len(explorer.unresolved)} cell(s) still meet an unsafe "
                                            f"piece after refinement; no witness replayed",
                            witness=explorer.unresolved[0])
            if opt.discrete_time:
                raise _Stop(Status.UNKNOWN, "no violation at the grid points (discrete time: "
                                            "behaviour between grid points is not checked)")
        except _Stop as stop:
            status, counterexample = stop.status, stop.counterexample
            details["reason"] = stop.reason
            if stop.witness is not None:
                details["witness"] = _witness_details(explorer, stop.witness)
        except lp.LPError as failure:
            status = Status.UNKNOWN
            details["reason"] = f"LP solver failure, nothing concluded: {failure}"
        details.update(_run_details(explorer))
        LOG.info("%s / %s: %s after %d stars, %d cells, %d LPs, %d aggregates", model.name, prop.id,
                 status.value if hasattr(status, "value") else status, explorer.stats.chains,
                 explorer.stats.cells, explorer.stats.lps, explorer.stats.aggregated)
        return Result(NAME, model.name, prop.id, status, time.perf_counter() - start,
                      counterexample=counterexample, details=details)


def _run_details(explorer: _Explorer) -> dict:
    s, opt = explorer.stats, explorer.opt
    substeps = {m: f.curvature(explorer.h)[3] for m, f in explorer.flows.items()}
    soundness = _DISCRETE if opt.discrete_time else _SOUNDNESS.format(
        q=", ".join(f"{m}: {q + 1}" for m, q in substeps.items()), lp_tol=DEPTH_LP_TOLERANCE,
        rel=opt.touch_tolerance, tol=s.tolerance)
    return {"method": "generalized star sets", "semantics": soundness, "step": explorer.h,
            "touch_tolerance": {"relative": opt.touch_tolerance, "largest": s.tolerance},
            "stars": s.chains, "cells": s.cells, "refined_cells": s.refined,
            "deepest_refinement": s.deepest, "lps": s.lps, "replays": explorer.replayed,
            "jumps": s.jumps, "time_reached": s.reached, "aggregates": s.aggregated,
            "aggregated_stars": s.members, "refined_aggregates": s.deaggregated}


def _witness_details(explorer: _Explorer, w: _Witness) -> dict:
    x0, switch = explorer.initial_point(w)
    return {"mode": w.mode, "piece": w.piece, "depth": w.depth, "state": w.state[:explorer.model.n].tolist(),
            "initial_state": x0.tolist(), "switch_time": switch}


BACKEND = StarBackend()


# ---------------------------------------------------------------------- safe-abort map

def safe_abort_time(model, props, low, high, options=None) -> float:
    """The latest ``T`` such that, from every initial state in the box ``[low, high]``, every
    run that aborts in ``[lo, T]`` (``lo, hi`` the model's abort window) is proven to satisfy
    every property of ``props`` (bound safety properties); ``hi`` if all aborts are safe.

    One exploration per property with the whole window: the first segment that cannot be
    cleared after refinement bounds ``T`` by its earliest abort time (or, before any abort,
    by its earliest clock); later aborts are skipped. No replays: a value below ``hi`` means
    "not proven beyond", not "unsafe".
    """
    windows = [tr.window for tr in model.transitions if tr.window is not None]
    if not windows:
        raise ValueError(f"model '{model.name}' has no abort window to sweep")
    opt = StarOptions.from_dict({**dict(options or {}), "replay": False})
    initial = Star.from_box(_LinearModel.of(model).initial_box(low, high))
    latest = max(w[2] for w in windows)
    for prop in props:
        reason = BACKEND.supports(model, prop)
        if reason is not None:
            raise ValueError(f"{prop.id}: {reason}")
        explorer = _Explorer(model, prop, opt, initial=initial, cutoff=latest)
        explorer.run()
        latest = min(latest, explorer.cutoff)
    return float(latest)


def arc_cells(model, radius: float, count: int, start_deg: float = 180.0, end_deg: float = 270.0,
              x: str = "x", y: str = "y"):
    """Initial cells along an arc of ``radius`` (angles in degrees, counter-clockwise):
    ``count`` boxes, each the bounding box of its stretch of arc in ``(x, y)``, the other
    states as in the model's initial box. Returns ``[(low, high, angle_mid)]``."""
    ix, iy = model.index(x), model.index(y)
    edges = np.radians(np.linspace(start_deg, end_deg, count + 1))
    cells = []
    for a, b in zip(edges[:-1], edges[1:]):
        angles = np.concatenate([[a, b], [k * np.pi / 2 for k in range(-4, 9) if a < k * np.pi / 2 < b]])
        low, high = model.initial.low.copy(), model.initial.high.copy()
        low[ix], high[ix] = radius * np.cos(angles).min(), radius * np.cos(angles).max()
        low[iy], high[iy] = radius * np.sin(angles).min(), radius * np.sin(angles).max()
        cells.append((low, high, float(np.degrees((a + b) / 2))))
    return cells


def _sweep_unit(model_file: str, property_files: tuple[str, ...], property_ids, low, high, options):
    """One cell of a sweep, loading its inputs itself (picklable for any executor)."""
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties
    model = load_model(model_file)
    props = [bind(p, model) for f in property_files for p in load_properties(f)
             if property_ids is None or p.id in property_ids]
    props = [p for p in props if BACKEND.supports(model, p) is None]
    return safe_abort_time(model, props, low, high, options)


def safe_abort_map(model_file: str, property_files, cells, property_ids=None, options=None,
                   executor=None) -> list[float]:
    """:func:`safe_abort_time` for every cell ``(low, high, ...)`` of ``cells`` (e.g. from
    :func:`arc_cells`), through ``executor`` (``map_unordered(fn, arg_list)`` yielding
    ``(index, ("ok", value))``, as :mod:`reach.bench.executors`; in-process if None).
    Properties the back-end does not support are left out. Returns one time per cell."""
    args = [(str(model_file), tuple(map(str, property_files)), property_ids, cell[0], cell[1], options)
            for cell in cells]
    if executor is None:
        return [_sweep_unit(*a) for a in args]
    out = [float("nan")] * len(args)
    for index, (status, value) in executor.map_unordered(_sweep_unit, args):
        if status == "ok":
            out[index] = value
    return out
