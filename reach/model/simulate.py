"""Vectorised simulation of a hybrid automaton: thousands of runs per numpy call.

Each run starts from its own initial state and (for models with a may-transition window)
its own switch instant ``tau``. A run is simulated segment by segment; a segment is the
stretch of time in one mode up to the run's next event, and all runs of a mode are advanced
together:

* linear modes use the exact flow ``[x; 1](t) = expm([[A, b], [0, 0]] t) [x; 1]``: the states
  on the grid ``t_k = k dt`` of a segment come from precomputed powers of the one-step
  matrix, hundreds of steps in one batched matrix product, up to the first event (off the
  grid: the series of the flow, :func:`reach.model.batch.taylor_flow`); where the mode's
  urgent guards and invariant are linear (and it has no may-transition with a general guard),
  the states and those margins come together, block by block of grid steps
  (:mod:`reach.model.batch`), and observers with a ``block`` method take whole blocks;
* nonlinear modes step classical RK4 (``substeps`` per grid step, more where the flow is
  stiff: :mod:`reach.model.batch_nonlinear`, Stability), stopping once every run
  of the group has met an event; where their urgent guards and invariant are linear, in
  blocks over all the runs at once (:mod:`reach.model.batch_nonlinear`);
* an urgent transition is taken at the first instant its guard holds, located by bisection
  inside the grid interval where it first holds (to ``dt * 2**-40``), also where a linear
  guard is met between two grid points, a slab of it crossed or a row dipped into
  (:mod:`reach.model.crossing`); the window transition
  is taken exactly at ``tau``; a may-transition with a general guard is taken when a run would
  leave the source invariant, if its guard holds there (the exit instant, by bisection: one
  of the automaton's runs, the one that stays longest), and, in a piece of a switching signal
  that asks for a switch, at the piece start or the first instant in it that its guard is
  entered (the one that leaves earliest); Gaussian kicks (if asked for) are
  applied at ``k * step``, and so are the pieces of a time-varying input signal (and its
  switching decisions; a piece start on the grid where a run's inputs keep their values and no
  switch is asked for changes nothing and does not end its segment); an urgent transition
  whose guard holds right after a kick is taken at that instant;
* a transition is *enabled* at a state where its guard holds and the target's invariant holds
  at the reset state (both to :data:`INVARIANT_TOLERANCE`); where several of the same kind
  are enabled at once (urgent ones whose guards hold together, may-transitions at an exit or
  a piece start), each run takes one by its :class:`Branches`, the first enabled by default,
  and a run that must jump and has none enabled is blocked;
* in a mode where no time passes (``Mode.timeless``, SpaceEx ``flow false``) a run takes an
  enabled transition (urgent or not) at the instant it enters, or is blocked there;
* a run is a run of the automaton only while it satisfies its mode's invariant: an initial
  state outside the initial mode's invariant is blocked at 0 and never watched; a run found
  outside the invariant at a grid point, or whose state at its next event or segment end lies
  outside, left it on the way and stops at the last instant it is inside (by bisection from
  its last grid state inside, :meth:`Simulator._last_inside`), where it is watched and takes
  an enabled may-transition with a general guard or is *blocked* (no continuation);
* a run that takes more than ``MAX_PASSES_PER_STEP`` events inside one grid step is Zeno (its
  jumps accumulate before the horizon, as a bouncing ball's with restitution below 1): it is
  stopped there and counted as blocked, so a simulation always ends.

Observers see every state a run visits (grid points, event instants, the states after each
jump) together with the run's mode, in time order per run; properties are monitored this way
without storing paths. Every state they see lies in its mode's invariant to
:data:`INVARIANT_TOLERANCE` ``(1 + m)`` per row, a hundredth of the tolerance
``NUMERICAL_TOLERANCE (1 + m)`` a violation must exceed
(:func:`reach.model.constraints.violation_test`): a violation is never reported at a state
beyond an invariant by more than rounding. ``m`` is the magnitude the row combines, its
states counted with those they are computed from (:func:`value_sources`,
:func:`reach.model.constraints.row_magnitudes`): a large state a row never meets does not
widen its tolerance.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import sympy

from reach.model import batch
from reach.model.automaton import HybridAutomaton
from reach.model.batch_nonlinear import (STABLE_STEP, STIFFNESS_CHECK, STIFFNESS_PROBES, beyond_rk4, jacobian_radius,
                                         probe_rows, rk4_steps, substeps_for)
from reach.model.constraints import affine_coefficients, lambdify_margins, row_magnitudes
from reach.model.crossing import Crossings

BISECTION_STEPS = 40
INVARIANT_TOLERANCE = 1e-11          # invariants and guards hold where margins <= this (1 + m), per row
SWITCH_TOLERANCE = 1e-14             # a guard asked to switch at a piece start: rounding only (_take_may)
FIRST_WINDOW = 64                 # grid points of a linear segment's first window of states
MAX_WINDOW = 256                  # grid points of its longest window
POWERS_HELD = 2 * (MAX_WINDOW + 2)  # one-step matrix powers a mode's table may hold (doubling past MAX_WINDOW + 2)
CHUNK_VALUES = 4_000_000          # states x steps x dims held at once in a linear segment
BATCH_RUNS = 4096                 # runs of one linear segment advanced together
MAX_STEPS = 5_000_000             # grid steps over the horizon (horizon / dt)
EXPONENTIALS_BYTES = 64 * 2 ** 20  # exponentials kept for recurring durations (Simulator._exponentials)
MAX_PASSES_PER_STEP = 50          # events of one run inside one grid step before it counts as Zeno
MAX_JUMPS_AT_INSTANT = 1000       # jumps of one run at one instant before it counts as Zeno
MEMORY_BUDGET = 4 * 2 ** 30       # bytes the simulator may plan to hold at once
RUN_BYTES_PER_VALUE = 8 * 24      # per run and state value: the arrays a batch of runs carries


def single_threaded():
    """A context with one BLAS thread: the simulator's products are many and small, and
    threads fighting over a loaded machine's cores make them several times slower."""
    return _blas_controller().limit(limits=1, user_api="blas")


@functools.cache
def _blas_controller():
    """The thread pools of the loaded libraries, found once: the search reads every loaded
    shared object (about 2 ms), and numpy's and scipy's BLAS are loaded with this module."""
    from threadpoolctl import ThreadpoolController
    return ThreadpoolController()


def check_size(model: HybridAutomaton, dt: float, runs: int = 0, given: bool = True, option: str = "dt") -> None:
    """Refuse (InputError) a grid or a batch of runs that would not fit: more than
    :data:`MAX_STEPS` steps, or an estimate of the one-step matrix powers of the linear modes
    plus ``runs`` runs' arrays above :data:`MEMORY_BUDGET`. The powers of a mode are at most
    :data:`POWERS_HELD` (:class:`_Powers` holds those asked for, and a segment asks for at most
    ``MAX_WINDOW + 1``), whatever the number of steps. ``given``: ``dt`` is the option's (else
    the model's default, and the message names the model's field that set it; ``option`` names
    the option that gave it)."""
    from reach.errors import InputError

    if given:
        file, step_field = None, f"options.{option}"
    else:                               # the model's own grid: its disturbance step, or its horizon
        file, step_field = model.file, "disturbance.step" if model.disturbance is not None else "horizon"
    if not np.isfinite(dt) or dt <= 0:
        raise InputError(f"the simulator step must be a positive number, got {dt}", file, step_field)
    if given and dt > model.horizon:    # a replay refuses such a run (check_run): so does the check
        raise InputError(f"the simulator step {dt:g} is longer than the horizon {model.horizon:g}", file, step_field)
    steps = model.horizon / dt
    if steps > MAX_STEPS:
        raise InputError(f"{model.name}: horizon {model.horizon:g} / step {dt:g} = {steps:.3g} grid steps; at "
                         f"most {MAX_STEPS:.0e} (" + ("use a larger dt)" if given else "a longer step)"),
                         file, step_field)
    linear = sum(1 for m in model.modes.values() if m.linear is not None)
    matrices = linear * min(steps + 2, POWERS_HELD) * (model.n + 1) ** 2 * 8
    planned = matrices + runs * (model.n + 4) * RUN_BYTES_PER_VALUE
    if planned > MEMORY_BUDGET:
        what = (f"{runs} runs" if runs else
                f"the step matrices of {linear} linear modes of {model.n} states")
        raise InputError(f"{model.name}: about {planned / 2 ** 30:.1f} GiB needed for {what} on {steps:.0f} "
                         f"steps; at most {MEMORY_BUDGET / 2 ** 30:.0f} GiB are planned for (fewer samples or a "
                         "larger dt)", *((None, "options.samples") if runs else (file, step_field)))


def fixed_parameters(model: HybridAutomaton) -> dict:
    """``{symbol: value}``: the states every run holds at one value: flow 0 in every mode,
    never reset, kicked or driven by a signal, and a single initial value (SpaceEx's ``k ==
    0.1`` for a constant ``k``: a state with flow 0). A run always has that value there."""
    reset = {i for tr in model.transitions for i in tr.reset}
    moved = set(model.disturbance.enters) if model.disturbance is not None else set()
    moved |= {u.index for u in model.varying_inputs}
    out = {}
    for i, symbol in enumerate(model.symbols):
        if i in reset or i in moved or model.initial.low[i] != model.initial.high[i]:
            continue
        if all(m.timeless or sympy.sympify(m.flow[i]) == 0 for m in model.modes.values()):
            out[symbol] = float(model.initial.low[i])
    return out


def value_sources(model: HybridAutomaton) -> np.ndarray:
    """``(n, n)`` booleans, ``[i, j]`` where a simulated state ``i`` is computed from state
    ``j``: itself, the states its flow in some mode or a reset of it reads, and theirs in turn
    (the transitive closure). Its rounding, and where an event is located its error (its rate,
    a function of those states, times the bisection's resolution), scale with their sizes,
    not with the states it never meets (a range in metres beside an angle in radians):
    :func:`reach.model.constraints.row_magnitudes`."""
    index = {symbol: i for i, symbol in enumerate(model.symbols)}
    reads = np.eye(model.n, dtype=bool)
    exprs = []
    for m in model.modes.values():
        if m.linear is not None:            # x' = A x + b reads the states of A's nonzero columns
            reads |= m.linear[0] != 0
        else:
            exprs += list(enumerate(m.flow))
    exprs += [(i, e) for tr in model.transitions for i, e in tr.reset.items()]
    for i, expr in exprs:
        for symbol in sympy.sympify(expr).free_symbols:
            if symbol in index:
                reads[i, index[symbol]] = True
    while True:                         # the closure, by squaring
        closed = (reads.astype(np.float32) @ reads.astype(np.float32)) > 0
        if np.array_equal(closed, reads):
            return reads
        reads = closed


def linear_with(mode, fixed: dict):
    """``(A, b)`` of ``mode``'s flow once the ``fixed`` parameters take their values (``-k (T - 30)``
    with ``k = 0.1``: affine), or None. Exact for every run: each holds those values throughout
    (:func:`fixed_parameters`), so the flow at its states is this affine one; the parameters'
    own rows stay 0 (flow 0)."""
    n = len(mode.symbols)
    A, b = np.zeros((n, n)), np.zeros(n)
    for i, f in enumerate(mode.flow):
        coeffs = affine_coefficients(sympy.sympify(f).subs(fixed), mode.symbols)
        if coeffs is None:
            return None
        A[i], b[i] = coeffs
    return A, b


def _start_probes(model: HybridAutomaton) -> np.ndarray:
    """The initial box's centre, its face centres (12 coordinates at most) and 8 random corners:
    the states where the RK4 substeps of a nonlinear mode are first set (the runs start there)."""
    low, high = np.asarray(model.initial.low, float), np.asarray(model.initial.high, float)
    finite = np.isfinite(low) & np.isfinite(high)
    centre = np.where(finite, (low + high) / 2, np.where(np.isfinite(low), low, np.where(np.isfinite(high), high, 0.0)))
    probes = [centre]
    free = np.flatnonzero(finite & (high > low))
    for i in free[:12]:
        for v in (low[i], high[i]):
            p = centre.copy()
            p[i] = v
            probes.append(p)
    rng = np.random.default_rng(0)
    for _ in range(8 if free.size else 0):
        p = centre.copy()
        p[free] = np.where(rng.random(free.size) < 0.5, low[free], high[free])
        probes.append(p)
    return np.array(probes)


def default_dt(model: HybridAutomaton) -> float:
    """Grid step: 1/2400 of the horizon, and a divisor of the disturbance step if any."""
    dt = model.horizon / 2400.0
    if model.disturbance is not None:
        step = model.disturbance.step
        dt = step / max(1, int(np.ceil(step / dt)))
    return dt


def batched_expm(M: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``expm(M h_k)`` for every ``h_k``, by scaling and squaring of a degree-16 Taylor series.

    After scaling, ``||M h_k / 2^(s_k)||_1 <= 1/4``, where the truncation error of the series is
    below ``(1/4)^17 / 17! < 1e-24``; each ``h_k`` has its own ``s_k`` (a short ``h_k`` is not
    squared more than it needs, so one call for many durations is as accurate as one call
    each), and the squarings are batched matrix products over the ``h_k`` that still need them.
    """
    h = np.asarray(h, dtype=float).reshape(-1)
    norm = np.linalg.norm(M, 1) * np.abs(h)
    with np.errstate(divide="ignore"):
        s = np.where(norm > 0.25, np.ceil(np.log2(np.maximum(norm, 0.25) / 0.25)), 0).astype(int)
    H = M[None, :, :] * (h / 2.0 ** s)[:, None, None]
    eye = np.broadcast_to(np.eye(M.shape[0]), H.shape)
    E = eye.copy()
    for k in range(16, 0, -1):          # Horner: I + H/1 (I + H/2 (I + ... ))
        E = eye + (H @ E) / k
    for i in range(int(s.max(initial=0))):
        more = s > i
        if more.all():
            E = E @ E
        else:
            E[more] = E[more] @ E[more]
    return E


@dataclass
class Trajectories:
    """Final state, mode and blocking time of every run; if recorded, the visited states and
    the names of the transitions each run took, in order."""

    final_state: np.ndarray
    final_mode: np.ndarray
    blocked_at: np.ndarray                      # time a run was blocked, nan if never
    branched: np.ndarray                        # jumps of each run at which several transitions were enabled
    path: dict = field(default_factory=dict)    # run -> (t (K,), mode (K,), x (K, n)) if recorded
    transitions: dict = field(default_factory=dict)     # run -> [transition name, ...] if recorded
    cut: int = 0                                # runs stopped by the caller's deadline (among the blocked)
    cut_rows: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=int))   # which runs those are


@dataclass(frozen=True)
class Branches:
    """Which enabled transition each run takes where several are enabled at one jump.

    A jump's options are the transitions of one kind leaving the run's mode, in the model's
    order: its urgent ones (at a guard entry, at once after a jump or a kick), its
    may-transitions with a general guard (at an invariant exit, at a piece start), both in a
    mode where no time passes. With ``values`` (N, D) in ``[0, 1)``, run ``r`` with ``m``
    enabled options at its ``j``-th jump takes the ``floor(m values[r, j mod D])``-th enabled
    one: a value ``(k + 1/2) / B`` takes the ``k``-th of ``B`` options at every jump, uniform
    values a uniform choice. With ``prescribed`` (per run, a list of transition names), a run
    takes the next name of its list where that transition is enabled (and moves on in the
    list), the first enabled one otherwise: a recorded run replays along its own branches, and
    a path missing some jumps (a witness of the star back-end) is still followed. Neither: the
    first enabled, at every jump.
    """

    values: np.ndarray | None = None
    prescribed: list | None = None

    def pick(self, rows: np.ndarray, count: np.ndarray, enabled: np.ndarray, names: list) -> np.ndarray:
        """For the runs ``rows`` (``count`` each: jumps so far, or prescribed names used) with
        ``enabled`` (R, T) over the options ``names``: the chosen option, -1 where none is
        enabled."""
        some = enabled.any(axis=1)
        first = np.where(some, enabled.argmax(axis=1), -1)
        if self.values is not None:
            m = enabled.sum(axis=1)
            u = self.values[rows, count % self.values.shape[1]]
            k = np.minimum((u * m).astype(int), np.maximum(m - 1, 0))
            rank = np.cumsum(enabled, axis=1) - 1
            return np.where(some, (enabled & (rank == k[:, None])).argmax(axis=1), -1)
        if self.prescribed is not None:
            out = first.copy()
            for i, (r, c) in enumerate(zip(rows, count)):
                path = self.prescribed[r]
                if c < len(path) and path[c] in names and enabled[i, names.index(path[c])]:
                    out[i] = names.index(path[c])
            return out
        return first

    def advances(self, rows: np.ndarray, count: np.ndarray, chosen: list) -> np.ndarray:
        """Whether each run's count moves on after it took ``chosen`` (names): at every jump
        with ``values``; where the prescribed name was taken with ``prescribed``."""
        if self.prescribed is None:
            return np.ones(len(rows), dtype=bool)
        return np.array([c < len(self.prescribed[r]) and self.prescribed[r][c] == name
                         for r, c, name in zip(rows, count, chosen)], dtype=bool)


@dataclass
class _Runs:
    """What a simulation carries per run: state, mode, time, window switch instant, blocking
    time; how it chooses among enabled transitions (``branches`` and each run's ``count``,
    :meth:`Branches.pick`), how many of its jumps had a choice (``branched``), the names of the
    transitions taken (``taken``, if recorded); the observers; and which runs are in a piece
    of their switching signal that asks for a switch (``eager``: they take a may-transition
    with a general guard at the first instant its guard is entered, :meth:`Simulator.run`)."""

    X: np.ndarray
    mode: np.ndarray
    t: np.ndarray
    tau: np.ndarray
    blocked_at: np.ndarray
    watchers: list
    branches: Branches
    count: np.ndarray
    branched: np.ndarray
    taken: list | None
    eager: np.ndarray | None = None     # runs whose current piece asks for a switch (run's signal)

    def watch(self, rows: np.ndarray) -> None:
        """The observers see the runs ``rows`` as they are now."""
        for f in self.watchers:
            f(self.t[rows], self.X[rows], self.mode[rows], rows)


#: numbers (steps x state x runs) the fast path of one linear mode holds before its observers
#: see them (:meth:`Simulator._step_eventless`)
EVENTLESS_BLOCK_VALUES = 1 << 20


class Simulator:
    """Simulates ``model`` on a grid of step ``dt`` (see the module docstring)."""

    def __init__(self, model: HybridAutomaton, dt: float | None = None, substeps: int = 2):
        self.model = model
        self.dt = float(dt) if dt else default_dt(model)
        check_size(model, self.dt, given=bool(dt))
        self.substeps = substeps
        self.mode_names = list(model.modes)
        self.n = model.n
        self.steps = int(np.ceil(model.horizon / self.dt - 1e-9))
        self.generators, self.powers, self.tables, self.exponentials = {}, {}, {}, {}
        fixed = fixed_parameters(model)
        for name, mode in model.modes.items():
            linear = mode.linear if mode.linear is not None or not fixed else linear_with(mode, fixed)
            if linear is not None:
                A, b = linear
                M = np.zeros((self.n + 1, self.n + 1))
                M[:self.n, :self.n], M[:self.n, self.n] = A, b
                self.generators[name] = M
                self.powers[name] = _Powers(scipy.linalg.expm(M * self.dt), self.steps + 1)
        self.urgent = {m: [] for m in model.modes}
        self.window = {m: None for m in model.modes}
        self.exits = {m: [] for m in model.modes}         # may-transitions taken at invariant exit
        for tr in model.transitions:
            if tr.urgent:
                self.urgent[tr.source].append((tr, lambdify_margins(tr.guard, model.symbols)))
            elif tr.window is not None:
                self.window[tr.source] = tr
            else:
                self.exits[tr.source].append((tr, lambdify_margins(tr.guard, model.symbols)))
        self.calm = {}                                  # checks of the substeps to pass (more_substeps)
        # RK4 substeps of the nonlinear modes, from their Jacobians where the runs start
        # (batch_nonlinear, Stability), and the modes RK4 cannot take at this step (their rho)
        start = _start_probes(model)
        radius = {m: jacobian_radius(model.modes[m].rhs, start) for m in model.modes
                  if m not in self.generators and not model.modes[m].timeless}
        self.mode_substeps = {m: substeps_for(self.dt, rho, substeps) for m, rho in radius.items()}
        self.too_stiff = {m: rho for m, rho in radius.items() if beyond_rk4(self.dt, rho)}
        self.resets = {tr.name: _reset_function(tr, model) for tr in model.transitions if tr.reset}
        self.sources, self.scales = value_sources(model), {}
        self.timeless = {m for m, mode in model.modes.items() if mode.timeless}
        self.crossings = {m: Crossings(self, m) for m in model.modes}
        # what a run may take at an instant: urgent transitions; in a timeless mode, every one
        self.instant = {m: self.urgent[m] + (self.exits[m] if m in self.timeless else []) for m in model.modes}
        #: the most options one jump can have (several enabled at once need Branches to choose)
        self.max_options = max([len(v) for table in (self.instant, self.exits) for v in table.values()] + [1])

    def more_substeps(self, mode: str, *states: np.ndarray) -> bool:
        """Raise the RK4 substeps of nonlinear ``mode`` where the flow's Jacobian at a few of
        the ``states`` (arrays (K, n)) the runs reached asks for more than it has
        (:meth:`wanted_substeps`) and one grid step at the two counts bears it out
        (:meth:`_steps_disagree`); True if it did: the grid steps that led there were unstable,
        and are to be taken again. Where ``h rho`` leaves room below ``STABLE_STEP`` the next
        calls pass without looking: ``k - 1`` of them where it is below ``STABLE_STEP 2^-k``
        (at most 7)."""
        if mode not in self.mode_substeps or mode in self.too_stiff:
            return False
        if self.calm.get(mode, 0) > 0:
            self.calm[mode] -= 1
            return False
        taken = self.mode_substeps[mode]
        wanted, rho = self.wanted_substeps(
            mode, np.concatenate([probe_rows(X, STIFFNESS_PROBES // len(states)) for X in states]))
        if np.isfinite(rho):
            room = STABLE_STEP / max(self.dt / taken * rho, 1e-300)
            self.calm[mode] = int(min(7, max(0, math.floor(math.log2(room)) - 1)))
        if wanted <= taken or not self._steps_disagree(mode, probe_rows(states[-1]), taken):
            return False
        if beyond_rk4(self.dt, rho):
            self.too_stiff[mode] = rho
        else:
            self.mode_substeps[mode] = wanted
        return True                         # the grid steps again (NaN from here where too stiff)

    def _steps_disagree(self, mode: str, X: np.ndarray, substeps: int) -> bool:
        """Whether one grid step from the states ``X`` (where the grid steps checked ended) with
        ``substeps`` RK4 steps and with twice as many differ by more than ``1e-3 (1 + |x|)``:
        the Jacobian's estimate is borne out (unstable steps have grown the states' error, and
        the two counts amplify it differently), not a large but harmless rate (a network's fine
        ripple on CW-SIREN, which the steps follow as well at either count)."""
        rhs = self.model.modes[mode].rhs
        ends = []
        with np.errstate(all="ignore"):
            for count in (substeps, 2 * substeps):
                ends.append(rk4_steps(rhs, X, self.dt / count, count))
        gap = np.abs(ends[0] - ends[1]).max(initial=0.0)
        return bool(not np.isfinite(gap) or gap > 1e-3 * (1.0 + np.abs(ends[1]).max(initial=0.0)))

    def wanted_substeps(self, mode: str, X: np.ndarray) -> tuple[int, float]:
        """``(substeps, rho)``: the RK4 substeps per grid step that keep ``h rho <= STABLE_STEP``
        at the states ``X`` of nonlinear ``mode`` (at least those it has), ``rho`` the largest
        spectral radius of the flow's Jacobian there. Only states the grid resolves count, where
        one grid step moves the state by less than its own size (``dt |f(x)| <= 1 + |x|``): a
        run blowing up (``x' = x^2`` near its escape time) asks for ever more substeps, and no
        number of them follows it."""
        rhs, taken = self.model.modes[mode].rhs, self.mode_substeps.get(mode, self.substeps)
        with np.errstate(all="ignore"):
            moved = self.dt * np.abs(np.asarray(rhs(X), dtype=float)).max(axis=1, initial=0.0)
        rho = jacobian_radius(rhs, X[moved <= 1.0 + np.abs(X).max(axis=1, initial=0.0)])
        return substeps_for(self.dt, rho, taken), rho

    # --------------------------------------------------------------- propagation
    def propagate(self, mode: str, X: np.ndarray, h) -> np.ndarray:
        """States after time ``h`` (scalar or one per run) in ``mode``, with no event: a linear
        mode by the Taylor series of ``expm(M h) [x; 1]`` summed on the vectors
        (:func:`reach.model.batch.taylor_flow`; for long durations, exponentials), a nonlinear
        one by RK4 (``substeps`` per grid step)."""
        h = np.broadcast_to(np.asarray(h, dtype=float), X.shape[:1])
        if X.shape[0] == 0:
            return X.copy()
        if mode in self.generators:
            Y = batch.taylor_flow(self.generators[mode], X, h)
            if Y is not None:
                return Y
            # beyond the series' reach: one exponential per distinct duration, gathered per run
            durations, which = np.unique(h, return_inverse=True)
            if durations.size <= 8:
                E = self._exponentials(mode, durations, (1.0,))[:, 0][which.reshape(-1)]
            elif durations.size <= X.shape[0] // 8:
                E = batched_expm(self.generators[mode], durations)[which.reshape(-1)]
            else:
                E = batched_expm(self.generators[mode], h)
            return np.einsum("kij,kj->ki", E[:, :self.n, :self.n], X) + E[:, :self.n, self.n]
        if mode in self.too_stiff:
            return np.full_like(X, np.nan)
        rhs = self.model.modes[mode].rhs
        count = max(1, int(np.ceil(self.mode_substeps.get(mode, self.substeps) * np.max(h) / self.dt)))
        return rk4_steps(rhs, X, (h / count)[:, None], count)

    def _grid_states(self, mode: str, Y0: np.ndarray, count: int, met=None) -> np.ndarray:
        """States at up to ``count`` successive grid points, ``Y0`` being the first: (N, K, n),
        ``K <= count`` ending where every run has met its event (``met(states, j0)`` says which
        runs meet one among the columns ``j0...`` of ``states``).

        Linear: in windows of grid points, :data:`FIRST_WINDOW` and each next one twice as
        long up to :data:`MAX_WINDOW`, the states ``[x_j; 1] = P^(j - a) [x_a; 1]`` from the
        last state ``x_a`` of the window before (``P`` the one-step matrix: one product per
        window, and at most ``MAX_WINDOW + 1`` powers). A large model followed by a few runs
        (fewer than ``n - 16``: a replay) steps instead, ``[x_j; 1] = P [x_{j-1}; 1]``: ``N n^2``
        operations per grid point rather than the ``n^3`` of each power. Nonlinear: RK4 steps,
        checked every :data:`STIFFNESS_CHECK` (events, and the stability of the steps:
        :meth:`more_substeps`).
        """
        N = Y0.shape[0]
        done = np.zeros(N, dtype=bool)
        if mode in self.powers:
            Z = np.concatenate([Y0, np.ones((N, 1))], axis=1)            # (N, n+1): [x_a; 1]
            windows, a, j0 = [], 0, 0
            width = FIRST_WINDOW if met is not None else MAX_WINDOW
            stepping = N < self.n - 16
            while j0 < count and not done.all():
                j1 = min(count, j0 + width)
                if stepping:
                    windows.append(self._stepped(mode, Z, j0 - a, j1 - j0))
                else:
                    P = self.powers[mode][j0 - a:j1 - a, :self.n, :]     # (j1 - j0, n, n+1)
                    windows.append((Z @ P.reshape(-1, self.n + 1).T).reshape(N, j1 - j0, self.n))
                if met is not None:
                    done |= met(windows[-1], j0)
                a, Z[:, :self.n] = j1 - 1, windows[-1][:, -1]
                j0, width = j1, min(2 * width, MAX_WINDOW)
            return np.concatenate(windows, axis=1)
        out = np.empty((N, count, self.n))
        out[:, 0] = Y0
        checked, j = 0, 1
        while j < count:
            j1 = min(count, j + STIFFNESS_CHECK)
            for k in range(j, j1):
                out[:, k] = self.propagate(mode, out[:, k - 1], self.dt)
            if self.more_substeps(mode, out[:, j - 1], out[:, j1 - 1]):
                continue                    # unstable steps: the same grid steps again, with more substeps
            j = j1
            if met is not None:
                done |= met(out[:, checked:j], checked)
                checked = j
                if done.all():
                    return out[:, :j]
        return out

    def _stepped(self, mode: str, Z: np.ndarray, first: int, count: int) -> np.ndarray:
        """States ``P^(first + k) [x; 1]`` for ``k < count`` from ``Z = [x; 1]`` (N, n+1), by
        successive products with the one-step matrix: (N, count, n)."""
        step = self.powers[mode][1].T                                    # (n+1, n+1)
        z = Z if first == 0 else Z @ self.powers[mode][first].T
        out = np.empty((Z.shape[0], count, self.n))
        for k in range(count):
            if k:
                z = z @ step
            out[:, k] = z[:, :self.n]
        return out

    def _first_entry(self, mode: str, X: np.ndarray, h: np.ndarray, guard) -> np.ndarray:
        """Earliest time in ``(0, h]`` at which ``guard`` holds (it holds at ``h``), by bisection."""
        return self._bisect(mode, X, h, lambda Z: np.all(guard(Z) <= 0, axis=1))[1]

    def invariant_scale(self, mode: str):
        """The magnitudes of the rows of ``mode``'s invariant, ``X -> (N, m)``: the scale of
        their tolerances (:func:`reach.model.constraints.row_magnitudes` over
        :func:`value_sources`), compiled on first use."""
        return self._scale(("invariant", mode), self.model.modes[mode].invariant)

    def _scale(self, key: tuple, constraints: list):
        """The magnitudes of ``constraints`` (:meth:`invariant_scale`), kept under ``key``."""
        if key not in self.scales:
            self.scales[key] = row_magnitudes(constraints, self.model.symbols, self.sources)
        return self.scales[key]

    def inside(self, mode: str, X: np.ndarray) -> np.ndarray:
        """Whether each state of ``X`` (N, n) lies in the invariant of ``mode``: every margin at
        most ``INVARIANT_TOLERANCE (1 + m)``, ``m`` the magnitude its row combines
        (:func:`reach.model.constraints.row_magnitudes`)."""
        return _holds(self.model.modes[mode].invariant_margins(X), INVARIANT_TOLERANCE, self.invariant_scale(mode), X)

    def _last_inside(self, mode: str, X: np.ndarray, h: np.ndarray) -> tuple:
        """``(s, x(s))``: the latest time in ``[0, h)`` at which the runs are still inside the
        invariant (inside at 0 to :meth:`inside`'s tolerance, outside at ``h``), by bisection,
        and the state there. The midpoints are tested exactly (every margin at most 0), so
        ``x(s)`` is the start state or a state the bisection found exactly inside: never
        beyond the invariant by more than the start state is."""
        inv = self.model.modes[mode].invariant_margins
        lo, _, x_lo = self._bisect(mode, X, h, lambda Z: ~np.all(inv(Z) <= 0, axis=1))
        return lo, x_lo

    def _bisect(self, mode: str, X: np.ndarray, h: np.ndarray, before) -> tuple:
        """``(lo, hi, x(lo))``, ``hi - lo = h 2^-BISECTION_STEPS``: :data:`BISECTION_STEPS`
        halvings of ``[0, h]`` (one interval per run), keeping the left half where
        ``before(x(mid))`` holds (the instant sought is at or before the midpoint), the right one
        otherwise; ``x(lo)`` is ``X`` or the last midpoint state where ``before`` failed.

        A linear mode carries the state at ``lo``: the midpoint lies ``w_j = h 2^-j`` after it
        at halving ``j``, so ``[x(mid); 1] = expm(M w_j) [x(lo); 1]``, with the exponentials of
        :meth:`_exponentials` (shared by every search from the same ``h``). A nonlinear mode
        integrates from 0 to each midpoint."""
        lo, hi = np.zeros_like(h), h.copy()
        x_lo = X.copy()
        if mode not in self.generators:
            for _ in range(BISECTION_STEPS):
                mid = 0.5 * (lo + hi)
                Z = self.propagate(mode, X, mid)
                left = before(Z)
                hi = np.where(left, mid, hi)
                lo = np.where(left, lo, mid)
                x_lo = np.where(left[:, None], x_lo, Z)
            return lo, hi, x_lo
        durations, which = np.unique(h, return_inverse=True)
        which = which.reshape(-1)
        halvings = tuple(2.0 ** -np.arange(1, BISECTION_STEPS + 1))
        kept = self._exponentials(mode, durations, halvings) if durations.size <= 8 else None
        n = self.n
        for j in range(BISECTION_STEPS):
            w = 2.0 ** (-j - 1)
            E = (kept[:, j] if kept is not None else batched_expm(self.generators[mode], durations * w))[which]
            Z = np.einsum("kij,kj->ki", E[:, :n, :n], x_lo) + E[:, :n, n]
            mid = lo + h * w
            left = before(Z)
            hi = np.where(left, mid, hi)
            lo = np.where(left, lo, mid)
            x_lo = np.where(left[:, None], x_lo, Z)
        return lo, hi, x_lo

    def _exponentials(self, mode: str, durations: np.ndarray, fractions: tuple) -> np.ndarray:
        """``expm(M d f)`` for each duration ``d`` and fraction ``f``: (D, F, n+1, n+1), kept
        per mode, duration and fractions (a few durations recur: a grid step, the rest of one)
        within :data:`EXPONENTIALS_BYTES`."""
        found = {d: self.exponentials.get((mode, d, fractions)) for d in durations}
        missing = np.array([d for d, E in found.items() if E is None])
        if missing.size:
            M = self.generators[mode]
            F = len(fractions)
            fresh = batched_expm(M, np.outer(missing, fractions)).reshape(missing.size, F, *M.shape)
            if sum(E.nbytes for E in self.exponentials.values()) + fresh.nbytes > EXPONENTIALS_BYTES:
                self.exponentials.clear()
            for d, E in zip(missing, fresh):
                found[d] = self.exponentials[mode, d, fractions] = E
        return np.stack([found[d] for d in durations])

    # --------------------------------------------------------------- runs
    def run(self, x0: np.ndarray, switch_times: np.ndarray | None = None, record: bool = False,
            observers=(), kicks=None, signal=None, branches: Branches | None = None,
            deadline: float = math.inf) -> Trajectories:
        """Simulate runs from ``x0`` (N, n) with window switch instants ``switch_times`` (N,).

        ``observers``: callables ``f(t, X, mode_index, rows)`` (``t`` per row) called with the
        visited states. ``kicks(k, count) -> (count, n)``: disturbance added at ``k * step``.
        ``signal = (step, values[, switch])``: the varying bounded inputs (``model.varying_inputs``)
        are piecewise constant, ``values[r, k]`` on ``[k step, (k+1) step)`` for run ``r``
        (``values`` is (N, K, m); the last piece lasts to the horizon); with ``switch`` (N, K)
        booleans, run ``r`` also takes, in a piece where ``switch[r, k]``, a may-transition with
        a general guard: at ``k step`` where one is enabled there (at time 0 after the urgent
        transitions of the initial state), and otherwise at the first instant in the piece that
        its guard is entered (held at no earlier point of the segment), located as an urgent
        guard's entry, where it is enabled there: the earliest switch, as the
        invariant's exit is the latest. ``branches``: which
        of several enabled transitions each run takes (:class:`Branches`; the first by default).
        ``deadline`` (a ``time.time()`` instant: a time budget): the runs still under way when it
        passes stop where they are, counted as blocked there and in ``Trajectories.cut`` (one
        linear mode without events steps every run at once to the horizon and is not cut).
        """
        X = np.array(x0, dtype=float).reshape(-1, self.n).copy()
        N = X.shape[0]
        check_size(self.model, self.dt, N)
        tau = np.full(N, np.nan) if switch_times is None else np.array(switch_times, dtype=float).reshape(N)
        recorder = _Recorder() if record else None
        runs = _Runs(X, np.full(N, self.mode_names.index(self.model.initial.mode)), np.zeros(N), tau,
                     np.full(N, np.nan), list(observers) + ([recorder] if recorder else []),
                     branches or Branches(), np.zeros(N, dtype=int), np.zeros(N, dtype=int),
                     [[] for _ in range(N)] if record else None, np.zeros(N, dtype=bool))
        mode, t, blocked_at = runs.mode, runs.t, runs.blocked_at
        kick_step = self.model.disturbance.step if (kicks is not None and self.model.disturbance) else None
        if signal is not None:
            if kick_step:
                raise ValueError("input signals and disturbance kicks together are not supported")
            kick_step, values = float(signal[0]), np.asarray(signal[1], dtype=float)
            if not self.on_grid(kick_step):
                raise ValueError(f"the signal's pieces ({kick_step:g}) are not a multiple of the step {self.dt:g}")
            switch = None if len(signal) < 3 or signal[2] is None else np.asarray(signal[2], dtype=bool)
            columns = np.array([u.index for u in self.model.varying_inputs], dtype=int)

            def kicks(k, sel):
                piece = min(k, values.shape[1] - 1)
                if columns.size:
                    X[np.ix_(sel, columns)] = values[sel, piece]
                if switch is not None:
                    runs.eager[sel] = switch[sel, piece]
                    if k > 0:
                        self._take_may(sel[switch[sel, piece]], runs)

            kicks(0, np.arange(N))
            following = self._signal_stops(kick_step, values, switch)
        elif kick_step:
            disturbance = kicks

            def kicks(k, sel):
                X[sel] += disturbance(k, sel.size)

            def following(k, sel):
                return k + 1
        next_kick = np.zeros(N) if kick_step else np.full(N, np.inf)
        kick_count = np.zeros(N, dtype=int)
        start = np.flatnonzero(self.inside(self.model.initial.mode, X))
        blocked_at[np.setdiff1d(np.arange(N), start)] = 0.0      # not an initial state of the automaton
        runs.watch(start)
        self._urgent_now(start, runs)
        if signal is not None and switch is not None:
            first = start[switch[start, 0]]
            self._take_may(first[np.isnan(blocked_at[first])], runs)
        if self._eventless():
            self._step_eventless(X, mode, t, kicks if kick_step else None, kick_step, runs.watchers)
            return self._trajectories(runs, recorder)
        horizon = self.model.horizon
        cell = np.full(N, -1.0)                # grid cell of each run's time at the last pass
        burst = np.zeros(N, dtype=int)         # passes without leaving that cell
        cut, cut_rows = 0, np.empty(0, dtype=int)
        while True:
            active = np.flatnonzero((t < horizon - 1e-12) & np.isnan(blocked_at))
            if active.size == 0:
                self._urgent_now(np.flatnonzero(np.isnan(blocked_at)), runs)    # jumps due at the horizon
                break
            if time.time() > deadline:         # the caller's time budget: stop the runs under way
                blocked_at[active], cut, cut_rows = t[active], active.size, active
                break
            now = np.floor(t[active] / self.dt)
            stuck = now == cell[active]
            burst[active] = np.where(stuck, burst[active] + 1, 0)
            cell[active] = now
            zeno = active[burst[active] > MAX_PASSES_PER_STEP]
            if zeno.size:                      # a Zeno run: jumps accumulate inside one step
                blocked_at[zeno] = t[zeno]
                active = np.setdiff1d(active, zeno)
                if active.size == 0:
                    break
            if kick_step:   # disturbance kicks due now
                due = active[np.abs(next_kick[active] - t[active]) <= 1e-9 * max(1.0, horizon)]
                if due.size:
                    for k in np.unique(kick_count[due]):
                        kicks(int(k), due[kick_count[due] == k])
                    kick_count[due] = following(kick_count[due], due)
                    next_kick[due] = np.where(kick_count[due] >= 0, kick_count[due] * kick_step, np.inf)
                    self._urgent_now(due[np.isnan(blocked_at[due])], runs)   # a kick may land a run in a guard
                    active = active[np.isnan(blocked_at[active])]
            for m_index, name in enumerate(self.mode_names):
                rows = active[mode[active] == m_index]
                if rows.size:
                    self._segment(name, rows, runs, next_kick)
        traj = self._trajectories(runs, recorder)
        traj.cut, traj.cut_rows = cut, cut_rows
        return traj

    @staticmethod
    def _trajectories(runs: _Runs, recorder) -> Trajectories:
        N = runs.X.shape[0]
        if recorder is None:
            return Trajectories(runs.X, runs.mode, runs.blocked_at, runs.branched)
        return Trajectories(runs.X, runs.mode, runs.blocked_at, runs.branched, recorder.paths(N),
                            {r: list(names) for r, names in enumerate(runs.taken)})

    def on_grid(self, step: float) -> bool:
        """Whether pieces of length ``step`` start on the grid over the whole horizon: ``step`` a
        multiple of ``dt`` up to a drift of 1e-9 of the horizon. A signal's pieces must (callers
        refine the grid to it: :func:`reach.backends.montecarlo.replay`)."""
        ratio = step / self.dt
        pieces = int(np.ceil(self.model.horizon / step))
        return round(ratio) >= 1 and abs(ratio - round(ratio)) * pieces * self.dt <= 1e-9 * max(1.0, self.model.horizon)

    def _signal_stops(self, step: float, values: np.ndarray, switch: np.ndarray | None):
        """``following(k, rows)``: for each run of ``rows`` at piece start ``k``, the next piece
        start at which its segment must stop (-1: none before the horizon).

        A piece start changes nothing where the inputs keep their values and no switch is asked
        for; on the grid (``step`` a multiple of ``dt``, :meth:`on_grid`) the states a segment
        visits through it are those it would visit stopping there, so only the other piece starts
        stop a segment: where the values change, where a switch is asked or was asked in the
        piece before (every start past the last piece if its switch is asked).
        """
        N, K = values.shape[:2]
        stop = np.zeros((N, K + 1), dtype=bool)
        stop[:, 1:K] = np.any(values[:, 1:] != values[:, :-1], axis=2)
        if switch is not None:
            stop[:, 1:K] |= switch[:, 1:] | switch[:, :-1]       # a switch asked for, or no longer
        # after[r, k]: the first stop of run r after piece start k (K if none among the pieces)
        index = np.where(stop, np.arange(K + 1), K)
        index[:, K] = K
        after = np.minimum.accumulate(index[:, ::-1], axis=1)[:, ::-1][:, 1:]
        every = np.zeros(N, dtype=bool) if switch is None else switch[:, -1]

        def following(k, rows):
            nxt = after[rows, np.minimum(k, K - 1)]
            beyond = np.where(every[rows], np.maximum(k + 1, K), -1)
            return np.where(nxt < K, nxt, beyond)

        return following

    def _eventless(self) -> bool:
        """One linear mode with no transitions and no invariant: nothing can happen but the flow."""
        (name, mode), = self.model.modes.items() if len(self.model.modes) == 1 else [(None, None)]
        return (mode is not None and name in self.powers and not self.model.transitions
                and not mode.invariant)

    def _step_eventless(self, X, mode, t, kicks, kick_step, watchers):
        """Grid stepping ``x <- Phi x + phi`` with kicks: the fast path for disturbed LTI models.

        Kick ``j`` lands at its instant ``j kick_step`` (those before the horizon), whatever
        ``dt``: on the grid point it lies on (to 1e-9 of the horizon, as the general path takes a
        kick due), after that point is watched; between two grid points, the step is cut there
        (the exact flow over each part) and the state just before the kick is watched, as the
        general path's segments end at a kick (:meth:`_kick_plan`).

        The observers see the states a block of steps at a time (:func:`.batch.notify_block`,
        at most :data:`EVENTLESS_BLOCK_VALUES` numbers), in time order: one call per step cost
        a replay of a 120,000-step input signal 6 s."""
        (name,) = self.model.modes
        E = self.powers[name][1]
        Phi, phi = E[:self.n, :self.n].T, E[:self.n, self.n]
        N = X.shape[0]
        rows = np.arange(N)
        horizon = self.model.horizon
        steps = int(np.ceil(horizon / self.dt - 1e-9))    # the horizon may have been cut
        on_grid, between = self._kick_plan(kick_step if kicks is not None else None, steps)
        size = max(1, min(steps + len(between), EVENTLESS_BLOCK_VALUES // max(1, N * self.n)))
        times, states, filled = np.empty((size, N)), np.empty((size, self.n, N)), [0]

        def flush() -> None:
            if filled[0]:
                k = filled[0]
                batch.notify_block(watchers, times[:k], states[:k], np.ones((k, N), dtype=bool), int(mode[0]), rows)
                filled[0] = 0

        def advance(to: float, h: float, full: bool, kick: int | None) -> None:
            X[:] = X @ Phi + phi if full else self.propagate(name, X, h)
            t[:] = to
            times[filled[0]], states[filled[0]] = to, X.T
            filled[0] += 1
            if filled[0] == size:
                flush()
            if kick is not None:
                kicks(kick, rows)

        if kicks is not None:
            kicks(0, rows)
        pending = iter(between + [(np.inf, None)])
        instant, j = next(pending)
        for k in range(steps):
            at, end = k * self.dt, min((k + 1) * self.dt, horizon)
            while instant < end:                        # kicks between this step's grid points
                advance(instant, instant - at, False, j)
                at = instant
                instant, j = next(pending)
            full = at == k * self.dt and end == (k + 1) * self.dt
            advance(end, self.dt if full else end - at, full, on_grid.get(k + 1))
        flush()

    def _kick_plan(self, kick_step: float | None, steps: int) -> tuple[dict, list]:
        """Where the kicks ``j >= 1`` at ``j kick_step`` before the horizon land on a grid of
        ``steps`` steps: ``({grid index: j}, [(instant, j), ...])``, the second those more
        than 1e-9 of the horizon from every grid point before the last, in time order
        (none without kicks)."""
        if kick_step is None:
            return {}, []
        horizon = self.model.horizon
        tol = 1e-9 * max(1.0, horizon)
        on_grid, between = {}, []
        for j in range(1, int(np.ceil((horizon - tol) / kick_step))):
            instant = j * kick_step
            k = int(round(instant / self.dt))
            if 1 <= k < steps and abs(k * self.dt - instant) <= tol:
                on_grid[k] = j
            else:
                between.append((instant, j))
        return on_grid, between

    def _enabled(self, options: list, X: np.ndarray, winner: np.ndarray | None = None,
                 tolerance: float = INVARIANT_TOLERANCE) -> tuple:
        """``(guards, enabled)``, (R, T) each, of the transitions ``options`` (``(tr, guard)``
        pairs) at the states ``X`` (R, n): where each guard holds (margins at most ``tolerance
        (1 + m)``, ``m`` the magnitude the row combines,
        :func:`reach.model.constraints.row_magnitudes`; the option ``winner[r]`` holds by
        construction -- its guard located the event, as the window's instant does for its
        transition, whose guard is given as None), and where the transition is enabled: its
        guard holds and the target's invariant holds at the reset state ``y`` (margins at most
        ``INVARIANT_TOLERANCE (1 + max(m(x), m(y)))``: the rounding of the state before the jump
        stays allowed after a reset that shrinks it)."""
        R, T = X.shape[0], len(options)
        guards, enabled = np.zeros((R, T), dtype=bool), np.zeros((R, T), dtype=bool)
        for j, (tr, guard) in enumerate(options):
            if guard is not None:                       # (the window transition's is its instant)
                guards[:, j] = _holds(guard(X), tolerance, self._scale(("guard", tr.name), tr.guard), X)
            if winner is not None:
                guards[:, j] |= winner == j
            sel = np.flatnonzero(guards[:, j])
            if sel.size:
                Y = self.resets[tr.name](X[sel]) if tr.name in self.resets else X[sel]
                enabled[sel, j] = _holds(self.model.modes[tr.target].invariant_margins(Y), INVARIANT_TOLERANCE,
                                         self.invariant_scale(tr.target), X[sel], Y)
        return guards, enabled

    def _jump(self, rows: np.ndarray, options: list, enabled: np.ndarray, runs: _Runs) -> np.ndarray:
        """The runs ``rows`` (one mode) each take one of the ``enabled`` (R, T) transitions of
        ``options`` (:meth:`Branches.pick`), the watchers see the states they land in; returns
        the runs that jumped (those with an enabled option)."""
        names = [tr.name for tr, _ in options]
        chosen = runs.branches.pick(rows, runs.count[rows], enabled, names)
        runs.branched[rows] += enabled.sum(axis=1) > 1
        for j, (tr, _) in enumerate(options):
            sel = rows[chosen == j]
            if sel.size == 0:
                continue
            runs.count[sel] += runs.branches.advances(sel, runs.count[sel], [tr.name] * sel.size)
            if tr.window is not None:
                runs.tau[sel] = np.nan                  # the window transition is taken once
            runs.mode[sel] = self.mode_names.index(tr.target)
            if tr.name in self.resets:
                runs.X[sel] = self.resets[tr.name](runs.X[sel])
            if runs.taken is not None:
                for r in sel:
                    runs.taken[r].append(tr.name)
            runs.watch(sel)
        return rows[chosen >= 0]

    def _urgent_now(self, rows: np.ndarray, runs: _Runs, left: int | None = None,
                    left_X: np.ndarray | None = None) -> None:
        """The runs ``rows`` at one instant (the start, after a jump from mode index ``left``
        out of the states ``left_X``, or after a kick) take the transitions they must take at
        once, watched after each jump: an enabled urgent one whose guard holds, and in a
        timeless mode any enabled one (guards tested exactly, every margin at most 0, as a
        segment tests urgent guards: a run that has just left a guard does not jump back on
        rounding).

        At one instant a run does not take a jump that lands it in a mode and state it has
        already been in at that instant: such a cycle of jumps would be Zeno (two closed guards
        that meet, ``s >= phi`` out of a layer and ``s <= phi`` into it, both hold on the
        boundary), so the transition that would close it is not taken then, and the run stays
        where it is (the flow decides). A jump whose reset changes the state goes on (a counter
        ``n := n + 1`` through a mode where no time passes comes back to the mode it left, one
        higher). A run that must jump and has none enabled (an urgent guard holds, or it is in
        a timeless mode) is blocked there, as is one still jumping after
        :data:`MAX_JUMPS_AT_INSTANT` jumps at the instant (a reset that never repeats a state)."""
        count = len(self.mode_names)
        seen = np.full((rows.size, count, runs.X.shape[1]), np.nan)    # (run, mode): its state there
        slot = np.full(runs.X.shape[0], -1)
        slot[rows] = np.arange(rows.size)
        if left is not None:
            seen[np.arange(rows.size), left] = left_X
            seen[np.arange(rows.size), runs.mode[rows]] = runs.X[rows]
        for _ in range(MAX_JUMPS_AT_INSTANT):
            if not rows.size:
                return
            moved = []
            modes = runs.mode[rows].copy()         # a run that jumps in this round waits for the next
            for m_index in np.unique(modes):
                name = self.mode_names[m_index]
                sel = rows[modes == m_index]
                options = self.instant[name]
                guards, enabled = self._enabled(options, runs.X[sel], tolerance=0.0)
                back = self._back(options, runs.X[sel], seen[slot[sel]])
                enabled &= ~back
                urgent = len(self.urgent[name])
                must = np.full(sel.size, name in self.timeless) | (guards & ~back)[:, :urgent].any(axis=1)
                stuck = sel[must & ~enabled.any(axis=1)]
                runs.blocked_at[stuck] = runs.t[stuck]
                can = enabled.any(axis=1)
                go = sel[can]
                if go.size:
                    seen[slot[go], m_index] = runs.X[go]
                    jumped = self._jump(go, options, enabled[can], runs)
                    seen[slot[jumped], runs.mode[jumped]] = runs.X[jumped]
                    moved.append(jumped)
            rows = np.concatenate(moved) if moved else rows[:0]
        runs.blocked_at[rows] = runs.t[rows]

    def _back(self, options: list, X: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """``(R, T)``: where option ``j`` (``(tr, guard)``) would bring run ``r`` at ``X[r]`` to
        a mode and state it has already been in at this instant (``seen[r, mode]``, NaN where
        it has not been in that mode): the jump that would close a cycle of jumps at one instant."""
        back = np.zeros((X.shape[0], len(options)), dtype=bool)
        for j, (tr, _) in enumerate(options):
            after = self.resets[tr.name](X) if tr.name in self.resets else X
            back[:, j] = np.all(seen[:, self.mode_names.index(tr.target)] == after, axis=1)
        return back

    def _take_may(self, rows: np.ndarray, runs: _Runs) -> None:
        """Each run of ``rows`` (at a piece start) takes an enabled may-transition with a
        general guard, if it has one, and then what it must take at once; then again from
        where it landed, at the same instant, as long as one is enabled that does not bring it
        back to a mode and state it has been in at this instant (a network's synchronised jump
        and a local one that both hold there, ``e`` then ``A -> B``, are taken together; two
        guards that hold everywhere, ``a -> b`` and ``b -> a``, give one jump, not a cycle).
        The guard must hold up to rounding only, margins at most ``SWITCH_TOLERANCE (1 + m)``
        per row (a few units in the last place: ``x' = 1`` from 0 is 1 - 1e-16 at t = 1 by the
        flow's exponential, and a switch asked for at ``x >= 1`` there is meant), not the looser
        ``INVARIANT_TOLERANCE``: a switch asked for at an instant is no event that located the
        guard, so a wider tolerance would let a run jump where the guard has not yet been met."""
        count = len(self.mode_names)
        seen = np.full((rows.size, count, runs.X.shape[1]), np.nan)    # (run, mode): its state there
        slot = np.full(runs.X.shape[0], -1)
        slot[rows] = np.arange(rows.size)
        for _ in range(MAX_JUMPS_AT_INSTANT):
            rows = rows[np.isnan(runs.blocked_at[rows])]
            if not rows.size:
                return
            moved = []
            modes = runs.mode[rows].copy()         # the modes before any of these runs jumps
            for m_index in np.unique(modes):
                name = self.mode_names[m_index]
                sel = rows[modes == m_index]
                if not self.exits[name]:
                    continue
                seen[slot[sel], m_index] = runs.X[sel]
                _, enabled = self._enabled(self.exits[name], runs.X[sel], tolerance=SWITCH_TOLERANCE)
                enabled &= ~self._back(self.exits[name], runs.X[sel], seen[slot[sel]])
                before = runs.X[sel].copy()
                jumped = self._jump(sel, self.exits[name], enabled, runs)
                self._urgent_now(jumped, runs, m_index, before[np.isin(sel, jumped)])
                moved.append(jumped)
            rows = np.concatenate(moved) if moved else rows[:0]

    def _event(self, rows: np.ndarray, Xe: np.ndarray, times: np.ndarray, options: list,
               winner: np.ndarray | None, runs: _Runs) -> None:
        """The runs ``rows`` (one mode) reach an event at ``times`` in the states ``Xe``: the
        watchers see them there, then each takes one of the enabled ``options`` (``winner``: per
        run, the option whose guard located the event) and what it must take at once; a run
        with none enabled is blocked there."""
        source = int(runs.mode[rows[0]])
        runs.X[rows], runs.t[rows] = Xe, times
        runs.watch(rows)
        _, enabled = self._enabled(options, Xe, winner)
        runs.blocked_at[rows[~enabled.any(axis=1)]] = times[~enabled.any(axis=1)]
        go = np.flatnonzero(enabled.any(axis=1))
        if go.size:
            jumped = self._jump(rows[go], options, enabled[go], runs)
            self._urgent_now(jumped, runs, source, Xe[go][np.isin(rows[go], jumped)])

    def _segment(self, name, rows, runs: _Runs, next_kick):
        """Advance ``rows`` (all in mode ``name``) to their next event, kick, or the horizon."""
        horizon = self.model.horizon
        if name not in self.tables:
            self.tables[name] = batch.table_for(self, name)
        table = self.tables[name]
        if table is not None:
            for start in range(0, rows.size, BATCH_RUNS):
                batch.segment_chunk(self, name, rows[start:start + BATCH_RUNS], runs, next_kick, horizon, table)
            return
        span = float(np.max(np.minimum(next_kick[rows], horizon) - runs.t[rows], initial=0.0))
        count = min(self.steps + 1, int(np.ceil(span / self.dt)) + 2)
        per_run = max(1, CHUNK_VALUES // (count * self.n))
        eager = runs.eager[rows] if self.exits[name] else np.zeros(rows.size, dtype=bool)
        for group, may in ((rows[~eager], False), (rows[eager], True)):
            for start in range(0, group.size, per_run):
                self._segment_chunk(name, group[start:start + per_run], runs, next_kick, horizon, may)

    def segment_limits(self, name, rows, t, tau, next_kick, horizon):
        """``(t0, k0, end, win_time, stop_at, count)`` of the runs ``rows`` in mode ``name``:
        their start, first grid point after it, segment end (next kick or horizon), the window
        transition's time where it falls in the segment, the known stop and the number of grid
        points to look at."""
        t0 = t[rows]
        k0 = np.floor(t0 / self.dt + 1e-9).astype(int) + 1                 # first grid point after t0
        end = np.minimum(next_kick[rows], horizon)
        win_time = np.full(rows.size, np.inf)
        if self.window[name] is not None:
            w = tau[rows]
            win_time = np.where((w >= t0 - 1e-12) & (w <= end), np.maximum(w, t0), np.inf)
        stop_at = np.minimum(end, win_time)                                # known limits
        count = int(np.max(np.ceil(np.minimum(stop_at, horizon) / self.dt - 1e-9) - k0 + 1, initial=0)) + 1
        return t0, k0, end, win_time, stop_at, count

    def _segment_chunk(self, name, rows, runs: _Runs, next_kick, horizon, eager: bool = False):
        """Advance ``rows`` to their next event (an urgent guard's entry, the window's instant,
        the invariant's exit; with ``eager``, also the entry of a may-transition's guard that
        held at no earlier point of the segment) or the segment's end."""
        X = runs.X
        n_rows = rows.size
        t0, k0, end, win_time, stop_at, count = self.segment_limits(name, rows, runs.t, runs.tau, next_kick,
                                                                    horizon)
        count = max(1, min(count, self.steps + 2 - int(k0.min())))
        first = k0 * self.dt
        Y0 = self.propagate(name, X[rows], np.maximum(first - t0, 0.0))
        grid_t = (k0[:, None] + np.arange(count)[None, :]) * self.dt       # (R, count)

        guards = self.urgent[name] + (self.exits[name] if eager else [])
        # where each guard may be entered: urgent ones anywhere; a may-transition's (eager runs)
        # only where it does not hold at the segment's start (it is entered, not sat in)
        fresh = [np.ones(n_rows, dtype=bool) if j < len(self.urgent[name]) else
                 ~np.all(guard(X[rows]) <= 0, axis=1) for j, (_, guard) in enumerate(guards)]

        def met(states, j0):
            j1 = j0 + states.shape[1]
            done = grid_t[:, j1 - 1] >= stop_at
            for (_, guard), entered in zip(guards, fresh):
                G = guard(states.reshape(-1, self.n)).reshape(n_rows, j1 - j0, -1)
                done |= np.any(np.all(G <= 0, axis=2), axis=1) & entered
            return done

        Y = self._grid_states(name, Y0, count, met)
        count = Y.shape[1]
        grid_t = grid_t[:, :count]
        finite = np.isfinite(Y[:, :, 0])
        valid = (grid_t <= stop_at[:, None] + 1e-12) & finite
        flat = (Y if finite.all() else np.where(finite[:, :, None], Y, 0.0)).reshape(-1, self.n)
        # the earliest urgent guard entry
        event_time, event_tr = win_time.copy(), np.where(np.isfinite(win_time), 0, -1)
        for j_tr, (tr, guard) in enumerate(guards, start=1):
            G = guard(flat).reshape(n_rows, count, -1)
            inside = np.all(G <= 0, axis=2) & valid & fresh[j_tr - 1][:, None]
            hit = np.flatnonzero(inside.any(axis=1))
            if hit.size:
                j = inside[hit].argmax(axis=1)
                prev_t = np.where(j == 0, t0[hit], grid_t[hit, np.maximum(j - 1, 0)])
                prev_x = np.where((j == 0)[:, None], X[rows[hit]], Y[hit, np.maximum(j - 1, 0)])
                s = self._first_entry(name, prev_x, grid_t[hit, j] - prev_t, guard)
                when = prev_t + s
                better = when < event_time[hit]
                event_time[hit[better]] = when[better]
                event_tr[hit[better]] = j_tr
            if j_tr > len(self.urgent[name]):
                continue                # (a may-transition's guard crossed between grid points: not followed)
            when = self.crossings[name].earliest(j_tr - 1, t0, X[rows], grid_t, Y, valid, event_time)
            better = when < event_time
            event_time[better], event_tr[better] = when[better], j_tr
        # invariant: the first grid point outside it (before the event) ends the run's visits
        outside = ~self.inside(name, flat).reshape(n_rows, count) & valid & (grid_t < event_time[:, None])
        blocked = outside.any(axis=1)
        block_j = np.where(blocked, outside.argmax(axis=1), count)
        seen = valid & (grid_t < event_time[:, None]) & (np.arange(count)[None, :] < block_j[:, None])
        batch.notify_block(runs.watchers, grid_t.T, Y.transpose(1, 2, 0), seen.T, int(runs.mode[rows[0]]), rows)
        last = np.where(seen.any(axis=1), (seen * np.arange(count)).max(axis=1), -1)
        last_t = np.where(last >= 0, grid_t[np.arange(n_rows), np.maximum(last, 0)], t0)
        last_x = np.where((last >= 0)[:, None], Y[np.arange(n_rows), np.maximum(last, 0)], X[rows])
        block_t = grid_t[np.arange(n_rows), np.minimum(block_j, count - 1)]
        self._finish(name, rows, runs, end, event_time, event_tr, blocked, block_t, last_t, last_x,
                     lambda Z, h: self.propagate(name, Z, h), guards)

    def _finish(self, name, rows, runs: _Runs, end, event_time, event_tr, blocked, block_t, last_t, last_x,
                propagate, guards: list | None = None) -> None:
        """The end of a segment of the runs ``rows`` in mode ``name``, from the last grid state
        each visited (``last_t``, ``last_x``): a run with an event at ``event_time <= end``
        (``event_tr`` 0 the window, ``j`` the ``j``-th urgent transition) goes to it and jumps,
        the others go to the segment end (a kick, a piece start or the horizon). A run
        ``blocked`` (outside the invariant at the grid time ``block_t``), or whose state at its
        event or segment end lies outside the invariant, left it after ``last_t``: it stops at
        the last instant inside (:meth:`_last_inside`), watched there, and takes an enabled
        transition whose guard holds there, urgent or a may-transition with a general guard, or
        is blocked. (An urgent guard that holds only on the invariant's boundary, SpaceEx's
        ``x == 2`` out of ``x <= 2``, holds at no grid point: it is met at the exit.) An urgent
        guard met between the last grid state and the stop (a slab crossed, a row dipped into:
        :mod:`reach.model.crossing`) is an event there. ``propagate(X, h)`` advances states without
        event; ``guards``: the transitions ``event_tr`` counts (the mode's urgent ones by default;
        an eager segment's also its may-transitions, :meth:`_segment_chunk`)."""
        horizon = self.model.horizon
        has_event = ~blocked & (event_tr >= 0) & (event_time <= end)
        stop_t = np.where(blocked, block_t, np.where(has_event, event_time, end))
        go = np.flatnonzero(~blocked)
        X_stop = propagate(last_x[go], stop_t[go] - last_t[go])
        # a guard met after the last grid state (not searched again before an urgent event: the
        # grid interval holding it was searched)
        open_end = np.flatnonzero(~(has_event[go] & (event_tr[go] > 0)))
        if self.crossings[name] and open_end.size:
            late = go[open_end]
            for j_tr in range(len(self.urgent[name])):
                when = self.crossings[name].earliest(j_tr, last_t[late], last_x[late], stop_t[late][:, None],
                                                     X_stop[open_end][:, None, :],
                                                     np.ones((late.size, 1), dtype=bool), stop_t[late])
                c = np.flatnonzero(when < stop_t[late])
                if c.size:
                    has_event[late[c]], event_time[late[c]], event_tr[late[c]] = True, when[c], j_tr + 1
                    stop_t[late[c]] = when[c]
                    X_stop[open_end[c]] = propagate(last_x[late[c]], when[c] - last_t[late[c]])
        left = ~self.inside(name, X_stop) & np.isfinite(X_stop).all(axis=1)
        blocked[go[left]] = True
        has_event &= ~blocked
        urgent = self.urgent[name]
        b = np.flatnonzero(blocked)
        if b.size:
            s, x_exit = self._last_inside(name, last_x[b], stop_t[b] - last_t[b])
            self._event(rows[b], x_exit, last_t[b] + s, urgent + self.exits[name], None, runs)
        urgent = urgent if guards is None else guards
        window = [(self.window[name], None)]
        for kind in (0, 1):
            e = np.flatnonzero(has_event[go] & ((event_tr[go] > 0) == bool(kind)))
            if e.size:
                options = urgent if kind else window
                winner = event_tr[go[e]] - 1 if kind else np.zeros(e.size, dtype=int)
                self._event(rows[go[e]], X_stop[e], event_time[go[e]], options, winner, runs)
        q = np.flatnonzero(~blocked[go] & ~has_event[go])
        if q.size:
            sel = rows[go[q]]
            runs.X[sel], runs.t[sel] = X_stop[q], end[go[q]]
            off_grid = end[go[q]] - last_t[go[q]] > 1e-9 * max(1.0, horizon)
            runs.watch(sel[off_grid])


def _holds(margins: np.ndarray, tolerance: float, scale, *states: np.ndarray) -> np.ndarray:
    """Whether every margin (N, m) of each state is at most ``tolerance (1 + m)``, ``m`` the
    larger of the row's magnitudes ``scale(X)`` (N, m) over ``states`` (the state before a
    jump and after its reset); the magnitudes are computed only where a margin exceeds
    ``tolerance`` (below it the row holds at any scale)."""
    holds = np.all(margins <= tolerance, axis=1)
    near = np.flatnonzero(~holds)
    if near.size and tolerance > 0:
        size = np.maximum.reduce([scale(X[near]) for X in states])
        holds[near] = np.all(margins[near] <= tolerance * (1.0 + size), axis=1)
    return holds


class _Recorder:
    """Observer that keeps every visited state (for replays and plots of a few runs)."""

    def __init__(self):
        self.chunks = []

    def __call__(self, t, X, mode, rows):
        self.chunks.append((np.asarray(t, float).copy(), X.copy(), np.asarray(mode).copy(), rows.copy()))

    def paths(self, n_runs: int) -> dict:
        t = np.concatenate([c[0] for c in self.chunks])
        X = np.concatenate([c[1] for c in self.chunks])
        m = np.concatenate([c[2] for c in self.chunks])
        r = np.concatenate([c[3] for c in self.chunks])
        order = np.lexsort((np.arange(t.size), t, r))      # by run, then time, then arrival
        t, X, m, r = t[order], X[order], m[order], r[order]
        return {int(i): (t[r == i], m[r == i], X[r == i]) for i in range(n_runs)}


def _powers(step: np.ndarray, count: int) -> np.ndarray:
    """``[I, step, step^2, ..., step^(count-1)]``."""
    out = np.empty((count,) + step.shape)
    out[0] = np.eye(step.shape[0])
    for k in range(1, count):
        out[k] = out[k - 1] @ step
    return out


class _Powers:
    """``[I, step, step^2, ...]`` up to ``limit`` entries, computed as far as they are asked for.

    Segments between disturbance kicks need only a few powers; a model with many modes and a
    long horizon would otherwise hold ``modes x steps`` matrices, and a replay of a large model,
    which steps by ``step`` alone, would form 64 powers of a 274 x 274 matrix for nothing.
    """

    def __init__(self, step: np.ndarray, limit: int):
        self.step, self.limit = step, limit
        self.table = _powers(step, min(limit, 2))

    def __getitem__(self, index):
        stop = index.stop if isinstance(index, slice) else (index[0] if isinstance(index, tuple) else index)
        if isinstance(stop, slice):
            stop = stop.stop
        need = self.limit if stop is None else min(self.limit, int(stop) + 1)
        if need > self.table.shape[0]:
            size = min(self.limit, max(need, 2 * self.table.shape[0]))
            more = np.empty((size,) + self.step.shape)
            k = self.table.shape[0]
            more[:k] = self.table
            while k < size:                     # P^(k + j) = P^k P^j for j < k: doubling
                m = min(k, size - k)
                np.matmul(more[k - 1] @ self.step, more[:m], out=more[k:k + m])
                k += m
            self.table = more
        return self.table[index]


def _reset_function(tr, model):
    """Vectorised reset map of a transition (unlisted states keep their value)."""
    import sympy

    fns = {i: sympy.lambdify([model.symbols], e, modules="numpy") for i, e in tr.reset.items()}

    def reset(X):
        Y = X.copy()
        for i, fn in fns.items():
            Y[:, i] = np.broadcast_to(np.asarray(fn(X.T), dtype=float), X.shape[:1])
        return Y

    return reset
