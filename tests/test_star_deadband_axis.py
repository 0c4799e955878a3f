"""A single-axis attitude controller with deadband thrusters and a constant bounded disturbance,
whose coast mode has no invariant: the urgent guards ``th >= 0.1 & w >= 0`` and ``th <= -0.1 & w
<= 0`` alone end its flow. Their complements are no convex sets, so star used to split each
segment by them and let the chain itself flow on past them: the coast chain reached ``th = 1.05``
at the horizon and fired ``fire_neg`` from every one of its cells (an aggregate with ``th`` in
``[0.1, 1.05]``), and every check of the model ended UNKNOWN at the time budget. The row ``th <=
0.1`` is now kept (:func:`reach.backends.star.explorer._barrier_rows`): on ``th = 0.1`` outside
the guard (``w < 0``) ``th' = w`` falls, so a run that enters with ``th <= 0.1`` cannot cross it.

References: the true extremes over the initial box and the input range (an exact event-driven
simulation); the largest ``th`` and ``w`` in closed form below (the first overshoot from ``th =
-0.05``, ``w = 0.03``, ``p = 2e-4``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from reach.backends.montecarlo.replays import replay
from reach.backends.star import BACKEND
from reach.backends.star.explorer import _barrier_rows
from reach.backends.star.transitions import _LinearModel
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

MODEL = """
name: {name}
state: [th, w]
bounded_inputs:
  p: {{range: [-2e-4, 2e-4]{varying}}}
modes:
  coast: {{flow: {{th: "{coast_th}", w: p}}}}
  fire_neg: {{flow: {{th: w, w: "p - 0.05"}}, invariant: ["w >= -0.01"]}}
  fire_pos: {{flow: {{th: w, w: "p + 0.05"}}, invariant: ["w <= 0.01"]}}
transitions:
  - {{from: coast, to: fire_neg, guard: ["th >= 0.1", "w >= {offset}"{cap}], urgent: true}}
  - {{from: coast, to: fire_pos, guard: ["th <= -0.1", "w <= -{offset}"{floor}], urgent: true}}
  - {{from: fire_neg, to: coast, guard: ["w <= -0.01"], urgent: true}}
  - {{from: fire_pos, to: coast, guard: ["w >= 0.01"], urgent: true}}
initial: {{mode: coast, box: {{th: [-0.05, 0.05], w: [0.02, 0.03]}}}}
horizon: 100
"""

#: the true extremes (exact event-driven simulation over the initial box and the input range)
MAX_TH, MIN_TH = 0.1096385542, -0.1018384294
MAX_W, MIN_W = 0.03098386677, -0.01353172457
EXTREMES = {"maxth": ("th <=", MAX_TH), "minth": ("th >=", MIN_TH),
            "maxw": ("w <=", MAX_W), "minw": ("w >=", MIN_W)}


def _model(tmp_path, name="deadband", varying=False, coast_th="w", offset="0", capped=False):
    """``capped``: each guard gains a third row, ``th <= 0.2`` and ``th >= -0.2``, which no run
    reaches (the extremes stay)."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(MODEL.format(name=name, varying=", varying: true" if varying else "",
                                 coast_th=coast_th, offset=offset, cap=', "th <= 0.2"' if capped else "",
                                 floor=', "th >= -0.2"' if capped else ""))
    return load_model(path)


def _prop(tmp_path, model, key: str, relative: float):
    """The requirement on ``key``'s quantity with its bound moved outward by ``relative`` of the
    true extreme (negative: inward, so the property is violated)."""
    text, extreme = EXTREMES[key]
    bound = extreme * (1 + relative)      # the minima are below zero: outward is further below
    path = tmp_path / f"{key}_{relative:+g}.yaml"
    path.write_text(f"properties:\n  - id: {key}\n    kind: safety\n    modes: [coast, fire_neg, fire_pos]\n"
                    f"    require: [\"{text} {bound!r}\"]\n")
    return bind(load_properties(path)[0], model), bound


def test_the_closed_form_overshoot_matches_the_reference():
    """From ``th = -0.05``, ``w = 0.03``, ``p = 2e-4`` the run coasts to ``th = 0.1`` with
    ``w1^2 = 0.03^2 + 2 p 0.15`` and fires until ``w = 0``: ``th`` rises by ``w1^2 / (2 (0.05 -
    p))``."""
    p = 2e-4
    w1 = math.sqrt(0.03 ** 2 + 2 * p * 0.15)
    assert w1 == pytest.approx(MAX_W, rel=1e-9)
    assert 0.1 + w1 ** 2 / (2 * (0.05 - p)) == pytest.approx(MAX_TH, rel=1e-9)


def test_the_band_rows_of_the_two_row_guards_are_kept(tmp_path):
    """On ``th = 0.1`` with ``w < 0`` (outside ``th >= 0.1 & w >= 0``) ``th' = w < 0``: the row
    ``th <= 0.1`` is kept; likewise ``th >= -0.1``. The rows on ``w`` are not (``w' = p`` has
    either sign)."""
    model = _model(tmp_path)
    data = _LinearModel.of(model)
    rows = {jump.target: [(np.round(a[:2], 12).tolist(), round(float(b), 12))
                          for a, b in _barrier_rows(data, "coast", jump)] for jump in data.jumps["coast"]}
    neg, pos = rows["fire_neg"], rows["fire_pos"]
    assert neg == [([1.0, 0.0], 0.1)]
    assert pos == [([-1.0, 0.0], 0.1)]


@pytest.mark.parametrize("variant", [{"offset": "0.005"}, {"coast_th": "w + p"}])
def test_a_row_the_flow_may_cross_outside_the_guard_is_not_kept(tmp_path, variant):
    """``w >= 0.005`` in the guard: on ``th = 0.1`` with ``0 < w < 0.005`` the run is outside the
    guard and ``th`` rises past 0.1. ``th' = w + p``: on ``th = 0.1`` with ``-p < w < 0`` the run
    is outside the guard and ``th`` rises past 0.1. No row may be kept."""
    model = _model(tmp_path, **variant)
    data = _LinearModel.of(model)
    jumps = [jump for jump in data.jumps["coast"] if jump.H.shape[0] > 1]
    assert len(jumps) == 2
    for jump in jumps:
        assert _barrier_rows(data, "coast", jump) == []


@pytest.mark.parametrize("key", ["maxth", "minth", "maxw", "minw"])
def test_safe_one_percent_beyond_the_true_extremes(tmp_path, key):
    model = _model(tmp_path)
    prop, _ = _prop(tmp_path, model, key, 0.01)
    result = BACKEND.check(model, prop)
    assert result.status is Status.SAFE, result.details.get("reason")
    assert "urgent guards of several rows cut by one of their rows" in result.details["semantics"]


def test_safe_at_the_largest_angle_plus_a_hundredth_of_a_percent(tmp_path):
    """The case that ran out of time at 2.8 GB: star's cover of the first overshoot is within
    1.1e-5 of the exact one."""
    model = _model(tmp_path)
    prop, _ = _prop(tmp_path, model, "maxth", 1e-4)
    result = BACKEND.check(model, prop)
    assert result.status is Status.SAFE, result.details.get("reason")


@pytest.mark.parametrize("key,relative", [("maxth", -1e-4), ("maxw", -1e-4), ("minth", -0.01), ("minw", -0.01)])
def test_never_safe_inside_the_true_extremes(tmp_path, key, relative):
    """Just inside the true extreme the property is violated: never SAFE; where star says
    UNSAFE, its counterexample starts in the initial box and the simulator replays the
    violation."""
    model = _model(tmp_path)
    prop, bound = _prop(tmp_path, model, key, relative)
    result = BACKEND.check(model, prop)
    assert result.status is not Status.SAFE
    if result.status is Status.UNSAFE:
        ce = result.counterexample
        assert ce is not None
        x0 = np.asarray(ce.initial_state, dtype=float)
        assert -0.05 - 1e-12 <= x0[0] <= 0.05 + 1e-12 and 0.02 - 1e-12 <= x0[1] <= 0.03 + 1e-12
        assert abs(x0[2]) <= 2e-4 + 1e-15
        rep = replay(model, prop, ce.initial_state, ce.switch_time, ce.dt, ce.input_signal)
        assert rep.violated


def test_time_varying_disturbance(tmp_path):
    """The same axis with ``p`` any measurable signal in its range: SAFE 1 % beyond the largest
    angle (the constant extreme signal attains it), UNSAFE with a replayed run 1 % inside."""
    model = _model(tmp_path, name="deadband_tv", varying=True)
    prop, _ = _prop(tmp_path, model, "maxth", 0.01)
    assert BACKEND.check(model, prop).status is Status.SAFE
    prop, _ = _prop(tmp_path, model, "maxth", -0.01)
    result = BACKEND.check(model, prop)
    assert result.status is Status.UNSAFE
    ce = result.counterexample
    assert replay(model, prop, ce.initial_state, ce.switch_time, ce.dt, ce.input_signal).violated


def test_a_guard_row_met_all_over_the_face_needs_no_rate(tmp_path):
    """With ``th <= 0.2`` in the guard, the face ``th = 0.1`` meets that row everywhere: the LP
    over the face where it is not met is infeasible, which proves the row ``th <= 0.1`` keeps
    as much as the rate on ``w < 0`` does. The other face, ``th = 0.2``, is crossed (``th' = w``
    falls there outside the guard, ``w < 0``): its row is not kept. SAFE 1 % beyond the largest
    angle, as with two rows."""
    model = _model(tmp_path, capped=True)
    data = _LinearModel.of(model)
    rows = {jump.target: [(np.round(a[:2], 12).tolist(), round(float(b), 12))
                          for a, b in _barrier_rows(data, "coast", jump)] for jump in data.jumps["coast"]}
    assert rows == {"fire_neg": [([1.0, 0.0], 0.1)], "fire_pos": [([-1.0, 0.0], 0.1)]}
    prop, _ = _prop(tmp_path, model, "maxth", 0.01)
    result = BACKEND.check(model, prop)
    assert result.status is Status.SAFE, result.details.get("reason")
