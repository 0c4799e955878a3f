"""A thruster deadband with a bounded time-varying disturbance torque and no clock: star decides
it with default options, against independent references (a closed-form bound of the overshoot,
scipy's solve_ivp with the extreme disturbance). Also the pieces of the method this rests on:
bounded-input coordinates keep their range through aggregation (so the fixpoint check closes),
pieces that miss a mode's invariant are not checked there, and the clockless second pass carries
the disturbance of rebased chains as generators."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reach.backends.star import BACKEND, StarOptions
from reach.backends.star.aggregation import interval_hull
from reach.backends.star.fixpoint import Covered, enlarged
from reach.backends.star.options import CLOCKED_FIRST_STARS, CLOCKLESS_FIRST_STARS, aggregating_retry
from reach.backends.star.transitions import _Piece, misses
from reach.model import load_model
from reach.result import Status
from reach.sets import Box, Star
from reach.spec import bind, load_properties

DEADBAND = """
name: deadband
state: [th, w]
bounded_inputs:
  d: {range: [-0.0005, 0.0005], varying: true}
modes:
  coast:
    flow: {th: "w", w: "d"}
    invariant: ["th <= 0.02", "th >= -0.02"]
  fire_neg:
    flow: {th: "w", w: "-0.01 + d"}
    invariant: ["w >= -0.002"]
  fire_pos:
    flow: {th: "w", w: "0.01 + d"}
    invariant: ["w <= 0.002"]
transitions:
  - {from: coast, to: fire_neg, guard: ["th >= 0.02", "w >= 0"], urgent: true}
  - {from: coast, to: fire_pos, guard: ["th <= -0.02", "w <= 0"], urgent: true}
  - {from: fire_neg, to: coast, guard: ["w <= -0.002"], urgent: true}
  - {from: fire_pos, to: coast, guard: ["w >= 0.002"], urgent: true}
initial: {mode: coast, box: {th: [-0.005, 0.005], w: [-0.001, 0.001]}}
horizon: 300
"""

D, THRUST, BAND = 5e-4, 0.01, 0.02


def overshoot_bound() -> float:
    """A bound of ``|th|`` on every run, in closed form. In coast ``|th| <= 0.02`` (invariant).
    A firing starts where coast meets its guard, at ``|th| = 0.02`` with speed ``|w0|``, and
    decelerates at ``|w'| >= 0.01 - 5e-4``, so ``|th|`` rises by at most ``w0^2 / (2 (0.01 -
    5e-4))``. In coast ``d(w^2)/dt = 2 w d <= 2 |d|_max |th'|``: from the last instant with
    ``w = 0``, or from the entry (initially ``|w| <= 0.001``, after a firing ``|w| = 0.002``),
    ``w0^2 <= 0.002^2 + 2 * 5e-4 * 0.04`` (at most the band's width travelled)."""
    w0_squared = 0.002 ** 2 + 2 * D * 2 * BAND
    return BAND + w0_squared / (2 * (THRUST - D))


def first_peak(th0: float, w0: float, d: float) -> float:
    """The largest ``th`` of the run from ``(th0, w0)`` with the disturbance held at ``d``: coast
    until ``th = 0.02`` (scipy event), then fire_neg until ``w = 0`` (the peak)."""
    def coast(_, z):
        return [z[1], d]

    def reach_band(_, z):
        return z[0] - BAND
    reach_band.terminal, reach_band.direction = True, 1
    run = solve_ivp(coast, (0, 300), [th0, w0], events=reach_band, rtol=1e-12, atol=1e-15, max_step=0.5)
    assert run.t_events[0].size == 1
    th1, w1 = run.y_events[0][0]

    def fire(_, z):
        return [z[1], -THRUST + d]

    def stop(_, z):
        return z[1]
    stop.terminal, stop.direction = True, -1
    peak = solve_ivp(fire, (0, 10), [th1, w1], events=stop, rtol=1e-12, atol=1e-15, max_step=0.01)
    return float(peak.y_events[0][0][0])


PROPERTIES = ("properties:\n"
              "  - {id: pointing, kind: safety, require: ['th <= 0.05', 'th >= -0.05']}\n"
              "  - {id: tight, kind: safety, require: ['th <= 0.021']}\n")


@pytest.fixture(scope="module")
def deadband(tmp_path_factory):
    folder = tmp_path_factory.mktemp("deadband")
    (folder / "m.yaml").write_text(DEADBAND)
    (folder / "p.yaml").write_text(PROPERTIES)
    model = load_model(folder / "m.yaml")
    return model, {p.id: bind(p, model) for p in load_properties(folder / "p.yaml")}


def test_the_references_bound_and_exceed_the_requirements():
    """The closed form keeps ``|th|`` below 0.0224 (inside ``pointing``), and the extreme
    disturbance from the far corner of the initial box overshoots ``tight`` on its first firing
    (scipy: peak 0.02137; closed form ``0.02 + (0.001^2 + 2 d 0.025) / (2 (0.01 - d))``)."""
    assert overshoot_bound() < 0.0224 < 0.05
    peak = first_peak(-0.005, 0.001, D)
    assert peak == pytest.approx(BAND + (0.001 ** 2 + 2 * D * 0.025) / (2 * (THRUST - D)), rel=1e-6)
    assert peak > 0.021
    assert first_peak(0.005, 0.001, D) < 0.021         # the near corner does not overshoot it


def test_pointing_is_proved_by_the_fixpoint_check(deadband):
    model, props = deadband
    result = BACKEND.check(model, props["pointing"])
    assert result.status is Status.SAFE, result.details.get("reason")
    assert result.details["covered_aggregates"] > 0


def test_tight_is_violated_with_a_replayed_counterexample(deadband):
    """UNSAFE only after the simulator replayed the witness; its run starts in the initial box and
    the reference says such runs exist (see above)."""
    model, props = deadband
    result = BACKEND.check(model, props["tight"])
    assert result.status is Status.UNSAFE, result.details.get("reason")
    x0 = np.asarray(result.details["witness"]["initial_state"][:2])
    assert np.all(np.abs(x0) <= [0.005 + 1e-12, 0.001 + 1e-12])
    assert result.counterexample is not None


def test_an_input_coordinate_keeps_its_range_through_aggregation():
    """Coordinate 1 is a bounded input (range [-1, 1], flow 0), coordinate 2 the clock. The
    aggregate's runs come back later with the same states, the input coordinate as the
    explored aggregate held it. Clipped to the range, hull and enlargement keep that
    coordinate at the range exactly, so the later aggregate is covered by the earlier one;
    unclipped, the later hull adds its outward rounding to the earlier margin and is not."""
    def aggregate_and_return(ranges):
        none = (np.zeros((0, 3)), np.zeros(0))
        member = Star.from_box(Box(np.array([0.0, -1.0, 1.0]), np.array([1.0, 1.0, 2.0])))
        first, rows = enlarged(interval_hull([(member, None)], none, lambda k: None, ranges)[0], none, none,
                               ranges)
        covered = Covered(clock=2)
        covered.record("m", first, rows)
        held = first.box_bound()
        back = Star.from_box(Box(np.array([0.0, held.low[1], 1.5]), np.array([1.0, held.high[1], 2.5])))
        later, kept = interval_hull([(back, None)], none, lambda k: None, ranges)
        assert len(kept) == 1
        return held, covered.covers("m", later, lambda k: None)

    held, covered = aggregate_and_return(Box(np.array([-np.inf, -1.0, -np.inf]), np.array([np.inf, 1.0, np.inf])))
    assert (held.low[1], held.high[1]) == (-1.0, 1.0) and covered
    held, covered = aggregate_and_return(None)
    assert held.high[1] > 1.0 and not covered


def test_a_piece_beyond_an_opposite_invariant_row_is_missed():
    """``th >= 0.05`` misses ``th <= 0.02`` (rows exactly opposite, apart by more than the touch
    tolerance); ``th >= 0.02`` touches it and ``th + w >= 0.05`` is not settled by one row pair."""
    H, g = np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([0.02, 0.02])
    far = _Piece(np.array([[-1.0, 0.0]]), np.array([-0.05]), False, "far")
    touching = _Piece(np.array([[-1.0, 0.0]]), np.array([-0.02]), False, "touching")
    slanted = _Piece(np.array([[-1.0, -1.0]]) / np.sqrt(2), np.array([-0.05]) / np.sqrt(2), False, "slanted")
    assert misses(far, H, g, 1e-9)
    assert not misses(touching, H, g, 1e-9)
    assert not misses(slanted, H, g, 1e-9)


def test_the_second_pass_carries_rebased_inputs_as_generators(deadband, clocked):
    model, _ = deadband
    retry, stars, on_vague = aggregating_retry(model, {}, StarOptions())
    assert retry.rebase_generators and retry.aggregate_after == 0 and stars == CLOCKLESS_FIRST_STARS
    assert not on_vague
    retry, stars, on_vague = aggregating_retry(clocked[0], {}, StarOptions())
    assert not retry.rebase_generators and stars == CLOCKED_FIRST_STARS and on_vague
    assert not aggregating_retry(model, {"input_cells": 0}, StarOptions())[0].rebase_generators
    assert aggregating_retry(model, {"aggregate_after": 2}, StarOptions()) is None



def with_clock(text: str) -> str:
    """The deadband with a declared global clock ``t`` that nothing reads (as SpaceEx files
    often declare one for the horizon): the model now depends on time for star."""
    text = text.replace("state: [th, w]", "state: [th, w, t]")
    for flow in ('"d"}', '"-0.01 + d"}', '"0.01 + d"}'):
        text = text.replace(flow, flow[:-1] + ', t: "1"}')
    return text.replace("w: [-0.001, 0.001]}", "w: [-0.001, 0.001], t: 0}")


@pytest.fixture(scope="module")
def clocked(tmp_path_factory):
    folder = tmp_path_factory.mktemp("clocked")
    (folder / "m.yaml").write_text(with_clock(DEADBAND))
    (folder / "p.yaml").write_text(PROPERTIES)
    model = load_model(folder / "m.yaml")
    assert model.global_clock == 2
    return model, {p.id: bind(p, model) for p in load_properties(folder / "p.yaml")}


def test_a_clocked_deadband_is_decided_aggregating_from_the_first_jump(clocked):
    """With the clock, per-cell successors multiply at every firing over 300 s; past
    CLOCKED_FIRST_STARS (or half the time budget) the check starts over aggregating from the
    first jump and decides both as the clockless model: SAFE within the closed-form bound,
    UNSAFE replayed."""
    model, props = clocked
    safe = BACKEND.check(model, props["pointing"])
    assert safe.status is Status.SAFE, safe.details.get("reason")
    assert "aggregating from the first jump" in safe.details["semantics"]
    unsafe = BACKEND.check(model, props["tight"])
    assert unsafe.status is Status.UNSAFE, unsafe.details.get("reason")
    assert unsafe.counterexample is not None
