"""star on linear hybrid automata with many switchings and no declared clock.

* The thermostat with hysteresis, written as a user writes it (no global clock): its closed
  form says every run stays in [19, 21] after reaching the band, so ``18 <= T <= 22`` holds and
  ``T <= 20.5`` fails within the first heating phase.
* Aggregation against references built from the dataclasses: the interval hull of the
  successors of a diagonal run contains points no run reaches; the check must refine the
  aggregate back into its members and still prove the property, and a real violation under an
  aggregate must come with a counterexample that replays.
"""

import logging

import numpy as np
import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND
from reach.errors import Where
from reach.model.automaton import HybridAutomaton, InitialSet, Mode, Transition
from reach.model.constraints import Constraint
from reach.model.loader import load_model
from reach.model.units import SI
from reach.result import Status
from reach.spec import bind, load_properties
from reach.spec.properties import BoundSafety

THERMOSTAT = """
name: thermostat
state: [T]
modes:
  heating:
    flow: {T: "-0.1*(T - 10) + 3"}
    invariant: ["T <= 21"]
  "off":
    flow: {T: "-0.1*(T - 10)"}
    invariant: ["T >= 19"]
transitions:
  - {from: heating, to: "off", guard: ["T >= 21"], urgent: true}
  - {from: "off", to: heating, guard: ["T <= 19"], urgent: true}
initial: {mode: heating, box: {T: [19.5, 20]}}
horizon: 60
"""

PROPERTIES = """
properties:
  - {id: band, kind: safety, modes: [heating, "off"], require: ["T >= 18", "T <= 22"]}
  - {id: below, kind: safety, modes: [heating, "off"], require: ["T <= 20.5"]}
  - {id: tight, kind: safety, modes: [heating, "off"], require: ["T >= 19", "T <= 21"]}
  - {id: inside, kind: safety, modes: [heating, "off"], require: ["T <= 20.9999"]}
"""


def heating_time(t_from, t_to):
    """Closed form of ``T' = 4 - 0.1 T``: the time to heat from ``t_from`` to ``t_to``."""
    return 10 * np.log((40 - t_from) / (40 - t_to))


def cooling_time(t_from, t_to):
    """Closed form of ``T' = -0.1 (T - 10)``."""
    return 10 * np.log((t_from - 10) / (t_to - 10))


@pytest.fixture(scope="module")
def thermostat(tmp_path_factory):
    folder = tmp_path_factory.mktemp("thermostat")
    (folder / "thermostat.yaml").write_text(THERMOSTAT)
    (folder / "props.yaml").write_text(PROPERTIES)
    model = load_model(folder / "thermostat.yaml")
    props = {p.id: bind(p, model) for p in load_properties(folder / "props.yaml")}
    return model, props


def test_the_model_needs_no_clock_and_has_many_switchings(thermostat):
    model, _ = thermostat
    assert model.clocks == [] and model.state == ["T"]
    period = heating_time(19, 21) + cooling_time(21, 19)
    assert 60 / period > 15                  # more than 30 jumps within the horizon


def test_thermostat_band_is_safe(thermostat, caplog):
    model, props = thermostat
    with caplog.at_level(logging.INFO, logger="reach.star"):
        result = BACKEND.check(model, props["band"], {"max_stars": 500})
    assert result.status is Status.SAFE, result.details
    assert result.details["aggregates"] > 0
    # the exploration closes by the fixpoint check: a later aggregate lies in an earlier one
    period = heating_time(19, 21) + cooling_time(21, 19)
    assert result.details["covered_aggregates"] > 0
    assert result.details["latest_chain_start"] < 60 - period
    # without it (off when the sets are kept for pictures) the runs reach the horizon: the
    # last chain starts within one period of it
    full = BACKEND.check(model, props["band"], {"max_stars": 500, "keep_sets": True})
    assert full.status is Status.SAFE and full.details["covered_aggregates"] == 0
    assert full.details["latest_chain_start"] > 60 - period
    assert full.details["jumps"] >= 2 * int((60 - heating_time(20, 21)) / period)


def test_thermostat_band_met_with_equality_at_every_switch_is_safe(thermostat):
    """The guards pin T = 21 and T = 19 on every switch: aggregates must keep that."""
    model, props = thermostat
    result = BACKEND.check(model, props["tight"])
    assert result.status is Status.SAFE, result.details
    assert result.details["covered_aggregates"] > 0                 # closed by the fixpoint check
    full = BACKEND.check(model, props["tight"], {"keep_sets": True})  # every switch to the horizon
    assert full.status is Status.SAFE, full.details
    assert full.details["aggregates"] > 10


def test_thermostat_bound_just_inside_the_switch_point_is_not_safe(thermostat):
    model, props = thermostat
    result = BACKEND.check(model, props["inside"])
    assert result.status is Status.UNSAFE, result.details
    cex = result.counterexample
    assert replay(model, props["inside"], np.array(cex.initial_state), cex.switch_time).violated


def test_thermostat_violation_replays(thermostat):
    model, props = thermostat
    result = BACKEND.check(model, props["below"])
    assert result.status is Status.UNSAFE, result.details
    cex = result.counterexample
    run = replay(model, props["below"], np.array(cex.initial_state), cex.switch_time)
    assert run.violated and run.state[0] > 20.5


COUNTING = THERMOSTAT.replace("state: [T]", "state: [T, c]").replace(
    '"-0.1*(T - 10) + 3"}', '"-0.1*(T - 10) + 3", c: 0}').replace('"-0.1*(T - 10)"}', '"-0.1*(T - 10)", c: 0}').replace(
    'guard: ["T <= 19"], urgent: true}', 'guard: ["T <= 19"], urgent: true, reset: {c: "c + 1"}}').replace(
    "box: {T: [19.5, 20]}", "box: {T: [19.5, 20], c: 0}")


def test_switch_count_is_exact_through_twenty_aggregations(tmp_path):
    """``c`` counts the heating restarts. Closed form: the k-th restart happens at
    heat(T0, 21) + cool(21, 19) + (k - 1) * period; the most restarts within the horizon over
    the initial interval is the reference. One more is SAFE; one fewer is violated only by the
    late switches, deep under aggregates, and must replay."""
    (tmp_path / "m.yaml").write_text(COUNTING)
    model = load_model(tmp_path / "m.yaml")
    period = heating_time(19, 21) + cooling_time(21, 19)
    restarts = max(int(np.floor((60 - heating_time(t0, 21) - cooling_time(21, 19)) / period)) + 1
                   for t0 in (19.5, 20))
    (tmp_path / "p.yaml").write_text(f"""
properties:
  - {{id: most, kind: safety, modes: [heating, "off"], require: ["c <= {restarts + 0.5}"]}}
  - {{id: fewer, kind: safety, modes: [heating, "off"], require: ["c <= {restarts - 0.5}"]}}
""")
    props = {p.id: bind(p, model) for p in load_properties(tmp_path / "p.yaml")}
    assert restarts > 10
    safe = BACKEND.check(model, props["most"])
    assert safe.status is Status.SAFE, safe.details
    assert safe.details["aggregates"] > 10
    violated = BACKEND.check(model, props["fewer"])
    assert violated.status is Status.UNSAFE, violated.details
    cex = violated.counterexample
    run = replay(model, props["fewer"], np.array(cex.initial_state), cex.switch_time)
    assert run.violated and run.state[1] == restarts


def test_star_budget_ends_in_unknown(thermostat):
    model, props = thermostat
    result = BACKEND.check(model, props["band"], {"max_stars": 2})     # the retry needs 3
    assert result.status is Status.UNKNOWN
    assert "max_stars" in result.details["reason"]


def test_without_aggregation_the_coefficient_guard_answers(thermostat):
    """Each segment doubles a star's coefficients: without aggregation the guard must stop
    the check with a reason instead of growing without bound."""
    model, props = thermostat
    result = BACKEND.check(model, props["band"], {"aggregate_after": None, "max_coefficients": 500})
    assert result.status is Status.UNKNOWN
    assert "coefficients" in result.details["reason"]


# ---------------------------------------------------------------------- aggregation

X, Y, Z, T = sympy.symbols("x y z t", real=True)
SYMBOLS = [X, Y, Z, T]


def c(g, strict=False):
    return Constraint(sympy.expand(g), strict, f"{g} <= 0", Where())


def diagonal(slope, window=(0.0, 3.0)):
    """``go``: x' = 1, y' = slope, z' = -z (not a constant flow), t' = 1, from the origin;
    at one instant of the window on t, ``stop`` (everything frozen but t). The states
    entering ``stop`` lie on the segment y = slope * x, 0 <= x <= 3."""
    lo, hi = window
    go = Mode("go", SYMBOLS, [sympy.Integer(1), sympy.Float(slope), -Z, sympy.Integer(1)], {}, [c(T - hi)])
    stop = Mode("stop", SYMBOLS, [sympy.Integer(0), sympy.Integer(0), -Z, sympy.Integer(1)], {}, [])
    jump = Transition("stop", "go", "stop", [c(lo - T), c(T - hi)], urgent=False, window=(3, lo, hi))
    initial = InitialSet("go", np.array([0.0, 0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0, 0.0]))
    return HybridAutomaton("diagonal", "test automaton", "(built in test)", SI, {}, ["x", "y", "z", "t"],
                           [], {"go": go, "stop": stop}, [jump], initial, 5.0, clocks=[3])


def gap_at_most(limit):
    """``x - y <= limit`` in ``stop`` (unsafe: ``limit - (x - y) < 0``)."""
    return BoundSafety("gap", ["stop"], {"stop": [[c(limit - (X - Y), strict=True)]]}, SYMBOLS,
                       file="(built in test)")


def test_a_spurious_hull_violation_is_refined_away():
    """y = x on entry, so x - y = 0 <= 0.5 always; the hull [0, 3]^2 has x - y up to 3."""
    model = diagonal(1.0)
    result = BACKEND.check(model, gap_at_most(0.5), {"aggregate_after": 0, "step": 0.5})
    assert result.status is Status.SAFE, result.details
    assert result.details["aggregates"] >= 1 and result.details["refined_aggregates"] >= 1


def test_a_real_violation_under_an_aggregate_replays():
    """y = x / 2: x - y = x / 2 exceeds 0.5 for every abort after t = 1."""
    model = diagonal(0.5)
    prop = gap_at_most(0.5)
    result = BACKEND.check(model, prop, {"aggregate_after": 0, "step": 0.5})
    assert result.status is Status.UNSAFE, result.details
    cex = result.counterexample
    assert cex.switch_time > 1.0
    run = replay(model, prop, np.array(cex.initial_state), cex.switch_time)
    assert run.violated and run.state[0] - run.state[1] > 0.5


def test_aggregation_keeps_the_verdict_of_the_exact_exploration():
    for slope, limit in ((1.0, 0.5), (0.5, 2.0), (0.5, 1.4)):
        prop = gap_at_most(limit)
        exact = BACKEND.check(diagonal(slope), prop, {"aggregate_after": None, "step": 0.5})
        merged = BACKEND.check(diagonal(slope), prop, {"aggregate_after": 0, "step": 0.5})
        assert exact.status is merged.status, (slope, limit, exact.details, merged.details)


def test_a_zero_dwell_cycle_ends_in_unknown(tmp_path):
    """Two urgent transitions that always hold: infinitely many jumps at t = 0 (Zeno)."""
    (tmp_path / "m.yaml").write_text("""
name: pingpong
state: [x]
modes:
  a: {flow: {x: 1}}
  b: {flow: {x: 1}}
transitions:
  - {from: a, to: b, guard: ["x >= 0"], urgent: true}
  - {from: b, to: a, guard: ["x >= 0"], urgent: true}
initial: {mode: a, box: {x: 0}}
horizon: 1
""")
    (tmp_path / "p.yaml").write_text("""
properties:
  - {id: small, kind: safety, modes: [a, b], require: ["x <= 10"]}
""")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    result = BACKEND.check(model, prop)
    assert result.status is Status.UNKNOWN
    assert "jumps within one time step" in result.details["reason"]


HYSTERESIS = """
name: hysteresis
state: [T]
modes:
  heating:
    flow: {{T: "-{a}*(T - {ambient}) + {power}"}}
    invariant: ["T <= {hi}"]
  "off":
    flow: {{T: "-{a}*(T - {ambient})"}}
    invariant: ["T >= {lo}"]
transitions:
  - {{from: heating, to: "off", guard: ["T >= {hi}"], urgent: true}}
  - {{from: "off", to: heating, guard: ["T <= {lo}"], urgent: true}}
initial: {{mode: heating, box: {{T: [{t0}, {t1}]}}}}
horizon: {horizon}
"""


@given(st.floats(0.05, 0.3), st.floats(1.0, 4.0), st.floats(-0.3, 0.3), st.integers(0, 2**32 - 1))
@settings(max_examples=8, deadline=None)
def test_hysteresis_verdicts_agree_with_simulated_runs(a, gap, delta, seed):
    """Random thermostats (heating reaches well above the upper threshold): star's SAFE for
    ``T <= hi + delta`` must hold on simulated runs from sampled initial states, its UNSAFE
    must replay, and with a clear margin (``delta >= 0.1``) the bound must be proved."""
    import tempfile
    from pathlib import Path
    rng = np.random.default_rng(seed)
    lo = 19.0
    hi = lo + gap
    ambient, power = 10.0, a * (hi + 5.0 - 10.0)           # heating settles 5 above hi
    text = HYSTERESIS.format(a=a, ambient=ambient, power=power, lo=lo, hi=hi, t0=lo + 0.2 * gap,
                             t1=lo + 0.4 * gap, horizon=60)
    with tempfile.TemporaryDirectory() as folder:
        (Path(folder) / "m.yaml").write_text(text)
        (Path(folder) / "p.yaml").write_text(
            f'properties:\n  - {{id: cap, kind: safety, modes: [heating, "off"], require: ["T <= {hi + delta}"]}}\n')
        model = load_model(Path(folder) / "m.yaml")
        prop = bind(load_properties(Path(folder) / "p.yaml")[0], model)
    result = BACKEND.check(model, prop, {"max_stars": 2000})
    if result.status is Status.SAFE:
        for x0 in rng.uniform(model.initial.low, model.initial.high, size=(5, 1)):
            assert not replay(model, prop, x0, None).violated
    if result.status is Status.UNSAFE:
        cex = result.counterexample
        assert replay(model, prop, np.array(cex.initial_state), cex.switch_time).violated
    if delta >= 0.1:
        assert result.status is Status.SAFE, result.details
    if delta < -0.01:
        assert result.status is not Status.SAFE, result.details
