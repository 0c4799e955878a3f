"""May-transitions taken at the first instant their guard is entered (the earliest switch),
where a run's switching signal asks for a switch in that piece, against closed forms.

A heater (Lygeros' example, as in HyST's ``heaterLygeros``): ``off`` decays as ``x' = -0.1 x``
with invariant ``x >= 18``, ``on`` heats as ``x' = -0.1 (x - 37)`` with ``x <= 29``; ``off -> on``
may be taken where ``x <= 18.1``. From ``x = 18.2`` the guard is entered at
``t_e = 10 ln(18.2 / 18.1)`` and the invariant left at ``t_x = 10 ln(18.2 / 18)``. Heating from
``18.1`` at ``t_e``, ``x`` reaches ``28.5`` at ``t_e + 10 ln(18.9 / 8.5) = 8.046``; from ``18`` at
``t_x``, at ``t_x + 10 ln(19 / 8.5) = 8.154``: ``x >= 28.5`` before ``t = 8.1`` is reachable by
the earliest switches only.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.star import BACKEND as STAR
from reach.backends.montecarlo.replays import replay
from reach.model.simulate import Simulator
from reach.result import Status
from model_files import load_files

HEATER = ("""
    name: heater
    state: [x, t]
    modes:
      "off": {flow: {x: "-0.1*x", t: "1"}, invariant: ["x >= 18"]}
      "on": {flow: {x: "-0.1*(x - 37)", t: "1"}, invariant: ["x <= 29"]}
    transitions:
      - {from: "off", to: "on", guard: ["x <= 18.1"]}
      - {from: "on", to: "off", guard: ["x >= 29"]}
    initial: {mode: "off", box: {x: [18.2, 18.2], t: [0, 0]}}
    horizon: 10
""", """
    properties:
      - {id: early_hot, kind: safety, modes: ["on"], avoid: ["x >= 28.5", "t <= 8.1"]}
""")
T_ENTRY, T_EXIT = 10 * math.log(18.2 / 18.1), 10 * math.log(18.2 / 18.0)


def _first_jump(sim, switch_first_piece: bool):
    K = 4
    switch = np.zeros((1, K), dtype=bool)
    switch[0, 0] = switch_first_piece
    traj = sim.run(np.array([[18.2, 0.0]]), record=True, signal=(2.5, np.zeros((1, K, 0)), switch))
    t, mode, X = traj.path[0]
    j = np.flatnonzero(mode == 1)[0]
    return t[j], X[j], traj


@pytest.mark.parametrize("eager,instant,level", [(True, T_ENTRY, 18.1), (False, T_EXIT, 18.0)])
def test_a_switch_asked_for_in_a_piece_is_taken_where_the_guard_is_entered(tmp_path, eager, instant, level):
    """Asked for in the first piece ``[0, 2.5)``: the jump comes at the guard's entry (the guard
    does not hold at 0); not asked for: at the invariant's exit, the latest switch."""
    model, _ = load_files(tmp_path, *HEATER)
    when, state, _ = _first_jump(Simulator(model), eager)
    assert when == pytest.approx(instant, abs=1e-9)
    assert state[0] == pytest.approx(level, abs=1e-8)


def test_a_guard_that_already_holds_is_not_taken_again_inside_the_piece(tmp_path):
    """Two modes whose may-guards both hold everywhere (``x >= 0``, ``x' = 1``): asked for in
    every piece, a run switches at each piece start and not again inside it (the guard is not
    entered there: it already holds), so it is neither blocked as Zeno nor jumping without end."""
    model, _ = load_files(tmp_path, """
        name: pingpong
        state: [x]
        modes: {a: {flow: {x: "1"}}, b: {flow: {x: "1"}}}
        transitions:
          - {from: a, to: b, guard: ["x >= 0"]}
          - {from: b, to: a, guard: ["x >= 0"]}
        initial: {mode: a, box: {x: [0, 0]}}
        horizon: 4
    """, "properties: [{id: p, kind: safety, modes: [a], require: ['x <= 10']}]")
    K = 4
    traj = Simulator(model).run(np.array([[0.0]]), record=True,
                                signal=(1.0, np.zeros((1, K, 0)), np.ones((1, K), dtype=bool)))
    assert np.isnan(traj.blocked_at[0])
    assert len(traj.transitions[0]) == K            # one switch at each piece start
    assert traj.final_state[0, 0] == pytest.approx(4.0)


def test_monte_carlo_finds_the_violation_only_the_earliest_switch_reaches(tmp_path):
    """The heater's ``x >= 28.5`` before ``t = 8.1``: found by a structured run switching at the
    guard's entry, and the counterexample replays (before: switches at piece starts only,
    ``horizon / 20`` apart, missed the window ``[t_e, 0.10]``; UNKNOWN)."""
    model, props = load_files(tmp_path, *HEATER)
    assert T_ENTRY + 10 * math.log(18.9 / 8.5) < 8.1 < T_EXIT + 10 * math.log(19 / 8.5)
    result = MONTECARLO.check(model, props["early_hot"], {"samples": 200, "optimise": False, "search_rounds": 0})
    assert result.status is Status.UNSAFE
    cex = result.counterexample
    rep = replay(model, props["early_hot"], cex.initial_state, cex.switch_time, cex.dt, cex.input_signal)
    assert rep.violated and rep.time < 8.1


# a network's synchronised jump ``e`` (``x >= 1``) and a local one (``x >= 0.5``) that both hold
# at t = 1: ``B__bad`` is reached only by taking the two at one instant or the second later
TWO_AT_ONCE = ("""
    name: two_at_once
    state: [x]
    modes:
      A__q0: {flow: {x: "1"}}
      A__bad: {flow: {x: "1"}}
      B__bad: {flow: {x: "1"}}
      B__q0: {flow: {x: "1"}}
    transitions:
      e: {from: A__q0, to: A__bad, guard: ["x >= 1"]}
      A__q0_to_B__q0: {from: A__q0, to: B__q0, guard: ["x >= 0.5"]}
      A__bad_to_B__bad: {from: A__bad, to: B__bad, guard: ["x >= 0.5"]}
      e_2: {from: B__q0, to: B__bad, guard: ["-x >= 1"]}
    initial: {mode: A__q0, box: {x: [0, 0]}}
    horizon: 3
""", """
    properties:
      - {id: never, kind: safety, modes: [B__bad], require: ["x <= -100"]}
""")


def test_may_transitions_enabled_together_are_taken_at_one_piece_start(tmp_path):
    """A switch asked for at t = 1 (and nowhere else) takes ``e`` (the first enabled) and then
    ``A__bad -> B__bad`` at that instant (before: one jump per piece start, so the run stayed in
    ``A__bad``)."""
    model, _ = load_files(tmp_path, *TWO_AT_ONCE)
    switch = np.zeros((1, 4), dtype=bool)
    switch[0, 1] = True
    traj = Simulator(model).run(np.array([[0.0]]), record=True, signal=(1.0, np.zeros((1, 4, 0)), switch))
    assert traj.transitions[0] == ["e", "A__bad_to_B__bad"]
    t, mode, _ = traj.path[0]
    assert t[np.flatnonzero(mode == list(model.modes).index("B__bad"))[0]] == 1.0


def test_star_replays_a_witness_of_two_may_jumps_at_one_instant(tmp_path):
    """star's witness jumps twice at t = 1; its replay asks for a switch there and now follows
    both (before: UNKNOWN after the finer passes, "no witness replayed")."""
    model, props = load_files(tmp_path, *TWO_AT_ONCE)
    result = STAR.check(model, props["never"], {"finer_retry": False})
    assert result.status is Status.UNSAFE
    cex = result.counterexample
    assert replay(model, props["never"], cex.initial_state, cex.switch_time, cex.dt, cex.input_signal).violated
