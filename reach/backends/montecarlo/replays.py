"""Replaying one run alone and the counterexample it gives.

A violation found among the sampled runs is only a candidate: :func:`replay` simulates that run
alone on the simulator's general per-segment path (independent of the block path the sampled
runs took) and checks the property along it; only a replayed violation is reported as UNSAFE,
with the counterexample of :meth:`Replay.counterexample` (its initial state, switch time, input
signal and the transitions it took). :func:`check_run` refuses a run that is none of the
model's (a counterexample file read back); :func:`signal_record` and :func:`constant_signal`
give input signals in their counterexample form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reach.backends.montecarlo.event_sampling import replay_event
from reach.backends.montecarlo.initial_sampling import PolytopeSampler
from reach.backends.montecarlo.monitors import SafetyMonitor
from reach.backends.montecarlo.sampling import switch_window
from reach.errors import InputError
from reach.model.automaton import HybridAutomaton
from reach.model.constraints import row_magnitudes
from reach.model.batch_nonlinear import probe_rows, too_stiff_text
from reach.model.simulate import MAX_STEPS, MEMORY_BUDGET, Branches, Simulator, single_threaded, value_sources
from reach.result import Counterexample
from reach.spec.properties import BoundEvent, BoundSafety

REPLAY_TOLERANCE = 1e-9        # relative rounding allowed on the bounds a replayed run must meet (check_run)


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
    extremum along the run, :func:`.event_sampling.replay_event`). The replay
    records the transitions the run took, so its counterexample replays along the same
    branches.

    A violation on a nonlinear mode (integrated by RK4, not exactly) must also show at a quarter
    of the step (:data:`CONFIRM_FACTOR`), with RK4 substeps stable at every state that finer run
    visits (:func:`_stable_along`: a flow that stiffens along the run gets them where it does):
    a violation that only the coarser integration makes (an unstable step on a stiff flow) is
    none, and the replay says so."""
    with single_threaded():
        signal = _signal_of(model, input_signal)
        sim = _replay_simulator(model, dt, signal)
        rep = _replay_with(model, prop, initial_state, switch_time, sim, signal, branches)
        if sim.too_stiff:                   # the run is NaN from where it entered such a mode
            rep.trajectory = {**(rep.trajectory or {}), "note": too_stiff_text(sim.dt, sim.too_stiff)}
        if not rep.violated or not sim.mode_substeps:      # every mode flows exactly (or not at all)
            return rep
        try:
            finer = _replay_simulator(model, sim.dt / CONFIRM_FACTOR, signal)
        except InputError:                  # too many steps at a quarter of it: the replay stands
            return rep
        confirmed = _stable_along(finer, lambda: _replay_with(model, prop, initial_state, switch_time,
                                                                     finer, signal, branches))
        if confirmed.violated:
            return rep
        confirmed.trajectory = dict(confirmed.trajectory or {})
        confirmed.trajectory["note"] = (f"violated at step {sim.dt:.4g} but not at {finer.dt:.4g}: the violation "
                                        f"comes from the integration of a nonlinear flow, not from the model")
        return confirmed


#: a violation on a nonlinear mode is replayed again at this fraction of the step (:func:`replay`)
CONFIRM_FACTOR = 4


def _stable_along(sim: Simulator, run, rounds: int = 3) -> "Replay":
    """``run()`` on ``sim`` again, with more RK4 substeps in a mode, while the flow's Jacobian at
    the states the run visited there asks for more than ``sim`` took
    (:meth:`reach.model.simulate.Simulator.wanted_substeps`, at most 1024 of them; at most
    ``rounds`` runs more, and :data:`reach.model.batch_nonlinear.MAX_SUBSTEPS` per step)."""
    rep = run()
    for _ in range(rounds):
        path = rep.trajectory or {}
        if "x" not in path or not path["x"]:
            return rep
        X, modes = np.asarray(path["x"], dtype=float), np.asarray(path["mode"])
        more = {}
        for mode, taken in sim.mode_substeps.items():
            states = X[modes == mode]
            if states.size:
                wanted, _ = sim.wanted_substeps(mode, probe_rows(states, 1024))
                if wanted > taken:
                    more[mode] = wanted
        if not more:
            return rep
        sim.mode_substeps.update(more)
        rep = run()
    return rep


def _replay_with(model, prop, initial_state, switch_time, sim: Simulator, signal, branches):
    """One replay on ``sim`` (its step; a safety or an event property)."""
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
    recorded = model.horizon / sim.dt * (model.n + 2) * RECORD_BYTES_PER_VALUE
    if recorded > MEMORY_BUDGET:
        raise InputError(f"{model.name}: a replay at step {sim.dt:g} records {model.horizon / sim.dt:.3g} "
                         f"states of {model.n} values, about {recorded / 2 ** 30:.1f} GiB; at most "
                         f"{MEMORY_BUDGET / 2 ** 30:.0f} GiB are planned for (use a larger dt)", field="dt")
    sim.tables = dict.fromkeys(model.modes)
    return sim


#: bytes a replay holds per recorded value (its time, mode and states per grid step: the
#: recorder's lists and the arrays made from them)
RECORD_BYTES_PER_VALUE = 64


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
                         "needs their input_signal" if names else
                         "the model has no time-varying inputs: expected null, or a switching signal "
                         "{step, inputs: [], values, switch}", field="input_signal")
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
    ``REPLAY_TOLERANCE (1 + |bound|)`` (rounding in a written file), invariant rows to
    ``REPLAY_TOLERANCE (1 + m)``, ``m`` the magnitude the row combines as the simulator
    scales it (:meth:`reach.model.simulate.Simulator.inside`)."""
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
    mode = model.modes[init.mode]
    margins = mode.invariant_margins(x[None, :])[0]
    scale = row_magnitudes(mode.invariant, model.symbols, value_sources(model))(x[None, :])[0]
    if np.any(margins > REPLAY_TOLERANCE * (1.0 + scale)):
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
