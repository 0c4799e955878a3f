"""Sampling event properties: the extremum of a quantity along simulated runs (the Monte Carlo
referee for the taylor back-end).

For each run the quantity ``q`` of the property is evaluated at every visited state in the listed
modes (the simulator's grid, guard crossings and switch instants) and its extremum kept. The
grid extremum is a value of ``q`` at a real state, so every sound bound of the run's extremum on
the side of the requirement contains it; it may miss the true extremum between grid points by
about the change of ``q`` over one grid step, reported as ``grid_slack``.

The run's margin is how far its extremum stays on the right side of the requirement (``v - max
q`` for ``max q <= v``, ``min q - v`` for ``min q >= v``); a negative margin is a violation. The
Monte Carlo back-end samples the runs (its initial states, input signals and branches, as for a
safety property), searches and optimises on the margin, and replays a violating run alone
(:func:`replay_event`) before it reports UNSAFE; otherwise the answer is UNKNOWN with the sampled
range of the extremum over the runs (:func:`event_details`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy

from reach.model.automaton import HybridAutomaton
from reach.model.simulate import Branches, Simulator
from reach.result import Counterexample
from reach.spec.properties import BoundEvent
from reach.stats import clopper_pearson_upper


class EventMonitor:
    """Per run: the extremum of ``q`` over the listed modes, when and where it was reached, and
    the largest change of ``q`` between consecutive visits in one mode (the grid slack)."""

    def __init__(self, model: HybridAutomaton, prop: BoundEvent, n_runs: int):
        names = list(model.modes)
        self.prop = prop
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

    @classmethod
    def merged(cls, model: HybridAutomaton, prop: BoundEvent, parts: list) -> "EventMonitor":
        """One monitor over the runs of several (monitors of the same property, in run order)."""
        out = cls(model, prop, 0)
        if parts:
            for name in ("best", "time", "state", "mode"):
                setattr(out, name, np.concatenate([getattr(p, name) for p in parts]))
            out.last = {m: np.concatenate([p.last[m] for p in parts]) for m in out.q}
            out.slack = max(p.slack for p in parts)
        return out

    def extrema(self) -> np.ndarray:
        """Sampled extremum of ``q`` per run (``nan`` for runs that never visited a listed mode;
        an infinite value, where ``q`` overflowed, is kept: it is past any finite requirement)."""
        out = self.sign * self.best
        return np.where(self.best == -np.inf, np.nan, out)


    def margins(self) -> np.ndarray:
        """Per run, how far its sampled extremum stays on the right side of the requirement
        (negative: a violation; ``inf`` for runs that never visited a listed mode)."""
        values = self.extrema()
        margin = self.prop.value - values if self.prop.op == "<=" else values - self.prop.value
        return np.where(np.isnan(values), np.inf, margin)

    @property
    def min_depth(self) -> np.ndarray:
        """The margins under the name the falsifier reads (:mod:`reach.backends.montecarlo.falsify`)."""
        return self.margins()

    def first_violation(self) -> int | None:
        """The run that breaks the requirement by most, if any."""
        bad = np.flatnonzero(violates(self.prop, self.extrema()))
        return None if bad.size == 0 else int(bad[np.argmin(self.margins()[bad])])


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
                   record: bool = False, branches: Branches | None = None, signal=None, general: bool = False):
    """Simulate the runs from ``x0`` (N, n) under the input ``signal`` (``(step, values, switch)``
    as :meth:`reach.model.simulate.Simulator.run` takes it, pieces on the grid): ``(monitor,
    trajectories, grid step)``. ``general``: on the simulator's per-segment path, not its block
    path (a replay independent of the sampled runs)."""
    sim = Simulator(model, dt)
    if general:
        sim.tables = dict.fromkeys(model.modes)
    monitor = EventMonitor(model, prop, len(x0))
    traj = sim.run(np.asarray(x0, dtype=float), None, record=record, observers=[monitor], branches=branches,
                   signal=signal)
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
    input_signal: dict | None = None

    def counterexample(self, model, prop, found_by: str) -> Counterexample:
        return Counterexample(
            model=model.name, property=prop.id, model_file=model.file, property_file=prop.file,
            initial_state=list(map(float, self.initial_state)), switch_time=None,
            violation_time=float(self.time), violation_mode=self.mode,
            violation_state=list(map(float, self.state)), dt=self.dt, trajectory=self.trajectory,
            found_by=found_by, transitions=list(self.transitions), input_signal=self.input_signal)


def replay_event(model: HybridAutomaton, prop: BoundEvent, initial_state, dt: float | None = None,
                 branches: Branches | None = None, signal=None) -> EventReplay:
    """Simulate one run (under the input ``signal``, its pieces on the grid of ``dt``; choosing
    among transitions enabled together by ``branches``) on the simulator's per-segment path and
    evaluate the event property along it; the transitions it took are recorded (the caller
    records the signal). A state outside a polytopic initial set starts no run of the model:
    no violation (``value`` nan)."""
    x0 = np.asarray(initial_state, dtype=float).reshape(1, -1)
    init = model.initial
    if not init.is_box:                     # a run from outside the initial polytope is no run of the model
        from reach.backends.montecarlo.initial_sampling import PolytopeSampler
        if not PolytopeSampler(init.polytope, init.low, init.high).contains(x0)[0]:
            return EventReplay(False, float("nan"), float("nan"), "", np.full(model.n, np.nan), x0[0],
                               float(dt or 0.0), float("-inf"))
    monitor, traj, step = sample_extrema(model, prop, x0, dt, record=True, branches=branches, signal=signal,
                                         general=True)
    names = list(model.modes)
    times, modes, states = traj.path[0]
    trajectory = {"t": times.tolist(), "mode": [names[int(m)] for m in modes], "x": states.tolist()}
    value = float(monitor.extrema()[0])
    mode = names[int(monitor.mode[0])] if monitor.mode[0] >= 0 else ""
    depth = value - prop.value if prop.op == "<=" else prop.value - value
    return EventReplay(bool(violates(prop, value)), value, float(monitor.time[0]), mode, monitor.state[0],
                       x0[0], step, float(depth), trajectory, traj.transitions[0])


def event_details(prop: BoundEvent, monitor: EventMonitor, runs: int, n_structured: int, samples: int,
                  step: float, cut=()) -> dict:
    """What the sampled runs (``n_structured`` structured first, then ``samples`` i.i.d.) say of
    the extremum: its sampled range, the closest margin, the grid slack and a 95 % upper bound
    of the violation probability over the i.i.d. runs, those a time budget stopped before the
    horizon (``cut``, indices among the i.i.d. runs) counted as violating: leaving them out would
    bias the bound low, since the runs a budget cuts are the slow ones, and slowness (many
    events, a mode of its own) may go with violating."""
    values = monitor.extrema()
    details = {"runs": int(runs), "iid_runs": int(samples), "dt": step, "sense": prop.sense,
               "grid_slack": monitor.slack,
               "semantics": "extremum of the quantity at the simulator's grid points, guard crossings and "
                            "switch instants in the listed modes"}
    if np.isfinite(values).any():
        details["sampled_range"] = (float(np.nanmin(values)), float(np.nanmax(values)))
        details["closest_margin"] = float(np.min(monitor.margins()))
    bad = np.asarray(violates(prop, values[n_structured:n_structured + samples]), dtype=bool).copy()
    bad[np.asarray(cut, dtype=int)] = True
    details["violation_probability_upper_95"] = clopper_pearson_upper(int(bad.sum()), samples)
    return details
