"""Sampling event properties: the extremum of a quantity along simulated runs (the Monte Carlo
referee for the taylor back-end).

For each run the quantity ``q`` of the property is evaluated at every visited state in the listed
modes (the simulator's grid, guard crossings and switch instants) and its extremum kept. The
grid extremum is a value of ``q`` at a real state, so every sound bound of the run's extremum on
the side of the requirement contains it; it may miss the true extremum between grid points by
about the change of ``q`` over one grid step, reported as ``grid_slack``.

A run whose sampled extremum breaks the requirement is a counterexample: it is replayed alone
(along the same branches where transitions can be enabled together,
:func:`reach.backends.initial_sampling.branch_plan`) and reported UNSAFE only if the replay
breaks it too. Otherwise the answer is UNKNOWN with the sampled range of the extremum over the
runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import sympy

from reach.backends.initial_sampling import branch_plan
from reach.model.automaton import HybridAutomaton
from reach.model.simulate import Branches, Simulator
from reach.result import Counterexample, Result, Status
from reach.spec.properties import BoundEvent
from reach.stats import clopper_pearson_upper


class EventMonitor:
    """Per run: the extremum of ``q`` over the listed modes, when and where it was reached, and
    the largest change of ``q`` between consecutive visits in one mode (the grid slack)."""

    def __init__(self, model: HybridAutomaton, prop: BoundEvent, n_runs: int):
        names = list(model.modes)
        self.q = {names.index(m): sympy.lambdify([model.symbols], sympy.sympify(prop.quantity[m]), "numpy")
                  for m in prop.modes}
        self.sign = 1.0 if prop.sense == "max" else -1.0
        self.best = np.full(n_runs, -np.inf)          # sign * extremum
        self.time = np.full(n_runs, np.nan)
        self.state = np.full((n_runs, model.n), np.nan)
        self.mode = np.full(n_runs, -1)
        self.last = {m: np.full(n_runs, np.nan) for m in self.q}     # previous visit, per mode
        self.slack = 0.0

    def __call__(self, t, X, mode, rows):
        for m_index, q in self.q.items():
            sel = np.flatnonzero(mode == m_index)
            if sel.size == 0:
                continue
            values = self.sign * (np.asarray(q(X[sel].T), dtype=float) * np.ones(sel.size))
            r = rows[sel]
            # the first visit of each run in this batch, against the previous batch
            _, first = np.unique(r, return_index=True)
            prev = self.last[m_index][r[first]]
            ok = np.isfinite(prev)
            if ok.any():
                self.slack = max(self.slack, float(np.max(np.abs(values[first][ok] - prev[ok]))))
            if sel.size > first.size:
                order = np.lexsort((np.arange(sel.size), r))
                same = r[order][1:] == r[order][:-1]
                if same.any():
                    jumps = np.abs(np.diff(values[order]))[same]
                    self.slack = max(self.slack, float(np.max(jumps)))
            last = np.full(len(self.best), np.nan)
            last[r] = values                         # later visits overwrite earlier ones
            seen = np.isfinite(last)
            self.last[m_index][seen] = last[seen]
            better = values > self.best[r]
            if better.any():
                order = np.argsort(values[better], kind="stable")
                idx = sel[better][order]
                rr = rows[idx]
                self.best[rr] = values[better][order]
                self.time[rr] = t[idx]
                self.state[rr] = X[idx]
                self.mode[rr] = m_index

    def extrema(self) -> np.ndarray:
        """Sampled extremum of ``q`` per run (``nan`` for runs that never visited a listed mode;
        an infinite value, where ``q`` overflowed, is kept: it is past any finite requirement)."""
        out = self.sign * self.best
        return np.where(self.best == -np.inf, np.nan, out)


def violates(prop: BoundEvent, value) -> np.ndarray:
    value = np.asarray(value, dtype=float)
    bad = value > prop.value if prop.op == "<=" else value < prop.value
    return bad & ~np.isnan(value)


def within_bound(values, lo: float, hi: float, sense: str, slack: float) -> np.ndarray:
    """Whether sampled extrema agree with a bound ``[lo, hi]`` of the true extremum. A sampled
    extremum is a value of ``q`` at a real state, so it lies inside on the outer side (below a
    maximum's upper end, above a minimum's lower end; up to 1e-9 relative rounding); on the inner
    side it may miss the true extremum by the grid ``slack``."""
    v = np.asarray(values, dtype=float)
    tol = 1e-9 * max(1.0, abs(lo), abs(hi))
    if sense == "max":
        return (v <= hi + tol) & (v >= lo - tol - slack)
    return (v >= lo - tol) & (v <= hi + tol + slack)


def outside_bounds(subdomains, x0: np.ndarray, values: np.ndarray, uncertain, sense: str, slack: float) -> int:
    """How many sampled runs have an extremum outside (:func:`within_bound`) the bound of the
    subdomain holding their initial state (rows with ``low``, ``high``, ``bound`` over the
    ``uncertain`` states, as the taylor back-end reports them). Every run must start in some
    subdomain."""
    count = 0
    covered = np.zeros(len(x0), dtype=bool)
    for row in subdomains:
        inside = np.all((x0[:, uncertain] >= row["low"]) & (x0[:, uncertain] <= row["high"]), axis=1)
        covered |= inside
        count += int(np.sum(~within_bound(values[inside], *row["bound"], sense, slack)))
    if not covered.all():
        raise ValueError("the subdomains do not cover every sampled initial state")
    return count


def sample_extrema(model: HybridAutomaton, prop: BoundEvent, x0: np.ndarray, dt: float | None = None,
                   record: bool = False, branches: Branches | None = None):
    """Simulate the runs from ``x0`` (N, n): ``(monitor, trajectories, grid step)``."""
    sim = Simulator(model, dt)
    monitor = EventMonitor(model, prop, len(x0))
    traj = sim.run(np.asarray(x0, dtype=float), None, record=record, observers=[monitor], branches=branches)
    return monitor, traj, sim.dt


@dataclass
class EventReplay:
    """One re-simulated run: its sampled extremum ``value`` (reached at ``time``, ``mode``,
    ``state``) and ``depth``, by how much it breaks the requirement (positive) or meets it."""

    violated: bool
    value: float
    time: float
    mode: str
    state: np.ndarray
    initial_state: np.ndarray
    dt: float
    depth: float
    trajectory: dict = field(default_factory=dict)
    transitions: list = field(default_factory=list)

    def counterexample(self, model, prop, found_by: str) -> Counterexample:
        return Counterexample(
            model=model.name, property=prop.id, model_file=model.file, property_file=prop.file,
            initial_state=list(map(float, self.initial_state)), switch_time=None,
            violation_time=float(self.time), violation_mode=self.mode,
            violation_state=list(map(float, self.state)), dt=self.dt, trajectory=self.trajectory,
            found_by=found_by, transitions=list(self.transitions))


def replay_event(model: HybridAutomaton, prop: BoundEvent, initial_state, dt: float | None = None,
                 branches: Branches | None = None) -> EventReplay:
    """Simulate one run (choosing among transitions enabled together by ``branches``) and
    evaluate the event property along it; the transitions it took are recorded."""
    x0 = np.asarray(initial_state, dtype=float).reshape(1, -1)
    monitor, traj, step = sample_extrema(model, prop, x0, dt, record=True, branches=branches)
    names = list(model.modes)
    times, modes, states = traj.path[0]
    trajectory = {"t": times.tolist(), "mode": [names[int(m)] for m in modes], "x": states.tolist()}
    value = float(monitor.extrema()[0])
    mode = names[int(monitor.mode[0])] if monitor.mode[0] >= 0 else ""
    depth = value - prop.value if prop.op == "<=" else prop.value - value
    return EventReplay(bool(violates(prop, value)), value, float(monitor.time[0]), mode, monitor.state[0],
                       x0[0], step, float(depth), trajectory, traj.transitions[0])


def check_events(model: HybridAutomaton, props: list[BoundEvent], samples: int, seed: int,
                 dt: float | None, structured: np.ndarray) -> list[Result]:
    """Per property: UNSAFE with a replayed counterexample, or UNKNOWN with the sampled range of
    the extremum. The properties share one simulation of the structured and i.i.d. runs."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    low, high = model.initial.low, model.initial.high
    iid = low + (high - low) * rng.random((samples, model.n))
    x0 = np.vstack([structured, iid])
    sim = Simulator(model, dt)
    n_structured, choice = len(structured), None
    if sim.max_options > 1:
        x0, _, _, choice, n_structured = branch_plan(sim.max_options, n_structured, x0, None, None, rng)
    monitors = [EventMonitor(model, prop, len(x0)) for prop in props]
    sim.run(x0, None, observers=monitors, branches=None if choice is None else Branches(values=choice))
    shared = (time.perf_counter() - start) / max(len(props), 1)
    results = []
    for prop, monitor in zip(props, monitors):
        begin = time.perf_counter()
        result = _verdict(model, prop, monitor, x0, choice, n_structured, samples, sim.dt)
        result.seconds = shared + time.perf_counter() - begin
        results.append(result)
    return results


def _verdict(model, prop, monitor, x0, choice, n_structured, samples, step) -> Result:
    values = monitor.extrema()
    visited = np.isfinite(values)
    details = {"runs": int(len(x0)), "iid_runs": int(samples), "dt": step, "sense": prop.sense,
               "grid_slack": monitor.slack,
               "semantics": "extremum of the quantity at the simulator's grid points, guard crossings and "
                            "switch instants in the listed modes"}
    if visited.any():
        details["sampled_range"] = (float(np.nanmin(values)), float(np.nanmax(values)))
        margin = (prop.value - values) if prop.op == "<=" else (values - prop.value)
        details["closest_margin"] = float(np.nanmin(margin))
    bad = np.flatnonzero(violates(prop, values))
    if bad.size:
        worst = bad[np.argmax(np.abs(values[bad] - prop.value))]
        rep = replay_event(model, prop, x0[worst], step,
                           None if choice is None else Branches(values=choice[worst:worst + 1]))
        if rep.violated:
            found = "structured" if worst < n_structured else "random"
            return Result("montecarlo", model.name, prop.id, Status.UNSAFE,
                          counterexample=rep.counterexample(model, prop, found), details=details)
        details["unreplayed"] = "a sampled violation did not replay alone"
    iid_bad = int(violates(prop, values[n_structured:]).sum())
    details["violation_probability_upper_95"] = clopper_pearson_upper(iid_bad, samples)
    return Result("montecarlo", model.name, prop.id, Status.UNKNOWN, details=details)
