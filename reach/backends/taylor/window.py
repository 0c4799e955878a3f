"""May-transition windows as expansion variables.

A may-transition whose guard is a clock window ``lo <= t <= hi`` switches at one instant ``tau``
of the window, chosen nondeterministically. When every source mode's invariant forces the switch
by ``hi`` (``t <= hi``: the ARCH abort), the runs of the automaton are exactly the runs of the
automaton in which ``tau`` is one more state, with rate 0 and initial range ``[lo, hi]``, and the
transition is urgent with guard ``t >= tau``: the run switches at the first instant ``t = tau``.
When the window reaches past the horizon ``T`` (and need not be forced), ``tau`` ranges over
``[lo, T]``: a switch at ``T`` is the run that never switches, plus its state at ``T`` in the target
mode, which only enlarges the set checked. ``tau`` is then expanded like an initial deviation:
ADS splits it like a state, and a point of a subdomain maps back to an initial state and a
switch time (the first ``n`` coordinates and ``tau``).
"""

from __future__ import annotations

import numpy as np
import sympy

from reach.model.automaton import HybridAutomaton, InitialSet, Mode, Transition
from reach.model.constraints import Constraint

SWITCH_STATE = "_switch_time"


def unsupported_window(model) -> str | None:
    """Why the may-transitions of ``model`` cannot be turned into a switch-time state, or None."""
    windows = [tr for tr in model.transitions if not tr.urgent]
    if not windows:
        return None
    for tr in windows:
        if tr.window is None:
            what = "no guard" if not tr.guard else "a guard that is not a clock window (lo <= t <= hi)"
            return (f"the may-transition '{tr.name}' has {what}: taylor handles one switch within a "
                    f"clock window, not switching at any time (star and montecarlo do)")
    if len({tr.window for tr in windows}) > 1:
        return "more than one may-transition window"
    if len({tr.source for tr in windows}) < len(windows):
        return "two may-transitions leave the same mode"
    if model.initial.polytope is not None:
        return "a switch-time state needs a box initial set"
    clock, lo, hi = windows[0].window
    if model.global_clock != clock:
        return "the window's clock is not a global clock (rate 1, starting at 0, never reset)"
    if hi < model.horizon and not all(_forced(model, tr.source, clock, hi) for tr in windows):
        return "the window does not force the switch (no invariant t <= hi in a source mode)"
    return None


def _forced(model, mode: str, clock: int, hi: float) -> bool:
    hs = model.modes[mode].invariant_halfspaces
    return hs is not None and any(row[clock] > 0 and np.count_nonzero(row) == 1 and g / row[clock] <= hi + 1e-12
                                  for row, g in zip(*hs))


def with_switch_time(model) -> tuple[HybridAutomaton, int | None]:
    """``(model, None)`` without a may-transition window; else the copy with the switch time
    ``tau`` as the last state and the window transition urgent on ``t >= tau``, and the index of
    ``tau`` (assumes :func:`unsupported_window` is None)."""
    windows = [tr for tr in model.transitions if not tr.urgent]
    if not windows:
        return model, None
    clock, lo, hi = windows[0].window
    T = model.horizon
    if lo > T:                          # never inside the horizon
        kept = [tr for tr in model.transitions if tr.urgent]
        return _copy(model, model.state, {n: m for n, m in model.modes.items()}, kept,
                     model.initial), None
    tau = sympy.Symbol(SWITCH_STATE, real=True)
    symbols = model.symbols + [tau]
    modes = {name: Mode(m.name, symbols, list(m.flow) + [sympy.Integer(0)], m.control, m.invariant,
                        m.controller, m.where, m.timeless) for name, m in model.modes.items()}
    t = model.symbols[clock]
    transitions = []
    for tr in model.transitions:
        if tr.urgent:
            transitions.append(tr)
            continue
        guard = [Constraint(tau - t, False, f"{t} >= switch time", tr.where)]
        transitions.append(Transition(tr.name, tr.source, tr.target, guard, True, dict(tr.reset), None, tr.where))
    init = model.initial
    initial = InitialSet(init.mode, np.append(init.low, lo), np.append(init.high, min(hi, T)))
    return _copy(model, model.state + [SWITCH_STATE], modes, transitions, initial), model.n


def _copy(model, state, modes, transitions, initial) -> HybridAutomaton:
    return HybridAutomaton(model.name, model.description, model.file, model.units, model.constants,
                           state, model.inputs, modes, transitions, initial, model.horizon,
                           model.disturbance, list(model.clocks), list(model.bounded_inputs),
                           model.dimensions)
