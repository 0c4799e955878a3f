"""The Monte Carlo referee: vectorised sampling of the same model, falsification first.

Safety properties. Runs are drawn in three rounds, each one numpy batch:

1. *structured*: corners, face centres and the centre of the initial box, crossed with the
   ends and middle of the abort window;
2. *random*: ``samples`` i.i.d. uniform initial states and switch instants;
3. *search*: a cross-entropy falsifier that resamples around the runs that came closest to
   the unsafe set (``search_rounds`` generations);
4. *optimiser* (``optimise``, deterministic models): the robustness (smallest depth) minimised
   over the initial state, the switch instant and the input values by differential evolution
   seeded with the closest runs so far, then a batched projected gradient descent (a grid
   refinement for at most two parameters) (:mod:`reach.backends.falsify`).

A polytopic initial set is sampled by its vertices, facet points and centre (structured) and
uniformly by hit-and-run (random); time-varying bounded inputs are piecewise-constant signals
with pieces of ``input_step`` (default horizon / 20): constant extremes and bang-bang signals
in the structured round, uniform pieces in the random one, perturbed by the search
(:mod:`reach.backends.initial_sampling`); where the sampled runs of a safety property find no
violation and the initial mode is linear, a round of bang-bang signals on finer pieces aimed
into the unsafe set by the maximum principle
(:func:`reach.backends.initial_sampling.extremal_runs`) comes before the search. May-transitions with general guards are taken where a
run would leave its invariant, and, in the random and search rounds, also at piece starts
where the run's switching signal says so and a guard holds (each with probability
``SWITCH_PROBABILITY``). A counterexample carries its input and switching signal.

Where several transitions can be enabled at one jump (two urgent guards that hold together,
may-transitions with general guards at an exit), each run carries choice values
(:func:`reach.backends.initial_sampling.branch_plan`): every structured run is repeated once
per option ``k`` of the largest jump (``B`` options), taking the ``k``-th enabled one at every
jump (values ``(k + 1/2) / B``), so each branch is covered deterministically; the i.i.d. runs
draw uniform values (a uniform choice at each jump); where some sampled run met such a choice,
the search perturbs them and the optimiser takes them as parameters. A counterexample names
the transition taken at each jump.

The structured and i.i.d. runs are one simulation shared by all safety properties of the call
(one monitor each; whole blocks of grid states are tested at once, every unsafe piece of a
mode stacked in one matrix whose rows the simulator's block product evaluates with the guards
and invariants: :mod:`reach.model.batch`). The i.i.d. runs are simulated in fixed blocks of
:data:`SAMPLE_BLOCK`, grouped into batches of ``batch`` runs that run in this process, on
``jobs`` local processes or on a Dask ``scheduler`` (:mod:`reach.executors`): a seed gives the
same answer whatever the split and the executor.

Every visited state is checked against every unsafe piece of the property. A violation is
replayed alone (:func:`replay`) and returned as UNSAFE with its counterexample. Otherwise the
answer is UNKNOWN with the closest approach (depth) found and a one-sided 95 % Clopper-Pearson
upper bound on the violation probability from the i.i.d. round. Monte Carlo never says SAFE.

Reach and reach-avoid properties of stochastic models are estimated from ``samples`` runs
with Gaussian kicks; the probability is a 95 % Wilson interval.

Event properties (the extremum of a quantity along the run) take the same structured and
i.i.d. runs (initial states, input signals, branches), one simulation shared by all event
properties of the call, then the same search and optimiser on the run's margin, the distance
of its extremum from the requirement (:mod:`reach.backends.event_sampling`).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from reach.backends.event_sampling import EventMonitor, event_details, replay_event
from reach.backends.falsify import Budget, falsify
from reach.backends.initial_sampling import (PolytopeSampler, branch_plan, extremal_runs, input_signals,
                                             input_step, structured_signals)
from reach.backends.options import parse_options, ranged
from reach.errors import InputError
from reach.model.automaton import HybridAutomaton
from reach.model.constraints import NUMERICAL_TOLERANCE, equality_rows, lambdify_margins
from reach.model.simulate import MAX_STEPS, Branches, Simulator, check_size, single_threaded
from reach.result import Counterexample, Result, Status
from reach.spec.properties import BoundEvent, BoundReach, BoundReachAvoid, BoundSafety
from reach.stats import clopper_pearson_upper, wilson

NAME = "montecarlo"
KEPT_RUNS = 40                 # sampled runs kept for pictures (option keep_sets)
SWITCH_PROBABILITY = 0.3       # chance that a random run takes an enabled may-transition at a piece start
REPLAY_TOLERANCE = 1e-9        # relative rounding allowed on the bounds a replayed run must meet (check_run)


@dataclass
class Options:
    samples: int = ranged(1000, 1, 10_000_000)           # i.i.d. runs (safety) or runs (stochastic reach)
    search_rounds: int = ranged(3, 0, 1000)        # cross-entropy generations after the i.i.d. round
    search_size: int = ranged(200, 1, 1_000_000)        # runs per generation
    seed: int = 0
    dt: float | None = None        # simulator grid step (model default if None)
    batch: int = ranged(20000, 1, 1_000_000)            # runs per batch (an executor unit; stochastic estimates)
    input_step: float | None = None  # piece length of sampled input signals (horizon/20 if None)
    jobs: int = ranged(1, 1, 256)  # local worker processes for the i.i.d. batches
    scheduler: object = None       # or a Dask scheduler address (or Client) to run them on
    optimise: bool = True          # falsification by optimisation after the search (reach.backends.falsify)
    generations: int = ranged(20, 0, 100_000)     # differential evolution generations
    population: int = ranged(40, 5, 1_000_000)    # runs per generation
    polish: int = ranged(1000, 0, 1_000_000)      # polish runs from the best point (reach.backends.falsify)
    keep_sets: bool = False        # safety, events: KEPT_RUNS sampled runs in Result.sets (pictures)
    max_seconds: float | None = ranged(None, 0.0, open_low=True)  # safety: no search or optimisation past it

    @classmethod
    def from_dict(cls, options: dict | None) -> "Options":
        return cls(**parse_options(cls, options, "montecarlo"))


# ------------------------------------------------------------------ the abort window

def switch_window(model: HybridAutomaton):
    """``(lo, hi, forced)`` of the model's may-transition window, or None if it has none.

    ``forced``: every source mode's invariant bounds the clock by ``hi`` (the ARCH abort),
    so every run switches; otherwise some runs never switch.
    """
    windows = {(tr.window[0], tr.window[1], tr.window[2]) for tr in model.transitions if tr.window}
    if not windows:
        return None
    if len(windows) > 1:
        raise ValueError("more than one distinct switching window")
    clock, lo, hi = windows.pop()
    forced = True
    for tr in model.transitions:
        if tr.window is None:
            continue
        hs = model.modes[tr.source].invariant_halfspaces
        bounded = hs is not None and any(
            row[clock] > 0 and np.count_nonzero(row) == 1 and g / row[clock] <= hi + 1e-12
            for row, g in zip(*hs))
        forced = forced and bounded
    return lo, min(hi, model.horizon), forced


# ------------------------------------------------------------------ monitoring

_COMPILED: dict = {}


def _compiled_tests(model: HybridAutomaton, prop: BoundSafety):
    """``(tests, stacked)`` of ``prop`` in ``model``'s modes, compiled once per (model, property):
    ``tests[mode index]`` the state-by-state violation test, ``stacked[mode index] = (L, c,
    starts)`` every unsafe piece's ``H x <= g`` stacked (pieces starting at rows ``starts``) where
    all pieces are linear and the property uses the standard test."""
    key = (id(model), id(prop))
    if key in _COMPILED and _COMPILED[key][0] is model and _COMPILED[key][1] is prop:
        return _COMPILED[key][2]
    names = list(model.modes)
    tests = {names.index(m): prop.violation(m) for m in prop.modes if prop.violation(m) is not None}
    stacked = {}
    standard = type(prop).violation is BoundSafety.violation          # not a subclass's own test
    for m_index, m in enumerate(names):
        hs = prop.halfspace_pieces(m) if m_index in tests and standard else None
        if any(equality_rows(piece) for piece in prop.pieces.get(m, [])):
            hs = None                   # an equality (an instant) takes the state-by-state test
        if hs:
            stacked[m_index] = (np.vstack([H for H, _ in hs]), np.concatenate([g for _, g in hs]),
                                np.cumsum([0] + [H.shape[0] for H, _ in hs[:-1]]))
    if len(_COMPILED) > 256:
        _COMPILED.clear()
    _COMPILED[key] = (model, prop, (tests, stacked))
    return tests, stacked


class SafetyMonitor:
    """Tracks, per run, the smallest depth into the unsafe set and the first violation."""

    def __init__(self, model: HybridAutomaton, prop: BoundSafety, n_runs: int):
        self.tests, self.stacked = _compiled_tests(model, prop)
        self.min_depth = np.full(n_runs, np.inf)
        self.violation_time = np.full(n_runs, np.nan)
        self.violation_state = np.full((n_runs, model.n), np.nan)
        self.violation_mode = np.full(n_runs, -1)

    def margin_rows(self, m_index: int):
        """``(H, g)``: every unsafe piece of the property in mode ``m_index`` stacked, whose
        margins ``H x - g`` :meth:`block` reads; None where it tests state by state."""
        stacked = self.stacked.get(m_index)
        return None if stacked is None else stacked[:2]

    def block(self, t, X, seen, m_index, rows, margins=None):
        """A whole block of grid states of one mode at once: ``X`` (B, n, R) at times ``t``
        (B, R), ``seen`` (B, R) the states the runs ``rows`` (distinct) visit, ``margins`` (B,
        k, R) the values of :meth:`margin_rows` there if the simulator computed them. The same
        test as :meth:`__call__`: a piece's depth is the largest of its margins ``H x - g``, the
        depth the smallest over the pieces, a violation a depth below ``-NUMERICAL_TOLERANCE (1
        + |x|_inf)``. That bound is at most ``-NUMERICAL_TOLERANCE``, so only the runs whose
        smallest depth in the block is below it are searched for their first violation."""
        if m_index not in self.tests or not seen.any():
            return
        if m_index not in self.stacked:            # a nonlinear piece: the state-by-state test
            j, r = np.nonzero(seen)
            self(t[j, r], np.moveaxis(X, 1, 2)[j, r], np.full(j.size, m_index), rows[r])
            return
        L, c, starts = self.stacked[m_index]
        if margins is None:
            margins = np.matmul(L, X)
            margins -= c[:, None]
        if seen.all() and starts.size == margins.shape[1]:        # one constraint per piece
            low = margins.min(axis=(0, 1))
        else:
            low = np.where(seen, _piece_depth(margins, starts), np.inf).min(axis=0)
        self.min_depth[rows] = np.minimum(self.min_depth[rows], low)
        r = np.flatnonzero((low < -NUMERICAL_TOLERANCE) & np.isnan(self.violation_time[rows]))
        if r.size:
            depth = _piece_depth(margins[:, :, r], starts)
            violated = seen[:, r] & (depth < -NUMERICAL_TOLERANCE * (1.0 + np.abs(X[:, :, r]).max(axis=1)))
            first = violated.any(axis=0)
            r, j = r[first], violated[:, first].argmax(axis=0)
            self.violation_time[rows[r]] = t[j, r]
            self.violation_state[rows[r]] = X[j, :, r]
            self.violation_mode[rows[r]] = m_index

    def __call__(self, t, X, mode, rows):
        """States one by one (``t``, ``X`` (N, n), ``mode``, ``rows`` per state; a run may appear
        several times, in time order): the property's own test, or where its pieces are
        stacked the same test from their rows (as :meth:`block`)."""
        for m_index, test in self.tests.items():
            sel = np.flatnonzero(mode == m_index)
            if sel.size == 0:
                continue
            if m_index in self.stacked:
                L, c, starts = self.stacked[m_index]
                Y = X[sel]
                d = _piece_depth((L @ Y.T - c[:, None])[None], starts)[0]
                violated = d < -NUMERICAL_TOLERANCE * (1.0 + np.abs(Y).max(axis=1))
            else:
                violated, d = test(X[sel])
            r = rows[sel]                      # a run may appear many times, in time order
            np.minimum.at(self.min_depth, r, d)
            hits = np.flatnonzero(violated & np.isnan(self.violation_time[r]))
            if hits.size:
                _, first = np.unique(r[hits], return_index=True)
                k = sel[hits[first]]
                self.violation_time[rows[k]] = t[k]
                self.violation_state[rows[k]] = X[k]
                self.violation_mode[rows[k]] = m_index

    ARRAYS = ("min_depth", "violation_time", "violation_state", "violation_mode")

    def arrays(self) -> tuple:
        """What the monitor found, per run (to send back from a worker and merge)."""
        return tuple(getattr(self, a) for a in self.ARRAYS)

    @classmethod
    def merged(cls, model: HybridAutomaton, prop: BoundSafety, parts: list) -> "SafetyMonitor":
        """One monitor over the runs of several (``arrays()`` of each, in run order)."""
        out = cls(model, prop, 0)
        for i, name in enumerate(cls.ARRAYS):
            setattr(out, name, np.concatenate([q[i] for q in parts]))
        return out

    def first_violation(self) -> int | None:
        """The violating run that went deepest into the unsafe set, if any."""
        hit = np.flatnonzero(np.isfinite(self.violation_time))
        return None if hit.size == 0 else int(hit[np.argmin(self.min_depth[hit])])


def _piece_depth(G: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``(B, R)``: the smallest over the pieces (starting at rows ``starts`` of ``G`` (B, k,
    R)) of the largest of their margins."""
    if starts.size == G.shape[1]:
        return G.min(axis=1)
    bounds = list(starts) + [G.shape[1]]
    depth = G[:, bounds[0]:bounds[1]].max(axis=1)
    for a, b in zip(bounds[1:-1], bounds[2:]):
        np.minimum(depth, G[:, a:b].max(axis=1), out=depth)
    return depth


@dataclass
class Replay:
    """One re-simulated run and whether it violates the property."""

    violated: bool
    time: float
    mode: str
    state: np.ndarray
    depth: float
    initial_state: np.ndarray
    switch_time: float | None
    dt: float
    trajectory: dict = field(default_factory=dict)
    input_signal: dict | None = None
    transitions: list = field(default_factory=list)

    def counterexample(self, model: HybridAutomaton, prop, found_by: str) -> Counterexample:
        return Counterexample(
            model=model.name, property=prop.id, model_file=model.file, property_file=prop.file,
            initial_state=list(map(float, self.initial_state)),
            switch_time=None if self.switch_time is None else float(self.switch_time),
            violation_time=float(self.time), violation_mode=self.mode,
            violation_state=list(map(float, self.state)), dt=self.dt,
            trajectory=self.trajectory, found_by=found_by, input_signal=self.input_signal,
            transitions=list(self.transitions))


def replay(model: HybridAutomaton, prop: BoundSafety, initial_state, switch_time: float | None,
           dt: float | None = None, input_signal: dict | None = None, branches: Branches | None = None) -> Replay:
    """Simulate exactly one run (abort at ``switch_time``, inputs ``input_signal``, its choices
    among transitions enabled together by ``branches``, :class:`reach.model.simulate.Branches`;
    the first enabled by default) on the simulator's general per-segment path (independent of
    the block path the sampled runs took) and check ``prop`` along it (an event property: its
    extremum along the run, :func:`reach.backends.event_sampling.replay_event`). The replay
    records the transitions the run took, so its counterexample replays along the same
    branches."""
    with single_threaded():
        signal = _signal_of(model, input_signal)
        sim = _replay_simulator(model, dt, signal)
        if isinstance(prop, BoundEvent):
            rep = replay_event(model, prop, initial_state, sim.dt, branches, signal)
            rep.input_signal = signal_record(model, signal, 0)
            return rep
        return _replay_safety(model, prop, initial_state, switch_time, sim, signal, branches)


def _replay_simulator(model: HybridAutomaton, dt: float | None, signal) -> Simulator:
    """The simulator of a replay: step ``dt`` (the model's default if None), refined so that
    every piece of ``signal`` starts on its grid (a witness's signal replayed at another step,
    or a file whose dt is missing), on its general per-segment path (not the block path)."""
    sim = Simulator(model, dt)
    if signal is not None and not sim.on_grid(signal[0]):
        sim = Simulator(model, signal[0] / math.ceil(signal[0] / sim.dt - 1e-9))
    sim.tables = dict.fromkeys(model.modes)
    return sim


def _replay_safety(model: HybridAutomaton, prop: BoundSafety, initial_state, switch_time: float | None,
                   sim: Simulator, signal, branches: Branches | None) -> Replay:
    x0 = np.asarray(initial_state, dtype=float).reshape(1, -1)
    tau = None if switch_time is None else np.array([float(switch_time)])
    monitor = SafetyMonitor(model, prop, 1)
    if not model.initial.is_box:
        init = model.initial
        if not PolytopeSampler(init.polytope, init.low, init.high).contains(x0)[0]:
            return Replay(False, float("nan"), "", np.full(model.n, np.nan), float("inf"), x0[0], switch_time,
                          sim.dt, {"note": "the initial state is outside the initial polytope"})
    traj = sim.run(x0, tau, record=True, observers=[monitor], signal=signal, branches=branches)
    rep = _replay_result(model, monitor, traj, sim, x0, switch_time)
    rep.input_signal = signal_record(model, signal, 0)
    rep.transitions = traj.transitions[0]
    return rep


def _signal_of(model: HybridAutomaton, data: dict | None):
    """``(step, values (1, K, m), switch (1, K) or None)`` from a counterexample's input
    signal, checked; None when the run needs none."""
    names = [u.name for u in model.varying_inputs]
    if data is None and not names:
        return None
    if not isinstance(data, dict) or data.get("inputs") != names:
        raise InputError(f"the model has time-varying inputs ({', '.join(names)}): the counterexample "
                         "needs their input_signal", field="input_signal")
    try:
        step = float(data["step"])
        values = np.asarray(data["values"], dtype=float)
        switch = None if data.get("switch") is None else np.asarray(data["switch"], dtype=int)
    except (KeyError, TypeError, ValueError):
        raise InputError("input_signal needs step and a list of values per piece", field="input_signal") from None
    if values.ndim != 2 or values.shape[1] != len(names) or values.shape[0] == 0 or values.shape[0] > 1_000_000:
        raise InputError(f"expected a list of pieces of {len(names)} values", field="input_signal")
    if switch is not None and (switch.shape != values.shape[:1] or np.any((switch != 0) & (switch != 1))):
        raise InputError("switch needs one 0 or 1 per piece", field="input_signal")
    lo = np.array([u.low for u in model.varying_inputs])
    hi = np.array([u.high for u in model.varying_inputs])
    if not (step > 0 and np.isfinite(step)):
        raise InputError("the step must be a positive number", field="input_signal")
    if model.horizon / step > MAX_STEPS:
        raise InputError(f"a step of {step:g} cuts the horizon {model.horizon:g} into more than {MAX_STEPS:.0e} "
                         "pieces", field="input_signal")
    if not np.all(np.isfinite(values)):
        raise InputError("expected finite values", field="input_signal")
    outside = (values < lo - REPLAY_TOLERANCE * (1 + np.abs(lo))) | (values > hi + REPLAY_TOLERANCE * (1 + np.abs(hi)))
    if outside.any():
        k, j = np.argwhere(outside)[0]
        raise InputError(f"value {values[k, j]:.6g} of '{names[j]}' on piece {k} is outside its "
                         f"range [{lo[j]:g}, {hi[j]:g}]", field="input_signal")
    values = np.clip(values, lo, hi)                # rounding only
    return step, values[None, :, :], None if switch is None else switch[None, :].astype(bool)


def check_run(model: HybridAutomaton, initial_state: list, switch_time: float | None, input_signal: dict | None,
              transitions: list | None, dt: float | None = None) -> None:
    """Refuse (InputError naming the field) a run that is none of ``model``'s: an initial state of
    the wrong length, not finite, outside the initial set or the initial mode's invariant; a
    switch time where the model has no window or outside it; an input signal with values
    outside the inputs' ranges; a transition the model does not have. Bounds are met to
    ``REPLAY_TOLERANCE (1 + |bound|)`` (rounding in a written file)."""
    if dt and not (model.horizon / MAX_STEPS <= dt <= model.horizon):
        raise InputError(f"a replay step of {dt:g} is outside [{model.horizon / MAX_STEPS:g}, {model.horizon:g}] "
                         f"(the horizon {model.horizon:g} in at most {MAX_STEPS:.0e} steps)", field="dt")
    x = np.asarray(initial_state, dtype=float)
    if x.shape != (model.n,):
        raise InputError(f"initial_state has {len(initial_state)} values, the model {model.n}", field="initial_state")
    if not np.all(np.isfinite(x)):
        raise InputError("expected a list of finite numbers", field="initial_state")
    init = model.initial
    slack = REPLAY_TOLERANCE * (1.0 + np.maximum(np.abs(init.low), np.abs(init.high)))
    outside = np.flatnonzero((x < init.low - slack) | (x > init.high + slack))
    if outside.size:
        i = outside[0]
        span = f"= {init.low[i]:g}" if init.low[i] == init.high[i] else f"in [{init.low[i]:g}, {init.high[i]:g}]"
        raise InputError(f"{model.state[i]} = {x[i]:.10g} is outside the initial set ({model.state[i]} {span})",
                         field="initial_state")
    if not init.is_box and not PolytopeSampler(init.polytope, init.low, init.high).contains(x[None, :])[0]:
        raise InputError("the state is outside the initial set (its polytope)", field="initial_state")
    margins = model.modes[init.mode].invariant_margins(x[None, :])[0]
    if np.any(margins > REPLAY_TOLERANCE * (1.0 + np.abs(x).max())):
        raise InputError(f"the state is outside the initial set: the invariant of mode '{init.mode}' does not hold",
                         field="initial_state")
    if switch_time is not None:
        window = switch_window(model)
        if window is None:
            raise InputError("the model has no switching window", field="switch_time")
        lo, hi, _ = window
        if not lo - REPLAY_TOLERANCE * (1 + abs(lo)) <= switch_time <= hi + REPLAY_TOLERANCE * (1 + abs(hi)):
            raise InputError(f"{switch_time:g} is outside the switching window [{lo:g}, {hi:g}]", field="switch_time")
    _signal_of(model, input_signal)
    names = {tr.name for tr in model.transitions}
    for k, name in enumerate(transitions or []):
        if name not in names:
            raise InputError(f"unknown transition '{name}'", field=f"transitions[{k}]")


def constant_signal(model: HybridAutomaton, x0) -> dict | None:
    """The counterexample form of time-varying inputs held at their values in ``x0`` (their state
    coordinates) over the whole horizon; None for a model without such inputs."""
    if not model.varying_inputs:
        return None
    values = [[float(np.clip(x0[u.index], u.low, u.high)) for u in model.varying_inputs]]
    return {"step": float(model.horizon), "inputs": [u.name for u in model.varying_inputs], "values": values}


def signal_record(model: HybridAutomaton, signal, row: int) -> dict | None:
    """The counterexample form of run ``row``'s signal."""
    if signal is None:
        return None
    out = {"step": float(signal[0]), "inputs": [u.name for u in model.varying_inputs],
           "values": signal[1][row].tolist()}
    if len(signal) > 2 and signal[2] is not None:
        out["switch"] = signal[2][row].astype(int).tolist()
    return out


def _replay_result(model, monitor, traj, sim, x0, switch_time) -> "Replay":
    names = list(model.modes)
    violated = bool(np.isfinite(monitor.violation_time[0]))
    times, modes, states = traj.path[0]
    trajectory = {"t": times.tolist(), "mode": [names[int(m)] for m in modes], "x": states.tolist()}
    if violated:
        return Replay(True, float(monitor.violation_time[0]), names[int(monitor.violation_mode[0])],
                      monitor.violation_state[0], float(monitor.min_depth[0]), x0[0], switch_time,
                      sim.dt, trajectory)
    return Replay(False, float("nan"), "", np.full(model.n, np.nan), float(monitor.min_depth[0]), x0[0],
                  switch_time, sim.dt, trajectory)


# ------------------------------------------------------------------ sampling plans

def structured_plan(model: HybridAutomaton, window, max_corners: int = 256, rng=None):
    """Corners, face centres and centre of the initial box (a polytope: vertices, facet points,
    centre) x {window ends, middle}."""
    low, high = model.initial.low, model.initial.high
    free = np.flatnonzero(high > low)
    centre = (low + high) / 2
    points = [centre]
    if not model.initial.is_box:
        points = list(PolytopeSampler(model.initial.polytope, low, high).structured()[:4 * max_corners])
    elif free.size:
        if 2 ** free.size <= max_corners:
            signs = np.array(list(itertools.product([0, 1], repeat=free.size)))
        else:
            signs = rng.integers(0, 2, size=(max_corners, free.size))
        for s in signs:
            p = centre.copy()
            p[free] = np.where(s == 1, high[free], low[free])
            points.append(p)
        for i in free:
            for v in (low[i], high[i]):
                p = centre.copy()
                p[i] = v
                points.append(p)
    X = np.array(points)
    if window is None:
        return X, None
    lo, hi, forced = window
    taus = sorted({lo, hi, (lo + hi) / 2})
    rows = [(x, tau) for x in X for tau in taus]
    if not forced:
        rows += [(x, np.nan) for x in X]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


def random_plan(model: HybridAutomaton, window, count: int, rng):
    low, high = model.initial.low, model.initial.high
    if model.initial.is_box:
        X = low + (high - low) * rng.random((count, model.n))
    else:
        X = PolytopeSampler(model.initial.polytope, low, high).uniform(count, rng)
    if window is None:
        return X, None
    lo, hi, forced = window
    tau = lo + (hi - lo) * rng.random(count)
    if not forced:
        tau[rng.random(count) < 0.1] = np.nan
    return X, tau


def _verdict(model: HybridAutomaton, prop, rounds: list, found, sim: Simulator, details: dict) -> Result:
    """UNSAFE with its counterexample if the run ``found`` (``(round, row)`` of ``rounds``, or
    None) violates ``prop`` when replayed alone (:func:`replay`), else UNKNOWN with ``details``
    (noting a sampled violation that did not replay)."""
    if found is not None:
        k, i = found
        label, Xk, tauk, _, sig, ch = rounds[k]
        t = None if tauk is None or np.isnan(tauk[i]) else float(tauk[i])
        rep = replay(model, prop, Xk[i], t, sim.dt, signal_record(model, sig, i),
                     None if ch is None else Branches(values=ch[i:i + 1]))
        if rep.violated:
            details["found_in"] = label
            return Result(NAME, model.name, prop.id, Status.UNSAFE, details=details,
                          counterexample=rep.counterexample(model, prop, f"montecarlo/{label}"))
        details["note"] = "a sampled violation did not replay on its own"
    return Result(NAME, model.name, prop.id, Status.UNKNOWN, details=details)


def run_plan(model: HybridAutomaton, sim: Simulator, window, opts: Options, rng):
    """The runs of the first round, ``(X, tau, signal, choice, n_structured, seeding)``: the
    structured initial states (with the structured signals of the time-varying inputs,
    :func:`.initial_sampling.structured_signals`) and ``opts.samples`` i.i.d. ones (uniform
    signals); where the model has may-transitions, each structured run twice, staying in a
    mode as long as it can and leaving at the first piece start a guard holds, and the random
    runs switch at random piece starts; where transitions can be enabled together, each structured run once per branch
    (:func:`branch_plan`). ``seeding`` marks the runs the search and the optimiser may start
    from: all but those of one-switch signals, a family of neighbours that would fill their
    populations around one local minimum (they are tried as they are)."""
    Xs, taus = structured_plan(model, window, rng=rng)
    Xr, taur = random_plan(model, window, opts.samples, rng)
    signal = None
    mays = any(sim.exits.values())      # may-transitions with general guards
    if model.varying_inputs or mays:
        step = input_step(model, sim.dt, opts.input_step)
        if model.varying_inputs:        # structured states with constant extremes, bang-bang, one switch
            Vs, owner, once = structured_signals(model, Xs.shape[0], step, rng)
            Xs = Xs[owner]
            taus = None if taus is None else taus[owner]
        else:
            Vs = input_signals(model, Xs.shape[0], step, rng)
        switch = None
        if mays:                        # structured runs twice: staying as long as they can, and
            count = Xs.shape[0]         # switching at the first piece start a guard holds; random
            Xs, Vs = np.concatenate([Xs, Xs]), np.concatenate([Vs, Vs])   # ones at random piece starts
            taus = None if taus is None else np.concatenate([taus, taus])
            if model.varying_inputs:
                once = np.concatenate([once, once])
        values = np.concatenate([Vs, input_signals(model, Xr.shape[0], step, rng)])
        if mays:
            switch = np.zeros(values.shape[:2], dtype=bool)
            switch[count:Xs.shape[0]] = True
            switch[Xs.shape[0]:] = rng.random((Xr.shape[0], values.shape[1])) < SWITCH_PROBABILITY
        signal = (step, values, switch)
    X = np.concatenate([Xs, Xr])
    tau = None if window is None else np.concatenate([taus, taur])
    n_structured = Xs.shape[0]
    seeding = np.ones(X.shape[0], dtype=bool)
    if model.varying_inputs:
        seeding[:n_structured] = ~once
    choice = None
    if sim.max_options > 1:
        seeding = np.r_[np.repeat(seeding[:n_structured], sim.max_options), seeding[n_structured:]]
        X, tau, signal, choice, n_structured = branch_plan(sim.max_options, n_structured, X, tau, signal, rng)
    check_size(model, sim.dt, X.shape[0])      # all the runs' arrays are held at once
    return X, tau, signal, choice, n_structured, seeding


# ------------------------------------------------------------------ the back-end

def sampled_runs(model: HybridAutomaton, sim: Simulator, X, tau, signal, choice, structured: int,
                 kicks=None) -> list:
    """``KEPT_RUNS`` of the planned runs (half from the ``structured`` first rows -- corners and
    faces -- the rest i.i.d.) simulated again with their path recorded, under disturbance kicks
    drawn by ``kicks`` (as the checked runs are; fresh draws, so the pictured runs are samples
    like them, not the same ones), one :class:`~reach.result.SetPiece` of kind ``run`` per
    stretch in one mode."""
    from reach.result import SetPiece

    first = min(KEPT_RUNS // 2, structured)
    rows = np.r_[np.arange(first), np.arange(structured, min(X.shape[0], structured + KEPT_RUNS - first))]
    sub = None if signal is None else (signal[0], signal[1][rows], None if signal[2] is None else signal[2][rows])
    traj = sim.run(X[rows], None if tau is None else tau[rows], record=True, signal=sub, kicks=kicks,
                   branches=None if choice is None else Branches(values=choice[rows]))
    names, modes = tuple(model.state), list(model.modes)
    pieces = []
    for t, mode, states in traj.path.values():
        cuts = np.flatnonzero(np.diff(mode)) + 1
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, mode.size]):
            pieces.append(SetPiece(modes[int(mode[a])], float(t[a]), float(t[b - 1]), "run", names,
                                   times=np.asarray(t[a:b], float), points=np.asarray(states[a:b], float)))
    return pieces


class MonteCarloBackend:
    name = NAME
    varying_inputs = True          # sampled as piecewise-constant signals

    def supports(self, model: HybridAutomaton, prop) -> str | None:
        try:
            switch_window(model)
        except ValueError as exc:
            return str(exc)
        if model.varying_inputs and (model.disturbance is not None or not isinstance(prop, (BoundSafety, BoundEvent))):
            return ("time-varying inputs are sampled for safety and event properties of models without "
                    "disturbance")
        if isinstance(prop, BoundEvent) and switch_window(model) is not None:
            return "sampling an event property with an abort window is not implemented"
        if isinstance(prop, (BoundReach, BoundReachAvoid)) and model.disturbance is None:
            if not np.array_equal(model.initial.low, model.initial.high):
                return "a reach probability needs a distribution: the model has no disturbance"
        if isinstance(prop, BoundSafety) and not prop.modes:
            return f"the model has none of the property's modes ({', '.join(prop.missing_modes)})"
        return None

    def check(self, model: HybridAutomaton, prop, options: dict | None = None) -> Result:
        return self.check_many(model, [prop], options)[0]

    def check_many(self, model: HybridAutomaton, props: list, options: dict | None = None) -> list[Result]:
        """Check several properties of one model; safety ones share the sampled runs."""
        with single_threaded():
            return self._check_many(model, props, Options.from_dict(options))

    def _check_many(self, model: HybridAutomaton, props: list, opts: Options) -> list[Result]:
        results = {}
        safety = [p for p in props if isinstance(p, BoundSafety)]
        if safety:
            for prop, result in zip(safety, self._safety(model, safety, opts)):
                results[id(prop)] = result
        events = [p for p in props if isinstance(p, BoundEvent)]
        if events:
            for prop, result in zip(events, self._events(model, events, opts)):
                results[id(prop)] = result
        for prop in props:
            if not isinstance(prop, (BoundSafety, BoundEvent)):
                start = time.perf_counter()
                results[id(prop)] = self._probability(model, prop, opts)
                results[id(prop)].seconds = time.perf_counter() - start
        return [results[id(p)] for p in props]

    # ---------------------------------------------------------- safety
    def _safety(self, model, props: list[BoundSafety], opts: Options) -> list[Result]:
        """Structured and i.i.d. runs shared by all properties, then a search per property."""
        start = time.perf_counter()
        deadline = math.inf if opts.max_seconds is None else start + opts.max_seconds
        rng = np.random.default_rng(opts.seed)
        window = switch_window(model)
        sim = Simulator(model, opts.dt)
        kicks = _kicks(model, rng)
        X, tau, signal, choice, n_structured, seeding = run_plan(model, sim, window, opts, rng)
        parts, kept = _simulate_rounds(model, props, sim, opts, X, tau, signal, choice, n_structured, kicks,
                                       time.time() + (deadline - time.perf_counter()))
        if kept.size < X.shape[0]:          # the time budget left i.i.d. blocks unsimulated
            X, tau, choice = X[kept], None if tau is None else tau[kept], None if choice is None else choice[kept]
            if signal is not None:
                signal = (signal[0], signal[1][kept], None if signal[2] is None else signal[2][kept])
        sampled = X.shape[0] - n_structured
        monitors = [SafetyMonitor.merged(model, p, [q[0][i] for q in parts]) for i, p in enumerate(props)]
        blocked = sum(q[1] for q in parts)
        branching = choice is not None and sum(q[2] for q in parts) > 0    # a choice met, not only possible
        runs = []
        if opts.keep_sets:
            pictured_kicks = _kicks(model, np.random.default_rng(np.random.SeedSequence(opts.seed, spawn_key=(2 ** 32,))))
            runs = sampled_runs(model, sim, X, tau, signal, choice, n_structured, pictured_kicks)
        shared = (time.perf_counter() - start) / len(props)
        results = []
        for prop, monitor in zip(props, monitors):
            begin = time.perf_counter()
            rounds = [("structured+random", X, tau, monitor, signal, choice)]
            details = {"dt": sim.dt, "seed": opts.seed, "structured_runs": int(n_structured),
                       "random_runs": int(sampled),
                       "blocked_runs": int(blocked),
                       "assumes": "states checked at grid points and event instants only "
                                  "(a falsifier, not a proof)"}
            fails = int(np.count_nonzero(np.isfinite(monitor.violation_time[n_structured:])))
            details["violating_runs"] = fails
            details["violation_probability_upper_95"] = clopper_pearson_upper(fails, sampled)
            if sampled < opts.samples:
                details["note"] = (f"time budget of {opts.max_seconds:.3g} s (option max_seconds) ended the "
                                   f"sampling after {sampled} of {opts.samples} random runs")
            found = monitor.first_violation()
            found = None if found is None else (0, found)
            monitors_of = partial(SafetyMonitor, model, prop)
            closest = float(np.min(monitor.min_depth))
            if found is None and model.disturbance is None:
                found, depth = self._extremal(model, prop, sim, rounds, n_structured, monitors_of)
                closest = min(closest, depth)
            if found is None and model.disturbance is None:
                found = self._search(model, window, sim, rounds, opts, rng, branching, deadline, monitors_of,
                                     seeding)
            if found is None and model.disturbance is None and opts.optimise and time.perf_counter() <= deadline:
                found = self._optimise(model, prop, window, sim, rounds, opts, branching, deadline, monitors_of,
                                       seeding)
                details["optimiser_runs"] = int(rounds[-1][3].runs)
            if found is None and time.perf_counter() > deadline and "note" not in details:
                details["note"] = (f"time budget of {opts.max_seconds:.3g} s (option max_seconds) "
                                   f"ended the search")
            details["search_runs"] = int(sum(r[1].shape[0] for r in rounds[1:] if r[0].startswith("search")))
            details["closest_depth"] = min([closest] + [float(np.min(r[3].min_depth)) for r in rounds])
            if found is not None and model.disturbance is not None:
                details["note"] = ("violations were sampled under random disturbance; "
                                   "a single run is not a replayable counterexample")
                found = None
            result = _verdict(model, prop, rounds, found, sim, details)
            result.seconds = shared + time.perf_counter() - begin
            result.sets = runs
            results.append(result)
        return results

    def _extremal(self, model, prop, sim, rounds, structured: int, monitors_of):
        """The runs aimed into ``prop``'s unsafe set by the inputs
        (:func:`.initial_sampling.extremal_runs`) from the first round's structured starts, a
        round of their own (their pieces are finer than the sampled signals'): ``((round, row),
        depth)`` with the round appended when one violates, else ``(None, closest depth)``."""
        _, X, tau, _, signal, choice = rounds[0]
        plan = extremal_runs(model, prop, X[:structured], sim.dt)
        if plan is None:
            return None, math.inf
        owner, Xe, step, values = plan
        switch = None if signal[2] is None else np.zeros(values.shape[:2], dtype=bool)
        taue = None if tau is None else tau[owner]
        choicee = None if choice is None else choice[owner]
        monitor = monitors_of(Xe.shape[0])
        sim.run(Xe, taue, observers=[monitor], signal=(step, values, switch),
                branches=None if choicee is None else Branches(values=choicee))
        i = monitor.first_violation()
        if i is None:
            return None, float(np.min(monitor.min_depth))
        rounds.append(("extremal inputs", Xe, taue, monitor, (step, values, switch), choicee))
        return (len(rounds) - 1, i), float(np.min(monitor.min_depth))

    def _search(self, model, window, sim, rounds, opts: Options, rng, branching: bool, deadline: float,
                monitors_of, seeding: np.ndarray):
        """Cross-entropy falsification: resample around the runs closest to the unsafe set
        (their choice values too where a sampled run met several enabled transitions); no
        generation starts past ``deadline``. ``monitors_of(count)`` watches ``count`` runs (a
        SafetyMonitor, or an EventMonitor, whose margin is its depth); the first round's runs
        resampled are those ``seeding`` marks (:func:`run_plan`)."""
        low, high = model.initial.low, model.initial.high
        span = np.where(high > low, high - low, 0.0)
        sampler = None if model.initial.is_box else PolytopeSampler(model.initial.polytope, low, high)
        ulo = np.array([u.low for u in model.varying_inputs])
        uhi = np.array([u.high for u in model.varying_inputs])
        for g in range(opts.search_rounds):
            if time.perf_counter() > deadline:
                break
            X_all = np.concatenate([r[1] for r in rounds])
            d_all = np.concatenate([r[3].min_depth for r in rounds])
            may_seed = np.concatenate([seeding, np.ones(d_all.size - seeding.size, dtype=bool)])
            elite = np.flatnonzero(may_seed)[np.argsort(d_all[may_seed])][:max(5, opts.search_size // 10)]
            scale = 0.25 * 0.6 ** g
            pick = rng.choice(elite, opts.search_size)
            X = np.clip(X_all[pick] + rng.normal(size=(opts.search_size, model.n)) * span * scale, low, high)
            if sampler is not None:
                X = sampler.pull_inside(X)
            signal = None
            if rounds[0][4] is not None:
                step = rounds[0][4][0]
                V_all = np.concatenate([r[4][1] for r in rounds])[pick]
                V = np.clip(V_all + rng.normal(size=V_all.shape) * (uhi - ulo) * scale, ulo, uhi)
                S = None
                if rounds[0][4][2] is not None:         # flip some switching decisions
                    S_all = np.concatenate([r[4][2] for r in rounds])[pick]
                    S = S_all ^ (rng.random(S_all.shape) < SWITCH_PROBABILITY * scale)
                signal = (step, V, S)
            tau = None
            if window is not None:
                lo, hi, _ = window
                base = np.concatenate([r[2] for r in rounds])[pick]
                base = np.where(np.isnan(base), (lo + hi) / 2, base)
                tau = np.clip(base + rng.normal(size=opts.search_size) * (hi - lo) * scale, lo, hi)
            choice = None
            if branching:                               # draw some choice values again
                C = np.concatenate([r[5] for r in rounds])[pick]
                choice = np.where(rng.random(C.shape) < scale, rng.random(C.shape), C)
            monitor = monitors_of(opts.search_size)
            sim.run(X, tau, observers=[monitor], signal=signal,
                    branches=None if choice is None else Branches(values=choice))
            rounds.append((f"search{g + 1}", X, tau, monitor, signal, choice))
            i = monitor.first_violation()
            if i is not None:
                return len(rounds) - 1, i
        return None

    def _optimise(self, model, prop, window, sim, rounds, opts: Options, branching: bool, deadline: float,
                  monitors_of, seeding: np.ndarray):
        """Differential evolution and a gradient polish on the robustness, seeded with the closest runs
        (their choice values as parameters where a sampled run met several enabled transitions)
        among those ``seeding`` marks in the first round (:func:`run_plan`) and those of the
        search rounds. Appends the best run as the round ``optimiser`` (its monitor carries
        ``runs``, the cost)."""
        X_all = np.concatenate([r[1] for r in rounds])
        d_all = np.concatenate([r[3].min_depth for r in rounds])
        may_seed = np.concatenate([seeding, np.ones(X_all.shape[0] - seeding.size, dtype=bool)])
        elite = np.flatnonzero(may_seed)[np.argsort(d_all[may_seed], kind="stable")][:opts.population // 2]
        tau_all = None if window is None else np.concatenate([r[2] for r in rounds])
        signal = rounds[0][4]
        elite_signal, step, pieces, switching = None, None, 0, False
        if signal is not None:
            step, pieces, switching = signal[0], signal[1].shape[1], signal[2] is not None
            elite_signal = (step, np.concatenate([r[4][1] for r in rounds])[elite], None)
        elite_choice = np.concatenate([r[5] for r in rounds])[elite] if branching else None
        out = falsify(model, prop, window, sim, monitors_of,
                      (X_all[elite], None if tau_all is None else tau_all[elite], elite_signal, elite_choice),
                      Budget(opts.generations, opts.population, opts.polish, deadline), opts.seed,
                      step, pieces, switching, 0 if elite_choice is None else elite_choice.shape[1])
        out.monitor.runs = out.runs
        rounds.append(("optimiser", out.X, out.tau, out.monitor, out.signal, out.choice))
        return (len(rounds) - 1, 0) if out.violated else None

    # ---------------------------------------------------------- events
    def _events(self, model, props: list[BoundEvent], opts: Options) -> list[Result]:
        """The extremum of each property's quantity along the runs of :func:`run_plan` (one
        simulation shared by all), then, where no run breaks a requirement, the search and the
        optimiser on the run's margin (:class:`~reach.backends.event_sampling.EventMonitor`); a
        violating run is replayed alone before it is reported."""
        start = time.perf_counter()
        deadline = math.inf if opts.max_seconds is None else start + opts.max_seconds
        rng = np.random.default_rng(opts.seed)
        sim = Simulator(model, opts.dt)
        X, _, signal, choice, n_structured, seeding = run_plan(model, sim, None, opts, rng)
        monitors = [EventMonitor(model, prop, X.shape[0]) for prop in props]
        sim.run(X, None, observers=monitors, signal=signal,
                branches=None if choice is None else Branches(values=choice))
        runs = sampled_runs(model, sim, X, None, signal, choice, n_structured) if opts.keep_sets else []
        shared = (time.perf_counter() - start) / len(props)
        results = []
        for prop, monitor in zip(props, monitors):
            begin = time.perf_counter()
            details = event_details(prop, monitor, X.shape[0], n_structured, X.shape[0] - n_structured, sim.dt)
            rounds = [("structured+random", X, None, monitor, signal, choice)]
            found = monitor.first_violation()
            found = None if found is None else (0, found)
            monitors_of = partial(EventMonitor, model, prop)
            if found is None and model.disturbance is None and time.perf_counter() <= deadline:
                found = self._search(model, None, sim, rounds, opts, rng, choice is not None, deadline, monitors_of,
                                     seeding)
                details["search_runs"] = int(sum(r[1].shape[0] for r in rounds[1:]))
            if found is None and model.disturbance is None and opts.optimise and time.perf_counter() <= deadline:
                found = self._optimise(model, prop, None, sim, rounds, opts, choice is not None, deadline,
                                       monitors_of, seeding)
                details["optimiser_runs"] = int(rounds[-1][3].runs)
            if found is None and time.perf_counter() > deadline:
                details["note"] = f"time budget of {opts.max_seconds:.3g} s (option max_seconds) ended the search"
            details["closest_margin"] = min(float(np.min(r[3].margins())) for r in rounds)
            extrema = np.concatenate([r[3].extrema() for r in rounds])      # every round's runs
            if np.isfinite(extrema).any():
                details["sampled_range"] = (float(np.nanmin(extrema)), float(np.nanmax(extrema)))
            result = _verdict(model, prop, rounds, found, sim, details)
            result.seconds = shared + time.perf_counter() - begin
            result.sets = runs
            results.append(result)
        return results

    # ---------------------------------------------------------- reach / reach-avoid
    def _probability(self, model, prop, opts: Options) -> Result:
        rng = np.random.default_rng(opts.seed)
        sim = Simulator(model, opts.dt)
        kicks = _kicks(model, rng)
        target = lambdify_margins(prop.target, model.symbols)
        safe = lambdify_margins(prop.safe, model.symbols) if isinstance(prop, BoundReachAvoid) else None
        step = model.disturbance.step if model.disturbance is not None else sim.dt
        successes, total = 0, 0
        remaining = opts.samples
        while remaining > 0:
            count = min(opts.batch, remaining)
            remaining -= count
            X0 = model.initial.low + (model.initial.high - model.initial.low) * rng.random((count, model.n))
            ok = np.ones(count, bool)
            final = np.full((count, model.n), np.nan)

            def observe(t, X, mode, rows):
                at_target = np.abs(t - prop.at) <= 1e-9 * max(1.0, prop.at)
                if np.any(at_target):
                    final[rows[at_target]] = X[at_target]
                if safe is not None:
                    k = t / step
                    on_step = (np.abs(k - np.round(k)) <= 1e-9 * max(1.0, k.max(initial=1.0))) & (t < prop.at - 1e-9)
                    if np.any(on_step):
                        ok[rows[on_step][~_meets(safe, X[on_step])]] = False

            horizon = model.horizon
            model.horizon = prop.at
            try:
                sim.run(X0, None, observers=[observe], kicks=kicks)
            finally:
                model.horizon = horizon
            hit = ok & _meets(target, final)
            successes += int(np.count_nonzero(hit))
            total += count
        lo, hi = wilson(successes, total)
        status = Status.UNKNOWN
        details = {"samples": total, "successes": successes, "estimate": successes / total, "dt": sim.dt,
                   "seed": opts.seed, "interval": "95 % Wilson"}
        return Result(NAME, model.name, prop.id, status, probability=(lo, hi), details=details)


def _meets(margins, X) -> np.ndarray:
    """Whether each state of ``X`` meets the constraints of ``margins`` up to rounding
    (``NUMERICAL_TOLERANCE (1 + |x|_inf)``, as fsr treats a deterministic row): a clock at
    ``0.9000000000000001`` meets ``z <= 0.9`` (a state with a continuous law meets a bound
    exactly with probability 0, so only deterministic coordinates feel it)."""
    tol = NUMERICAL_TOLERANCE * (1.0 + np.abs(X).max(axis=1, initial=0.0))
    return np.all(margins(X) <= tol[:, None], axis=1)


SAMPLE_BLOCK = 1000     # i.i.d. runs always simulated together: the unit of batches


def _simulate_rounds(model, props, sim, opts: Options, X, tau, signal, choice, n_structured: int, kicks,
                     deadline: float = math.inf) -> tuple[list, np.ndarray]:
    """Simulate the structured runs (in this process) and the i.i.d. ones, monitoring every
    property; ``([(monitor arrays per property, blocked runs, runs that met a choice)], rows)``:
    the parts in the order of ``rows``, the indices of the runs simulated. No block of i.i.d.
    runs starts after ``deadline`` (a ``time.time()`` instant, which worker processes share):
    those simulated are the structured ones and a leading part of each batch's blocks.

    The i.i.d. runs are simulated in blocks of :data:`SAMPLE_BLOCK`, each block on its own
    (disturbance kicks from ``SeedSequence(seed, spawn_key=(k,))`` for block ``k``): a run's
    outcome depends on the seed and its index only, not on how the blocks are grouped into
    batches of ``batch`` runs nor on where a batch runs (in this process, on ``jobs`` local
    processes, or on a Dask ``scheduler``)."""
    def rows(a, b):
        return (X[a:b], None if tau is None else tau[a:b],
                None if signal is None else (signal[0], signal[1][a:b], None if signal[2] is None else signal[2][a:b]),
                None if choice is None else choice[a:b])

    monitors = [SafetyMonitor(model, p, n_structured) for p in props]
    Xs, taus, signals, choices = rows(0, n_structured)
    traj = sim.run(Xs, taus, observers=monitors, kicks=kicks, signal=signals,
                   branches=None if choices is None else Branches(values=choices))
    parts = [([m.arrays() for m in monitors], *_counts(traj))]
    starts = list(range(n_structured, X.shape[0], SAMPLE_BLOCK))
    blocks = [(k,) + rows(a, min(a + SAMPLE_BLOCK, X.shape[0])) for k, a in enumerate(starts)]
    per_unit = max(1, -(-opts.batch // SAMPLE_BLOCK))
    units = [(model, props, sim.dt, opts.seed, blocks[i:i + per_unit], deadline)
             for i in range(0, len(blocks), per_unit)]
    if len(units) <= 1 or (opts.jobs <= 1 and opts.scheduler is None):
        out = [simulate_blocks(*unit) for unit in units]
    else:
        from reach.executors import make_executor

        out = [None] * len(units)
        for i, (status, value) in make_executor(opts.jobs, opts.scheduler).map_unordered(simulate_blocks, units):
            if status != "ok":
                raise RuntimeError(f"a Monte Carlo batch did not finish ({status})")
            out[i] = value
    done = [j for i, unit in enumerate(out) for j in range(i * per_unit, i * per_unit + len(unit))]
    kept = np.concatenate([np.arange(n_structured)] + [np.arange(starts[j], min(starts[j] + SAMPLE_BLOCK, X.shape[0]))
                                                       for j in done]).astype(int)
    return parts + [part for unit in out for part in unit], kept


def simulate_blocks(model, props, dt, seed, blocks, deadline: float = math.inf) -> list:
    """One batch (an executor unit): each block ``(k, X, tau, signal, choice)`` of i.i.d. runs
    simulated on its own with one monitor per property, none started after ``deadline``
    (``time.time()``); ``[(monitor arrays, blocked runs, runs that met a choice)]`` of the
    blocks simulated, a leading part of ``blocks``."""
    sim = Simulator(model, dt)
    out = []
    with single_threaded():
        for k, X, tau, signal, choice in blocks:
            if time.time() > deadline:
                break
            kicks = _kicks(model, np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k,))))
            monitors = [SafetyMonitor(model, p, X.shape[0]) for p in props]
            traj = sim.run(X, tau, observers=monitors, kicks=kicks, signal=signal,
                           branches=None if choice is None else Branches(values=choice))
            out.append(([m.arrays() for m in monitors], *_counts(traj)))
    return out


def _counts(traj) -> tuple:
    """``(blocked runs, runs that met several enabled transitions at a jump)``."""
    return int(np.count_nonzero(np.isfinite(traj.blocked_at))), int(np.count_nonzero(traj.branched))


def _kicks(model: HybridAutomaton, rng):
    """Sampler of the Gaussian disturbance kicks (None for a deterministic model)."""
    dist = model.disturbance
    if dist is None:
        return None
    E = np.zeros((len(dist.enters), model.n))
    E[np.arange(len(dist.enters)), dist.enters] = 1.0

    def kicks(k: int, count: int) -> np.ndarray:
        return rng.multivariate_normal(dist.mean, dist.cov, size=count, method="eigh") @ E

    return kicks


BACKEND = MonteCarloBackend()
