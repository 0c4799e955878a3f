"""star's SAFE is a proof: discrete time never proves, strict and non-strict bounds are told
apart up to a stated tolerance, and a solver failure is no verdict.

References: closed forms of ``x' = 1`` (the run from ``x0`` is ``x0 + t``), and the rendezvous
models, where every run enters the rendezvous mode at exactly ``x = -100`` (the guard of the
urgent entry, with the approach invariant ``x <= -100``).
"""

import numpy as np
import pytest
import sympy

from reach import lp
from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND
from reach.errors import Where
from reach.model.automaton import HybridAutomaton, InitialSet, Mode
from reach.model.constraints import Constraint
from reach.model.units import SI
from reach.result import Status
from reach.spec.properties import BoundSafety

X, T = sympy.symbols("x t", real=True)


def ramp(horizon=1.0, x0=(0.0, 0.0)):
    """One mode, ``x' = 1``, ``t' = 1``: ``x(t) = x0 + t`` up to the horizon."""
    mode = Mode("go", [X, T], [sympy.Integer(1), sympy.Integer(1)], {}, [])
    initial = InitialSet("go", np.array([x0[0], 0.0]), np.array([x0[1], 0.0]))
    return HybridAutomaton("ramp", "x' = 1", "(built in test)", SI, {}, ["x", "t"], [],
                           {"go": mode}, [], initial, horizon, clocks=[1])


def x_below(limit, strict_unsafe):
    """``x <= limit`` (unsafe ``x > limit``, strict) or ``x < limit`` (unsafe ``x >= limit``)."""
    g = sympy.Float(limit) - X                 # unsafe piece: limit - x < 0 (or <= 0)
    text = f"x {'<=' if strict_unsafe else '<'} {limit}"
    piece = Constraint(g, strict_unsafe, f"{limit} - x {'<' if strict_unsafe else '<='} 0", Where())
    return BoundSafety(text, ["go"], {"go": [[piece]]}, [X, T], file="(built in test)")


@pytest.mark.parametrize("x_max", [1.0, 100.0, 1e4])
def test_a_bound_met_with_equality_is_safe_and_one_just_inside_is_not(x_max):
    """``max x = x_max`` (the run from ``x0 = x_max - 1`` at ``t = 1``): ``x <= x_max`` holds,
    ``x <= x_max (1 - 1e-8)`` is violated by more than the stated tolerance."""
    model = ramp(x0=(x_max - 1.5, x_max - 1.0))
    safe = BACKEND.check(model, x_below(x_max, strict_unsafe=True))
    assert safe.status is Status.SAFE, safe.details
    tolerance = safe.details["touch_tolerance"]
    assert 0 < tolerance["largest"] <= tolerance["relative"] * (1 + 2 * x_max)
    assert "entered at a depth above" in safe.details["semantics"]

    tight = x_max - 1e-8 * x_max
    assert 1e-8 * x_max > tolerance["largest"]
    violated = BACKEND.check(model, x_below(tight, strict_unsafe=True))
    assert violated.status is not Status.SAFE, violated.details
    if violated.status is Status.UNSAFE:
        cex = violated.counterexample
        assert replay(model, x_below(tight, True), np.array(cex.initial_state), cex.switch_time).violated


def test_a_closed_unsafe_piece_that_is_only_touched_is_not_safe():
    """``x < 1`` fails at ``t = 1`` for ``x0 = 0`` (``x = 1`` is unsafe): never SAFE."""
    result = BACKEND.check(ramp(x0=(-0.5, 0.0)), x_below(1.0, strict_unsafe=False))
    assert result.status is not Status.SAFE, result.details


def test_discrete_time_never_proves_safety():
    """On the grid the ramp never exceeds its final value either, but a grid is no proof."""
    model = ramp(x0=(-0.5, 0.0))
    result = BACKEND.check(model, x_below(2.0, strict_unsafe=True), {"discrete_time": True, "step": 0.25})
    assert result.status is Status.UNKNOWN
    assert "no violation at the grid points" in result.details["reason"]
    assert BACKEND.check(model, x_below(2.0, strict_unsafe=True), {"step": 0.25}).status is Status.SAFE


def test_discrete_time_still_finds_violations_at_grid_points():
    model = ramp(x0=(-0.5, 0.0))
    prop = x_below(0.7, strict_unsafe=True)
    result = BACKEND.check(model, prop, {"discrete_time": True, "step": 0.25})
    assert result.status is Status.UNSAFE, result.details
    cex = result.counterexample
    assert replay(model, prop, np.array(cex.initial_state), cex.switch_time).violated


def test_solver_failure_is_unknown_with_the_reason(monkeypatch):
    def failing(*args, **kwargs):
        raise lp.LPError("LP solver stopped without a verdict: (HiGHS Status 4: Solve error)")

    monkeypatch.setattr(lp, "minimize", failing)
    result = BACKEND.check(ramp(x0=(-0.5, 0.0)), x_below(0.7, strict_unsafe=True))
    assert result.status is Status.UNKNOWN
    assert "LP solver failure" in result.details["reason"] and "Status 4" in result.details["reason"]


# ---------------------------------------------------------------------- the rendezvous entry

@pytest.fixture(scope="module")
def sra02():
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties
    model = load_model("models/SRA02.yaml")
    props = {p.id: bind(p, model) for f in ("properties/rendezvous.yaml", "tests/data/star_los_edge.yaml")
             for p in load_properties(f)}
    return model, props


def test_los_met_with_equality_on_entry_stays_safe(sra02):
    model, props = sra02
    for pid in ("los", "los_x"):
        result = BACKEND.check(model, props[pid])
        assert result.status is Status.SAFE, (pid, result.details)


def test_a_bound_1e6_inside_the_entry_line_is_not_safe(sra02):
    model, props = sra02
    prop = props["los_x_inside"]
    result = BACKEND.check(model, prop)
    assert result.status in (Status.UNSAFE, Status.UNKNOWN), result.details
    if result.status is Status.UNSAFE:
        cex = result.counterexample
        run = replay(model, prop, np.array(cex.initial_state), cex.switch_time)
        assert run.violated and run.state[model.index("x")] < -99.999999


def test_coarse_unrefined_check_of_sra08_answers_without_a_crash():
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties
    model = load_model("models/SRA08.yaml")
    prop = next(bind(p, model) for p in load_properties("properties/rendezvous.yaml") if p.id == "collision")
    result = BACKEND.check(model, prop, {"max_refinements": 0, "step": 30.0})
    assert result.status in (Status.UNKNOWN, Status.SAFE), result.details
    if result.status is Status.UNKNOWN:
        assert result.details["reason"]


TOUCH_JUMP = """
name: touch
state: [x, t]
modes:
  a: {flow: {x: "1", t: "1"}, invariant: ["x <= 1"]}
  b: {flow: {x: "0", t: "1"}}
transitions:
  - {from: a, to: b, guard: ["x >= 1"], urgent: true}
initial: {mode: a, box: {x: [0, 0], t: [0, 0]}}
horizon: 1
"""


@pytest.mark.parametrize("step", [1e-3, 1e-4])
def test_a_jump_taken_at_the_horizon_is_not_lost_to_rounding(tmp_path, step):
    """The run reaches the guard ``x = 1`` at ``t = 1``, the horizon, and jumps into ``b``, all of
    which is unsafe. Ten thousand additions of the step fall 1e-13 short of 1: a guard test
    without the touch tolerance took no jump there and answered SAFE."""
    from reach.model import load_model
    from reach.spec import bind, load_properties
    (tmp_path / "m.yaml").write_text(TOUCH_JUMP)
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: inb, kind: safety, modes: [b], avoid: ['x >= 0']}\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    result = BACKEND.check(model, prop, {"step": step, "finer_retry": False})
    assert result.status is not Status.SAFE, result.details


EARLY_GUARD = """
name: early_guard
state: [x, y, c, t]
modes:
  A: {flow: {x: "-x + 2", y: "0", c: "0", t: "1"}}
  B: {flow: {x: "0", y: "1e7", c: "0", t: "1"}}
transitions:
  - {from: A, to: B, guard: ["x >= 1"]}
initial: {mode: A, box: {x: [0, 0], y: [0, 0], c: [1e9, 1e9], t: [0, 0]}}
horizon: 1
"""


def test_a_replayed_switch_waits_for_its_guard_to_hold_exactly(tmp_path):
    """``x = 2 (1 - e^{-t})`` meets the guard ``x >= 1`` at ``t = ln 2``, so ``y`` reaches at
    most ``1e7 (1 - ln 2) = 3068528.19`` in ``B``. A coarse cell's witness asks the replay to
    switch at a grid instant before ``ln 2``; a guard tested with a tolerance relative to the
    state's size (``c = 1e9``) let it jump at ``x = 0.9969`` and answered UNSAFE with a run
    that is none of the model's."""
    from reach.model import load_model
    from reach.spec import bind, load_properties
    (tmp_path / "m.yaml").write_text(EARLY_GUARD)
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: top, kind: safety, modes: [B], "
                                     "require: ['y <= 3068530.2']}\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    assert 1e7 * (1 - np.log(2)) < 3068530.2
    result = BACKEND.check(model, prop, {"step": 0.25})
    assert result.status is Status.SAFE, result.details.get("reason")
    early = np.zeros(2400, dtype=int)
    early[1663] = 1                          # t = 0.69292 < ln 2 = 0.693147 on the grid of 1/2400
    run = replay(model, prop, [0.0, 0.0, 1e9, 0.0], None, 1 / 2400,
                 {"step": 1 / 2400, "inputs": [], "values": [[]] * 2400, "switch": early.tolist()})
    assert not run.violated
