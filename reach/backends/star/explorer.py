"""One check of one safety property: the depth-first exploration of chains, cells, jumps,
refinement and aggregation (the method is described in :mod:`reach.backends.star`)."""

from __future__ import annotations

import bisect
import itertools
import logging
import threading
import time
from dataclasses import dataclass, replace

import numpy as np

from reach import lp
from reach.backends.star.aggregation import _Aggregate, interval_hull, one_coordinate, shared_shape_hull
from reach.backends.star.fixpoint import Covered, applies, enlarged, time_invariant
from reach.backends.star.flowpipe import (ChainInputs, _block_spreads, _chain_abs_bounds, _chain_bounds, _depth,
                                          _hull_abs_bounds, _plus_box, _segment, _tightened, chunk_cells, folded)
from reach.backends.star.options import (CHATTER_JUMPS, DEPTH_LP_TOLERANCE, ERROR_RATIO, INSTANT_STEP_FRACTION, INSTANT_WIDTH,
                                         MAX_CELLS, MAX_CHAIN_BYTES, MEMORY_FRACTION, MEMORY_PERIOD, NAME,
                                         PROGRESS_SECONDS, STALL_JUMPS, TIGHT_RATIO, StarOptions)
from reach.backends.star.returns import entry_rows, rising, undone
from reach.backends.star.stops import meets, stop_pieces, stop_rows
from reach.backends.star.switching import group_pieces
from reach.backends.star.transitions import (_LinearModel, _modes_leading_to, _Piece,
                                             _unsafe_pieces, kept_rows, misses)
from reach.backends.star.witnesses import _Witness, extremal_signal, nearest_point, signal_pieces, trace
from reach.errors import InputError
from reach.memory import physical_bytes, resident_bytes
from reach.result import Status
from reach.sets import Box, Star


LOG = logging.getLogger("reach.star")

#: the first half of a bisected cell gets its own input-effect bound when that takes a grid of at
#: most this many cells (:meth:`_Explorer._half_spread`)
HALF_SPREAD_CELLS = 512

#: rows of unsafe pieces and guards per mode along which the input effect is bounded besides its
#: box (:meth:`_Explorer._input_directions`)
MAX_INPUT_DIRECTIONS = 16
#: the most parts a segment is split into by urgent guards of several rows (:meth:`_Explorer._split`)
MAX_SPLIT_PARTS = 8

#: relative size of a grid star's possible rounding (terms that cancel) beyond which a chain ends
#: UNKNOWN (:meth:`_Explorer._cancellation_guard`): a thousand times the default touch tolerance
PRECISION_LOST = 1e-6

#: seconds after which an exploration run without ``-v`` says once that it is still going
QUIET_HINT_SECONDS = 60.0

#: how an UNKNOWN for time begins (:meth:`_Explorer.out_of_time`; the finer passes name whose)
OUT_OF_TIME = "time budget of"


def budget_text(seconds: float) -> str:
    """Why an exploration stopped for time (:meth:`_Explorer.out_of_time`)."""
    return f"{OUT_OF_TIME} {seconds:.3g} s exhausted"

#: pieces of a replay's switching signal (:meth:`_Explorer._switching_signal`), at most: as many
#: as a counterexample's input signal may have (:func:`reach.backends.montecarlo.replay`)
MAX_SIGNAL_PIECES = 1_000_000
#: instants per step at which a failing cell's witness run is probed (:meth:`_Explorer._probed`)
PROBES = 64
#: probed witnesses whose replay did not violate, after which a check probes no more
PROBE_MISSES = 2
#: time-varying inputs read by resets along a witness's path whose range corners are replayed
MAX_READ_INPUTS = 3


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
    since the initial star; ``stalled`` the jumps since the earliest clock last moved on by a
    time step or more (from ``since``)."""

    entries: tuple[_Entry, ...] = ()
    blocks: tuple[int, ...] = ()
    open: tuple[bool, ...] = ()
    abort: float = np.inf          # earliest clock of the first window switch on the path
    jumps: int = 0
    stalled: int = 0
    origin: _Aggregate | None = None
    since: float = 0.0             # earliest clock when ``stalled`` was last reset
    nested: int = 0                # aggregates refined into their members along the history
    instant: bool = False          # the last jump was taken at its instant (_at_instant)

    def descend(self, entry: _Entry, block: int, can_refine: bool, clock: float,
                step: float) -> "_Path":
        """The path one jump further, entering at earliest clock ``clock``."""
        abort = min(self.abort, clock) if entry.window and self.abort == np.inf else self.abort
        moved = clock >= self.since + step
        return _Path(self.entries + (entry,), self.blocks + (block,), self.open + (can_refine,), abort,
                     self.jumps + 1, 0 if moved else self.stalled + 1, self.origin,
                     clock if moved else self.since, self.nested)

    def closed(self, refinements: int = 0) -> "_Path":
        """The same history with no cell left to bisect (its cells' frames are gone), and
        ``refinements`` more (a member of an aggregate being refined: one)."""
        return _Path(self.entries, self.blocks, (False,) * len(self.open), self.abort, self.jumps,
                     self.stalled, self.origin, self.since, self.nested + refinements)


class _Pending(dict):
    """The successors a chain collects for aggregation: per transition index, a list of
    ``(member, path)``; ``sizes[index]``: a bound of ``|x|`` per coordinate over the states
    that took it (their box bounds, no LP), for :func:`.transitions.kept_rows`."""

    def __init__(self):
        super().__init__()
        self.sizes: dict[int, np.ndarray] = {}

    def note_size(self, index: int, entered: Star):
        bound = entered.box_bound()
        size = np.maximum(np.abs(bound.low), np.abs(bound.high))
        self.sizes[index] = np.maximum(self.sizes[index], size) if index in self.sizes else size


class _Stop(Exception):
    """Abort the exploration: a replayed counterexample, or the LP budget is spent.
    ``imprecise``: undecided for want of precision, which a finer step may bring
    (:func:`.options.finer_retry`)."""

    def __init__(self, status: Status, reason: str, counterexample=None, witness=None, imprecise=False):
        super().__init__(reason)
        self.status, self.reason = status, reason
        self.counterexample, self.witness = counterexample, witness
        self.imprecise = imprecise


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
    nested: int = 0                 # the most refinements on one history (max_nested_refinements)
    rebased: int = 0                # block ends of chains with inputs (see _rebase_cells)
    memory_blocks: int = 0          # block ends of chains too long to hold (_cells_in_memory)
    instants: int = 0               # jumps taken at one instant (see _at_instant)
    returns: int = 0                # zero-dwell returns not taken (see .returns)


def _urgent_keeps(model, data, options) -> tuple[dict[str, list], dict[str, list]]:
    """``(keeps, splits)``: per mode, what a run keeps while it flows there because an urgent
    transition (no window) would otherwise have been taken.

    ``keeps``: rows ``a x <= b``. For a guard of one row ``h x <= c``, ``-h x <= -c`` (a run
    that enters with ``h x >= c`` leaves the instant ``h x = c``); for a slab, two rows
    ``h x <= c_hi`` and ``-h x <= -c_lo`` with exactly opposite (normalised) normals and
    ``c_lo <= c_hi`` (an equality when they are equal), both negations (a run that enters with
    ``h x <= c_lo`` leaves the instant ``h x = c_lo``, which lies in the slab; likewise from
    above; the simulator finds the slab crossed between grid points, :mod:`reach.model.crossing`,
    so the replays follow the cut).

    ``splits``: the other guards of several rows, ``(name, H, g)``. The states outside such a
    guard ``G = {H x <= g}`` are no convex set but a union of half-spaces ``h_i x >= g_i``; a
    run that flows in the mode is, at every instant, in the closure of one of them (it leaves
    the instant it reaches ``G``), so each segment is checked as the union of its parts in those
    half-spaces (:meth:`_Explorer._split`), except where the mode's invariant already keeps
    one of them (:func:`_invariant_keeps`). Each split guard carries its rows that no run can
    cross outside it (:func:`_barrier_rows`, on plain linear models): a chain whose entry star
    lies on such a row's far side keeps that row instead of splitting by the guard
    (:meth:`_Explorer._barriers_of`). Discrete time keeps neither (a run jumps from the
    first grid state inside the guard, which the cut would remove)."""
    if options.discrete_time:
        return {}, {}
    urgent = {tr.name for tr in model.transitions if tr.urgent and tr.window is None}
    keeps: dict[str, list] = {}
    splits: dict[str, list] = {}
    for mode, jumps in data.jumps.items():
        for jump in jumps:
            if jump is None or jump.name not in urgent:
                continue
            slab = (jump.H.shape[0] == 2 and np.array_equal(jump.H[0], -jump.H[1])
                    and jump.g[0] + jump.g[1] >= 0)
            if jump.H.shape[0] == 1 or slab:
                keeps.setdefault(mode, []).extend((-a, -b) for a, b in zip(jump.H, jump.g))
            elif jump.H.shape[0] > 1 and not _invariant_keeps(data.invariants[mode], jump):
                plain = type(data) is _LinearModel and mode not in data.timeless    # timeless: no flow to cross
                barriers = _barrier_rows(data, mode, jump) if plain else []
                splits.setdefault(mode, []).append((jump.name, jump.H, jump.g, barriers))
    return keeps, splits


#: the slope ``kappa`` of :func:`_barrier_rows`, relative to the size of the row's rate
BARRIER_SLOPE = 1e-6


def _barrier_rows(data, mode: str, jump) -> list:
    """The rows ``-h_i x <= -g_i`` (``h_i x >= g_i``, the far side of the guard row
    ``h_i x <= g_i``) of an urgent guard ``G = {H x <= g}`` of several rows that no run of
    ``mode`` can cross while it flows there, whatever its (bounded) inputs: on the face
    ``h_i x = g_i``, wherever another row ``j`` of the guard is not met (``h_j x > g_j``, so
    the state is not in ``G``), the flow enters ``h_i x > g_i`` strictly.

    Argument. Let a run start in ``K = {h_i x >= g_i}`` and flow in ``mode`` up to ``T`` (it
    leaves the instant it reaches ``G``: ``x(t)`` is outside ``G`` for ``t < T``). Were
    ``h_i x(t1) < g_i`` for some ``t1 <= T``, take ``tau`` the last instant before ``t1`` with
    ``h_i x = g_i``: ``tau < T``, so ``x(tau)`` is on the face outside ``G``, where the rate
    of ``h_i x`` is at least ``L(x) = h_i (A x + b) - |h_i B| u_r > 0`` (any input signal);
    ``L`` is continuous, so ``h_i x`` rises right after ``tau``: a contradiction. So every such
    run keeps ``h_i x >= g_i``, and the row cuts the chain as a single-row guard's keep does.

    The condition is one LP per other row ``j`` over the face cut by ``h_j x >= g_j``, the
    mode's invariant and the ranges of the constant inputs (and the clock, at least 0):
    ``min L(x) - kappa (h_j x - g_j) >= 0`` with ``kappa = BARRIER_SLOPE |h_i A| > 0`` (so
    ``L >= kappa (h_j x - g_j) > 0`` where row ``j`` is not met; a constant rate must be
    positive). The deadband's coast mode and its guard ``th >= 0.1 & w >= 0`` (``th' = w``):
    on ``th = 0.1`` with ``w < 0``, ``th`` falls, so a run that enters with ``th <= 0.1``
    keeps it. An infeasible LP (that part of the face empty: ``th <= 0.2`` in ``th >= 0.1 & w >= 0
    & th <= 0.2`` is met all over ``th = 0.1``) needs no rate; an unbounded or failed one
    proves nothing."""
    flow = data.flows[mode]
    out = []
    for i, (h, c) in enumerate(zip(jump.H, jump.g)):
        rate = h @ flow.A
        const = float(h @ flow.b)
        if flow.B is not None and flow.u_radius is not None and flow.B.size:
            const -= float(np.abs(h @ flow.B) @ flow.u_radius)
        kappa = BARRIER_SLOPE * float(np.linalg.norm(rate))
        if all(_enters_beyond(data, mode, h, c, rate, const, kappa, jump.H[j], jump.g[j])
               for j in range(jump.H.shape[0]) if j != i):
            out.append((-h, -c))
    return out


def _enters_beyond(data, mode: str, h, c: float, rate, const: float, kappa: float, hj, gj: float) -> bool:
    """Whether ``min L(x) - kappa (hj x - gj) >= 0`` (``> 0`` where ``kappa = 0``) over the face
    ``h x = c`` cut by ``hj x >= gj``, the invariant of ``mode`` and the ranges of
    :func:`_barrier_rows` (``L(x) = rate . x + const``): one LP. True when that part of the
    face is empty (the LP infeasible: no point meets its rows even to the solver's tolerance,
    so on the face row ``j`` is always met and no run is outside ``G`` there for that row);
    False when it is unbounded or fails."""
    H_inv, g_inv = data.invariants[mode]
    A_ub = np.vstack([-hj[None], H_inv]) if H_inv.shape[0] else -hj[None]
    b_ub = np.concatenate([[-gj], g_inv])
    try:
        res = lp.minimize(rate - kappa * hj, A_ub, b_ub, A_eq=h[None], b_eq=np.array([c]),
                          bounds=(data.ranges.low, data.ranges.high), tolerance=DEPTH_LP_TOLERANCE)
    except lp.LPError:
        return False
    if res.infeasible:
        return True
    if not res.optimal:
        return False
    value = res.value + const + kappa * float(gj)
    return value > 0.0 or (kappa > 0.0 and value >= 0.0)


def _invariant_keeps(invariant, jump) -> bool:
    """Whether a row of the mode's invariant (rows normalised, as the guard's) already keeps one
    of the half-spaces outside the guard: ``h x <= c`` with ``-h`` a guard row ``-h x <= -g``
    and ``c <= g`` (coast's ``th <= 0.02`` under the guard ``th >= 0.02 & w >= 0``). Every
    state of the mode's flow then lies in that half-space, and splitting by the guard would
    only repeat it."""
    H, g = invariant
    return any(np.allclose(H[i], -a, rtol=0.0, atol=1e-12) and g[i] <= -b
               for a, b in zip(jump.H, jump.g) for i in range(H.shape[0]))


class _Explorer:
    """One check of one safety property on one linear hybrid automaton."""

    def __init__(self, model, prop, options: StarOptions, initial: Star | None = None,
                 cutoff: float | None = None, data=None, linearise=None):
        """``cutoff`` switches to the safe-abort sweep: instead of a verdict, the explorer
        lowers ``cutoff`` to the earliest time from which a run may violate (an abort at or
        after it, or a violation before any abort at it) and skips everything later.
        ``data``: the automaton's matrices (default: :class:`_LinearModel`); ``linearise``: the
        chains of nonlinear modes, block by block (:class:`.linearise.Blocks`)."""
        self.model, self.prop, self.opt = model, prop, options
        self.sweep = cutoff is not None
        self.cutoff = np.inf if cutoff is None else float(cutoff)
        self.linearise = linearise
        data = _LinearModel.of(model) if data is None else data
        self.data = data
        self.n, self.clock = data.n, data.clock
        self.clock_row = np.eye(self.n)[self.clock]
        self.horizon = float(model.horizon)
        self.h = float(options.step) if options.step else self.horizon / 60.0
        if self.horizon / self.h > MAX_CELLS:
            raise InputError(f"{model.name}: horizon {self.horizon:g} / step {self.h:g} = {self.horizon / self.h:.3g} "
                             f"cells; at most {MAX_CELLS:.0e} (use a larger step)", field="options.star.step")
        self.flows, self.invariants, self.jumps = dict(data.flows), data.invariants, data.fired
        self.max_jumps = np.inf if options.max_jumps is None else options.max_jumps
        self.too_deep: str | None = None        # why a path past max_jumps was not followed
        self.stall_limit = STALL_JUMPS if data.zero_dwell else CHATTER_JUMPS
        self.aggregate_after = None if self.sweep else options.aggregate_after
        self.last_progress = self.started = time.perf_counter()
        self.hinted = False                     # the quiet run's one hint (_progress)
        self.memory_limit, self.memory_read = MEMORY_FRACTION * physical_bytes(), -np.inf
        self.memory_start = resident_bytes()    # what the process held before (earlier checks)
        self._leading: dict[str, set[str]] = {}
        self._initial_sampler = None            # a polytopic initial set's (_inside_initial)
        self._may = {tr.name for tr in model.transitions if not tr.urgent and tr.window is None}
        self._keeps, self._splits = _urgent_keeps(model, data, options)   # see _flow_invariant, _split
        self._kept: dict[str, list] = {}          # per mode, the keeps of the chains under way
        self._split_by: dict[str, list] = {}      # per mode, the splitting guards of the chains under way
        self.uncut_urgent: list[str] = []       # urgent guards an entry star reaches inside (_splits_of)
        self.barrier_guards: set[str] = set()   # urgent guards of several rows cut by a row (_barriers_of)
        self.cancel = threading.Event()         # set by the caller that stopped waiting (reach.deep)
        self.deadline = np.inf if options.max_seconds is None else time.perf_counter() + options.max_seconds
        self.replay_seconds: float | None = None        # the last replay's (a finer one's cost scales with it)
        self.pieces = {mode: [_Piece(data.widen(p.H, p.g)[0], p.g, p.strict, p.label) for p in pieces]
                       for mode, pieces in _unsafe_pieces(prop).items()} if data.added_clock \
            else _unsafe_pieces(prop)
        self.pieces = self._reachable_pieces(group_pieces(self.pieces, getattr(data, "groups", ())))
        self.covered = Covered(self.clock, time_invariant(model)) if applies(model) and not options.keep_sets \
            else None
        self.stops = stop_rows(model, data.widen)           # see _note_stops
        self._stop_pieces: dict[int, list] = {}             # per face, its parts (found on first use)
        self.stopped: dict[tuple[str, str], float] = {}
        self.relevant = _modes_leading_to(model, set(self.pieces))
        self.horizon = min(self.horizon, max(self._last_unsafe_instant(), 0.0))
        self._guard_rows: dict[str, np.ndarray] = {}       # per mode, see _transient
        self._timer_rows: dict[str, list] = {}              # per mode, see _timers
        self._directions: dict[str, np.ndarray | None] = {}     # per mode, see _input_directions
        self._sources = {}                                  # jump name -> (mode, jump), see _returns
        for source, jumps in self.jumps.items():
            for jump in jumps:
                self._sources.setdefault(jump.name, []).append((source, jump))
        self.stats = _Stats()
        self.unresolved: list[_Witness] = []
        self.finer_replays = 0          # replays allowed beyond max_replays (replay_finer)
        self.probe_misses = 0           # probed witnesses that did not violate (_probed)
        self.replayed: list = []
        self.sets: list = []            # SetPiece of every explored segment (option keep_sets)
        self.root = initial if initial is not None else data.initial_star(model.initial)
        self.root_mode = model.initial.mode

    def _last_unsafe_instant(self) -> float:
        """The latest clock value any unsafe piece allows: the least upper bound its rows that
        read the model's clock alone give (``t <= 0.3``), pushed out by a relative 1e-9 against
        rounding; ``inf`` where a piece has none, or the clock is the check's own (no property
        reads it). No run violates after it, so the exploration stops there: a property about
        the first 0.3 s of a 10 s horizon costs 0.3 s of flow, at the step the horizon gives."""
        if self.data.added_clock:
            return np.inf
        latest = -np.inf
        for pieces in self.pieces.values():
            for piece in pieces or [None]:
                if piece is None:
                    return np.inf
                only_clock = (piece.H[:, self.clock] > 0) & one_coordinate(piece.H)
                if not only_clock.any():
                    return np.inf
                bound = float(np.min(piece.g[only_clock] / piece.H[only_clock, self.clock]))
                latest = max(latest, bound + 1e-9 * (1.0 + abs(bound)))
        return latest if latest > -np.inf else np.inf      # (no piece: nothing to cut by)

    def _reachable_pieces(self, pieces: dict) -> dict:
        """``pieces`` without those that miss their mode's invariant (:func:`.transitions.misses`),
        and without the modes left with none: every set a check meets a piece with -- segment,
        entry star, instant -- is cut by the invariant, so such a piece is never met (its depth
        LP, on stars of many coefficients, would only say so at a cost)."""
        out = {}
        for mode, listed in pieces.items():
            kept = [p for p in listed if not misses(p, *self.invariants[mode], self.opt.touch_tolerance)]
            if kept or not listed:
                out[mode] = kept
        return out

    # ---- LPs

    def _leading_to(self, mode: str) -> set[str]:
        """The modes from which ``mode`` can be reached (cached)."""
        if mode not in self._leading:
            self._leading[mode] = _modes_leading_to(self.model, {mode})
        return self._leading[mode]

    def _lp_budget(self):
        self._lp_count(1)

    def _lp_count(self, count: int):
        self._interrupted()
        self._progress()
        self.stats.lps += count
        if self.stats.lps > self.opt.max_lps:
            raise _Stop(Status.UNKNOWN, f"LP budget of {self.opt.max_lps} exhausted", imprecise=True)

    def _feasible(self, star: Star):
        """Coefficients of a point of ``star`` (an LP), or None if it is empty."""
        self._lp_budget()
        return star.feasible_alpha()

    # ---- exploration

    def _earliest(self, star: Star) -> float:
        """A lower bound of the clock over ``star`` (its coefficient box, no LP)."""
        return -star.support_bounds(-self.clock_row)[0]

    def _start(self, star: Star, guess, direction=None) -> tuple[Star | None, np.ndarray | None]:
        """``(star, point)`` for a star about to be explored: ``star`` with its coefficient box
        shrunk by bound propagation over all its predicate rows (:func:`.flowpipe._tightened`;
        the same set, and cheaper support bounds for everything after), and the coefficients
        of a point of it: ``guess``, or the middle of the stretch of ``guess + s direction``
        (``0 <= s <= 1``) inside the predicate, without an LP if possible; else an LP's point.
        ``(None, None)`` if ``star`` is empty: bound propagation proves most empty successors
        so, without the LP."""
        tight = _tightened(star, star.predicate.A.shape[0])
        if tight is None:
            return None, None
        if guess is not None:
            if direction is not None:
                A, b = tight.predicate.A, tight.predicate.b
                slope, room = A @ direction, b - A @ guess
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = room / slope
                lo = max(0.0, np.max(ratio[slope < 0], initial=-np.inf))
                hi = min(1.0, np.min(ratio[slope > 0], initial=np.inf))
                guess = guess + (lo + hi) / 2 * direction if lo <= hi else guess
            if tight.box.contains(guess, 1e-12) and tight.predicate.contains(guess):
                return tight, guess
        point = self._feasible(tight)
        return (tight, point) if point is not None else (None, None)

    def run(self):
        with lp.deadline(self.deadline):
            start = self.root.intersect_halfspaces(*self.invariants[self.root_mode])
            self._chain(self.root_mode, start, _Path(), self.root.box.center)

    def _chain(self, mode: str, star: Star, path: _Path, guess=None, direction=None):
        """Explore ``star`` in ``mode`` up to the horizon (:meth:`_flow_chain`); in a mode with a
        nonlinear flow block by block, each with its own linearisation (``linearise``)."""
        if self.linearise is not None and mode in self.linearise.curved:
            self.linearise.chain(self, mode, star, path, guess, direction)
            return
        barriers = self._barriers_of(mode, star)
        self._kept.setdefault(mode, []).append(self._keeps_of(mode, star, barriers))
        self._split_by.setdefault(mode, []).append(self._splits_of(mode, star, barriers))
        try:
            self._chain_blocks(mode, star, path, guess, direction)
        finally:
            self._kept[mode].pop()
            self._split_by[mode].pop()

    def _barriers_of(self, mode: str, star: Star) -> dict[str, list]:
        """Per urgent guard of several rows, its rows of :func:`_barrier_rows` that every state
        of the entry ``star`` meets (as :meth:`_keeps_of`): every run from ``star`` keeps them
        while it flows in ``mode``, so they cut its chain and the guard needs no split."""
        out: dict[str, list] = {}
        if mode in self.data.timeless or not star.box.bounded:
            return out
        for name, _, _, barriers in self._splits.get(mode, ()):
            rows = [(a, b) for a, b in barriers if _meets_row(star, a, b)]
            if rows:
                out[name] = rows
                self.barrier_guards.add(f"{name} (from {mode})")
        return out

    def _keeps_of(self, mode: str, star: Star, barriers: dict | None = None):
        """``(H, g)``: the invariant of ``mode`` and the rows ``a x <= b`` of :func:`_urgent_keeps`
        that every state of the entry ``star`` meets (its depth into ``a x >= b`` at most 0, a
        weak-duality bound: no state is strictly inside the urgent guard, so none leaves at
        once). Every run from ``star`` then meets them as long as it stays in ``mode``: it
        leaves the instant it reaches the guard. ``barriers``: rows of guards of several rows
        (:meth:`_barriers_of`), kept likewise."""
        Hi, gi = self.invariants[mode]
        rows = [(a, b) for a, b in self._keeps.get(mode, ()) if star.box.bounded and _meets_row(star, a, b)]
        rows += [row for kept in (barriers or {}).values() for row in kept]
        if not rows:
            return Hi, gi
        return np.vstack([Hi] + [a[None] for a, _ in rows]), np.concatenate([gi, [b for _, b in rows]])

    def _splits_of(self, mode: str, star: Star, barriers: dict | None = None) -> list:
        """The guards of :func:`_urgent_keeps`'s ``splits`` whose interior the entry ``star``
        does not reach (its depth into ``G`` at most 0, a weak-duality bound), as lists of the
        rows ``-h_i x <= -g_i`` one of which each run meets while it stays in ``mode``. A
        guard the entry reaches inside (those runs leave at once) is not used for the chain;
        an undecided answer names it."""
        out = []
        if mode in self.data.timeless:          # one instant: no flow to split
            return out
        for name, H, g, _ in self._splits.get(mode, ()):
            if barriers and name in barriers:       # a kept row: every run is on its side
                continue
            outside = np.any(-star.support_bounds(-H) >= g)        # wholly on one row's far side
            if star.box.bounded and (outside or star.depth(H, g)[0] <= 0.0):
                out.append([(-a, -b) for a, b in zip(H, g)])
            elif f"{name} (from {mode})" not in self.uncut_urgent:
                self.uncut_urgent.append(f"{name} (from {mode})")
        return out

    def _split(self, mode: str, seg: Star) -> list[Star]:
        """The parts of a segment that hold the runs still flowing in ``mode``: for each guard of
        :meth:`_splits_of` the segment meets one of its half-spaces ``h_i x >= g_i``, so the
        segment's runs lie in the union of the parts cut by one half-space per guard (at most
        :data:`MAX_SPLIT_PARTS` combinations; the guards beyond are left out, which only adds
        states). A half-space the segment lies in whole makes its guard no cut; one the
        segment misses (its support bound) is dropped; a part bound propagation proves
        empty is dropped. The parts overlap; each is checked and jumps on its own."""
        splits = self._split_by.get(mode)
        if not splits or not splits[-1]:
            return [seg]
        parts = [seg]
        for rows in splits[-1]:
            A = np.array([a for a, _ in rows])
            b = np.array([c for _, c in rows])
            if np.any(seg.support_bounds(A) <= b):           # the segment lies in one whole
                continue
            met = -seg.support_bounds(-A) <= b               # half-spaces the segment may meet
            if len(parts) * int(np.count_nonzero(met)) > MAX_SPLIT_PARTS:
                continue
            parts = [cut for part in parts for i in np.flatnonzero(met)
                     if (cut := _tightened(part.intersect_halfspaces(A[i][None], b[i:i + 1]), 1)) is not None]
        return parts

    def _flow_invariant(self, mode: str):
        """``(H, g)`` that cut the grid stars and segments of the chain under way in ``mode``:
        :meth:`_keeps_of` its entry star (not the entry star itself, whose states inside a
        guard jump at once)."""
        kept = self._kept.get(mode)
        return kept[-1] if kept else self.invariants[mode]

    def _chain_blocks(self, mode: str, star: Star, path: _Path, guess=None, direction=None):
        """:meth:`_chain` of a mode with a linear flow."""
        cells = self._rebase_cells(mode)
        fit = self._cells_in_memory(mode, star)
        if cells is None and fit is None:
            self._flow_chain(mode, star, path, guess, direction)
            return
        pending = _Pending()
        inherited = None
        while star is not None:
            block = min(c for c in (cells, fit) if c is not None) if (cells or fit) else None
            handed = self._flow_chain(mode, star, path, guess, direction, block, pending, inherited)
            if handed is None:
                break
            star, guess, inherited = handed
            star = _tightened(star, len(self.invariants[mode][1])) or star
            direction = None
            if cells is None:
                self.stats.memory_blocks += 1
            else:
                self.stats.rebased += 1
            if self.covered is not None and self.covered.covers(mode, star, self._lp_count):
                break
            if 4 * star.nvars > self.opt.max_coefficients:     # the rest of the chain in one piece,
                cells = None                                   # its segments still within the limit
            fit = self._cells_in_memory(mode, star)
        self._aggregate_pending(mode, pending)

    def _cells_in_memory(self, mode: str, star: Star) -> int | None:
        """Cells per block of a chain too long to hold at once, or None where it fits.

        A chain keeps the centre and basis of each of its grid stars, ``(count + 1) n (m + 1)``
        numbers (three such arrays while they are built); a large model over many steps
        (ISS: 270 states and coefficients, 2000 steps, 3.6 GB) exceeds
        :data:`.options.MAX_CHAIN_BYTES`. Without inputs, it is then explored in blocks of cells
        that fit, each starting from the grid star that ends the block before (cut by the
        invariant): the same stars, with the same coefficients, as one chain's
        (:meth:`_chain`), and the rounding carried from block to block
        (:meth:`_cancellation_guard`)."""
        flow = self.flows[mode]
        if flow.inputs or self.opt.discrete_time or mode in self.data.timeless:
            return None
        count = max(1, int(np.ceil((self.horizon - self._earliest(star)) / self.h - 1e-9)))
        if (count + 1) * self._grid_bytes(star.nvars) <= MAX_CHAIN_BYTES:
            return None
        return max(1, MAX_CHAIN_BYTES // self._grid_bytes(star.nvars) - 1)

    def _grid_bytes(self, nvars: int) -> int:
        """Bytes a chain holds per grid star of ``nvars`` coefficients while it is built:
        three arrays of centre and basis, ``n (nvars + 1)`` numbers each."""
        return 8 * 3 * self.n * (nvars + 1)

    def _aggregate_pending(self, mode: str, pending: _Pending | None):
        """Aggregate the successors a chain in ``mode`` collected, per transition, cut by the
        rows of :func:`.transitions.kept_rows` from the rows the chain's segments were cut by
        (:meth:`_flow_invariant`: every run that jumps meets them)."""
        Hi, gi = self._flow_invariant(mode)
        for index, members in (pending or {}).items():
            jump = self.jumps[mode][index]
            rows = kept_rows(jump, Hi, gi, self._inputs_read(jump), self.opt.touch_tolerance,
                             pending.sizes.get(index))
            self._aggregate(jump.target, members, rows)

    def _rebase_cells(self, mode: str) -> int | None:
        """Cells per block of a chain whose input effect restarts at each block end, or None.

        The input effect ``R_j`` of :meth:`.flowpipe.AffineFlow.deviation` is a box that grows
        with the time since the chain's start, and the invariant can only cut the input-free
        runs, relaxed by ``|H| R_j`` (:meth:`_flow_chain`). In a mode whose invariant reads the
        states an input moves, the runs that left the invariant long ago then stay in the box.
        Such a chain is explored ``rebase_cells`` cells at a time (:meth:`_chain`): the next
        block starts from the block's end star (its grid star plus ``R``, new coefficients, cut
        by the exact invariant) with ``R = 0``. Every run still in the mode at the block end is
        in that star, so the blocks cover what one chain would, and the invariant now cuts the
        runs themselves. The star gains a coefficient per moved state and block. Where the
        fixpoint check is on, a block end whose states lie in an earlier aggregate of the mode
        ends the chain (its runs are time-shifted runs of that aggregate's). The successors of
        all blocks are aggregated together, as one chain's are. Once the star holds a quarter of
        ``max_coefficients``, the rest of the chain is explored in one piece."""
        flow = self.flows[mode]
        if not self.opt.rebase_cells or not flow.inputs or flow.drift or self.opt.discrete_time:
            return None
        Hi = self.invariants[mode][0]
        moved = np.abs(Hi) @ flow.deviation(self.h, 1)[1] > 0
        return self.opt.rebase_cells if np.any(moved) else None

    def _flow_chain(self, mode: str, star: Star, path: _Path, guess=None, direction=None,
                    block: int | None = None, collect: dict | None = None, inherited=None):
        """Explore ``star`` in ``mode`` up to the horizon: checks, jumps, refinement.

        ``guess`` (and ``direction``): where a point of ``star`` may be (see :meth:`_start`).
        The run of a known point proves the chain non-empty for as long as it stays inside
        the invariant, without LPs. ``block``: stop after this many cells and return
        ``(star, point)``, the star every run still in the mode is in at that time (the grid
        star plus its input effect, in the invariant) and a point guess for it; None if the
        chain ended before (or went to the horizon). ``collect``: where the successors to be
        aggregated are gathered, for the caller to aggregate (None: aggregated here).
        ``inherited``: a bound of the rounding ``star`` already carries (a block's start is the
        end of the block before, :meth:`_cancellation_guard`); with ``block`` the handed star
        comes with its own, ``(star, point, inherited)``.
        """
        if mode not in self.relevant:
            return
        self._memory_guard()
        star, point = self._start(star, guess, direction)
        if star is None:
            return
        if path.jumps > self.max_jumps:         # not followed; the other paths still are (a
            self.too_deep = (f"more than {self.max_jumps} discrete jumps on a path "    # violation
                             f"(option max_jumps; a SpaceEx cfg's iter-max sets it)")  # within them
            return                                                                      # is UNSAFE)
        if path.stalled > self.stall_limit:
            cause = "possible zero-dwell cycle" if self.data.zero_dwell else "switching faster than the step resolves"
            raise _Stop(Status.UNKNOWN, f"{path.stalled} jumps within one time step ({cause})", imprecise=True)
        t0 = self._earliest(star)
        if t0 > self.horizon:                   # every run of the star is past the horizon
            return
        self.stats.chains += 1
        if self.stats.chains > self.opt.max_stars:
            raise _Stop(Status.UNKNOWN, f"star budget of {self.opt.max_stars} exhausted "
                                        f"(option max_stars)", imprecise=True)
        if mode in self.data.timeless:
            self._instant(mode, star, path, point)
            return
        flow, h = self.flows[mode], self.h
        count = max(1, int(np.ceil((self.horizon - t0) / h - 1e-9)))
        handoff = block is not None and block < count
        count = block if handoff else count
        input_cells = self.opt.input_cells or int(block is not None and self.opt.rebase_generators)
        nvars = star.nvars + (ChainInputs.generators(flow, count, input_cells) if flow.inputs else 0)
        segment_vars = nvars if flow.drift else 2 * nvars + 1 + self.n
        if segment_vars > self.opt.max_coefficients or \
                (count + 1) * self._grid_bytes(nvars) > MAX_CHAIN_BYTES:
            raise _Stop(Status.UNKNOWN, f"a segment in mode '{mode}' needs {segment_vars} coefficients "
                                        f"over {count} steps (limits: option max_coefficients = "
                                        f"{self.opt.max_coefficients}, {MAX_CHAIN_BYTES >> 20} MiB per "
                                        f"chain); aggregate sooner (option aggregate_after)")
        self.stats.jumps = max(self.stats.jumps, path.jumps)
        self.stats.reached = max(self.stats.reached, t0)
        self._progress()
        Phis, psis = flow.powers(h, count)
        inputs = ChainInputs(flow, h, count, input_cells, self._input_directions(mode)) if flow.inputs else None
        if inputs is not None and inputs.count:                  # the blocks' generators
            star = inputs.extend(star)
            point = np.concatenate([point, np.zeros(inputs.count)])   # input at its centre
        dev = None if inputs is None else inputs.grid             # the box left per grid point
        centers = star.center @ np.swapaxes(Phis, 1, 2) + psis
        bases = np.matmul(Phis, star.basis)
        carried = self._cancellation_guard(mode, star, Phis, psis, centers, bases, inherited)
        if inputs is not None and inputs.count:
            bases[:, :, -inputs.count:] += inputs.columns
        box = star.box
        Hi, gi = self._flow_invariant(mode)

        # invariant: the first grid star entirely outside ends the chain; rows that are not
        # implied by the coefficient box join the predicate exactly, step by step. With
        # inputs the grid stars hold the runs up to the box ``dev_j`` (:class:`ChainInputs`):
        # the rows are relaxed by |H| dev_j (every run inside the invariant satisfies them)
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
        steps = sorted(extra)
        predicates = [star.predicate]   # predicates[k]: with the rows of grid points steps[:k]

        def grid_star(j: int) -> Star:
            # the rows of grid point i read the state at t_i, c_i + V_i a (not at t_j): every
            # run still in the mode at t_j met the invariant at every earlier grid point
            if j not in stars:
                k = bisect.bisect_right(steps, j)
                while len(predicates) <= k:
                    i = steps[len(predicates) - 1]
                    at_i = Star(centers[i], bases[i], predicates[-1], box).intersect_halfspaces(*extra[i])
                    predicates.append(at_i.predicate)
                stars[j] = Star(centers[j], bases[j], predicates[k], box)
            return stars[j]

        for j in sorted(extra):                  # `point` stays a point of every grid star
            if j > last or (j == last and known_empty):
                break
            self._interrupted()
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

        # cheap screening, vectorised over the chain: the interpolation error from the grid
        # stars' interval hulls first, the exact one (:func:`_chain_abs_bounds`) for the cells
        # that do not pass with it (all of them when the sets are kept for a picture)
        # (lazily where a chunk of them costs much: :data:`.flowpipe.PRODUCT_BYTES` per chunk,
        # computed when the exploration reaches it, so a violation found early spares the rest)
        curvature = None                        # the cells' interpolation errors, where exact
        later, chunk = [], 0                    # cells whose exact error waits, and per chunk
        lowers: dict = {}                       # the grid stars' support bounds, per row set
        if self.opt.discrete_time:
            error = np.zeros((last + 1, self.n)) if dev is None else dev[:last + 1].copy()
            candidates, fanout = self._screen_chain(mode, centers, bases, box, error, cells, lowers)
        else:
            D, d, F, _ = flow.curvature(h)
            spread = 0.0 if inputs is None else inputs.cell[:last]        # the whole cell
            exact = list(cells) if self.opt.keep_sets else None

            def exact_error(js):
                return h * h / 8 * _chain_abs_bounds(centers[js], bases[js], box, D, d, self._guards).max(axis=1) @ F.T

            if exact is None:
                loose = h * h / 8 * _hull_abs_bounds(centers[:last], bases[:last], box, D, d).max(axis=1) @ F.T
                candidates, fanout = self._screen_chain(mode, centers, bases, box, loose + spread, cells, lowers)
                exact = sorted(candidates)
                chunk = chunk_cells(D, bases.shape[1], bases.shape[2])
                # the exact errors only lower the fanout: lazily where it cannot make the chain wide
                if len(exact) > chunk and np.all(np.isfinite(box.radius)) and not (flow.drift and inputs is None) \
                        and (self.opt.aggregate_fanout is None or fanout <= self.opt.aggregate_fanout):
                    exact, later = exact[:chunk], exact[chunk:]
            curvature = np.zeros((last, self.n)) if exact == list(cells) else loose
            if exact:
                curvature[exact] = exact_error(exact)
                candidates, fanout = self._screen_chain(mode, centers, bases, box, curvature + spread, cells, lowers)
            error = curvature + spread
            if not np.all(np.isfinite(box.radius)):     # the cells bound their errors by LPs
                curvature = None
        if self.opt.keep_sets:
            self._keep_chain(mode, grid_star, centers, bases, error, [j for j in cells if j not in candidates])

        drift_limit = None if self.sweep else self.opt.aggregate_drift_coefficients
        merged = flow.drift and inputs is None and not self.opt.discrete_time    # (_consecutive)
        wide = self.opt.aggregate_fanout is not None and fanout > self.opt.aggregate_fanout and not merged
        shifts = self.covered is not None and self.covered.shift
        aggregate = (self.aggregate_after is not None and (not flow.drift or flow.inputs or shifts)
                     and (path.jumps >= self.aggregate_after or wide)) or \
                    (self.aggregate_after is not None and flow.drift and drift_limit is not None
                     and star.nvars > drift_limit)
        pending: _Pending | None = None if not aggregate else _Pending() if collect is None else collect
        runs = _consecutive(sorted(candidates)) if merged else [(j, 1) for j in sorted(candidates)]
        returns = self._returns(mode, star, path) if inherited is None and 0 in candidates else ()
        while runs:
            j, length = runs.pop(0)
            if later and j >= later[0]:         # the next chunk's exact errors, then its cells again
                block, later = later[:chunk], later[chunk:]
                curvature[block] = exact_error(block)
                error[block] = curvature[block] + (spread if np.isscalar(spread) else spread[block])
                kept, _ = self._screen_chain(mode, centers, bases, box, error, block, lowers)
                runs = [(k, 1) for k in sorted({j, *(k for k, _ in runs)} - (set(block) - kept))]
                continue
            known = None if curvature is None or length > 1 else curvature[j]
            first = returns if j == 0 else ()
            if inputs is None:
                self._cell(mode, grid_star(j), length * h, path, 0, point, pending, error=known, returns=first)
            elif self.opt.discrete_time:
                self._cell(mode, grid_star(j), h, path, 0, point, pending, dev[j])
            else:
                self._cell(mode, grid_star(j), h, path, 0, point, pending, inputs.cell[j],
                           inputs.since[j], inputs.carried[j],
                           None if inputs.directed is None else (inputs.directed[0], inputs.directed[1][j]),
                           error=known, returns=first)
        if mode in self.stops and not self.opt.discrete_time:
            self._note_stops(mode, grid_star, centers, bases, box, error, dev, cells,
                             None if curvature is None else curvature, inputs)
        if collect is None:
            self._aggregate_pending(mode, pending)
        if handoff and ended_inside:
            end = grid_star(count) if dev is None else _plus_box(grid_star(count), dev[count])
            return (end.intersect_halfspaces(Hi, gi), np.concatenate([point, np.zeros(end.nvars - point.size)]),
                    carried[count])
        return None

    def _cancellation_guard(self, mode: str, star: Star, Phis, psis, centers, bases, inherited=None):
        """UNKNOWN where rounding may move the grid stars by more than the touch tolerance.

        A grid star is ``Phi_j c + psi_j + Phi_j V a``, each product rounded to about
        ``(n + 2) eps`` of the magnitudes it sums, and ``Phi_j`` from ``j`` products (its
        exponential taken as computed). Where those magnitudes,
        ``|Phi_j| (|c| + |V| |a|) + |psi_j|``, times ``8 (n + 2)(j + 1) eps`` exceed
        :data:`PRECISION_LOST` of the star's own size, terms cancel that rounding cannot be
        trusted with (an unstable mode run from its equilibrium: ``e^{A t} c`` and ``psi`` of
        1e15 summing to 1), and no verdict rests on such stars. Below it, rounding is within a
        thousand touch tolerances, as the semantics state (exponentials not enclosed).

        A chain explored block by block (a linearisation, a switching group, rebased inputs)
        starts each block from the end of the one before, whose rounding the block carries on:
        ``inherited = (v, s)`` bounds that error componentwise (``|e| <= v``) and in Euclidean
        norm (``||e|| <= s``); the error moves with the flow, so at grid point ``j`` it is within
        ``min(|Phi_j| v, ||Phi_j||_2 s)`` per component: the first stays linear under a shear
        (``[[1, h], [0, 1]]``, whose norm compounds), the second stays put under a rotation
        (whose ``|Phi|`` row sums compound). Both bounds, with the block's own rounding added,
        are returned per grid point for the next block. Without it, an unstable equilibrium
        explored in blocks of two cells drifts by ``1e-16 e^t`` unnoticed (x' = x - 1 from
        x = 1: 0.16 at t = 35, a wrong SAFE)."""
        a = np.maximum(np.abs(star.box.low), np.abs(star.box.high))
        a = np.where(np.isfinite(a), a, 0.0)
        summed = np.abs(Phis) @ (np.abs(star.center) + np.abs(star.basis) @ a) + np.abs(psis)
        size = np.abs(centers) + np.abs(bases) @ a
        steps = np.arange(1, len(Phis) + 1)[:, None]
        fresh = 8 * (self.n + 2) * steps * np.finfo(float).eps * summed
        grown, norms = np.zeros_like(fresh), np.zeros(len(Phis))
        if inherited is not None:
            vector, norm = inherited
            norms = np.linalg.norm(Phis, 2, axis=(1, 2)) * norm
            grown = np.minimum(np.abs(Phis) @ vector, norms[:, None])
        rounding = fresh + grown
        lost = np.any(rounding > PRECISION_LOST * np.maximum(1.0, size), axis=1)
        if np.any(lost):
            j = int(np.argmax(lost))
            raise _Stop(Status.UNKNOWN, f"precision lost in mode '{mode}': at step {j} the flow's terms "
                                        f"(size {summed[j].max():.3g}) cancel to {size[j].max():.3g} with a "
                                        f"rounding bound of {rounding[j].max():.3g}"
                                        + (" (most of it carried from earlier blocks)"
                                           if np.any(grown[j] > fresh[j]) else "")
                                        + ", beyond what rounding can be trusted with (an unstable mode "
                                          "near its equilibrium; a shorter horizon helps)")
        carried = np.minimum(np.linalg.norm(fresh, axis=1) + norms, np.linalg.norm(rounding, axis=1))
        return [(rounding[j], carried[j]) for j in range(len(Phis))]

    def _past_cutoff(self, start: Star, path: _Path) -> bool:
        """In the safe-abort sweep: whether every run from ``start`` aborted, or (without an
        abort on its path) is, at or after the cutoff (nothing later needs a check)."""
        if not self.sweep:
            return False
        since = path.abort if path.abort < np.inf else self._earliest(start)
        return since >= self.cutoff

    def _instant(self, mode: str, star: Star, path: _Path, point):
        """Explore ``star`` in a mode where no time passes (``flow false``): the star itself is
        everything the mode holds, checked once, and its jumps fire from it at once.

        Why this covers the mode: every state keeps its value there (rate 0) and only the
        explored clock, which the model added and no guard, invariant, reset or property
        mentions, could advance. A run that waited would leave with the same state later, and
        the automaton does not depend on that clock, so all it could do after is a time-shifted
        part of what the run that jumped at once does, cut earlier by the horizon. The instant
        owns no coefficients: it can neither be bisected nor blamed."""
        if self._past_cutoff(star, path):
            return
        self.stats.cells += 1
        block = star.nvars
        if self.opt.keep_sets:
            self._keep(mode, (star,))
        self._check_segment(mode, star, path, block, False)
        self._jump_from(mode, star, path, block, False, point)

    def _keep_chain(self, mode: str, grid_star, centers, bases, error, cells):
        """The screened-out cells of a chain as set pieces (option ``keep_sets``; the others are
        kept by :meth:`_cell` at their final refinement). Segment ``j`` is the hull of grid star
        ``j`` and grid star ``j + 1`` under the predicate of ``j`` (every run still in the mode
        at ``t_j`` satisfies the invariant rows known up to ``t_j``), plus the box ``error_j``:
        the bound the screening itself rests on (:meth:`_screen`). In discrete time the pieces
        are the grid stars plus their input spread."""
        for j in cells:
            first = grid_star(j)
            stars = (first,) if self.opt.discrete_time else (
                first, Star(centers[j + 1], bases[j + 1], first.predicate, first.box))
            self._keep(mode, stars, error[j])

    def _keep(self, mode: str, stars, bloat=None):
        """One set piece: the hull of ``stars`` plus the box ``bloat``, dated by its clock."""
        from reach.result import SetPiece

        names = tuple(self.model.state) + (("time",) if self.data.added_clock else ())
        clock = self.clock_row[None]
        t0 = min(-float(s.support_bounds(-clock)[0]) for s in stars)
        t1 = max(float(s.support_bounds(clock)[0]) for s in stars)
        self.sets.append(SetPiece(mode, t0, t1, "star", names, tuple(stars),
                                  None if bloat is None else np.asarray(bloat, float)))

    def _touch(self, g, bound):
        """The touch allowance of rows ``... <= g`` whose bound is ``bound``:
        ``touch_tolerance * max(1, |g|, |bound|)``, as the depth LP reads a touch."""
        return self.opt.touch_tolerance * np.maximum(1.0, np.maximum(np.abs(g), np.abs(bound)))

    def _at_horizon(self, seg: Star) -> bool:
        """Whether ``seg`` reaches the horizon up to the touch tolerance (the chain's last cell)."""
        latest = float(seg.support_bounds(self.clock_row[None])[0])
        return latest >= self.horizon - self._touch(self.horizon, latest)

    def _interrupted(self):
        """UNKNOWN at once when the caller has been interrupted (``cancel``, :mod:`reach.deep`)
        or the time budget is spent; checked at every chain, cell, LP and invariant step, so a
        time limit ends the search within one LP."""
        if self.cancel.is_set():
            raise _Stop(Status.UNKNOWN, "stopped: the caller was interrupted")
        reason = self.out_of_time()
        if reason is not None:
            raise _Stop(Status.UNKNOWN, reason)

    def out_of_time(self) -> str | None:
        """Why the search must stop for time (option ``max_seconds``, or the finer passes' share
        of the time, see :func:`reach.backends.star.finer_retry`), or None while it may go on."""
        if time.perf_counter() > self.deadline:
            return budget_text(self.opt.max_seconds)
        return None

    def _memory_guard(self):
        """UNKNOWN once the exploration holds more than ``MEMORY_FRACTION`` of the memory the
        process may hold (:func:`reach.memory.physical_bytes`: the machine's, or a cgroup's or
        address-space limit) beyond what the process held when it started (a bench worker keeps the memory of
        its earlier checks; the stars' predicates grow with jumps and refinement; no
        out-of-memory kill); stops at
        once when the caller has been interrupted (``cancel``) or the time budget is spent."""
        self._interrupted()
        now = time.perf_counter()
        if now - self.memory_read < MEMORY_PERIOD:
            return
        self.memory_read, held = now, resident_bytes() - self.memory_start
        if held > self.memory_limit:
            raise _Stop(Status.UNKNOWN, f"memory: the exploration holds {held / 2**30:.1f} GiB, more than "
                                        f"{MEMORY_FRACTION:.0%} of the "
                                        f"{self.memory_limit / MEMORY_FRACTION / 2**30:.0f} GiB this process may hold "
                                        f"(coarser step, fewer coefficients or sooner aggregation)")

    def _guards(self):
        """The memory and time guards, and a progress line when one is due (long computations
        on one chain call it between their parts)."""
        self._memory_guard()
        self._progress()

    def _progress(self):
        """Progress under ``-v`` every :data:`.options.PROGRESS_SECONDS`; without it, one
        line after :data:`QUIET_HINT_SECONDS`, so a long exploration does not look like a hang."""
        now = time.perf_counter()
        if not self.hinted and now - self.started >= QUIET_HINT_SECONDS and not LOG.isEnabledFor(logging.INFO):
            self.hinted = True
            LOG.warning("star: still exploring after %.0f s (time %.6g of %.6g reached, %d stars); -v shows "
                        "progress, -o max_seconds=S bounds the time", now - self.started, self.stats.reached,
                        self.horizon, self.stats.chains)
        if now - self.last_progress >= PROGRESS_SECONDS:
            self.last_progress = now
            s = self.stats
            LOG.info("%d stars, %d cells, %d LPs, up to %d jumps on a path, time %.6g of %.6g, "
                     "%d aggregates of %d stars (%d refined)", s.chains, s.cells, s.lps, s.jumps,
                     s.reached, self.horizon, s.aggregated, s.members, s.deaggregated)

    def _aggregate(self, mode: str, members: list[tuple[Star, _Path]], rows):
        """Explore the successor stars ``members`` entering ``mode`` as one star (successors of a
        jump at its instant that stay small: in their own shape, :meth:`_shaped`).

        ``rows``: constraints every member satisfies besides the invariant of ``mode``
        (:func:`.transitions.kept_rows`). The aggregate (:func:`.aggregation.interval_hull`,
        cut by the invariant and ``rows``) contains every member, so a SAFE
        under it covers them. When a check under it fails and its witness does not replay,
        the members are explored instead, each with its own exact history (no cell before the
        aggregation is bisected again). Where the fixpoint check is on (:mod:`.fixpoint`), an
        aggregate inside an earlier one is not explored, and the hull is first explored
        slightly enlarged (:func:`.fixpoint.enlarged`, so that later ones equal to it up to
        rounding fall inside); a failure under the enlarged hull falls back to the exact one.
        """
        if all(path.instant for _, path in members) and self._shaped(mode, members):
            return
        H, g = self.invariants[mode]
        ranges = self.data.ranges
        if self.covered is not None and not self.covered.shift:
            origins = {id(p.origin): p.origin for _, p in members}.values()     # each once
            ranges = self._clock_from(ranges, min(0.0 if a is None else a.star.box_bound().low[self.clock]
                                                  for a in origins))
        hull, kept = interval_hull(members, (np.vstack([H, rows[0]]), np.concatenate([g, rows[1]])),
                                   self._lp_count, ranges)
        if not kept:
            return
        if hull is None:                                       # unbounded: explore the members
            for star, path in kept:
                self._chain(mode, star, path.closed())
            return
        candidates = [(hull, rows)]
        if self.covered is not None:
            if self.covered.covers(mode, hull, self._lp_count, self._entered_by(kept)):
                return
            if not self.covered.shift:                         # the clock's start is exact
                ranges = self._clock_from(ranges, hull.box_bound().low[self.clock])
            candidates.insert(0, enlarged(hull, (H, g), rows, ranges))
        self.stats.aggregated += 1
        self.stats.members += len(kept)
        self._explore_joined(mode, kept, candidates)

    def _explore_joined(self, mode: str, members: list[tuple[Star, _Path]], candidates, record: bool = True,
                        base: int | None = None):
        """Explore ``members`` entering ``mode`` as one star: under each of ``candidates``
        (``(star, rows)``, each containing every member) in turn while a check under the one
        before fails without a replayed witness, then as the members themselves, each with its
        own history. ``record``: the candidates are boxes the fixpoint check records
        (:mod:`.fixpoint`). Whatever the exploration under a candidate that fails has recorded
        (the aggregates below it, itself if recorded) is forgotten: their exploration did not
        end, so they cover nothing. ``base``: the leading coefficients the candidates keep (all
        of them where None: fresh ones)."""
        start = min(path.since for _, path in members)
        jumps = max(path.jumps for _, path in members)
        stalled = max(path.stalled for _, path in members if path.since == start)   # as from ``start``
        nested = max(path.nested for _, path in members)
        kept_sets = len(self.sets)
        for k, (star, star_rows) in enumerate(candidates):
            agg = _Aggregate(mode, star, members, base=star.nvars if base is None else base)
            mark = None if self.covered is None else self.covered.mark()
            if record and self.covered is not None:         # (tagged: see .fixpoint, returns)
                entry = self._entered_by(members)
                self.covered.record(mode, star, star_rows, entry if self._undoing(mode, entry) else None)
            try:
                self._chain(mode, star, _Path(jumps=jumps, stalled=stalled, origin=agg, since=start,
                                              nested=nested), star.box.center if record else None)
                return
            except _Deaggregate as failure:
                if failure.target is not agg:
                    raise
                piece = failure.witness.piece
            # what replaces it is explored once the handler has ended (the failure's traceback
            # holds the frames of the failed exploration: see _cell)
            del self.sets[kept_sets:]               # what replaces it has its own segments
            if mark is not None:
                self.covered.forget(mark)
            if k + 1 < len(candidates):
                LOG.info("enlarged aggregate entering '%s' replaced by the exact hull (%s)", mode, piece)
                continue
            agg.refined = True
            self.stats.deaggregated += 1
            self.stats.nested = max(self.stats.nested, nested + 1)
            LOG.info("aggregate of %d stars entering '%s' refined into its members (%s; up to %d "
                     "coefficients)", len(members), mode, piece, max(m.nvars for m, _ in members))
            for member, path in members:
                self._chain(mode, member, path.closed(refinements=1))

    def _shaped(self, mode: str, members) -> bool:
        """Explore the successors of a jump taken at its instant without their interval hull,
        where that keeps them small: a lone member, or members of one shape
        (:func:`.aggregation.shared_shape_hull`: one instant met by two cells), with tiny
        coefficients folded into a box (:func:`.flowpipe.folded`; an instant jump's spread),
        at most ``2 n`` more than the star they descend from (a tick from a bisected cell
        carries its halves' chord and error coefficients). A sampled controller's tick keeps
        the start's shape so, the held control tied to the state it was computed from, which an
        interval hull would lose at every tick. The shape is that of the initial star, or of the
        interval hull the members descend from where one came between (:meth:`_base`): one
        tick that had to be hulled does not hull every later one. The star stands for the
        members as an aggregate does: a failure under it that no replay confirms is checked
        again under the members. Not recorded for the fixpoint check (that records boxes), but
        not explored where an earlier aggregate covers it. False where it does not apply."""
        keep = self._base(members)
        if keep is None:
            return False
        star = members[0][0] if len(members) == 1 else shared_shape_hull(members, keep, self._lp_count)
        if star is None:
            return False
        star = folded(star, keep)
        if star.nvars > keep + 2 * self.n:
            return False
        if self.covered is not None and self.covered.covers(mode, star, self._lp_count, self._entered_by(members)):
            return True
        if len(members) == 1 and star is members[0][0]:        # its cells' frames are gone:
            self._chain(mode, star, members[0][1].closed())   # nothing of its history to bisect
            return True
        self._explore_joined(mode, members, [(star, None)], record=False, base=keep)
        return True

    def _base(self, members) -> int | None:
        """The leading coefficients all ``members`` share (:attr:`.aggregation._Aggregate.base`
        of the aggregate they descend from, the initial star's where none), None where they
        descend from aggregates of different bases."""
        bases = {self.root.nvars if path.origin is None else path.origin.base for _, path in members}
        return bases.pop() if len(bases) == 1 else None

    def _clock_from(self, ranges: Box, start: float) -> Box:
        """``ranges`` with the clock at least ``start``.

        The fixpoint check of a model with its own clock (:mod:`.fixpoint`, not ``shift``)
        needs a later aggregate's clock to start no earlier than the aggregate it descends
        from; outward rounding would move each start down a little (1e-7 at clock 10), and
        around a cycle of modes no aggregate would ever lie in an earlier one. But time only
        runs forward: every state reached from an aggregate has a clock at least the
        aggregate's least one. So the hull of successors is clipped at the least clock of
        the aggregates its members descend from (0 for the initial star's), and an enlarged
        hull keeps its own least clock."""
        low = ranges.low.copy()
        low[self.clock] = max(low[self.clock], start)
        return Box(low, ranges.high)

    def _screen_chain(self, mode: str, centers, bases, box, error, cells, lowers) -> tuple[set[int], int]:
        """The cells among ``cells`` of a chain whose segments may meet an unsafe piece or a
        relevant guard (:meth:`_screen`), and the most of them a transition back into ``mode``
        (on a cycle of modes) may fire from. ``lowers``: the chain's support bounds per piece and
        guard, kept between calls."""
        candidates = set()
        for piece in self.pieces.get(mode, []):
            candidates |= self._screen(centers, bases, box, error, piece.H, piece.g, cells, lowers)
        fanout = 0
        for jump in self.jumps[mode]:
            if jump.target in self.relevant:
                firing = self._screen(centers, bases, box, error, jump.H, jump.g, cells, lowers)
                candidates |= firing
                if jump.target in self._leading_to(mode):
                    fanout = max(fanout, len(firing))
        return candidates, fanout

    def _screen(self, centers, bases, box, error, H, g, cells, lowers) -> set[int]:
        """Cells whose segment may meet ``{H x <= g}`` by support bounds (cheap). A cell is
        passed over only where a bound misses a row by more than the touch tolerance
        (``touch_tolerance * max(1, |g|, |bound|)``, as the depth LP reads a touch): the grid
        stars carry the rounding of thousands of products, and a run that only touches a
        closed unsafe set (``x = 1`` at the horizon against ``x < 1``) would otherwise be
        screened out by the last digits (with 2000 cells or more of the ramp ``x' = 1``)."""
        if H.shape[0] == 0:
            return set(cells)
        if id(H) not in lowers:
            lowers[id(H)] = (H, -_chain_bounds(centers, bases, box, -H))      # (J, rows)
        lower = lowers[id(H)][1]
        k = error.shape[0]
        if self.opt.discrete_time:
            seg = lower[:k] - error @ np.abs(H).T
        else:
            seg = np.minimum(lower[:-1], lower[1:])[:k] - error @ np.abs(H).T
        missed = np.any(seg > g + self._touch(g, seg), axis=1)
        return {j for j in cells if not missed[j]}

    # ---- one cell

    def _segment(self, mode: str, start: Star, h: float, spread=None, directed=None,
                 error=None) -> tuple[Star, np.ndarray]:
        """``(segment, error)`` of the cell of length ``h`` starting at ``start``; ``spread``:
        the bound of the input effect on the cell (added as a box met by the rows ``directed``,
        :func:`.flowpipe._plus_box`, then the invariant, :meth:`_flow_invariant`); ``error``:
        the interpolation error, when the chain has computed it."""
        Hi, gi = self._flow_invariant(mode)
        if self.opt.discrete_time:
            if spread is None:
                return start, np.zeros(self.n)
            return _plus_box(start, spread).intersect_halfspaces(Hi, gi), np.zeros(self.n)
        seg, _, error = _segment(self.flows[mode], start, h, error)
        if spread is not None:
            seg = _plus_box(seg, spread, directed)
        seg = seg.intersect_halfspaces(Hi, gi)
        return (_tightened(seg, len(gi)) or seg) if self.flows[mode].drift else seg, error

    def _cell(self, mode: str, start: Star, h: float, path: _Path, depth: int, point, pending=None,
              spread=None, since: float = 0.0, carried=0.0, directed=None, error=None, returns=(),
              skip=frozenset()):
        """Check one cell and launch its successors; bisect when a failure is blamed on it.

        The segment's own coefficients are the block starting at ``start.nvars``; a failure
        (here or in a successor) names the block that contributes most to it, and only
        the cell owning that block is bisected. ``point``: coefficients of a point of
        ``start`` (passed on as a guess to successors). ``pending``: where successors to be
        aggregated are collected (per outgoing jump), None to explore them at once.
        ``spread``: bound of the input effect on the cell (None without inputs): ``carried``
        (the remainders of completed input blocks, :class:`.flowpipe.ChainInputs`) plus the
        effect of the block in progress, which started ``since`` before the cell; the second
        half keeps ``spread``, the first takes the bound at its own end (:meth:`_half_spread`).
        ``directed``: rows and bounds of the input effect on the cell along the unsafe pieces'
        and guards' directions (:class:`.flowpipe.ChainInputs`), split as ``spread`` is
        (:meth:`_half_directed`). ``error``: the cell's interpolation error, when the chain has
        computed it (the halves compute their own). ``returns``: in the first cell of a chain,
        the jumps that may return its runs to the mode they came from (:meth:`_returns`);
        ``skip``: the names of those proved not to be taken from the cell (:mod:`.returns`),
        passed on to its halves.
        """
        if self._past_cutoff(start, path):
            return
        self._memory_guard()
        seg, error = self._segment(mode, start, h, spread, directed, error)
        if returns:
            skip = skip | {jump.name for jump, rows in returns if rising(self.flows[mode], jump, rows, seg)}
        final = depth >= self.opt.max_refinements or self.opt.discrete_time or self.flows[mode].drift
        block = start.nvars
        kept_sets = len(self.sets)
        mark = None if self.covered is None else self.covered.mark()
        parts = ()
        try:
            if not final and self._transient(mode, seg, error):
                raise _Refine(None, block)          # a fast transient: refine before checking
            parts = self._split(mode, seg)
            if self.opt.keep_sets:
                self._keep(mode, parts)
            # the directed rows may cut the input box: its columns are no error an LP cannot remove
            cut_from = None if directed is None else seg.nvars - int(np.count_nonzero(np.asarray(spread) > 0))
            for part in parts:
                self._check_segment(mode, part, path, block, not final, cut_from, (start, h))
            for part in parts:
                self._jump_from(mode, part, path, block, not final, point, pending, (start, spread), skip)
            return
        except _Refine as failure:
            if final or failure.blame != block:
                raise
        # the halves are explored once the handler has ended: the failure's traceback holds the
        # frames it came through (their stars), which would otherwise live as long as the halves
        # (and, chained as the context of a later exception, past the check)
        del seg, error, parts
        del self.sets[kept_sets:]                   # the halves keep their own segments
        if mark is not None:            # aggregates explored from the cell cover nothing: their
            self.covered.forget(mark)   # exploration was cut short, the halves explore their own
        self.stats.refined += 1
        self.stats.deepest = max(self.stats.deepest, depth + 1)
        half = h / 2
        first = self._half_spread(mode, spread, since, half, carried)
        self._cell(mode, start, half, path, depth + 1, point, pending, first, since, carried,
                   self._half_directed(mode, directed, since, half, carried), skip=skip)
        mid = start.affine_map(*self.flows[mode].step(half))
        Hi, gi = self._flow_invariant(mode)      # relaxed by the input effect, as on the grid
        mid = mid.intersect_halfspaces(Hi, gi if first is None else gi + np.abs(Hi) @ first)
        mid, mid_point = self._start(mid, point)
        if mid is not None:
            self._cell(mode, mid, half, path, depth + 1, mid_point, pending, spread, since + half,
                       carried, directed, skip=skip)

    def _note_stops(self, mode: str, grid_star, centers, bases, box, error, dev, cells, curvature, inputs):
        """Record the invariant faces of ``mode`` where runs may stop (:mod:`.stops`) that a
        cell of the chain meets, each with the earliest clock of a cell meeting it. A cell is
        looked at only where its bound along the face's row (grid stars at both ends, plus the
        cell's error and the grid points' input box ``dev``) reaches the face; then its
        segment, as :meth:`_cell` builds it, decides by one LP."""
        H = np.vstack([E for _, E, _ in self.stops[mode]])                  # the face rows E
        f = np.concatenate([g for _, _, g in self.stops[mode]])
        upper = _chain_bounds(centers, bases, box, H)
        if dev is not None:
            upper = upper + dev[:upper.shape[0]] @ np.abs(H).T
        for j in cells:
            reach_ = np.maximum(upper[j], upper[j + 1]) + np.abs(H) @ error[j]
            near = reach_ >= f - 1e-9 * (1.0 + np.abs(f))
            if not np.any(near):
                continue
            spread = None if inputs is None else inputs.cell[j]
            directed = None if inputs is None or inputs.directed is None else (inputs.directed[0],
                                                                                inputs.directed[1][j])
            seg, _ = self._segment(mode, grid_star(j), self.h, spread, directed,
                                   None if curvature is None else curvature[j])
            start = float(-seg.support_bounds(-self.clock_row[None])[0])
            for k in np.flatnonzero(near):
                face = self.stops[mode][k][0]
                if self.stopped.get((mode, face.text), np.inf) <= start:
                    continue
                if id(face) not in self._stop_pieces:
                    self._stop_pieces[id(face)] = stop_pieces(face, self.data.widen)
                for piece in self._stop_pieces[id(face)]:
                    self._lp_budget()
                    if meets(seg, *piece, error=error[j]):
                        self.stopped[(mode, face.text)] = start
                        break

    def _returns(self, mode: str, start: Star, path: _Path) -> tuple:
        """``(jump, rows)`` for each jump of ``mode`` that may return the runs of a chain's
        ``start`` to the mode they all came from, undoing the reset they came by, with the rows of
        its guard that every run meets from outside at its entry: conditions (a) of
        :mod:`.returns` (``_cell`` checks (b) on the first cell's segment). Empty where the runs
        came by different jumps (an aggregate of several), from the initial star, or where the
        mode's flow is a linearisation (valid only in its block's region)."""
        if self.linearise is not None and mode in self.linearise.curved:
            return ()
        if path.entries:
            name = path.entries[-1].transition
        elif path.origin is not None:
            name = self._entered_by(path.origin.members)
        else:
            return ()
        out = []
        for jump in self._undoing(mode, name):
            rows = entry_rows(jump, self.invariants[mode], start)
            if rows:
                out.append((jump, rows))
        return tuple(out)

    def _undoing(self, mode: str, name: str | None) -> list:
        """The jumps of ``mode`` back to the mode the transition ``name`` leaves that undo its
        reset (:func:`.returns.undone`); empty where ``name`` is None or names several jumps."""
        came = self._sources.get(name, []) if name is not None else []
        if len(came) != 1:
            return []
        source, first = came[0]
        return [j for j in self.jumps[mode] if j.target == source and j.H.shape[0] and undone(first, j)]

    @staticmethod
    def _entered_by(members) -> str | None:
        """The transition every member (a successor star with its path) entered by, or None."""
        names = {path.entries[-1].transition if path.entries else None for _, path in members}
        return names.pop() if len(names) == 1 else None

    def _half_spread(self, mode: str, spread, since: float, half: float, carried=0.0):
        """The input-effect bound ``carried + R(since + half)`` of the first half of a bisected cell
        (:meth:`.flowpipe.AffineFlow.deviation` on the grid of step ``half``), or ``spread``, the
        bound of the whole cell (``R`` is non-decreasing), when that grid would exceed
        :data:`HALF_SPREAD_CELLS` cells. Near the start of the input effect (a jump, or a block
        start of :meth:`_rebase_cells`) the bound then shrinks with the cell."""
        if spread is None:
            return None
        k = int(round((since + half) / half))
        if k > HALF_SPREAD_CELLS:
            return spread
        count = 1 << (k - 1).bit_length()          # tables of 2^i cells: each built once
        return np.minimum(spread, carried + self.flows[mode].deviation(half, count)[k])

    def _input_directions(self, mode: str) -> np.ndarray | None:
        """The rows along which the input effect is bounded besides its box: those of the mode's
        unsafe pieces and of its relevant guards that mix components (along one component the
        box is already the exact support), at most :data:`MAX_INPUT_DIRECTIONS` of them."""
        if mode not in self._directions:
            rows = [piece.H for piece in self.pieces.get(mode, [])]
            rows += [j.H for j in self.jumps[mode] if j.target in self.relevant]
            C = np.vstack([np.zeros((0, self.n))] + rows)
            C = C[np.count_nonzero(C, axis=1) > 1]
            C = np.unique(C, axis=0)[:MAX_INPUT_DIRECTIONS]
            self._directions[mode] = C if C.shape[0] else None
        return self._directions[mode]

    def _half_directed(self, mode: str, directed, since: float, half: float, carried=0.0):
        """The directed input-effect bounds of the first half of a bisected cell, as
        :meth:`_half_spread` takes its box: ``|C| carried + R_C(since + half)``, or the whole
        cell's ``directed`` (valid for both halves: the bound grows with time)."""
        if directed is None:
            return None
        k = int(round((since + half) / half))
        if k > HALF_SPREAD_CELLS:
            return directed
        C, bounds = directed
        count = 1 << (k - 1).bit_length()
        rest = np.abs(C) @ np.broadcast_to(carried, (self.n,))
        return C, np.minimum(bounds, rest + self.flows[mode].deviation(half, count, C)[k])

    def _transient(self, mode: str, seg: Star, error) -> bool:
        """Whether the interpolation error of a segment, along a guard row of the mode's
        relevant jumps, exceeds ``ERROR_RATIO`` of the row's magnitude over the segment. The
        error enters nothing but the segment (the grid stars are exact): a fast transient in
        a state no guard reads is left alone, and along the unsafe pieces the check itself
        refines where the error is what keeps the segment from clearing a piece
        (:meth:`_check_segment`)."""
        rows = self._guard_rows.get(mode)
        if rows is None:
            rows = self._guard_rows[mode] = np.vstack(
                [np.zeros((0, self.n))] + [j.H for j in self.jumps[mode] if j.target in self.relevant])
        if not rows.shape[0]:
            return False
        magnitude = seg.support_bounds(np.vstack([rows, -rows])).reshape(2, -1).max(axis=0)
        return bool(np.any(np.abs(rows) @ error > ERROR_RATIO * magnitude))

    def _check_segment(self, mode: str, seg: Star, path: _Path, block: int, own_open: bool,
                       cut_from: int | None = None, cell=None):
        """Check every unsafe piece of ``mode`` on a segment.

        Cheap support bounds first. When they fail, the interpolation error of each cell
        along the path (its error coefficients' extent along each piece row) is compared with
        the row's deficit: an error larger than the deficit cannot be argued away by an LP,
        so that cell is refined at once (the segment's columns from ``cut_from`` on, an input box
        the LP may cut by directed rows, do not count as error). Otherwise an LP decides; on a hit the open block
        (an ancestor cell or this one) with the largest spread is blamed, and the witness is
        replayed when nothing can be refined or when it lies deeper in the piece than all
        refinable spread together.
        """
        horizon_row = self.clock_row[None]
        blocks, open_ = path.blocks + (block,), path.open + (own_open,)
        for piece in self.pieces.get(mode, []):
            if not piece.H.shape[0]:
                self._check_whole_mode(mode, seg, path, blocks, open_, piece)
                continue
            lower = -seg.support_bounds(-piece.H)
            if np.any(lower > piece.g + self._touch(piece.g, lower)):   # missed beyond a touch (_screen)
                continue
            spread, error = _block_spreads(seg, piece.H, blocks, cut_from)     # (blocks, rows) each
            gain = np.where(np.array(open_)[:, None], error - (piece.g - lower), -np.inf)
            if gain.max(initial=-np.inf) > 0:
                raise _Refine(None, blocks[int(np.argmax(gain.max(axis=1)))])
            self._lp_budget()
            H = np.vstack([piece.H, horizon_row])
            g = np.append(piece.g, self.horizon)
            depth, alpha, lp_tol = _depth(seg, H, g, len(piece.g), self.opt.touch_tolerance)
            tol = max(self.opt.touch_tolerance, 10 * lp_tol) * _row_scale(piece, seg)
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
                self._try_replay(witness, piece, seg)
            elif cell is not None and self._probed(mode, piece, witness, *cell):
                self._try_replay(witness, piece, seg)
                self.probe_misses += 1          # (the replay did not violate)
            self._unresolved(witness, blame, seg)

    def _probed(self, mode: str, piece: _Piece, witness: _Witness, start: Star, h: float) -> bool:
        """Whether the run through the witness's point of the cell's ``start`` enters ``piece`` at
        one of the instants ``k h / PROBES`` of the mode's step that fall in the cell: then the
        witness is worth a replay before the cell is refined (the replay alone decides). One
        matrix-vector product per instant. Not in modes with time-varying inputs (the run of
        one signal says little of the others), nor after :data:`PROBE_MISSES` probed witnesses
        whose replay did not violate."""
        flow = self.flows[mode]
        if flow.drift or flow.inputs or self.opt.discrete_time or self.probe_misses >= PROBE_MISSES:
            return False
        Phi, psi = flow.step(self.h / PROBES)
        x = start.center + start.basis @ witness.alpha[:start.nvars]
        for _ in range(max(1, int(round(h / self.h * PROBES)))):
            x = Phi @ x + psi
            slack = piece.g - piece.H @ x
            if np.all(slack > 0 if piece.strict else slack >= 0):
                return True
        return False

    def _check_whole_mode(self, mode: str, seg: Star, path: _Path, blocks, open_, piece):
        """A piece without rows: the whole of ``mode`` is unsafe (a SpaceEx ``loc() == error``),
        so any point of the segment before the horizon violates (depth unbounded). The
        witness is replayed at once; if the run does not reach the mode, the cell that fired
        the latest open jump on the path is blamed (the segment's own cell cannot help: the
        segment is non-empty however it is cut)."""
        self._lp_budget()
        alpha = seg.intersect_halfspaces(self.clock_row[None],
                                         np.array([self.horizon])).feasible_alpha()
        if alpha is None:
            return
        witness = _Witness(mode, piece.label, np.inf, alpha, seg.point(alpha), path)
        self._try_replay(witness)
        refinable = [b for b, o in zip(blocks[:-1], open_[:-1]) if o]
        self._unresolved(witness, refinable[-1] if refinable else None, seg)

    def _unresolved(self, witness: _Witness, blame, seg: Star):
        """A segment meets a piece and no replay violated: refine ``blame`` (a block), or
        lower the sweep's cutoff, refine an aggregate, or record the cell as unresolved."""
        if blame is not None:
            raise _Refine(witness, blame)
        if self.sweep:
            self.cutoff = min(self.cutoff, self._failure_time(witness, seg))
            return
        path = witness.path
        if path.origin is not None and self.stats.deaggregated < self.opt.max_deaggregations \
                and path.nested < self.opt.max_nested_refinements:
            raise _Deaggregate(witness, path.origin)
        self.unresolved.append(witness)
        if len(self.unresolved) >= self.opt.max_unresolved:
            raise _Stop(Status.UNKNOWN, f"{len(self.unresolved)} cells still meet an unsafe "
                                        f"piece after refinement; no witness replayed",
                        witness=self.unresolved[0], imprecise=True)

    def _failure_time(self, witness: _Witness, seg: Star) -> float:
        """Earliest time from which the runs behind a failing segment may violate: the
        earliest abort on its path, or, with no abort, the segment's earliest clock."""
        windows = [e for e in witness.history if e.window]
        if windows:
            e = windows[-1]
            box = Box(seg.box.low[:e.row.size], seg.box.high[:e.row.size])
            return e.offset - box.support(-e.row)
        return self._earliest(seg)

    def _jump_from(self, mode: str, seg: Star, path: _Path, block: int, own_open: bool, point,
                   pending=None, cell=None, skip=frozenset()):
        for index, jump in enumerate(self.jumps[mode]):
            if jump.target not in self.relevant:
                continue
            if self.sweep and jump.window is not None and path.abort == np.inf and \
                    self._earliest(seg) >= self.cutoff:
                continue
            # in a cell that ends at the horizon, the guard relaxed by the touch tolerance (as
            # _screen): the grid falls short of the horizon by rounding (x = 1 reached at t = 1
            # after 10^4 additions of the step, 1e-13 short), and a run meeting the guard only
            # there must still jump; more successors, never fewer. Earlier cells need no
            # allowance (the next cell straddles the guard), and keep exact timing
            lower = -seg.support_bounds(-jump.H)
            relaxed = jump.g + self._touch(jump.g, lower) if self._at_horizon(seg) else jump.g
            if jump.H.shape[0] and np.any(lower > relaxed):
                continue
            if jump.name in skip:               # a zero-dwell return (see _cell)
                self.stats.returns += 1
                continue
            # runs that switch after the horizon do not matter: the clock row cuts them
            H = np.vstack([jump.H, self.clock_row])
            g = np.append(relaxed, self.horizon)
            entered = seg.intersect_halfspaces(H, g)
            if self.flows[mode].drift:
                entered = _tightened(entered, len(g))
                if entered is None or np.any(-entered.support_bounds(-jump.H) > relaxed):
                    continue
            instant = None if cell is None or self.flows[mode].drift else \
                self._at_instant(mode, entered, seg, H, g, *cell)
            if instant is not None:
                entered = instant
                self.stats.instants += 1
            clock = _Entry(jump.name, jump.window is not None,
                           float(entered.center[self.clock]), entered.basis[self.clock].copy(),
                           jump.window is None or jump.window[0] == self.clock)
            earliest = self._earliest(entered)
            reads = self._inputs_read(jump)
            if reads:                           # the input's value at the jump: any of its range
                entered = self._fresh_inputs(entered, reads)
            successor = entered.affine_map(jump.R, jump.r)
            if reads:                           # and later ones independent of what it set
                successor = self._fresh_inputs(successor, reads)
            successor = successor.intersect_halfspaces(*self.invariants[jump.target])
            if self.flows[mode].drift:
                successor = _tightened(successor, len(self.invariants[jump.target][1]))
                if successor is None:
                    continue
            descended = path.descend(clock, block, own_open, earliest, self.h)
            if instant is not None:
                descended = replace(descended, instant=True)
            if pending is not None:             # bound propagation drops a member proved empty
                member = _tightened(successor, len(g) + len(self.invariants[jump.target][1]))
                if member is not None:
                    pending.setdefault(index, []).append((member, descended))
                    pending.note_size(index, entered)
                continue
            # the known point's own chord: (a, lam a, lam, 0) from lam = 0 to 1, or its ray
            # (a, s) from s = 0 to 1 in a constant-flow mode
            m, pad = point.size, successor.nvars - point.size
            guess = np.concatenate([point, np.zeros(pad)])
            if instant is not None:              # the start's point, moved with the flow
                direction = None
            elif self.flows[mode].drift and not self.opt.discrete_time:
                direction = np.concatenate([np.zeros(m), [1.0]]) if pad == 1 else None
            else:
                direction = np.concatenate([np.zeros(m), point, [1.0], np.zeros(pad - m - 1)]) \
                    if pad > m else None
            self._chain(jump.target, successor, descended, guess, direction)

    def _inputs_read(self, jump) -> list[int]:
        """The coordinates of the time-varying inputs that ``jump``'s reset reads into another
        state (``y := u``)."""
        return [u.index for u in self.data.varying if np.any(np.delete(jump.R[:, u.index], u.index) != 0)]

    def _fresh_inputs(self, star: Star, inputs: list[int]) -> Star:
        """``star`` with the time-varying inputs ``inputs`` free in their ranges, each on a new
        coefficient. Their coordinate stands for the input's value at the time of the set; a
        reset that reads one takes its value at the jump, which the signal may choose anywhere in
        the range whatever it was before, and after the jump it is again independent of the
        state it was copied into."""
        center, basis = star.center.copy(), star.basis.copy()
        low, high = self.data.ranges.low[inputs], self.data.ranges.high[inputs]
        center[inputs], basis[inputs] = (low + high) / 2, 0.0
        radius = np.zeros(self.n)
        radius[inputs] = (high - low) / 2
        return _plus_box(Star(center, basis, star.predicate, star.box), radius)

    def _at_instant(self, mode: str, entered: Star, seg: Star, H, g, start: Star, spread) -> Star | None:
        """The runs that take a time-triggered jump out of a cell, as an image of the cell's start
        star, or None where that does not apply.

        It applies when, for a timer of the mode (:meth:`_timers`: the global clock, or a local
        one such as a sampled controller's, ``c' = r`` with ``r > 0``), the runs of ``start``
        have it in ``[first, last]`` and the guard leaves the timer of ``entered`` (the segment
        cut by the guard, bound-propagated) in ``[lo, hi]``, with ``hi - first`` at rounding
        level past ``lo - last`` (a switch at ``c == 5`` by guard and invariant). A run from
        ``first <= c <= last`` that jumps at ``c*`` has flowed ``d = (c* - c) / r`` in
        ``[tau, tau + w]``, ``tau = max(0, (lo - last) / r)``, ``w = (hi - first) / r - tau``.
        At ``s + tau`` (``s`` the run's time at the cell start) its
        state is ``x_free + dev``: the input-free run ``Phi(tau) x0 + psi(tau)`` from its point
        ``x0`` of ``start`` plus the input's effect, within ``spread`` as on the segment. From
        ``s + tau`` to ``t*`` it stays in the mode and the cell, so in the segment, where
        ``|x'| <= v = |A| |x| + |b| + |B| u_r``: it moves at most ``w v``. So the image
        ``Phi(tau) start`` plus the box ``spread + w v`` holds ``x(t*)`` (the clock's own ``v``
        is 1: the box spans ``[lo, hi]`` in the clock), cut by the invariant and the guard,
        which ``x(t*)`` satisfies. Unlike the segment it carries no second copy of the
        coefficients and no interpolation error, so a schedule of switches keeps stars small
        and tight."""
        if self.opt.discrete_time:
            return None
        tightened = _tightened(entered, len(g))
        if tightened is None:
            return None
        for k, rate in self._timers(mode):
            clock = np.eye(self.n)[k][None]
            first, last = -float(start.support_bounds(-clock)[0]), float(start.support_bounds(clock)[0])
            lo, hi = -float(tightened.support_bounds(-clock)[0]), float(tightened.support_bounds(clock)[0])
            tau = max(0.0, (lo - last) / rate)      # a run jumps no earlier than its cell start
            w = max(0.0, (hi - first) / rate - tau)
            local = INSTANT_STEP_FRACTION * self.h if k != self.clock else 0.0     # (see the options)
            if w <= max(INSTANT_WIDTH * max(1.0, abs(hi) / rate), local):
                break
        else:
            return None
        flow = self.flows[mode]
        size = np.abs(seg.support_bounds(np.vstack([np.eye(self.n), -np.eye(self.n)]))).reshape(2, -1).max(axis=0)
        speed = np.abs(flow.A) @ size + np.abs(flow.b)
        if flow.inputs:
            speed = speed + np.abs(flow.B) @ flow.u_radius
        bloat = w * speed + (0.0 if spread is None else spread)
        image = _plus_box(start.affine_map(*flow.step(tau)), bloat)
        return image.intersect_halfspaces(*self.invariants[mode]).intersect_halfspaces(H, g)

    def _timers(self, mode: str) -> list[tuple[int, float]]:
        """``(coordinate, rate)`` of the timers of ``mode``, the explored clock first: states
        whose flow there is a positive constant that no input moves (``c' = r``)."""
        if mode not in self._timer_rows:
            flow = self.flows[mode]
            still = ~np.any(flow.A != 0, axis=1) & (flow.b > 0)
            if flow.B is not None and flow.B.size:
                still &= ~np.any(flow.B != 0, axis=1)
            order = [self.clock] + [k for k in range(self.n) if k != self.clock]
            self._timer_rows[mode] = [(k, float(flow.b[k])) for k in order if still[k]]
        return self._timer_rows[mode]

    # ---- witnesses

    def _try_replay(self, witness: _Witness, piece: _Piece | None = None, seg: Star | None = None):
        """Replay ``witness`` with its inputs held at the witness's initial values, along the
        transitions of its path; with time-varying inputs and the ``piece`` the segment ``seg``
        meets, then also the extremal input witness of :meth:`_extremal_witness`. UNSAFE
        (:class:`_Stop`) on the first replay that violates."""
        if not self.opt.replay or self.stats.replays >= self.opt.max_replays:
            return
        try:
            from reach.backends.montecarlo import constant_signal
        except ImportError:
            return
        x0, switch, transitions, times = self._start_of(witness)
        signal = constant_signal(self.model, x0)
        self._replay(witness, x0, switch, signal, transitions)
        timed = self._switching_signal(signal, transitions, times)
        if timed is not None:
            self._replay(witness, x0, switch, timed, transitions)
        if self.data.varying and piece is not None and seg is not None:
            found = self._extremal_witness(witness, piece, seg)
            if found is not None:
                self._replay(*found)
        for corner in self._input_corners(x0, transitions):
            self._replay(witness, corner, switch, constant_signal(self.model, corner), transitions)

    def _input_corners(self, x0, transitions) -> list:
        """``x0`` with the time-varying inputs that a reset along ``transitions`` reads held at
        each corner of their ranges (none where more than :data:`MAX_READ_INPUTS` are read): the
        witness takes such an input's value at the jump freely (:meth:`_fresh_inputs`), which
        the run of the one value ``x0`` holds does not."""
        read = sorted({k for name in transitions for _, jump in self._sources.get(name, [])
                       for k in self._inputs_read(jump)})
        if not read or len(read) > MAX_READ_INPUTS:
            return []
        out = []
        for values in itertools.product(*[(self.data.ranges.low[k], self.data.ranges.high[k]) for k in read]):
            corner = x0.copy()
            corner[read] = values
            out.append(corner)
        return out

    def _replay(self, witness: _Witness, x0, switch, signal, transitions, dt=None):
        """One replay of ``witness``'s run: where transitions are enabled together, the run takes
        the next one of its path's ``transitions`` (:class:`reach.model.simulate.Branches`)."""
        if self.stats.replays >= self.opt.max_replays + self.finer_replays:
            return
        from reach.backends.montecarlo import replay
        from reach.model.simulate import Branches
        self.stats.replays += 1
        began = time.perf_counter()
        try:
            run = replay(self.model, self.prop, x0, switch, dt or self.opt.replay_dt, signal,
                         Branches(prescribed=[transitions]))
        except InputError as exc:       # a candidate the simulator cannot take: no replay, not bad input
            self.replayed.append({"initial_state": x0.tolist(), "switch_time": switch, "refused": exc.message})
            return
        finally:
            self.replay_seconds = time.perf_counter() - began
        self.replayed.append({"initial_state": x0.tolist(), "switch_time": switch,
                              "input_signal": None if signal is None else f"{len(signal['values'])} pieces",
                              "violated": bool(run.violated)})
        if run.violated:
            raise _Stop(Status.UNSAFE, "replayed counterexample",
                        counterexample=run.counterexample(self.model, self.prop, NAME),
                        witness=witness)

    def _extremal_witness(self, witness: _Witness, piece: _Piece, seg: Star):
        """``(witness, initial state, switch time, input signal, transitions, replay step)``: a run aimed
        deepest into ``piece`` by the time-varying inputs, or None.

        The direction is ``c = -h_r`` for the row ``h_r x <= g_r`` of the piece that the
        inputs move most (``|h_r| R`` largest, ``R`` the largest input reach bound over the
        horizon of the path's modes,
        :meth:`.flowpipe.AffineFlow.deviation`); the other rows are kept as constraints (an
        instant ``t == 20`` stays an instant). Two LPs: the point of ``seg``
        (cut by those rows and the horizon) that maximises ``c^T x``, at the latest instant
        among such points; its coefficients give the initial state (as any witness) and its
        clock ``t`` the instant to aim at. The input
        signal is :func:`.witnesses.extremal_signal` along the witness's path (its modes, jump
        instants and resets, :meth:`_earlier_flows`), which attains the input's exact support
        along ``c`` at ``t`` for that path (exact without jumps; a candidate otherwise, since
        the signal may move the jumps). Only the replay decides."""
        flow = self.data.flows[witness.mode]     # the modes' own inputs (a block may add more)
        moving = [f for f in [flow] + [f for f, _, _ in self._earlier_flows(witness)] if f.inputs]
        if not moving:
            return None
        cells = max(1, int(np.ceil(self.horizon / self.h - 1e-9)))
        reach = np.max([f.deviation(self.h, cells)[-1] for f in moving], axis=0)
        moved = np.abs(piece.H) @ reach
        if not np.any(moved > 0):
            return None
        r = int(np.argmax(moved))
        others = np.delete(np.arange(len(piece.g)), r)
        H = np.vstack([piece.H[others], self.clock_row])
        g = np.append(piece.g[others], self.horizon)
        self._lp_budget()
        cut = seg.intersect_halfspaces(H, g)
        res = cut.maximize(-piece.H[r])
        if not res.optimal:
            return None
        alpha = res.x
        # the latest instant of that maximum: the input's exact support grows with time, while
        # the bounds of a cell's input effect are those of its end, whatever the instant
        self._lp_budget()
        level = res.value - 1e-9 * max(1.0, abs(res.value))
        late = cut.intersect_halfspaces(piece.H[r][None], np.array([-level])).maximize(self.clock_row)
        if late.optimal:
            alpha = late.x
        aimed = _Witness(witness.mode, witness.piece, witness.depth, alpha, seg.point(alpha), witness.path)
        t = float(aimed.state[self.clock])
        base = self._replay_step()
        if not t >= base:               # within the first replay step: the held inputs' replay covers it
            return None
        x0, switch, transitions = self.initial_point(aimed)
        step, values = extremal_signal(flow, -piece.H[r], t, [u.low for u in self.data.varying],
                                       [u.high for u in self.data.varying], signal_pieces(t, base),
                                       self._earlier_flows(aimed))
        signal = {"step": step, "inputs": [u.name for u in self.data.varying], "values": values.tolist()}
        return aimed, x0, switch, signal, transitions, step / max(1, int(np.ceil(step / base - 1e-9)))

    def _earlier_flows(self, witness: _Witness) -> list:
        """The path of ``witness`` before its mode, as :func:`.witnesses.extremal_signal` takes it:
        ``(flow, jump time, reset matrix)`` per jump, in time order (the times read off the
        witness's coefficients, :meth:`_start_of`). Empty where a transition of the path is not
        an outgoing linear jump of the mode it leaves (the witness mode's flow alone then)."""
        _, _, transitions, times = self._start_of(witness)
        mode, out = self.root_mode, []
        for name, tau in zip(transitions, times):
            jump = next((j for j in self.data.jumps.get(mode, ()) if j is not None and j.name == name), None)
            if jump is None or mode not in self.data.flows:
                return []
            out.append((self.data.flows[mode], tau, jump.R))
            mode = jump.target
        return out if mode == witness.mode else []

    def _replay_step(self) -> float:
        """The replay step asked for, or the simulator's default. A signal's replay uses the
        largest ``step / k`` not above it, so that every piece -- and the instant ``t`` the
        signal aims at -- starts on the simulator's grid."""
        from reach.model.simulate import default_dt
        return self.opt.replay_dt or default_dt(self.model)

    def initial_point(self, witness: _Witness):
        """Initial state and abort time of a witness, read off its coefficients, and the names
        of the transitions along its path (through aggregates, the members' paths)."""
        return self._start_of(witness)[:3]

    def _start_of(self, witness: _Witness):
        """:meth:`initial_point`, and the time of each jump along the path (the global clock
        at the switch, read off the witness's coefficients)."""
        alpha, entries = self._trace(witness.alpha, witness.path)
        m0 = self.root.nvars
        x0 = self.root.point(alpha[:m0])[:self.model.n]
        x0 = self._inside_initial(np.clip(x0, self.model.initial.low, self.model.initial.high))
        transitions = [e.transition for e, _ in entries]
        times = [float(e.offset + e.row @ a[:e.row.size]) for e, a in entries]
        windows = [(e, t) for (e, _), t in zip(entries, times) if e.window]
        if len(windows) > 1 or any(not e.global_window for e, _ in windows):
            return x0, None, transitions, times     # not one switch at a global time: no switch
        switch = windows[-1][1] if windows else self._latest_abort(witness.mode)
        return x0, switch, transitions, times

    def replay_finer(self, count: int = 2, factors=(10, 100)):
        """The first ``count`` unresolved witnesses replayed once more on grids ``factors`` times
        finer than the replay step, their may-transitions asked at the first instant of that grid
        after the witness's jump time: on the default grid that delay (up to one step) can cost
        a violation by less than what the run loses in it (a switch at ``y = -0.5`` that an
        exponential mode magnifies). Grids of more than a tenth of the simulator's step limit
        are not tried, nor one whose replay would overrun the time budget (its cost taken as the
        last replay's times the ratio of their grids). These replays come on top of
        ``max_replays``. UNSAFE (:class:`_Stop`) on
        the first replay that violates."""
        from reach.backends.montecarlo import constant_signal
        from reach.model.simulate import MAX_STEPS

        self.finer_replays = count * len(factors)      # beyond max_replays, which the search may have used
        for witness in self.unresolved[:count]:
            x0, switch, transitions, times = self._start_of(witness)
            signal = constant_signal(self.model, x0)
            cost, before = self.replay_seconds, 1
            for factor in factors:
                step = self._replay_step() / factor
                if self.model.horizon / step > MAX_STEPS / 10 or self.out_of_time():
                    break
                if cost is not None and time.perf_counter() + cost * factor / before > self.deadline:
                    break                   # a finer grid costs in proportion: it would overrun the budget
                timed = self._switching_signal(signal, transitions, times, step)
                self._replay(witness, x0, switch, timed or signal, transitions, step)
                cost, before = self.replay_seconds, factor

    def _switching_signal(self, signal, transitions, times, step: float | None = None):
        """The counterexample's input signal (``signal``: the inputs held constant, or None
        without time-varying inputs) on the replay grid, asking for a switch where the path
        takes a may-transition (no urgency, no window): at the first grid instant at or after
        its jump time (time 0 itself included). The replay then takes those transitions when
        the witness does (:meth:`reach.model.simulate.Simulator.run`, ``switch``), not only
        where an invariant forces them, as an early switch over a wide guard needs. None if the
        path takes no may-transition (the first replay already followed it). ``step``: the grid
        (the replay step by default)."""
        may = [t for name, t in zip(transitions, times) if name in self._may]
        if not may:
            return None
        step = step or self._replay_step()
        starts = sorted({max(0, int(np.ceil(t / step - 1e-9))) for t in may})
        pieces = starts[-1] + 2                    # the last piece asks for no switch
        if pieces > MAX_SIGNAL_PIECES:
            return None
        switch = np.zeros(pieces, dtype=int)
        switch[starts] = 1
        values = signal["values"][0] if signal is not None else []
        return {"step": step, "inputs": [u.name for u in self.model.varying_inputs],
                "values": [values] * pieces, "switch": switch.tolist()}

    def _inside_initial(self, x0):
        """``x0`` moved into a polytopic initial set, which the LP's point may miss by the
        solver's tolerance (and the replay would refuse): projected onto the set's affine hull
        (its equalities), then moved towards an interior point by the least fraction, among
        ``1e-9, 1e-8, ..., 1``, that makes it a member. Unchanged for a box, or a member."""
        init = self.model.initial
        if init.is_box:
            return x0
        from reach.backends.montecarlo.initial_sampling import PolytopeSampler
        if self._initial_sampler is None:
            self._initial_sampler = PolytopeSampler(init.polytope, init.low, init.high)
        sampler = self._initial_sampler
        if sampler.contains(x0[None])[0]:
            return x0
        on_hull = sampler.to_x(sampler.to_z(x0[None]))[0]
        centre = sampler.to_x(sampler.centre_z[None])[0]
        for fraction in 10.0 ** np.arange(-9, 1):
            x = on_hull + fraction * (centre - on_hull)
            if sampler.contains(x[None])[0]:
                return x
        return x0

    def _trace(self, alpha, path: _Path):
        """:func:`.witnesses.trace`, one LP per member of each aggregate on the way."""
        def nearest(star, x):
            self._lp_budget()
            return nearest_point(star, x)
        return trace(alpha, path, nearest)

    def _latest_abort(self, mode: str):
        """Without an abort on the witness's path: the latest abort of its mode's windows
        (the run stays in the mode as long as possible), or None if there is none."""
        his = [j.window[2] for j in self.jumps[mode] if j.window is not None and j.window[0] == self.clock]
        return max(his) if his else None


def _meets_row(star: Star, a, b: float) -> bool:
    """Whether every state of ``star`` meets ``a x <= b``: its depth into ``a x >= b`` is at
    most 0 (a weak-duality bound)."""
    return star.depth(-a[None], np.array([-b]))[0] <= 0.0


def _row_scale(piece: _Piece, seg: Star) -> float:
    """The scale a depth into ``piece`` is read at (times the touch tolerance):
    ``max(1, |g|, |h . c|)`` over the piece's rows (``c`` the segment's centre), which covers a
    ramp meeting ``x = 1`` at the horizon through the rounding of thousands of products. A piece
    of strict rows, whose depth up to the tolerance counts as a touch (not entered), is read at
    the smaller of that and the size of its rows' terms over the segment, ``max(|g|, |h| |c| +
    |h V| r)`` (``V`` the basis, ``r`` the coefficient box's radius): the grid stars' rounding
    is relative to it, and the floor of 1 read a rate of 1e-6 rad/s exceeding its bound by
    7e-11 as a touch, a SAFE no rounding explains. Never larger than the first: a wide segment
    (a box of +-1e6 cut by ``x - y <= 1e-3`` against ``x <= y``) must not widen it. A piece
    with a non-strict row is met from minus the tolerance, where a larger one only errs towards
    met."""
    scale = max(1.0, np.abs(piece.g).max(initial=0.0), np.abs(piece.H @ seg.center).max(initial=0.0))
    if not piece.strict or not np.all(np.isfinite(seg.box.radius)):
        return scale
    terms = np.abs(piece.H) @ np.abs(seg.center) + np.abs(piece.H @ seg.basis) @ seg.box.radius
    return min(scale, float(np.max(np.maximum(np.abs(piece.g), terms), initial=0.0)))


def _consecutive(cells: list[int]) -> list[tuple[int, int]]:
    """``(first, length)`` of each run of consecutive cell indices. In a constant-flow mode a
    run of cells from grid star ``Y_j`` is one exact cell ``Y_j + [0, length h] b``
    (:func:`.flowpipe._drift_segment`): one segment and one successor per transition
    instead of one per cell, so a guard crossed over several cells does not multiply the
    successors at every jump (``2^k`` stars after ``k`` such jumps)."""
    runs: list[tuple[int, int]] = []
    for j in cells:
        if runs and runs[-1][0] + runs[-1][1] == j:
            runs[-1] = (runs[-1][0], runs[-1][1] + 1)
        else:
            runs.append((j, 1))
    return runs


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
