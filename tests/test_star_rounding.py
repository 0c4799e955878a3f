"""Rounding where a flow's terms cancel: an unstable mode run from its equilibrium. ``x' = x - 1``
from ``x = 1`` stays at 1 (closed form), while ``e^{t} x0`` and the affine part reach 1e15 by
t = 35 and cancel; star's grid stars and the switching hull's centre lose the digits that
decide. Neither may then say SAFE of a set every run is in."""

from __future__ import annotations

import pytest

from reach.backends.star import BACKEND
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

MODEL = """
name: equilibrium
state: [x, z, t]
modes:
  a: {{flow: {{x: "x - 1", z: "-z", t: "1"}}}}
{second}
transitions: {transitions}
initial: {{mode: a, box: {{x: [1, 1], z: [0, 0], t: [0, 0]}}}}
horizon: {horizon}
"""
SWITCHING = ('  b: {flow: {x: "x - 1", z: "-2*z", t: "1"}}',
             "\n  - {from: a, to: b}\n  - {from: b, to: a}")


@pytest.mark.parametrize("switching", [False, True])
@pytest.mark.parametrize("horizon", [34, 35, 40])
def test_an_unstable_equilibrium_is_never_proved_to_leave_a_set_it_stays_in(tmp_path, switching, horizon):
    second, transitions = SWITCHING if switching else ("", "[]")
    (tmp_path / "m.yaml").write_text(MODEL.format(second=second, transitions=transitions, horizon=horizon))
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: late, kind: safety, modes: [a%s], avoid: {box: {x: [0.9, 1.1], t: [%d, %d]}}}\n"
        % (", b" if switching else "", horizon - 2, horizon))
    model = load_model(tmp_path / "m.yaml")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model))
    assert result.status != Status.SAFE
    if result.status == Status.UNSAFE:
        assert result.counterexample is not None


@pytest.mark.parametrize("step", [0.2, 0.1, 0.0583])
def test_blocks_carry_the_rounding_of_the_blocks_before(tmp_path, step):
    """The switching group is explored in blocks of two cells, each from the end of the one
    before: at a fine step the rounding of 1e-16 per block, grown by ``e^t``, moved the computed
    equilibrium past 1.1 by ``t = 33`` and the check said SAFE. Carried from block to block, it
    stops the check (UNKNOWN, precision lost) instead."""
    (tmp_path / "m.yaml").write_text(MODEL.format(second=SWITCHING[0], transitions=SWITCHING[1], horizon=35))
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: late, kind: safety, modes: [a, b], avoid: {box: {x: [0.9, 1.1], t: [33, 35]}}}\n")
    model = load_model(tmp_path / "m.yaml")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model), {"step": step})
    assert result.status != Status.SAFE


def test_a_rotation_does_not_compound_the_carried_rounding(tmp_path):
    """``x'' = -x + u``, ``|u| <= 0.01``, explored in blocks (the input moves the invariant's
    state): ``r = |(x, y)|`` grows at most by ``|u| <= 0.01`` a second, so ``x <= 1.005 + 2`` over
    200 s. The rounding carried across the blocks moves with the rotation (``||Phi||_2 = 1``);
    bounded componentwise (``|Phi|``, row sums up to 1.4 a block) it grew like ``e^{0.3 t}`` and
    stopped the check with "precision lost"."""
    (tmp_path / "m.yaml").write_text(
        "name: osc\nstate: [x, y]\nbounded_inputs:\n  u: {range: [-0.01, 0.01], varying: true}\n"
        "modes:\n  m: {flow: {x: 'y', y: '-x + u'}, invariant: ['x <= 5']}\n"
        "initial: {mode: m, box: {x: [0.9, 1], y: [0, 0.1]}}\nhorizon: 200\n")
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: small, kind: safety, require: ['x <= 3.1']}\n")
    model = load_model(tmp_path / "m.yaml")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model), {"step": 1.0})
    assert result.status is Status.SAFE, result.details.get("reason")
    assert result.details["rebased_blocks"] > 0
