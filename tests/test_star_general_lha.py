"""star on linear hybrid automata a new user writes, with the closed forms that decide them:
a clocked tank of constant rates (a guard crossed over several cells gives one successor, not
one per cell; with a disturbance, the successors are aggregated), a thermostat whose switches
are may-transitions over wide guards (the fan-out is aggregated from the first jump), one whose
guards overlap (a zero-dwell cycle, closed by the fixpoint check with the clock as a state;
refinement inside refinement bounded), a saturated PD loop whose hysteresis band the default
step does not resolve and a sawtooth whose period it misses (a finer pass decides both) and a
witness on the face of a polytopic initial set (replayed from inside the set)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reach.backends.montecarlo.initial_sampling import PolytopeSampler
from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND
from reach.model import load_model
from reach.model.simulate import Branches
from reach.result import Status
from reach.spec import bind, load_properties

TANK = """
name: tank
state: [x, t]
modes:
  fill: {flow: {x: "2", t: "1"}, invariant: ["x <= 10"]}
  drain: {flow: {x: "-3", t: "1"}, invariant: ["x >= 2"]}
transitions:
  - {from: fill, to: drain, guard: ["x >= 10"], urgent: true}
  - {from: drain, to: fill, guard: ["x <= 2"], urgent: true}
initial: {mode: fill, box: {x: [4, 6], t: [0, 0]}}
horizon: 40
"""

DISTURBED_TANK = TANK.replace("x: \"2\"", "x: \"2 + d\"").replace("x: \"-3\"", "x: \"-3 + d\"").replace(
    "modes:", "bounded_inputs:\n  d: {range: [-0.2, 0.2], varying: true}\nmodes:").replace("horizon: 40", "horizon: 20")

MAY_THERMOSTAT = """
name: may_thermostat
state: [T, t]
modes:
  heat: {flow: {T: "-0.1*(T - 10) + 3", t: "1"}, invariant: ["T <= 22"]}
  cool: {flow: {T: "-0.1*(T - 10)", t: "1"}, invariant: ["T >= 18"]}
transitions:
  - {from: heat, to: cool, guard: ["T >= 20"]}
  - {from: cool, to: heat, guard: ["T <= 19"]}
initial: {mode: heat, box: {T: [19.5, 20], t: [0, 0]}}
horizon: 30
"""

OVERLAP_THERMOSTAT = MAY_THERMOSTAT.replace("T >= 20", "T >= 19").replace("T <= 19", "T <= 21").replace(
    "T: [19.5, 20]", "T: [19, 20]").replace("horizon: 30", "horizon: 10")

SAWTOOTH = """
name: sawtooth
state: [x, y, t]
modes:
  up: {flow: {x: "1", y: "-y", t: "1"}, invariant: ["x <= 1"]}
transitions:
  - {from: up, to: up, guard: ["x >= 1"], reset: {x: "0", y: "y + 1"}, urgent: true}
initial: {mode: up, box: {x: [0, 0.1], y: [0, 0.1], t: [0, 0]}}
horizon: 100
"""

FACE = """
name: face
state: [x, y, z]
modes:
  go: {flow: {x: "1", y: "-0.3*y + 0.1*z", z: "-z"}}
initial:
  mode: go
  box: {x: [0, 1], y: [0, 1], z: [0, 1]}
  constraints: ["x + y <= 1", "x - 0.3*y + 0.7*z == 0.2"]
horizon: 0.6
"""


def checked(tmp_path, model_text, requirements: dict, options=None) -> dict:
    (tmp_path / "m.yaml").write_text(model_text)
    (tmp_path / "p.yaml").write_text("properties:\n" + "".join(
        f"  - {{id: {k}, kind: safety, require: ['{v}']}}\n" for k, v in requirements.items()))
    model = load_model(tmp_path / "m.yaml")
    return {p.id: BACKEND.check(model, bind(p, model), options or {})
            for p in load_properties(tmp_path / "p.yaml")}, model


def replayed(model, prop, result):
    """The simulator's run of ``result``'s counterexample, on its own (independent of star)."""
    cex = result.counterexample.to_dict()
    return replay(model, prop, cex["initial_state"], cex["switch_time"], cex["dt"], cex["input_signal"],
                  Branches(prescribed=[cex["transitions"]])), cex


def bound_property(tmp_path, name: str = "p"):
    """The property ``name`` of ``tmp_path/p.yaml`` bound to the model ``tmp_path/m.yaml``."""
    model = load_model(tmp_path / "m.yaml")
    (prop,) = [bind(p, model) for p in load_properties(tmp_path / "p.yaml") if p.id == name]
    return model, prop


def test_a_clocked_tank_of_constant_rates_is_decided_with_few_stars(tmp_path):
    """The level stays in [2, 10] and reaches both ends (fill from 4..6 to 10 in at most 3 s,
    drain to 2 in 8/3 s). Each guard is crossed over two or three cells; one successor per
    crossing keeps the 12 jumps to a few dozen stars (one per cell: 2^13)."""
    results, _ = checked(tmp_path, TANK, {"high": "x <= 10.1", "low": "x >= 1.9", "tight": "x <= 9.9"})
    assert results["high"].status is Status.SAFE and results["low"].status is Status.SAFE
    assert results["high"].details["stars"] < 100
    assert results["tight"].status is Status.UNSAFE and results["tight"].counterexample is not None


def test_a_disturbed_tank_of_constant_rates_aggregates_its_successors(tmp_path):
    """With a disturbance ``|d| <= 0.2`` on both rates the level still stays in [2, 10] (the
    invariants) and reaches both ends; each crossing now spans several cells whose successors
    are aggregated after the first jumps instead of multiplying."""
    assert "2 + d" in DISTURBED_TANK and "varying: true" in DISTURBED_TANK
    results, _ = checked(tmp_path, DISTURBED_TANK, {"high": "x <= 10.1", "low": "x >= 1.9", "tight": "x <= 9.9"})
    assert results["high"].status is Status.SAFE and results["low"].status is Status.SAFE
    assert results["high"].details["aggregates"] > 0
    assert results["tight"].status is Status.UNSAFE


def test_a_disturbed_tank_at_a_fine_step_aggregates_its_wide_crossings(tmp_path):
    """At a step of 1/30 each crossing of the disturbed tank spans a dozen cells or more (the
    fill ends between 1.8 and 2.3 time units after its start): its successors are aggregated
    from the first jump (option aggregate_fanout) instead of multiplying over the first two
    jumps. The level never passes the urgent guard at 10."""
    results, _ = checked(tmp_path, DISTURBED_TANK, {"band": "x <= 10.05"}, {"step": 1 / 30, "finer_retry": False})
    assert results["band"].status is Status.SAFE, results["band"].details.get("reason")
    assert results["band"].details["stars"] < 200


def test_may_transitions_over_wide_guards_are_aggregated_from_the_first_jump(tmp_path):
    """Any run stays below 22 (the heating invariant) and some run heats up to it: a switch
    to cool may wait until the invariant forces it."""
    results, _ = checked(tmp_path, MAY_THERMOSTAT, {"below": "T <= 22.05", "reached": "T <= 21.95"})
    assert results["below"].status is Status.SAFE, results["below"].details.get("reason")
    assert results["below"].details["aggregates"] > 0
    assert results["reached"].status is Status.UNSAFE


EARLY_SWITCH = MAY_THERMOSTAT.replace("horizon: 30", "horizon: 2")


def test_a_violation_that_needs_an_early_may_transition_is_replayed(tmp_path):
    """Within 2 min a run reaches ``cool`` below 19.8 only by switching off as soon as the
    guard ``T >= 20`` allows: waiting until the invariant forces the switch at 22 keeps ``T``
    above 20.9 in ``cool`` (the closed form ``10 + 12 e^{-0.1 (t - t_s)}``, ``t_s >= 1.05``).
    Switched at 20, ``T = 10 + 10 e^{-0.1 t}`` goes below 19.8 after ``10 ln(10/9.8) = 0.202``
    and stays above ``10 + 10 e^{-0.2} = 18.19``: the counterexample switches early, on the
    replay grid, and replays; the floor 18.1 holds."""
    (tmp_path / "m.yaml").write_text(EARLY_SWITCH)
    (tmp_path / "p.yaml").write_text("properties:\n"
                                     "  - {id: early, kind: safety, modes: [cool], require: ['T >= 19.8']}\n"
                                     "  - {id: floor, kind: safety, modes: [cool], require: ['T >= 18.1']}\n")
    model = load_model(tmp_path / "m.yaml")
    props = {p.id: bind(p, model) for p in load_properties(tmp_path / "p.yaml")}
    results = {k: BACKEND.check(model, prop, {}) for k, prop in props.items()}
    early = results["early"]
    assert early.status is Status.UNSAFE, early.details.get("reason")
    cex = early.counterexample.to_dict()
    assert cex["input_signal"]["switch"].count(1) == 1
    switched = cex["input_signal"]["step"] * cex["input_signal"]["switch"].index(1)
    assert switched < 1.0                               # long before the invariant forces it
    assert cex["violation_time"] >= 10 * np.log(10 / 9.8) - 1e-9
    run = replay(model, props["early"], cex["initial_state"],
                 cex["switch_time"], cex["dt"], cex["input_signal"], Branches(prescribed=[cex["transitions"]]))
    assert run.violated and run.time == pytest.approx(cex["violation_time"])
    assert results["floor"].status is Status.SAFE, results["floor"].details.get("reason")


ROTATE_THEN_GROW = """
name: rotate_then_grow
state: [x, y, t]
modes:
  A: {flow: {x: "y", y: "-x", t: "1"}, invariant: ["t <= 4"]}
  B: {flow: {x: "0.2*x", y: "0", t: "1"}}
transitions:
  - {from: A, to: B, guard: ["y <= -0.5"], reset: {x: "2*x"}}
initial: {mode: A, box: {x: 1, y: 0, t: 0}}
horizon: 8
"""


@pytest.mark.parametrize("fraction,status", [(0.999, Status.UNSAFE), (1.001, Status.SAFE)])
def test_a_violation_lost_in_the_switch_delay_of_the_replay_grid_is_found_on_a_finer_one(
        tmp_path, fraction, status):
    """In ``A`` the run turns, ``x = cos t``, ``y = -sin t``; it may switch once ``y <= -0.5``
    (``t`` in ``[pi/6, 5 pi/6]``), doubling ``x``, which then grows as ``e^{0.2 t}``: at the
    horizon ``x = 2 cos(t_s) e^{0.2 (8 - t_s)}``, largest at the earliest switch, ``2 cos(pi/6)
    e^{0.2 (8 - pi/6)} = 7.7258``. A switch one default replay step (8/2400) late loses more
    than 0.1 % of that, so the bound 0.1 % below it was UNKNOWN (no witness replayed); the
    unresolved witnesses are replayed again on grids 10 and 100 times finer: UNSAFE, and the
    counterexample replays. 0.1 % above it: SAFE."""
    truth = 2 * np.cos(np.pi / 6) * np.exp(0.2 * (8 - np.pi / 6))
    (tmp_path / "m.yaml").write_text(ROTATE_THEN_GROW)
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: p, kind: safety, modes: [B], "
                                     f"require: ['x <= {float(fraction * truth)!r}']}}\n")
    model, prop = bound_property(tmp_path)
    result = BACKEND.check(model, prop, {"finer_retry": False})
    assert result.status is status, result.details.get("reason")
    if status is Status.UNSAFE:
        run, cex = replayed(model, prop, result)
        assert run.violated and cex["dt"] < model.horizon / 2400


def hottest(t: float) -> float:
    """The highest temperature at time ``t`` of the overlapping thermostat: heating all along
    from 20, ``T = 40 - 20 e^{-0.1 t}`` (switching to cool only lowers it, and ``T`` stays
    below the heating invariant 22 until ``t = 10 ln 10/9 = 1.05``)."""
    return 40.0 - 20.0 * np.exp(-0.1 * t)


def test_overlapping_guards_close_by_the_fixpoint_with_the_clock_as_a_state(tmp_path):
    """Guards that overlap (cool from 19, heat up to 21) let every run switch back and forth
    at one instant as often as it likes. The model has its own clock, read by the early-time
    bounds: aggregates of later passes around the cycle lie in earlier ones, clock included,
    and are not explored, so the ceiling (heating invariant 22, cooling only lowers ``T``) is
    proved in a few aggregates instead of unrolling the cycle to the horizon. The early bound
    21.5 is violated (``hottest(0.8) = 21.538``), with a replayed counterexample."""
    assert OVERLAP_THERMOSTAT.count("T >= 19") == 1 and OVERLAP_THERMOSTAT.count("T <= 21") == 1
    (tmp_path / "m.yaml").write_text(OVERLAP_THERMOSTAT)
    (tmp_path / "p.yaml").write_text(
        "properties:\n"
        "  - {id: ceiling, kind: safety, require: ['T <= 22.01']}\n"
        "  - {id: early, kind: safety, avoid: ['t <= 0.8', 'T >= 21.5']}\n")
    model = load_model(tmp_path / "m.yaml")
    assert model.global_clock is not None
    props = {p.id: bind(p, model) for p in load_properties(tmp_path / "p.yaml")}
    ceiling = BACKEND.check(model, props["ceiling"], {})
    assert ceiling.status is Status.SAFE, ceiling.details.get("reason")
    assert ceiling.details["covered_aggregates"] > 0
    assert "the clock included" in ceiling.details["semantics"]
    assert hottest(0.8) > 21.5
    early = BACKEND.check(model, props["early"], {})
    assert early.status is Status.UNSAFE, early.details.get("reason")
    cex = early.counterexample.to_dict()
    assert cex["violation_time"] <= 0.8 + 1e-9
    run = replay(model, props["early"], cex["initial_state"], cex["switch_time"], cex["dt"],
                 cex.get("input_signal"), Branches(prescribed=[cex["transitions"]]))
    assert run.violated


PUMP = """
name: pump
state: [h, time]
modes:
  filling: {flow: {h: "2 - 0.1*h", time: "1"}, invariant: ["h <= 8"]}
  draining: {flow: {h: "-0.5*h", time: "1"}, invariant: ["h >= 2"]}
transitions:
  - {from: filling, to: draining, guard: ["h >= 5"]}
  - {from: draining, to: filling, guard: ["h <= 6"]}
initial: {mode: filling, box: {h: [3, 4], time: [0, 0]}}
horizon: 20
"""


def test_a_cycle_entered_late_closes_though_rounding_moves_each_start(tmp_path):
    """The pump's first switch comes at ``time >= 0.65`` (from 4, ``h = 20 - 16 e^{-0.1 t}``
    reaches 5 then), so every aggregate of the overlapping cycle starts there, and outward
    rounding would lower each start by about 1e-7: none would lie in an earlier one, clock
    included, and the cycle would be unrolled without end. Time only runs forward, so each
    hull keeps the start of the aggregate it descends from; the cycle closes and both bounds
    the invariants give (``h <= 8`` filling, ``h >= 2`` draining, each mode moving ``h``
    away from the other's bound) are proved."""
    results, _ = checked(tmp_path, PUMP, {"top": "h <= 8.01", "bottom": "h >= 1.99"}, {"finer_retry": False})
    for result in results.values():
        assert result.status is Status.SAFE, result.details.get("reason")
        assert result.details["covered_aggregates"] > 0


def test_a_band_on_both_invariants_closes(tmp_path):
    """``18 <= T <= 22`` in one property, each bound exactly an invariant of the overlapping
    thermostat (cool keeps ``T >= 18``, heat ``T <= 22``, and each mode moves ``T`` away from
    the other's bound): every aggregate touches both bounds. Its hull takes them from the rows
    exactly, and the enlarged hull stays within the touch tolerance of them, so the cycle
    closes as for one bound alone."""
    assert 'invariant: ["T <= 22"]' in OVERLAP_THERMOSTAT and 'invariant: ["T >= 18"]' in OVERLAP_THERMOSTAT
    (tmp_path / "m.yaml").write_text(OVERLAP_THERMOSTAT)
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: band, kind: safety, require: ['T >= 18', 'T <= 22']}\n")
    model = load_model(tmp_path / "m.yaml")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model), {"finer_retry": False})
    assert result.status is Status.SAFE, result.details.get("reason")
    assert result.details["covered_aggregates"] > 0


@pytest.mark.parametrize("depth", [1, 3])
def test_refinement_inside_refinement_is_bounded(tmp_path, depth):
    """The early bound 21.55 holds (``hottest(0.8) = 21.538``) but no aggregate around the
    cycle keeps when each temperature was reached, and each refinement's members carry twice
    the coefficients of the level before. At most ``max_nested_refinements`` levels are
    refined; past them the failure counts as unresolved: UNKNOWN, never UNSAFE, in a few
    seconds instead of a cascade that outlasts any budget."""
    assert hottest(0.8) < 21.55
    (tmp_path / "m.yaml").write_text(OVERLAP_THERMOSTAT)
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: early, kind: safety, avoid: ['t <= 0.8', 'T >= 21.55']}\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    result = BACKEND.check(model, prop, {"finer_retry": False, "max_nested_refinements": depth})
    assert result.status in (Status.UNKNOWN, Status.SAFE), result.details.get("reason")
    assert 1 <= result.details["nested_refinements"] <= depth


DINT_HYSTERESIS = """
name: dint_hysteresis
state: [x, v, t]
bounded_inputs:
  b: {range: [-0.01, 0.01]}
modes:
  sat_neg:
    flow: {x: "v", v: "-0.2 + b", t: "1"}
    invariant: ["-x - 1.4*v <= -0.2"]
  linear:
    flow: {x: "v", v: "-x - 1.4*v + b", t: "1"}
    invariant: ["-x - 1.4*v >= -0.202", "-x - 1.4*v <= 0.202"]
  sat_pos:
    flow: {x: "v", v: "0.2 + b", t: "1"}
    invariant: ["-x - 1.4*v >= 0.2"]
transitions:
  - {from: sat_neg, to: linear, guard: ["-x - 1.4*v >= -0.2"], urgent: true}
  - {from: linear, to: sat_neg, guard: ["-x - 1.4*v <= -0.202"], urgent: true}
  - {from: linear, to: sat_pos, guard: ["-x - 1.4*v >= 0.202"], urgent: true}
  - {from: sat_pos, to: linear, guard: ["-x - 1.4*v <= 0.2"], urgent: true}
initial: {mode: sat_neg, box: {x: [4, 5], v: [-0.1, 0.1], t: [0, 0]}}
horizon: 40
"""


def lowest_speed(x0: float, v0: float, b: float) -> float:
    """The lowest ``v`` of the saturated PD loop from ``(x0, v0)`` with the bias ``b`` (scipy):
    saturated until ``u = -x - 1.4 v`` reaches -0.2, then linear. ``v`` is lowest where
    ``v' = u + b = 0``, long before ``u`` reaches the other band at 0.202, so the other modes
    do not matter."""
    def saturated(_, z):
        return [z[1], -0.2 + b]

    def leaves(_, z):
        return -z[0] - 1.4 * z[1] + 0.2
    leaves.terminal, leaves.direction = True, 1
    first = solve_ivp(saturated, (0, 40), [x0, v0], events=leaves, rtol=1e-11, atol=1e-13, max_step=0.01)
    second = solve_ivp(lambda _, z: [z[1], -z[0] - 1.4 * z[1] + b], (first.t[-1], 40), first.y[:, -1],
                       rtol=1e-11, atol=1e-13, max_step=0.01)
    return float(min(first.y[1].min(), second.y[1].min()))


def test_switching_faster_than_the_step_is_decided_at_a_finer_step(tmp_path):
    """A saturated PD double integrator whose linear band has a hysteresis of 0.002: at the
    default step (40/60) each cell crosses the band back and forth, and the aggregates chatter
    (thousands of jumps, a few thousandths of a second apart, until the LP budget). After
    ``CHATTER_JUMPS`` jumps within one step the pass is undecided and a finer one proves the
    speed bound, true by 0.004 (scipy: the lowest speed from the far corner with the bias
    against it is -1.1756)."""
    worst = min(lowest_speed(x0, v0, b) for x0 in (4, 5) for v0 in (-0.1, 0.1) for b in (-0.01, 0.01))
    assert -1.18 < worst < -1.17
    results, _ = checked(tmp_path, DINT_HYSTERESIS, {"speed": "v >= -1.18"})
    result = results["speed"]
    assert result.status is Status.SAFE, result.details.get("reason")
    assert "switching faster than the step resolves" in result.details["semantics"]


def fixed_point_of_the_sawtooth() -> float:
    """``y`` just after the k-th reset is ``y_{k-1} e^{-1} + 1`` (the period is 1): it rises to
    ``1 / (1 - e^{-1}) = 1.582`` from below, and decays in between."""
    return 1.0 / (1.0 - np.exp(-1.0))


def test_a_period_the_default_step_misses_is_decided_by_a_finer_pass(tmp_path):
    assert fixed_point_of_the_sawtooth() < 1.6
    results, _ = checked(tmp_path, SAWTOOTH, {"bound": "y <= 1.6"})
    result = results["bound"]
    assert result.status is Status.SAFE, result.details.get("reason")
    assert "left it undecided" in result.details["semantics"]
    assert result.details["step"] == pytest.approx(100 / 60 / 10)
    plain, _ = checked(tmp_path, SAWTOOTH, {"bound": "y <= 1.6"}, {"finer_retry": False})
    assert plain["bound"].status is Status.UNKNOWN


def test_a_witness_on_a_face_of_the_initial_polytope_replays_from_inside_it(tmp_path):
    """``x + y`` grows at rate at most ``1 + 0.1 z``; the largest value at 0.6 needs a start on
    the face ``x + y = 1``. The replayed initial state is a member of the polytope."""
    results, model = checked(tmp_path, FACE, {"sum": "x + y <= 1.45"})
    result = results["sum"]
    assert result.status is Status.UNSAFE, result.details.get("reason")
    x0 = np.asarray(result.details["witness"]["initial_state"][:3])
    init = model.initial
    assert PolytopeSampler(init.polytope, init.low, init.high).contains(x0[None])[0]


@pytest.mark.parametrize("high, low, warned", [(12.1, 11.9, False), (12.0, 12.0, True), (12.1, "[11.9, 12.2]", True)])
def test_a_zero_dwell_cycle_is_judged_with_the_constants_the_initial_set_gives(tmp_path, high, low, warned):
    """A hysteresis switch on x >= hi and x <= lo, hi and lo constant states (flow 0, never
    reset): both guards can hold at one instant only if lo >= hi is possible within their
    initial ranges. The lint warns of a zero-dwell cycle exactly then (it took them as free)."""
    from reach.model import load_model
    (tmp_path / "m.yaml").write_text(
        "name: buck\nstate: [x, hi, lo]\nmodes:\n"
        "  up: {flow: {x: 1, hi: 0, lo: 0}}\n  down: {flow: {x: -1, hi: 0, lo: 0}}\n"
        "transitions:\n  - {from: up, to: down, guard: [\"x >= hi\"]}\n"
        "  - {from: down, to: up, guard: [\"x <= lo\"]}\n"
        f"initial: {{mode: up, box: {{x: 11, hi: {high}, lo: {low}}}}}\nhorizon: 5\n")
    lints = load_model(tmp_path / "m.yaml").lints
    assert any("zero-dwell" in text for text in lints) == warned, lints


DEADBAND = """
name: deadband
state: [th, w]
modes:
  coast: {flow: {th: "w", w: "0"}}
  neg: {flow: {th: "w", w: "-ACC"}}
  pos: {flow: {th: "w", w: "ACC"}}
transitions:
  - {from: coast, to: neg, guard: ["th >= 1", "w >= 0"], urgent: true}
  - {from: neg, to: coast, guard: ["w <= -0.2"], urgent: true}
  - {from: coast, to: pos, guard: ["th <= -1", "w <= 0"], urgent: true}
  - {from: pos, to: coast, guard: ["w >= 0.2"], urgent: true}
initial: {mode: coast, box: {th: [0, 0.5], w: [0.1, W0]}}
horizon: 40
"""


@pytest.mark.parametrize("acc, w0", [(1.0, 0.3), (0.5, 0.25)])
def test_urgent_guards_of_two_rows_end_the_flow_of_their_mode(tmp_path, acc, w0):
    """A deadband with no invariants: coasting at ``w`` until ``th >= 1 & w >= 0`` (or its
    mirror), then firing at ``-acc`` until ``w = -0.2``. The angle overshoots the band by
    ``w^2 / (2 acc)``: at most ``1 + w0^2 / (2 acc)`` (the first firing), and at least
    ``-1 - 0.2^2 / (2 acc)`` (every later one; solve_ivp agrees below). Runs followed past the
    two-row guard would coast on without bound, so every bound was UNKNOWN; each segment is now
    checked as its parts in ``th <= 1`` and in ``w <= 0``: 0.05 % outside each extreme is SAFE,
    0.05 % inside is UNSAFE and the counterexample replays."""
    high, low = 1 + w0 ** 2 / (2 * acc), -1 - 0.2 ** 2 / (2 * acc)

    def firing(t, y):
        return [y[1], -acc]
    overshoot = solve_ivp(firing, (0, 2 * w0 / acc), [1.0, w0], max_step=1e-3, rtol=1e-10, atol=1e-12)
    assert overshoot.y[0].max() == pytest.approx(high, abs=1e-9)
    model_text = DEADBAND.replace("ACC", repr(acc)).replace("W0", repr(w0))
    results, model = checked(tmp_path, model_text, {
        "high_ok": f"th <= {high * 1.0005!r}", "high_bad": f"th <= {high * 0.9995!r}",
        "low_ok": f"th >= {low * 1.0005!r}", "low_bad": f"th >= {low * 0.9995!r}"})
    assert results["high_ok"].status is Status.SAFE, results["high_ok"].details.get("reason")
    assert results["low_ok"].status is Status.SAFE, results["low_ok"].details.get("reason")
    for name in ("high_bad", "low_bad"):
        assert results[name].status is Status.UNSAFE, results[name].details.get("reason")
        _, prop = bound_property(tmp_path, name)
        assert replayed(model, prop, results[name])[0].violated



SAMPLED = """
name: sampled
state: [th, w, u, c]
modes:
  fly:
    flow: {th: "w", w: "u", u: "0", c: "1"}
    invariant: ["c <= PERIOD"]
transitions:
  - {from: fly, to: fly, guard: ["c >= PERIOD"], reset: {u: "-K1*th - K2*w", c: "0"}, urgent: true}
initial:
  mode: fly
  box: {th: [0.9, 1.1], w: [W0, W1], c: [0, 0]}
  constraints: ["u == -K1*th - K2*w"]
horizon: HORIZON
"""


def sampled_extremes(th0, w0, period, horizon, k) -> tuple[float, float]:
    """The least and largest angle of the sampled PD loop from ``(th0, w0)`` with ``u = -k1 th0 -
    k2 w0``: between ticks the held control moves the double integrator in closed form,
    ``th(s) = th + w s + u s^2 / 2`` (extreme at an end of the period or at ``s = -w / u``), and
    each tick sets ``u = -k1 th - k2 w``."""
    th, w, t = th0, w0, 0.0
    u = -k[0] * th - k[1] * w
    low = high = th0
    while t < horizon - 1e-12:
        span = min(period, horizon - t)
        inside = [s for s in ([-w / u] if u else []) if 0 < s < span]
        values = [th + w * s + u * s * s / 2 for s in inside + [span]]
        low, high = min([low] + values), max([high] + values)
        th, w, t = th + w * span + u * span * span / 2, w + u * span, t + span
        u = -k[0] * th - k[1] * w
    return low, high


@pytest.mark.parametrize("period, horizon, k, w_range", [(0.5, 7.0, (1.0, 1.5), (0.0, 0.0)),
                                                         (1.0, 30.0, (0.3, 0.8), (-0.1, 0.1))])
def test_a_sampled_controller_keeps_its_shape_through_the_ticks(tmp_path, period, horizon, k, w_range):
    """A PD loop sampled by a local timer (reset at each tick, no global clock): each tick is
    taken at its instant and its successors keep their shape (the held control tied to the state
    it was computed from), tiny spreads folded into a box; two cells that share a tick on a grid
    point (period 1, step 0.5) give one successor of that shape. As interval hulls every tick
    lost that tie, and both loops were UNKNOWN even at ``|th| <= 5``. The extremes over the
    initial box (the run is linear in its start: a vertex) against 0.2 % of the range."""
    starts = [(th, w) for th in (0.9, 1.1) for w in w_range]
    low = min(sampled_extremes(th, w, period, horizon, k)[0] for th, w in starts)
    high = max(sampled_extremes(th, w, period, horizon, k)[1] for th, w in starts)
    pad = 0.002 * (high - low)
    text = SAMPLED.replace("PERIOD", repr(period)).replace("HORIZON", repr(horizon)).replace(
        "K1", repr(k[0])).replace("K2", repr(k[1])).replace("W0", repr(w_range[0])).replace("W1", repr(w_range[1]))
    results, model = checked(tmp_path, text, {
        "far": "th >= -5", "ok": f"th >= {low - pad!r}", "bad": f"th >= {low + pad!r}",
        "high_ok": f"th <= {high + pad!r}"})
    for name in ("far", "ok", "high_ok"):
        assert results[name].status is Status.SAFE, (name, results[name].details.get("reason"))
    assert results["bad"].status is Status.UNSAFE, results["bad"].details.get("reason")
    _, prop = bound_property(tmp_path, "bad")
    assert replayed(model, prop, results["bad"])[0].violated

LANDER = """
name: lander
state: [h, v]
bounded_inputs:
  w: {range: [-0.1, 0.1], varying: true}
modes:
  coast: {flow: {h: "v", v: "-1 + w"}, invariant: ["h >= 2"]}
  brake: {flow: {h: "v", v: "2 + w"}}
transitions:
  - {from: coast, to: brake, guard: ["h <= 5"]}
initial: {mode: coast, box: {h: [9.9, 10], v: [0, 0]}}
horizon: 8
"""


def test_the_input_generators_pass_gets_its_share_of_the_time_budget(tmp_path):
    """A lander that may brake anywhere below 5 m under a wind ``|w| <= 0.1``: the lowest point,
    ``2 - 2.2 (10 - 2) / (2 * 1.9) = -2.632`` (coast at -1.1 to the invariant's 2 m, brake at
    1.9), is far above -3.2. The default pass (the input effect as a box) refines cells without
    end and took the whole budget, so the pass with the effect as generators, which decides it,
    never ran; the default pass now gets a quarter of the budget."""
    results, _ = checked(tmp_path, LANDER, {"ok": "h >= -3.2"}, {"max_seconds": 20})
    assert results["ok"].status is Status.SAFE, results["ok"].details.get("reason")


SPIN_THEN_DAMP = """
name: spin_then_damp
state: [x, y, t]
modes:
  spin: {flow: {x: "y", y: "-x", t: "1"}, invariant: ["t <= pi"]}
  damp: {flow: {x: "-x", y: "-y", t: "1"}}
transitions:
  - {from: spin, to: damp, guard: ["t >= pi"], urgent: true}
initial:
  mode: spin
  box: {t: 0}
  constraints: ["x >= 0", "y >= 0", "x + y <= 1"]
horizon: 6
"""


@pytest.mark.parametrize("fraction, status", [(0.999, Status.UNSAFE), (1.001, Status.SAFE)])
def test_a_forbidden_instant_is_entered_as_deep_as_its_other_rows_allow(tmp_path, fraction, status):
    """``avoid t == 4.15 and y <= b``: half a turn maps the start ``(x0, y0)`` of the triangle to
    ``(-x0, -y0)`` at ``pi``, then ``y`` decays, ``y(4.15) = -y0 e^{-(4.15 - pi)}``, least at the
    vertex ``(0, 1)``. The equality capped the depth at 0, so the witness was the shallowest point
    of the slice (``y = b`` exactly), whose replay does not violate: UNKNOWN however far ``b`` lay
    inside. The equality is now a hard limit and the depth is taken in ``y``."""
    least = -np.exp(-(4.15 - np.pi))
    (tmp_path / "m.yaml").write_text(SPIN_THEN_DAMP)
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: p, kind: safety, "
                                     f"avoid: ['t == 4.15', 'y <= {float(least * fraction)!r}']}}\n")
    model, prop = bound_property(tmp_path)
    result = BACKEND.check(model, prop, {"finer_retry": False})
    assert result.status is status, result.details.get("reason")
    if status is Status.UNSAFE:
        assert replayed(model, prop, result)[0].violated
