"""taylor on safety properties (margins of the unsafe pieces) and through may-transition windows
(the switch time as an expansion variable), against closed forms and replayed runs."""

from __future__ import annotations

import numpy as np
import pytest

from reach.backends.montecarlo import replay
from reach.backends.taylor import BACKEND
from reach.backends.taylor.safety import margins
from reach.backends.taylor.window import with_switch_time
from reach.model.loader import load_model
from reach.result import Status
from reach.spec.properties import bind, load_properties
from model_files import load_files

RIGOROUS = {"remainder": "rigorous"}

# x' = 1 until the abort at tau in [lo, hi] (forced by t <= hi), x' = -1 after it:
# x(t) = x0 + 2 tau - t in passive.
RAMP = """
name: ramp
state: [x, t]
modes:
  go:
    flow: {{x: 1, t: 1}}
    invariant: ["t <= {hi}"]
  back:
    flow: {{x: -1, t: 1}}
transitions:
  abort: {{from: go, to: back, guard: ["t >= {lo}", "t <= {hi}"]}}
initial: {{mode: go, box: {{x: [2, 2.5], t: 0}}}}
horizon: {horizon}
"""

# an undamped oscillator from x0 in [0.9, 1.1], v0 = 0: x(t) = x0 cos t, so max x = max x0
SPRING = """
name: spring
state: [x, v, t]
modes:
  m:
    flow: {x: v, v: -x, t: 1}
initial: {mode: m, box: {x: [0.9, 1.1], v: 0, t: 0}}
horizon: 4
"""


def test_required_constraint_margin_contains_the_closed_form_and_proves_safe(tmp_path):
    model, props = load_files(tmp_path, SPRING, """
        properties:
          - {id: low, kind: safety, require: ["x <= 1.2"]}
          - {id: high, kind: safety, require: ["x <= 1.05"]}
    """)
    safe = BACKEND.check(model, props["low"], RIGOROUS)
    assert safe.status is Status.SAFE
    lo, hi = safe.details["margin_bound"]
    assert 0 < lo <= 1.2 - 1.1 + 1e-12 <= hi + 1e-9        # min margin 1.2 - max x0 = 0.1
    # the estimated remainder bounds the same margin but proves nothing
    estimated = BACKEND.check(model, props["low"], {})
    assert estimated.status is Status.UNKNOWN
    assert estimated.details["margin_bound"][0] == pytest.approx(0.1, abs=1e-6)
    # x0 = 1.1 reaches x = 1.1 > 1.05: a witness that replays
    unsafe = BACKEND.check(model, props["high"], RIGOROUS)
    assert unsafe.status is Status.UNSAFE
    c = unsafe.counterexample
    assert replay(model, props["high"], c.initial_state, c.switch_time).violated
    assert c.initial_state[0] > 1.05


def test_a_point_initial_state_is_a_flow_expansion_in_no_variable(tmp_path):
    """From the single state ``x0 = 1, v0 = 0`` (no uncertain variable to expand in) the
    spring's ``x = cos t`` stays within ``[-1, 1]``: ``x <= 1.05`` is proved, ``x <= 0.9`` fails
    at ``t = 0``."""
    model, props = load_files(tmp_path, SPRING.replace("x: [0.9, 1.1]", "x: 1"), """
        properties:
          - {id: low, kind: safety, require: ["x <= 1.05"]}
          - {id: high, kind: safety, require: ["x <= 0.9"]}
    """)
    assert BACKEND.check(model, props["low"], RIGOROUS).status is Status.SAFE
    unsafe = BACKEND.check(model, props["high"], RIGOROUS)
    assert unsafe.status is Status.UNSAFE
    assert replay(model, props["high"], unsafe.counterexample.initial_state, None).violated


def test_constraint_implied_by_the_mode_invariant_is_not_bounded(tmp_path):
    srna = load_model("models/SRNA01.yaml")
    los = {p.id: bind(p, srna) for p in load_properties("properties/rendezvous.yaml")}["los"]
    parts = margins(srna, los)
    assert [p.text for p in parts] == ["x >= -100[m]", "y >= x*tan(pi/6)", "-y >= x*tan(pi/6)"]
    assert parts[0].event is None and parts[0].implied_in == ["rendezvous"]
    assert all(p.event is not None and p.event.sense == "min" for p in parts[1:])
    # the margin of y >= x tan(30 deg) is y - x tan(30 deg)
    x, y = srna.symbols[0], srna.symbols[1]
    g = parts[1].event.quantity["rendezvous"]
    assert float(g.subs({x: -50.0, y: 10.0})) == pytest.approx(10.0 + 50.0 * np.tan(np.pi / 6))


def test_switch_time_becomes_a_state_and_the_switch_is_urgent():
    sra = load_model("models/SRA02.yaml")
    aug, k = with_switch_time(sra)
    assert k == sra.n and aug.state[-1] == "_switch_time"
    assert (aug.initial.low[k], aug.initial.high[k]) == (120.0, 125.0)
    assert all(tr.urgent for tr in aug.transitions)
    assert all(m.flow[k] == 0 for m in aug.modes.values())


@pytest.mark.parametrize("horizon, status", [(2.5, Status.SAFE), (5.0, Status.UNSAFE)])
def test_avoid_set_after_a_window_against_the_closed_form(tmp_path, horizon, status):
    """Passive x = x0 + 2 tau - t >= 2 + 2 - T: the box |x| <= 0.5 is missed by 1 for T = 2.5
    (SAFE, proved step by step) and entered for T = 5 (a switch time and initial state that
    replay)."""
    model, props = load_files(tmp_path, RAMP.format(lo=1.0, hi=1.5, horizon=horizon), """
        properties:
          - {id: hit, kind: safety, modes: [back], avoid: {box: {x: [-0.5, 0.5]}}}
    """)
    result = BACKEND.check(model, props["hit"], {"refine": 3})
    assert result.status is status
    lo, hi = result.details["margin_bound"]
    if status is Status.SAFE:
        # the closest approach: x0 = 2, tau = 1, t = T gives x = 1.5, margin x - 0.5 = 1
        assert 0 < lo <= 1.0 + 1e-9 <= hi + 2e-9
    else:
        c = result.counterexample
        assert 1.0 <= c.switch_time <= 1.5
        run = replay(model, props["hit"], c.initial_state, c.switch_time)
        assert run.violated and abs(run.state[0]) <= 0.5


def test_thrust_safety_margin_agrees_with_the_event_file():
    """rendezvous.yaml's thrust (|Fx| <= 10 N in approach and rendezvous) read as margins and
    rendezvous_events.yaml's largest Fx in approach: margin = 10 N - max Fx (estimated)."""
    srna = load_model("models/SRNA01.yaml")
    thrust = {p.id: bind(p, srna) for p in load_properties("properties/rendezvous.yaml")}["thrust"]
    events = {p.id: bind(p, srna) for p in load_properties("properties/rendezvous_events.yaml")}
    part = margins(srna, thrust)[0]                      # Fx <= 10 N
    assert part.event.modes == ["approach", "rendezvous"]
    approach_only = type(part.event)(**{**part.event.__dict__, "modes": ["approach"],
                                        "quantity": {"approach": part.event.quantity["approach"]}})
    margin = BACKEND.check(srna, approach_only, {})
    fx = BACKEND.check(srna, events["thrust_x_max"], {})
    ten_newton = 10.0 * 60.0 ** 2                         # kg m/min^2
    assert margin.bound[0] == pytest.approx(ten_newton - fx.bound[1], rel=1e-9)
    assert margin.bound[1] == pytest.approx(ten_newton - fx.bound[0], rel=1e-9)


def test_kept_sets_of_a_safety_check_hold_the_closed_form_runs(tmp_path):
    """With ``keep_sets`` a safety answer carries the rigorous step boxes, and the closed-form
    runs x(t) = x0 cos t, v(t) = -x0 sin t lie in the boxes of their time (the picture's promise)."""
    model, props = load_files(tmp_path, SPRING, """
        properties:
          - {id: low, kind: safety, require: ["x <= 1.2"]}
    """)
    result = BACKEND.check(model, props["low"], {**RIGOROUS, "keep_sets": True})
    assert result.status is Status.SAFE and result.sets
    for x0 in (0.9, 1.0, 1.1):
        for piece in result.sets[:: max(1, len(result.sets) // 25)]:
            t = 0.5 * (piece.t0 + piece.t1)
            (xs, vs) = piece.polygon("x", "v").T
            x, v = x0 * np.cos(t), -x0 * np.sin(t)
            assert xs.min() - 1e-9 <= x <= xs.max() + 1e-9 and vs.min() - 1e-9 <= v <= vs.max() + 1e-9
    assert not BACKEND.check(model, props["low"], RIGOROUS).sets


# a clockless two-mode automaton: x' = 1 from x0 in [0, 0.5] until the urgent switch at x = 2
# (t = 2 - x0), then x' = -1: x(t) = 4 - x0 - t in ``down``, least at the horizon 3, 1 - x0 >= 0.5
CLOCKLESS = """
name: updown
state: [x]
modes:
  up: {flow: {x: 1}, invariant: ["x <= 2"]}
  down: {flow: {x: -1}}
transitions:
  - {from: up, to: down, guard: ["x >= 2"], urgent: true}
initial: {mode: up, box: {x: [0, 0.5]}}
horizon: 3
"""


@pytest.mark.parametrize("floor, expected", [(0.3, Status.SAFE), (0.8, Status.UNSAFE)])
def test_a_model_without_a_clock_gets_one_for_events_past_a_switch(tmp_path, floor, expected):
    """``x >= floor`` in ``down`` holds for floor < 0.5 (closed form above) and fails above it;
    taylor reads the horizon on a clock of its own, the model having none."""
    (tmp_path / "m.yaml").write_text(CLOCKLESS)
    (tmp_path / "p.yaml").write_text(
        f"properties:\n  - {{id: low, kind: safety, modes: [down], require: ['x >= {floor}']}}\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    assert BACKEND.supports(model, prop) is None
    result = BACKEND.check(model, prop, RIGOROUS if expected == Status.SAFE else None)
    assert result.status == expected
    if expected == Status.UNSAFE:
        cex = result.counterexample
        assert replay(model, prop, cex.initial_state, cex.switch_time, cex.dt or None).violated


def test_a_spent_time_budget_bounds_nothing_and_names_the_option(tmp_path):
    model, props = load_files(tmp_path, SPRING, """
        properties:
          - {id: low, kind: safety, require: ["x <= 1.2"]}
    """)
    result = BACKEND.check(model, props["low"], {**RIGOROUS, "max_seconds": 1e-9})
    assert result.status is Status.UNKNOWN
    assert result.details["margin_bound"] == [-np.inf, np.inf]
    assert "time budget of 1e-09 s (option max_seconds) exhausted" in result.details["reason"]
    # a budget the check stays within changes nothing
    within = BACKEND.check(model, props["low"], {**RIGOROUS, "max_seconds": 600})
    free = BACKEND.check(model, props["low"], RIGOROUS)
    assert within.status is free.status is Status.SAFE
    assert within.details["margin_bound"] == free.details["margin_bound"]


TANK = """
name: tank
state: [x, c]
modes:
  "on":
    flow: {x: "1 - 0.1*x", c: 1}
    invariant: ["x <= 8"]
  on_delay:
    flow: {x: "1 - 0.1*x", c: 1}
    invariant: ["c <= 1"]
  "off":
    flow: {x: "-0.1*x", c: 1}
    invariant: ["x >= 4"]
  off_delay:
    flow: {x: "-0.1*x", c: 1}
    invariant: ["c <= 1"]
transitions:
  - {from: "on", to: on_delay, guard: ["x >= 8"], urgent: true, reset: {c: 0}}
  - {from: on_delay, to: "off", guard: ["c >= 1"], urgent: true}
  - {from: "off", to: off_delay, guard: ["x <= 4"], urgent: true, reset: {c: 0}}
  - {from: off_delay, to: "on", guard: ["c >= 1"], urgent: true}
initial: {mode: "on", box: {x: [5, 6], c: 0}}
horizon: 100
"""


@pytest.mark.parametrize("side", ["avoid", "require"])
def test_a_forbidden_bound_the_rigorous_sweep_leaves_open_is_searched_and_replayed(tmp_path, side):
    """A pump switched off 1 s after the level reaches 8: every run peaks at 10 - 2 e^-0.1 =
    8.19033 (closed form), so ``x >= 8.1`` is met by all of them. The rigorous sweep (forced for
    an avoid set, asked for the requirement) cannot show that every run leaves ``on``; the
    one-constraint margin is then searched with the estimated remainder, and its violation
    replays. A bound above the peak is never called UNSAFE."""
    path, props = tmp_path / "tank.yaml", tmp_path / "p.yaml"
    path.write_text(TANK)
    unsafe = '["x >= 8.1"]' if side == "avoid" else '["x < 8.1"]'
    safe = '["x >= 8.3"]' if side == "avoid" else '["x < 8.3"]'
    props.write_text("properties:\n"
                     f"  - {{id: over, kind: safety, modes: ['on', on_delay, 'off', off_delay], {side}: {unsafe}}}\n"
                     f"  - {{id: under, kind: safety, modes: ['on', on_delay, 'off', off_delay], {side}: {safe}}}\n")
    model = load_model(path)
    over, under = (bind(p, model) for p in load_properties(props))
    result = BACKEND.check(model, over, RIGOROUS)
    assert result.status == Status.UNSAFE
    cx = result.counterexample
    run = replay(model, over, np.asarray(cx.initial_state), cx.switch_time)
    assert run.violated
    peak = 10 - 2 * np.exp(-0.1)
    low, high = result.details["margin_bound"]
    assert low <= 8.1 - peak + 1e-6 and high >= 8.1 - peak - 1e-3      # the estimate holds the truth
    assert BACKEND.check(model, under, RIGOROUS).status != Status.UNSAFE


ROTATION = """
name: rotation
state: [x, y]
modes:
  run:
    flow: {x: "y", y: "-x"}
initial: {mode: run, box: {x: [0.9, 1.1], y: [-0.1, 0.1]}}
horizon: 3
"""


@pytest.mark.parametrize("options", [{}, RIGOROUS])
def test_a_quantity_the_flow_conserves_keeps_its_entry_value(tmp_path, options):
    """x^2 + y^2 is constant along a rotation: its rate is 0, so the nominal run turns nowhere
    (its values differ by rounding only). taylor crashed there (IndexError on the rate's
    expansion); its bound is now the entry set's range, [0.81, 1.22] (the box's nearest point
    and corners) widened by the polynomial range only. Estimated remainders prove no margin."""
    _, props = load_files(tmp_path, ROTATION, """
        properties:
          - {id: disc, kind: safety, modes: [run], require: ["x**2 + y**2 <= 1.2322"]}
          - {id: radius, kind: event, modes: [run], maximize: "x**2 + y**2", require: "<= 1.2322"}
        """)
    model = load_model(tmp_path / "model.yaml")
    assert BACKEND.check(model, props["disc"], options).status is (Status.SAFE if options else Status.UNKNOWN)
    lo, hi = BACKEND.check(model, props["radius"], options).bound
    assert lo <= 0.81 and 1.22 <= hi <= 1.2201
