"""The runs Monte Carlo samples and their simulation.

The runs of the first round (:func:`run_plan`): the structured ones (:func:`structured_plan`:
corners, face centres and centre of the initial set crossed with the ends and middle of the
abort window, :func:`switch_window`) and the i.i.d. ones (:func:`random_plan`), with their input
signals, switching signals and choice values (:mod:`.initial_sampling`).

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


def run_plan(model: HybridAutomaton, sim: Simulator, window, opts: Options, rng):
    """The runs of the first round, ``(X, tau, signal, choice, n_structured, seeding)``: the
    structured initial states (with the structured signals of the time-varying inputs,
    :func:`.initial_sampling.structured_signals`) and ``opts.samples`` i.i.d. ones (uniform
    signals); where the model has may-transitions, each structured run twice, staying in a
    mode as long as it can and leaving where a guard is first entered (every piece asks for a
    switch: :meth:`reach.model.simulate.Simulator.run`), and the random runs ask in random
    pieces; where transitions can be enabled together, each structured run once per branch
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
    check_size(model, sim.dt, X.shape[0])      # all the runs' arrays are held at once
    return X, tau, signal, choice, n_structured, seeding


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
                     deadline: float = math.inf) -> tuple[list, np.ndarray]:
    """Simulate the structured runs (in this process) and the i.i.d. ones, monitoring every
    property; ``([(monitor arrays per property, blocked runs, runs that met a choice, runs cut
    by the deadline)], rows)``: the parts in the order of ``rows``, the indices of the runs
    simulated. No block of i.i.d. runs starts after ``deadline`` (a ``time.time()`` instant,
    which worker processes share), and the runs under way when it passes stop there (counted
    as blocked and as cut): those simulated are the structured ones and a leading part of each
    batch's blocks.

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
                   branches=None if choices is None else Branches(values=choices), deadline=deadline)
    parts = [([m.arrays() for m in monitors], *_counts(traj))]
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
    kept = np.concatenate([np.arange(n_structured)] + [np.arange(starts[j], min(starts[j] + SAMPLE_BLOCK, X.shape[0]))
                                                       for j in done]).astype(int)
    return parts + [part for unit in out for part in unit], kept


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
