"""The runs Monte Carlo samples and their simulation.

The runs of the first round (:func:`run_plan`): the structured ones (:func:`structured_plan`:
corners, face centres and centre of the initial set crossed with the ends and middle of the
abort window, :func:`switch_window`) and the i.i.d. ones (:func:`random_plan`), with their input
signals, switching signals and choice values (:mod:`.initial_sampling`).

The structured runs are at most :func:`structured_cap` (option ``structured``; by default the
larger of ``STRUCTURED_PER_SAMPLE * samples`` and what fits in :data:`STRUCTURED_WORK`
state-steps, runs x grid steps x states): where the plan has more, one run of
each of that many equal stretches of the plan is kept, drawn by the seed (:func:`spread`), so
every family of the plan (initial points, abort instants, input signals, switch decisions,
branches) keeps its share. They run in this process in batches (:class:`Batches`): a first one
of about :data:`FIRST_BATCH_WORK` state-steps (runs x grid steps x states), timed, then batches
four times larger up to :data:`BATCH_WORK`; under a time budget a batch is cut down to what the
budget has left by the times so far, none starts past it, and the runs under way stop there.

The structured and i.i.d. runs are one simulation shared by all safety properties of the call
(one monitor each, :class:`~.monitors.SafetyMonitor`). The i.i.d. runs are simulated in fixed
blocks of :data:`SAMPLE_BLOCK`, grouped into batches of ``batch`` runs that run in this process,
on ``jobs`` local processes or on a Dask ``scheduler`` (:mod:`reach.executors`): a seed gives the
same answer whatever the split and the executor.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from typing import NamedTuple

import numpy as np

from reach.backends.montecarlo.initial_sampling import (PolytopeSampler, branch_plan, input_signals, input_step,
                                                        structured_signals)
from reach.backends.montecarlo.monitors import SafetyMonitor
from reach.backends.montecarlo.options import Options
from reach.model.automaton import HybridAutomaton
from reach.model.simulate import Branches, Simulator, check_size, single_threaded

LOG = logging.getLogger("reach.montecarlo")
KEPT_RUNS = 40                 # sampled runs kept for pictures (option keep_sets)
SWITCH_PROBABILITY = 0.3       # chance that a random run takes an enabled may-transition at a piece start
STRUCTURED_WORK = 2e8         # state-steps of structured runs allowed whatever the samples (structured_cap)
STRUCTURED_PER_SAMPLE = 8      # structured runs allowed per i.i.d. sample (structured_cap)
STRUCTURED_KEY = 2 ** 32 + 1   # spawn key of the seed's draw of the structured runs kept (spread)
FIRST_BATCH_WORK = 5e7         # state-steps of the first batch of structured runs (Batches)
BATCH_WORK = 2e9               # state-steps of a batch of structured runs at most (Batches)
PROGRESS_SECONDS = 10.0        # a batch under way says how far its runs are at most this often (-v)


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


class Plan(NamedTuple):
    """The runs of the first round (:func:`run_plan`)."""

    X: np.ndarray                   # (N, n) initial states, the structured runs first
    tau: np.ndarray | None          # (N,) switch instants of the abort window
    signal: tuple | None            # (step, values (N, K, m), switch (N, K) or None)
    choice: np.ndarray | None       # (N, CHOICE_SLOTS) choice values
    structured: int                 # structured runs kept (the first rows)
    seeding: np.ndarray             # (N,) runs the search and the optimiser may start from
    planned: int                    # structured runs planned, before structured_cap
    planned_points: int             # distinct initial states of the planned structured runs


def run_plan(model: HybridAutomaton, sim: Simulator, window, opts: Options, rng) -> Plan:
    """The runs of the first round (:class:`Plan`): the structured initial states (with the
    structured signals of the time-varying inputs, :func:`.initial_sampling.structured_signals`)
    and ``opts.samples`` i.i.d. ones (uniform signals); where the model has may-transitions,
    each structured run twice, staying in a mode as long as it can and leaving where a guard is
    first entered (every piece asks for a switch: :meth:`reach.model.simulate.Simulator.run`),
    and the random runs ask in random pieces; where transitions can be enabled together, each
    structured run once per branch (:func:`branch_plan`); at most :func:`structured_cap`
    structured runs, spread over the plan (:func:`spread`). ``seeding`` marks the runs the
    search and the optimiser may start from: all but those of one-switch signals, a family of
    neighbours that would fill their populations around one local minimum (they are tried as
    they are)."""
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
            count = Xs.shape[0]         # switching where a guard is first entered; random ones
            Xs, Vs = np.concatenate([Xs, Xs]), np.concatenate([Vs, Vs])   # in random pieces
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
    planned, points = n_structured, initial_points(X[:n_structured])
    cap = structured_cap(opts, sim.steps, model.n)
    if n_structured > cap:                      # one run of each of ``cap`` stretches of the plan
        keep = np.r_[spread(n_structured, cap, opts.seed), np.arange(n_structured, X.shape[0])]
        X, tau, signal, choice = take_rows(X, tau, signal, choice, keep)
        seeding, n_structured = seeding[keep], cap
    check_size(model, sim.dt, X.shape[0])      # all the runs' arrays are held at once
    return Plan(X, tau, signal, choice, n_structured, seeding, planned, points)


def structured_cap(opts: Options, steps: int, states: int) -> int:
    """The most structured runs of a check of runs of ``steps`` grid steps on ``states`` states:
    the option ``structured``, by default the larger of ``STRUCTURED_PER_SAMPLE * samples`` and
    the runs whose work (runs x steps x states) fits in :data:`STRUCTURED_WORK` (about a second
    on a linear model). A plan of cheap runs runs whole whatever the samples; one of long runs
    is held to what the samples asked for (the suite's plans, at most a few thousand runs for
    500 samples, run whole)."""
    if opts.structured is not None:
        return int(opts.structured)
    return max(STRUCTURED_PER_SAMPLE * int(opts.samples),
               int(STRUCTURED_WORK // (max(1, steps) * max(1, states))))


def spread(total: int, count: int, seed: int) -> np.ndarray:
    """``count`` increasing indices of ``range(total)`` (``count <= total``), one drawn uniformly
    in each of ``count`` equal stretches ``[floor(k total / count), floor((k + 1) total /
    count))`` by ``SeedSequence(seed, spawn_key=(STRUCTURED_KEY,))``: spread over the whole plan,
    and unlike every ``total / count``-th run not locked on a period of the plan (the copies of a
    run per branch, per abort instant, per input corner lie next to each other)."""
    edges = np.floor(np.linspace(0, total, count + 1)).astype(int)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(STRUCTURED_KEY,)))
    return edges[:-1] + np.floor(rng.random(count) * (edges[1:] - edges[:-1])).astype(int)


def take_rows(X, tau, signal, choice, rows):
    """The runs ``rows`` of a plan: ``(X, tau, signal, choice)`` restricted to them."""
    return (X[rows], None if tau is None else tau[rows],
            None if signal is None else (signal[0], signal[1][rows], None if signal[2] is None else signal[2][rows]),
            None if choice is None else choice[rows])


def initial_points(X: np.ndarray) -> int:
    """How many distinct initial states the runs ``X`` start from."""
    return 0 if X.shape[0] == 0 else int(np.unique(X, axis=0).shape[0])


class Batches:
    """The batches ``(a, b)`` of ``total`` structured runs of ``steps`` grid steps on ``states``
    states, in this process: iterating yields them one by one, timing each (the time between a
    yield and the next request is the batch's).

    Without a budget the sizes depend on the plan only (a seed draws the same disturbance kicks
    whatever the machine): all at once where the whole work (runs x steps x states) is at most
    :data:`BATCH_WORK`, else a first batch of about :data:`FIRST_BATCH_WORK` (at least one run),
    then each four times the one before, at most :data:`BATCH_WORK`. Under a budget
    (``deadline``, a ``time.time()`` instant) all at once only up to :data:`FIRST_BATCH_WORK`;
    no batch after the first starts past it, and a batch is cut down to the runs that the time
    left allows by the line ``seconds = c0 + c1 runs`` fitted to the batches so far (``c0``:
    what a batch costs whatever its runs, as the per-step work of one linear mode); the runs
    under way stop at the deadline (one linear mode without events, which the simulator steps
    to the horizon at once, only at the batch's end). ``-v`` shows the plan, each batch's end
    with the time the rest should take by that line, and, while a batch runs long, how far its
    runs are (:meth:`watcher`)."""

    def __init__(self, total: int, steps: int, states: int, deadline: float = math.inf,
                 what: str = "structured runs", horizon: float | None = None):
        self.total, self.what, self.horizon = int(total), what, horizon
        self.per_run = float(max(1, steps)) * max(1, states)
        self.deadline = deadline
        self.timings: list[tuple[int, float]] = []
        self.done = 0
        self.steps, self.states = int(steps), int(states)
        self.begin = time.perf_counter()

    def sizes(self, size: int, left: int) -> list[int]:
        """The sizes of the batches of ``left`` runs from one of ``size`` on, without a budget."""
        top = max(1, int(BATCH_WORK // self.per_run))
        out = []
        while left > 0:
            out.append(min(size, left))
            left -= out[-1]
            size = max(size, min(4 * size, top))
        return out

    def first_size(self) -> int:
        if self.total * self.per_run <= (BATCH_WORK if math.isinf(self.deadline) else FIRST_BATCH_WORK):
            return self.total
        return int(min(self.total, max(1, FIRST_BATCH_WORK // self.per_run)))

    def line(self) -> tuple[float, float]:
        """``(c0, c1)`` of the batches so far: ``c0`` from a least-squares line, held between 0
        and the quickest batch's time, then ``c1`` the pooled time per run beyond it (one batch:
        ``c0 = 0`` and its time per run, which overestimates the larger batches after it)."""
        runs = np.array([n for n, _ in self.timings], dtype=float)
        secs = np.array([s for _, s in self.timings], dtype=float)
        c0 = 0.0
        if np.unique(runs).size >= 2:
            c0 = float(np.clip(np.polyfit(runs, secs, 1)[1], 0.0, secs.min()))
        return c0, max(float((secs - c0).sum() / runs.sum()), 1e-9)

    def estimate(self, size: int) -> float:
        """Seconds the runs left should take in batches from one of ``size`` on."""
        c0, c1 = self.line()
        left = self.total - self.done
        return len(self.sizes(size, left)) * c0 + c1 * left

    def __iter__(self):
        size = self.first_size()
        if self.total:
            LOG.info("%s: %d x %d steps (%d states, %.3g state-steps)%s", self.what, self.total, self.steps,
                     self.states, self.total * self.per_run,
                     "" if size >= self.total else f"; a first batch of {size} timed, then batches of up to "
                                                   f"{max(1, int(BATCH_WORK // self.per_run))}")
        while self.done < self.total:
            if self.timings and time.time() > self.deadline:
                return
            size = min(size, self.total - self.done)
            if self.timings and math.isfinite(self.deadline):       # what the time left allows
                c0, c1 = self.line()
                size = int(max(1, min(size, (self.deadline - time.time() - c0) // c1)))
            start = time.perf_counter()
            yield self.done, self.done + size
            self.timings.append((size, time.perf_counter() - start))
            self.done += size
            if self.done < self.total:
                grown = max(size, min(4 * size, max(1, int(BATCH_WORK // self.per_run))))
                c0, c1 = self.line()
                LOG.info("%s: %d of %d simulated (%.1f s); %s %.3g s for the other %d", self.what, self.done,
                         self.total, time.perf_counter() - self.begin,
                         "about" if len(self.timings) > 1 else "at most about", self.estimate(grown),
                         self.total - self.done)
                size = grown
            elif len(self.timings) > 1:
                LOG.info("%s: all %d simulated (%.1f s)", self.what, self.total, time.perf_counter() - self.begin)

    def watcher(self, a: int, b: int):
        """An observer of the batch ``(a, b)`` that says under ``-v``, at most every
        :data:`PROGRESS_SECONDS`, the latest instant its runs have reached (the runs of a batch
        need not move together: those of a stiffer flow take more substeps)."""
        return _Progress(f"{self.what} {a + 1}-{b} of {self.total}", self.horizon, self.begin)


class _Progress:
    """Says under ``-v`` how far the runs of a batch are, at most every :data:`PROGRESS_SECONDS`
    (an observer of :meth:`reach.model.simulate.Simulator.run`: it reads only the times)."""

    def __init__(self, label: str, horizon: float | None, begin: float):
        self.label, self.horizon, self.begin = label, horizon, begin
        self.next = time.perf_counter() + PROGRESS_SECONDS
        self.latest = -math.inf

    def _seen(self, t) -> None:
        t = np.asarray(t, dtype=float)
        if t.size:
            latest = float(np.max(t))          # NaN where a time is NaN: kept out below
            if latest > self.latest:
                self.latest = latest
        now = time.perf_counter()
        if now < self.next:
            return
        self.next = now + PROGRESS_SECONDS
        LOG.info("%s: the first runs have reached t = %.6g%s (%.1f s)", self.label,
                 self.latest if self.horizon is None else min(self.latest, self.horizon),
                 "" if self.horizon is None else f" of {self.horizon:g}", now - self.begin)

    def __call__(self, t, X, mode, rows) -> None:
        self._seen(t)

    def block(self, t, S, seen, m_index, rows, margins=None) -> None:
        self._seen(t[-1] if np.ndim(t) > 1 else t)


# ------------------------------------------------------------------ simulating the runs

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


SAMPLE_BLOCK = 1000     # i.i.d. runs always simulated together: the unit of batches


def _simulate_rounds(model, props, sim, opts: Options, X, tau, signal, choice, n_structured: int, kicks,
                     deadline: float = math.inf) -> tuple[list, np.ndarray, int]:
    """Simulate the structured runs (in this process, in :class:`Batches`) and the i.i.d. ones,
    monitoring every property; ``([(monitor arrays per property, blocked runs, runs that met a
    choice, runs cut by the deadline)], rows, structured parts)``: the parts in the order of
    ``rows``, the indices of the runs simulated, the first ``structured parts`` of the parts
    those of the structured runs. No batch of structured runs after the first and no block of
    i.i.d. runs starts after ``deadline`` (a ``time.time()`` instant, which worker processes
    share), and the runs under way when it passes stop there (counted as blocked and as cut):
    those simulated are a leading part of the structured runs and of each batch's blocks.

    The i.i.d. runs are simulated in blocks of :data:`SAMPLE_BLOCK`, each block on its own
    (disturbance kicks from ``SeedSequence(seed, spawn_key=(k,))`` for block ``k``): a run's
    outcome depends on the seed and its index only, not on how the blocks are grouped into
    batches of ``batch`` runs nor on where a batch runs (in this process, on ``jobs`` local
    processes, or on a Dask ``scheduler``)."""
    def rows(a, b):
        return take_rows(X, tau, signal, choice, slice(a, b))

    parts = []
    batches = Batches(n_structured, sim.steps, model.n, deadline, horizon=model.horizon)
    for a, b in batches:
        monitors = [SafetyMonitor(model, p, b - a) for p in props]
        Xs, taus, signals, choices = rows(a, b)
        traj = sim.run(Xs, taus, observers=monitors + [batches.watcher(a, b)], kicks=kicks, signal=signals,
                       branches=None if choices is None else Branches(values=choices), deadline=deadline)
        parts.append(([m.arrays() for m in monitors], *_counts(traj)))
    structured_parts = len(parts)
    starts = list(range(n_structured, X.shape[0], SAMPLE_BLOCK))
    blocks = [(k,) + rows(a, min(a + SAMPLE_BLOCK, X.shape[0])) for k, a in enumerate(starts)]
    per_unit = max(1, -(-opts.batch // SAMPLE_BLOCK))
    units = [(model, props, sim.dt, opts.seed, blocks[i:i + per_unit], deadline)
             for i in range(0, len(blocks), per_unit)]
    begin = time.perf_counter()
    if len(units) <= 1 or (opts.jobs <= 1 and opts.scheduler is None):
        out = []
        for unit in units:
            out.append(simulate_blocks(*unit))
            _progress(len(out), len(units), begin)
    else:
        from reach.executors import make_executor

        out = [None] * len(units)
        for done, (i, (status, value)) in enumerate(
                make_executor(opts.jobs, opts.scheduler).map_unordered(simulate_blocks, units), start=1):
            if status != "ok":
                raise RuntimeError(f"a Monte Carlo batch did not finish ({status})")
            out[i] = value
            _progress(done, len(units), begin)
    done = [j for i, unit in enumerate(out) for j in range(i * per_unit, i * per_unit + len(unit))]
    kept = np.concatenate([np.arange(batches.done)] + [np.arange(starts[j], min(starts[j] + SAMPLE_BLOCK, X.shape[0]))
                                                       for j in done]).astype(int)
    return parts + [part for unit in out for part in unit], kept, structured_parts


def _progress(done: int, total: int, begin: float) -> None:
    """One line under ``-v`` per batch of i.i.d. runs simulated, when there are several."""
    if total > 1:
        LOG.info("batch %d of %d of random runs simulated (%.1f s)", done, total, time.perf_counter() - begin)


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
                           branches=None if choice is None else Branches(values=choice), deadline=deadline)
            out.append(([m.arrays() for m in monitors], *_counts(traj)))
    return out


def _counts(traj) -> tuple:
    """``(blocked runs, runs that met several enabled transitions at a jump, runs cut by the
    deadline)``."""
    return int(np.count_nonzero(np.isfinite(traj.blocked_at))), int(np.count_nonzero(traj.branched)), traj.cut


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
