"""The fixpoint check (reach.backends.star.fixpoint): an aggregate inside an earlier one (of a
clockless automaton: up to a shift in time) is not explored; what is skipped is covered, and
the verdicts stay sound against an independent reference (scipy's solve_ivp with events)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.star import BACKEND
from reach.backends.star.fixpoint import Covered, enlarged
from reach.model import load_model
from reach.result import Status
from reach.sets import Box, Star
from reach.spec import bind, load_properties

boxes = st.lists(st.tuples(st.floats(-5, 5), st.floats(0, 3)), min_size=3, max_size=3)


def _star(spec, row, rhs):
    low = np.array([a for a, _ in spec])
    return Star.from_box(Box(low, low + np.array([w for _, w in spec]))).intersect_halfspaces(row, rhs)


@settings(max_examples=200, deadline=None)
@given(boxes, boxes, st.floats(-3, 3), st.floats(-3, 3), st.floats(-4, 4), st.floats(-4, 4))
@example([(0.0, 0.0), (0.0, 1.0), (0.0, 0.0)], [(0.0, 0.0), (1.77e-13, 0.0), (0.0, 0.0)], 0.0, 1.0, -1.0, 0.0)
def test_a_covered_aggregate_lies_in_the_earlier_one(old, new, a, b, g_old, g_new):
    """Whenever ``covers`` says yes, every sampled state of the new aggregate (coordinate 2 is
    the clock) is in the recorded one: inside its box and its row, and it started no later."""
    row = np.array([[a, b, 0.0]])
    earlier = _star(old, row, [g_old])
    covered = Covered(clock=2)
    covered.record("m", earlier, (row, np.array([g_old])))
    later = _star(new, row, [g_new])
    if later.feasible_alpha() is None or not covered.covers("m", later, lambda k: None):
        return
    box, entry = later.box_bound(), earlier.box_bound()
    assert box.low[2] >= entry.low[2]
    rng = np.random.default_rng(0)
    alphas = rng.uniform(later.box.low, later.box.high, size=(400, later.nvars))
    inside = np.all(alphas @ later.predicate.A.T <= later.predicate.b, axis=1)   # exactly (an LP may
    # call a star empty that misses its row by 1e-13, and covers it)
    points = later.center + alphas[inside] @ later.basis.T
    assert np.all(points[:, :2] >= entry.low[:2] - 1e-12) and np.all(points[:, :2] <= entry.high[:2] + 1e-12)
    assert np.all(points @ row[0] <= g_old + 1e-9)


@settings(max_examples=200, deadline=None)
@given(boxes, boxes, st.floats(-3, 3), st.floats(-3, 3), st.floats(-4, 4), st.floats(-4, 4))
def test_without_shift_a_covered_aggregate_lies_in_the_earlier_one_clock_included(old, new, a, b, g_old, g_new):
    """A model with its own clock may read it (``t <= 0.8 and T >= 21.55``): there ``covers``
    (``shift=False``) says yes only when every sampled state of the new aggregate, its clock
    included, lies in the recorded one, so its runs are among the recorded one's."""
    row = np.array([[a, 0.0, b]])                       # the row reads the clock too
    earlier = _star(old, row, [g_old])
    covered = Covered(clock=2, shift=False)
    covered.record("m", earlier, (row, np.array([g_old])))
    later = _star(new, row, [g_new])
    if later.feasible_alpha() is None or not covered.covers("m", later, lambda k: None):
        return
    entry = earlier.box_bound()
    rng = np.random.default_rng(0)
    alphas = rng.uniform(later.box.low, later.box.high, size=(400, later.nvars))
    inside = np.all(alphas @ later.predicate.A.T <= later.predicate.b, axis=1)   # exactly (an LP may
    # call a star empty that misses its row by 1e-13, and covers it)
    points = later.center + alphas[inside] @ later.basis.T
    assert np.all(points >= entry.low - 1e-12) and np.all(points <= entry.high + 1e-12)
    assert np.all(points @ row[0] <= g_old + 1e-9)


def test_a_later_copy_of_an_aggregate_is_covered_only_where_time_does_not_matter():
    """The same states one time unit later: a time-shifted run of the recorded aggregate's in a
    model that does not read time (``shift``), but not covered where the clock is a state like
    any other (the later clock interval reaches past the recorded one)."""
    earlier = Star.from_box(Box(np.array([0.0, 0.0]), np.array([1.0, 2.0])))
    later = Star.from_box(Box(np.array([0.0, 1.0]), np.array([1.0, 3.0])))
    none = (np.zeros((0, 2)), np.zeros(0))
    verdicts = {}
    for shift in (True, False):
        covered = Covered(clock=1, shift=shift)
        covered.record("m", earlier, none)
        verdicts[shift] = covered.covers("m", later, lambda k: None)
    assert verdicts == {True: True, False: False}


def test_enlarged_contains_the_hull_and_only_a_margin_more():
    hull = _star([(1.0, 2.0), (-3.0, 0.5), (0.0, 1.0)], np.array([[1.0, 1.0, 0.0]]), [0.0])
    star, (H, g) = enlarged(hull, (np.zeros((0, 3)), np.zeros(0)), (np.array([[1.0, 1.0, 0.0]]), np.array([0.0])))
    inner, outer = hull.box_bound(), star.box_bound()
    assert np.all(outer.low <= inner.low) and np.all(outer.high >= inner.high)
    assert np.all(outer.high - inner.high <= 1e-7) and 0 < g[0] <= 1e-7


DEADBAND = """
name: deadband
state: [th, w]
modes:
  coast: {flow: {th: w, w: 0}, invariant: ["th + 5*w <= 0.01", "th + 5*w >= -0.01"]}
  push_neg: {flow: {th: w, w: -0.002}, invariant: ["th + 5*w >= 0"]}
  push_pos: {flow: {th: w, w: 0.002}, invariant: ["th + 5*w <= 0"]}
transitions:
  - {from: coast, to: push_neg, guard: ["th + 5*w >= 0.01"], urgent: true}
  - {from: coast, to: push_pos, guard: ["th + 5*w <= -0.01"], urgent: true}
  - {from: push_neg, to: coast, guard: ["th + 5*w <= 0"], urgent: true}
  - {from: push_pos, to: coast, guard: ["th + 5*w >= 0"], urgent: true}
initial: {mode: coast, box: {th: [-0.005, 0.005], w: [-0.001, 0.001]}}
horizon: 400
"""


def _coast_drift(th0, w0, until):
    """th at ``until`` of a run that stays in coast (scipy): th' = w, w' = 0 while
    |th + 5 w| <= 0.01 (no switch before ``until``, checked)."""
    sol = solve_ivp(lambda _, z: [z[1], 0.0], (0, until), [th0, w0], rtol=1e-12, atol=1e-15, max_step=1.0)
    assert np.all(np.abs(sol.y[0] + 5 * sol.y[1]) <= 0.01 + 1e-12)
    return float(sol.y[0, -1])


@pytest.fixture(scope="module")
def deadband(tmp_path_factory):
    folder = tmp_path_factory.mktemp("deadband")
    (folder / "m.yaml").write_text(DEADBAND)
    return load_model(folder / "m.yaml")


def _angle_bound(model, folder, bound):
    (folder / "p.yaml").write_text(
        f"properties: [{{id: angle, kind: safety, modes: [coast, push_neg, push_pos], "
        f"require: ['th <= {bound!r}', 'th >= {-bound!r}']}}]\n")
    return bind(load_properties(folder / "p.yaml")[0], model)


def test_a_deadband_loop_closes_by_the_fixpoint_and_stays_sound(deadband, tmp_path):
    """A limit cycle with no clock. Closed form: |th| < 0.01 on every run (in coast th + 5 w is
    in [-0.01, 0.01] and th moves towards the end it leaves by; in a push the peak is
    0.01 - 5 w + w^2 / 0.004 <= 0.01 for the entry speed w in [0, 0.02]), and a slow drift comes
    close to it: from th = 0.005, w = 2e-5 coast reaches th = 0.0099 at t = 245 (scipy). The
    check proves 0.0102 and ends long before the horizon (aggregates covered by earlier ones);
    it does not prove 0.0095."""
    model = deadband
    assert _coast_drift(0.005, 2e-5, 245.0) == pytest.approx(0.0099, rel=1e-9)
    above = BACKEND.check(model, _angle_bound(model, tmp_path, 0.0102))
    assert above.status is Status.SAFE, above.details
    assert above.details["covered_aggregates"] > 0
    assert above.details["latest_chain_start"] < 200
    below = BACKEND.check(model, _angle_bound(model, tmp_path, 0.0095))
    assert below.status is not Status.SAFE


# a thermostat with constant rates (exact segments): x' = +-1000 between 19 and 21, switching
# every 2 ms, 500 switches over the horizon; closed form: x stays in [19, 21], reaching both
FAST = """
name: fast
state: [x]
modes:
  heat: {flow: {x: "1000"}, invariant: ["x <= 21"]}
  cool: {flow: {x: "-1000"}, invariant: ["x >= 19"]}
transitions:
  - {from: heat, to: cool, guard: ["x >= 21"], urgent: true}
  - {from: cool, to: heat, guard: ["x <= 19"], urgent: true}
initial: {mode: heat, box: {x: [19.5, 20]}}
horizon: 1
"""


@pytest.mark.parametrize("require, expected", [
    (["x >= 18.99999", "x <= 21.00001"], Status.SAFE),
    (["x <= 20.99"], Status.UNSAFE),
    (["x >= 19.01"], Status.UNSAFE),
])
def test_a_cycle_of_constant_rate_modes_closes(tmp_path, require, expected):
    """Constant-rate modes aggregate too on a clockless model, so the 500-switch cycle closes
    by the fixpoint check: the band (closed form [19, 21]) is proved with a margin of 1e-5, and
    bounds inside it fail with a replayed counterexample."""
    (tmp_path / "m.yaml").write_text(FAST)
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: b, kind: safety, require: {require}}}\n")
    model = load_model(tmp_path / "m.yaml")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model))
    assert result.status == expected
    if expected == Status.SAFE:
        assert result.details["covered_aggregates"] >= 1
    else:
        assert result.counterexample is not None
