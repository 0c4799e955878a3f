"""The Monte Carlo referee: vectorised sampling of the same model, falsification first.

Safety properties. Runs are drawn in rounds of numpy batches:

1. *structured*: corners, face centres and the centre of the initial box, crossed with the
   ends and middle of the abort window; at most :func:`.sampling.structured_cap` of them
   (option ``structured``; by default the larger of 8 per sample and what fits in
   :data:`.sampling.STRUCTURED_WORK` state-steps), spread over the plan where it has more,
   simulated in timed batches that the time budget stops (:class:`.sampling.Batches`);
2. *random*: ``samples`` i.i.d. uniform initial states and switch instants;
3. *search*: a cross-entropy falsifier that resamples around the runs that came closest to
   the unsafe set (``search_rounds`` generations);
4. *optimiser* (``optimise``, deterministic models): the robustness (smallest depth) minimised
   over the initial state, the switch instant and the input values by differential evolution
   seeded with the closest runs so far, then a batched projected gradient descent (a grid
   refinement for at most two parameters) (:mod:`.falsify`).

A polytopic initial set is sampled by its vertices, facet points and centre (structured) and
uniformly by hit-and-run (random); time-varying bounded inputs are piecewise-constant signals
with pieces of ``input_step`` (default horizon / 20): constant extremes and bang-bang signals
in the structured round, uniform pieces in the random one, perturbed by the search
(:mod:`.initial_sampling`); where the sampled runs of a safety property find no
violation and the initial mode is linear, a round of bang-bang signals on finer pieces aimed
into the unsafe set by the maximum principle
(:func:`.initial_sampling.extremal_runs`) comes before the search. May-transitions with general guards are taken where a
run would leave its invariant, and, in the pieces where the run's switching signal asks for a
switch (every piece for one copy of each structured run; each with probability
``SWITCH_PROBABILITY`` in the random and search rounds), also at the piece start where a guard
holds or else where a guard is first entered in the piece. A counterexample carries its input and switching signal.

Where several transitions can be enabled at one jump (two urgent guards that hold together,
may-transitions with general guards at an exit), each run carries choice values
(:func:`.initial_sampling.branch_plan`): every structured run is repeated once
per option ``k`` of the largest jump (``B`` options), taking the ``k``-th enabled one at every
jump (values ``(k + 1/2) / B``), so each branch is covered deterministically; the i.i.d. runs
draw uniform values (a uniform choice at each jump); where some sampled run met such a choice,
the search perturbs them and the optimiser takes them as parameters. A counterexample names
the transition taken at each jump.

The structured and i.i.d. runs are one simulation shared by all safety properties of the call
(one monitor each, :mod:`.monitors`), its i.i.d. runs in fixed blocks that run in this process,
on local processes or on a Dask scheduler (:mod:`.sampling`): a seed gives the same answer
whatever the split and the executor.

Every visited state is checked against every unsafe piece of the property. A violation is
replayed alone (:func:`replay`, :mod:`.replays`) and returned as UNSAFE with its counterexample.
Otherwise the answer is UNKNOWN with the closest approach (depth) found and a one-sided 95 %
Clopper-Pearson upper bound on the violation probability from the i.i.d. round. Monte Carlo
never says SAFE.

Reach and reach-avoid properties of stochastic models are estimated from ``samples`` runs
with Gaussian kicks from initial states uniform over the initial box or polytope; the
probability is a 95 % Wilson interval.

Event properties (the extremum of a quantity along the run) take the same structured and
i.i.d. runs (initial states, input signals, branches), one simulation shared by all event
properties of the call, then the same search and optimiser on the run's margin, the distance
of its extremum from the requirement (:mod:`.event_sampling`).
"""

from __future__ import annotations

import logging
import math
import time
from functools import partial

import numpy as np

from reach.backends.montecarlo.event_sampling import EventMonitor, event_details
from reach.backends.montecarlo.falsify import Budget, falsify
from reach.backends.montecarlo.initial_sampling import PolytopeSampler, extremal_runs
from reach.backends.montecarlo.monitors import SafetyMonitor
from reach.backends.montecarlo.options import NAME, Options
from reach.backends.montecarlo.replays import check_run, constant_signal, replay, signal_record
from reach.backends.montecarlo.sampling import (STRUCTURED_PER_SAMPLE, STRUCTURED_WORK, SWITCH_PROBABILITY, Batches,
                                                _kicks, _simulate_rounds, initial_points, random_plan, run_plan,
                                                sampled_runs, structured_cap, structured_plan, switch_window,
                                                take_rows)
from reach.model.automaton import HybridAutomaton
from reach.model.batch_nonlinear import too_stiff_text
from reach.model.constraints import NUMERICAL_TOLERANCE, lambdify_margins, row_magnitudes
from reach.model.simulate import Branches, Simulator, single_threaded
from reach.result import Result, Status
from reach.spec.properties import BoundEvent, BoundReach, BoundReachAvoid, BoundSafety
from reach.stats import VERDICT_CONFIDENCE, clopper_pearson_upper, wilson

__all__ = ["BACKEND", "NAME", "MonteCarloBackend", "Options", "SafetyMonitor", "check_run",
           "constant_signal", "random_plan", "replay", "structured_plan", "switch_window"]


#: progress under ``reach check -v``: the rounds of runs and the searches, with their times
LOG = logging.getLogger("reach.montecarlo")

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
        X, tau, signal, choice, n_structured, seeding, planned, points = run_plan(model, sim, window, opts, rng)
        LOG.info("%s and %d random runs of %d steps (%.1f s)", _structured_text(opts, sim, planned, n_structured),
                 X.shape[0] - n_structured, sim.steps, time.perf_counter() - start)
        wall = _wall(deadline)
        parts, kept, structured_parts = _simulate_rounds(model, props, sim, opts, X, tau, signal, choice,
                                                         n_structured, kicks, wall)
        planned_random = X.shape[0] - n_structured
        ran_structured = int(np.count_nonzero(kept < n_structured))
        if kept.size < X.shape[0]:          # the time budget left runs unsimulated
            X, tau, signal, choice = take_rows(X, tau, signal, choice, kept)
            seeding = seeding[kept]
        unstarted = n_structured - ran_structured
        n_structured = ran_structured
        sampled = X.shape[0] - n_structured
        monitors = [SafetyMonitor.merged(model, p, [q[0][i] for q in parts]) if parts else SafetyMonitor(model, p, 0)
                    for i, p in enumerate(props)]
        blocked = sum(q[1] for q in parts)
        cut = sum(q[3] for q in parts)              # runs the time budget stopped under way
        cut_random = sum(q[3] for q in parts[structured_parts:])
        branching = choice is not None and sum(q[2] for q in parts) > 0    # a choice met, not only possible
        structured = _structured_details(opts, sim, planned, points, n_structured, unstarted, X[:n_structured])
        per_run = (time.perf_counter() - start) / max(1, X.shape[0])     # seconds a run took, about
        runs = []
        if opts.keep_sets:
            pictured_kicks = _kicks(model, np.random.default_rng(np.random.SeedSequence(opts.seed, spawn_key=(2 ** 32,))))
            runs = sampled_runs(model, sim, X, tau, signal, choice, n_structured, pictured_kicks)
        LOG.info("simulated %d runs (%.1f s)", X.shape[0], time.perf_counter() - start)
        shared = (time.perf_counter() - start) / len(props)
        results = []
        for prop, monitor in zip(props, monitors):
            begin = time.perf_counter()
            rounds = [("structured+random", X, tau, monitor, signal, choice)]
            details = {"dt": sim.dt, "seed": opts.seed, **structured,
                       "random_runs": int(sampled),
                       "blocked_runs": int(blocked),
                       "assumes": "states checked at grid points and event instants only "
                                  "(a falsifier, not a proof)"}
            fails = int(np.count_nonzero(np.isfinite(monitor.violation_time[n_structured:])))
            # runs that left the real numbers (NaN states) without a violation before: a violating
            # run that does so later counts as violating, not as undefined
            undefined = int(np.count_nonzero(np.isnan(monitor.min_depth[n_structured:])
                                             & np.isnan(monitor.violation_time[n_structured:])))
            details["violating_runs"] = fails
            # a run cut short by the budget was not watched to the horizon: counted as violating.
            # Leaving it out would bias the bound low: the runs a budget cuts are the slow ones, and
            # slowness (many jumps, a mode of its own) may go with violating. A cut run that had
            # already violated is counted once or twice: the bound stays an upper bound
            n = sampled - undefined
            details["violation_probability_upper_95"] = clopper_pearson_upper(min(fails + cut_random, n), n)
            if undefined:                   # NaN states: sqrt of a negative level, a division by zero
                details["undefined_runs"] = undefined
                details["undefined"] = (f"{undefined} of {sampled} random runs reached states where the model's "
                                        f"flow is not a real number (NaN): the model leaves its domain there (an "
                                        f"invariant can keep it in), or the RK4 steps of a nonlinear flow diverged "
                                        f"(a stiff flow: a smaller -o dt); the violation bound counts the other runs"
                                        + (f" ({too_stiff_text(sim.dt, sim.too_stiff)})" if sim.too_stiff else ""))
            details.update(_budget_details(opts, n_structured, unstarted, sampled, planned_random, cut))
            found = monitor.first_violation()
            found = None if found is None else (0, found)
            monitors_of = partial(SafetyMonitor, model, prop)
            closest = _least(monitor.min_depth)
            if found is None and model.disturbance is None and time.perf_counter() <= deadline:
                found, depth = self._extremal(model, prop, sim, rounds, n_structured, monitors_of, wall)
                closest = min(closest, depth)
            if found is None and model.disturbance is None and time.perf_counter() <= deadline:
                LOG.info("%s: no violation sampled (closest margin %.4g, model units); searching (%s)", prop.id,
                         closest, _search_work(opts, sim, per_run))
                found = self._search(model, window, sim, rounds, opts, rng, branching, deadline, monitors_of,
                                     seeding)
            if found is None and model.disturbance is None and opts.optimise and time.perf_counter() <= deadline:
                LOG.info("%s: optimising the robustness (%.1f s; %s)", prop.id, time.perf_counter() - start,
                         _optimiser_work(opts, sim, per_run))
                found = self._optimise(model, prop, window, sim, rounds, opts, branching, deadline, monitors_of,
                                       seeding)
                details["optimiser_runs"] = int(rounds[-1][3].runs)
            LOG.info("%s: %s (%.1f s)", prop.id, "violation found" if found is not None else "no violation found",
                     time.perf_counter() - start)
            if found is None and time.perf_counter() > deadline and "note" not in details:
                details["note"] = (f"time budget of {opts.max_seconds:.3g} s (option max_seconds) "
                                   f"ended the search")
            details["search_runs"] = int(sum(r[1].shape[0] for r in rounds[1:] if r[0].startswith("search")))
            details["closest_depth"] = min([closest] + [_least(r[3].min_depth) for r in rounds])
            if found is not None and model.disturbance is not None:
                details["note"] = ("violations were sampled under random disturbance; "
                                   "a single run is not a replayable counterexample")
                found = None
            result = _verdict(model, prop, rounds, found, sim, details)
            result.seconds = shared + time.perf_counter() - begin
            result.sets = runs
            results.append(result)
        return results

    def _extremal(self, model, prop, sim, rounds, structured: int, monitors_of, wall: float = math.inf):
        """The runs aimed into ``prop``'s unsafe set by the inputs
        (:func:`.initial_sampling.extremal_runs`) from the first round's structured starts, a
        round of their own (their pieces are finer than the sampled signals'): ``((round, row),
        depth)`` with the round appended when one violates, else ``(None, closest depth)``. None
        without structured runs to start from; the runs under way at ``wall`` (a ``time.time()``
        instant) stop there."""
        _, X, tau, _, signal, choice = rounds[0]
        if structured == 0:
            return None, math.inf
        plan = extremal_runs(model, prop, X[:structured], sim.dt)
        if plan is None:
            return None, math.inf
        owner, Xe, step, values = plan
        switch = None if signal[2] is None else np.zeros(values.shape[:2], dtype=bool)
        taue = None if tau is None else tau[owner]
        choicee = None if choice is None else choice[owner]
        parts, i = [], None
        batches = Batches(Xe.shape[0], sim.steps, model.n, wall, f"{prop.id}: runs of input signals aimed at "
                                                                 f"the unsafe set", model.horizon)
        for a, b in batches:                # in batches, up to the first that violates
            monitor = monitors_of(b - a)
            sim.run(Xe[a:b], None if taue is None else taue[a:b], observers=[monitor, batches.watcher(a, b)],
                    signal=(step, values[a:b], None if switch is None else switch[a:b]),
                    branches=None if choicee is None else Branches(values=choicee[a:b]), deadline=wall)
            parts.append(monitor.arrays())
            if monitor.first_violation() is not None:
                break
        done = sum(p[0].size for p in parts)
        monitor = SafetyMonitor.merged(model, prop, parts)
        depth = float(np.min(monitor.min_depth, initial=np.inf))
        i = monitor.first_violation()
        if i is None:
            return None, depth
        rounds.append(("extremal inputs", Xe[:done], None if taue is None else taue[:done], monitor,
                       (step, values[:done], None if switch is None else switch[:done]),
                       None if choicee is None else choicee[:done]))
        return (len(rounds) - 1, i), depth

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
            if elite.size == 0:                         # no run to search around
                break
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
                    branches=None if choice is None else Branches(values=choice), deadline=_wall(deadline))
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
        optimiser on the run's margin (:class:`~.event_sampling.EventMonitor`); a
        violating run is replayed alone before it is reported."""
        start = time.perf_counter()
        deadline = math.inf if opts.max_seconds is None else start + opts.max_seconds
        wall = _wall(deadline)
        rng = np.random.default_rng(opts.seed)
        sim = Simulator(model, opts.dt)
        X, _, signal, choice, n_structured, seeding, planned, points = run_plan(model, sim, None, opts, rng)
        LOG.info("%s and %d random runs of %d steps (%.1f s)", _structured_text(opts, sim, planned, n_structured),
                 X.shape[0] - n_structured, sim.steps, time.perf_counter() - start)
        parts = [[] for _ in props]
        cut, cut_random = 0, np.empty(0, dtype=int)
        batches = Batches(n_structured, sim.steps, model.n, wall, horizon=model.horizon)
        for a, b in batches:                    # the structured runs, in batches
            Xs, _, signals, choices = take_rows(X, None, signal, choice, slice(a, b))
            batch = [EventMonitor(model, prop, b - a) for prop in props]
            traj = sim.run(Xs, None, observers=batch + [batches.watcher(a, b)], signal=signals,
                           branches=None if choices is None else Branches(values=choices), deadline=wall)
            cut += traj.cut
            for i, m in enumerate(batch):
                parts[i].append(m)
        kept = np.arange(batches.done)
        if X.shape[0] > n_structured and time.time() <= wall:      # the i.i.d. runs
            Xr, _, signalr, choicer = take_rows(X, None, signal, choice, slice(n_structured, None))
            batch = [EventMonitor(model, prop, Xr.shape[0]) for prop in props]
            traj = sim.run(Xr, None, observers=batch, signal=signalr,
                           branches=None if choicer is None else Branches(values=choicer), deadline=wall)
            cut, cut_random = cut + traj.cut, traj.cut_rows
            for i, m in enumerate(batch):
                parts[i].append(m)
            kept = np.r_[kept, np.arange(n_structured, X.shape[0])]
        planned_random = X.shape[0] - n_structured
        unstarted = n_structured - batches.done
        if kept.size < X.shape[0]:              # the time budget left runs unsimulated
            X, _, signal, choice = take_rows(X, None, signal, choice, kept)
            seeding = seeding[kept]
        n_structured = batches.done
        monitors = [EventMonitor.merged(model, prop, part) for prop, part in zip(props, parts)]
        runs = sampled_runs(model, sim, X, None, signal, choice, n_structured) if opts.keep_sets else []
        LOG.info("simulated %d runs (%.1f s)", X.shape[0], time.perf_counter() - start)
        shared = (time.perf_counter() - start) / len(props)
        results = []
        for prop, monitor in zip(props, monitors):
            begin = time.perf_counter()
            details = event_details(prop, monitor, X.shape[0], n_structured, X.shape[0] - n_structured, sim.dt,
                                    cut_random)
            details.update(_structured_details(opts, sim, planned, points, n_structured, unstarted,
                                               X[:n_structured]))
            details.update(_budget_details(opts, n_structured, unstarted, X.shape[0] - n_structured,
                                           planned_random, cut))
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
            if found is None and time.perf_counter() > deadline and "note" not in details:
                details["note"] = f"time budget of {opts.max_seconds:.3g} s (option max_seconds) ended the search"
            details["closest_margin"] = min(float(np.min(r[3].margins(), initial=np.inf)) for r in rounds)
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
        """``samples`` runs under Gaussian kicks from initial states drawn from the initial set
        (uniform over the box, or over the polytope: :class:`.initial_sampling.PolytopeSampler`,
        ``details["initial"]`` says which law); the 95 % Wilson interval of the share that
        meets the property; a violation is judged by the Wilson interval at
        :data:`reach.stats.VERDICT_CONFIDENCE` (``verdict_interval``)."""
        rng = np.random.default_rng(opts.seed)
        init = model.initial
        sampler = None if init.is_box else PolytopeSampler(init.polytope, init.low, init.high)
        sim = Simulator(model, opts.dt)
        kicks = _kicks(model, rng)
        target = _meets(prop.target, model.symbols)
        safe = _meets(prop.safe, model.symbols) if isinstance(prop, BoundReachAvoid) else None
        step = model.disturbance.step if model.disturbance is not None else sim.dt
        successes, total = 0, 0
        remaining = opts.samples
        while remaining > 0:
            count = min(opts.batch, remaining)
            remaining -= count
            X0 = (init.low + (init.high - init.low) * rng.random((count, model.n)) if sampler is None
                  else sampler.uniform(count, rng))
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
                        ok[rows[on_step][~safe(X[on_step])]] = False

            horizon = model.horizon
            model.horizon = prop.at
            try:
                sim.run(X0, None, observers=[observe], kicks=kicks)
            finally:
                model.horizon = horizon
            hit = ok & target(final)
            successes += int(np.count_nonzero(hit))
            total += count
        lo, hi = wilson(successes, total)
        status = Status.UNKNOWN
        details = {"samples": total, "successes": successes, "estimate": successes / total, "dt": sim.dt,
                   "seed": opts.seed, "interval": "95 % Wilson",
                   "verdict_interval": wilson(successes, total, VERDICT_CONFIDENCE),
                   "initial": (sampler.law() if sampler is not None else "point"
                               if np.array_equal(init.low, init.high) else "uniform over the initial box")}
        return Result(NAME, model.name, prop.id, status, probability=(lo, hi), details=details)


def _meets(constraints, symbols):
    """``X (N, n) -> (N,)``: whether each state meets every constraint up to rounding relative
    to that row, ``g <= NUMERICAL_TOLERANCE m`` with ``m`` the magnitude the row combines
    (:func:`reach.model.constraints.row_magnitudes`; as fsr treats a deterministic row): a clock
    at ``0.9000000000000001`` meets ``z <= 0.9``. A state with a continuous law meets a bound
    exactly with probability 0, so only deterministic coordinates feel it; a row's scale is its
    own, so a large coordinate it does not read (a range of 7e6 m beside an angle) does not
    widen it."""
    margins = lambdify_margins(constraints, symbols)
    magnitudes = row_magnitudes(constraints, symbols)

    def meets(X: np.ndarray) -> np.ndarray:
        return np.all(margins(X) <= NUMERICAL_TOLERANCE * magnitudes(X), axis=1)

    return meets


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


BACKEND = MonteCarloBackend()


def _least(depths) -> float:
    """The least depth of runs whose states are numbers (a run that left its flow's domain has
    NaN ones, which say nothing of a margin); ``inf`` if there is none."""
    depths = np.asarray(depths, dtype=float)
    return float(np.min(depths[~np.isnan(depths)], initial=np.inf))


def _wall(deadline: float) -> float:
    """The ``time.time()`` instant of a ``time.perf_counter()`` deadline (what the simulator and
    worker processes read)."""
    return math.inf if math.isinf(deadline) else time.time() + (deadline - time.perf_counter())


def _cap_text(opts: Options, sim: Simulator) -> str:
    """Where the cap on the structured runs comes from (:func:`.sampling.structured_cap`)."""
    cap = structured_cap(opts, sim.steps, sim.n)
    if opts.structured is not None:
        return f"option structured={cap}"
    return (f"{cap}: by default the larger of {STRUCTURED_PER_SAMPLE} x samples and the runs of "
            f"{sim.steps} steps on {sim.n} states that fit in {STRUCTURED_WORK:.3g} state-steps; option structured")


def _structured_text(opts: Options, sim: Simulator, planned: int, kept: int) -> str:
    """The structured runs of a check in words, with the cap where it left some out."""
    if kept >= planned:
        return f"{kept} structured runs"
    return f"{kept} of {planned} planned structured runs (at most {_cap_text(opts, sim)})"


def _budget_details(opts: Options, structured: int, unstarted: int, sampled: int, planned_random: int,
                    cut: int) -> dict:
    """``note`` and ``cut_runs`` where the time budget ended the runs early (structured runs left
    unstarted, random runs not sampled, runs cut short under way); empty otherwise."""
    if not (sampled < planned_random or cut or unstarted):
        return {}
    out = {"note": (f"time budget of {opts.max_seconds:.3g} s (option max_seconds) ended the "
                    + (f"structured runs after {structured} of {structured + unstarted} and the " if unstarted else "")
                    + f"sampling after {sampled} of {planned_random} random runs"
                    + (f", {cut} of the runs simulated cut short before the horizon (counted as violating in "
                       "the violation bound)" if cut else ""))}
    if cut:
        out["cut_runs"] = int(cut)
    return out


def _structured_details(opts: Options, sim: Simulator, planned: int, points: int, ran: int, unstarted: int,
                        X) -> dict:
    """``details`` of the structured runs: how many were planned and simulated, and where some
    were left out, how many by the cap (:func:`.sampling.structured_cap`) and by the time budget,
    which ones, and how many of the plan's initial states the simulated ones start from."""
    out = {"structured_runs": int(ran), "structured_planned": int(planned)}
    capped = planned - ran - unstarted
    if not (capped or unstarted):
        return out
    out["structured_left_out"] = {"cap": int(capped), "time_budget": int(unstarted)}
    why = []
    if capped:
        why.append(f"{capped} by the cap (at most {_cap_text(opts, sim)}): one run kept in each of "
                   f"{ran + unstarted} equal stretches of the plan, drawn by the seed")
    if unstarted:
        why.append(f"{unstarted} by the time budget (option max_seconds: the last of the kept runs)")
    out["structured_note"] = (f"{ran} of {planned} planned structured runs (the initial set's corners or "
                              f"vertices, face points and centre, with the abort instants, input extremes, "
                              f"switch decisions and branches) were simulated, from {initial_points(X)} of "
                              f"its {points} initial states; left out: " + "; ".join(why)
                              + ". The violation bound counts the random runs only")
    return out


def _search_work(opts: Options, sim: Simulator, per_run: float) -> str:
    """The cross-entropy search's work in words, its time from the seconds a run took so far."""
    runs = opts.search_rounds * opts.search_size
    return f"up to {opts.search_rounds} x {opts.search_size} runs of {sim.steps} steps, about {runs * per_run:.3g} s"


def _optimiser_work(opts: Options, sim: Simulator, per_run: float) -> str:
    """The optimiser's work in words (:class:`.falsify.Budget`), its time as :func:`_search_work`."""
    runs = (opts.generations + 1) * max(5, opts.population) + opts.polish
    return (f"up to {opts.generations + 1} x {max(5, opts.population)} + {opts.polish} runs of {sim.steps} steps, "
            f"about {runs * per_run:.3g} s")
