"""star on modes where no time passes (``flow: false``), against the closed form.

A ball starts at rest at height ``x0 in [1, 2]`` in a timeless mode ``start``, falls under
``v' = -1`` and lands in a timeless mode ``stuck`` at ``x = 0`` with ``v = -sqrt(2 x0)``, that
is ``v in [-2, -sqrt(2)]``. Neither timeless mode lets time pass: the set each holds is the one
it is entered with, so star explores one star per entry and decides at the closed-form
values: the landing speed is never above 2 (SAFE beyond it), a landing speed below 1.5 is
reached (UNSAFE, replayed), and so is ``x >= 1.9`` in ``start`` (never SAFE).
"""

import numpy as np
import pytest

from reach.backends.star import BACKEND
from reach.model.loader import load_model
from reach.result import Status
from reach.spec import bind, load_properties

MODEL = """
name: drop
state: [x, v]
modes:
  start: {flow: false}
  fall:
    flow: {x: v, v: -1}
    invariant: ["x >= 0"]
  stuck: {flow: false}
transitions:
  - {from: start, to: fall, urgent: true}
  - {from: fall, to: stuck, guard: ["x <= 0"], urgent: true}
initial: {mode: start, box: {x: [1, 2], v: 0}}
horizon: 3
"""

PROPERTIES = """
properties:
  - {id: fast, kind: safety, modes: [stuck], avoid: ["v <= -2.2"]}
  - {id: slow, kind: safety, modes: [stuck], avoid: ["v >= -1.5"]}
  - {id: high, kind: safety, modes: [start], avoid: ["x >= 1.9"]}
  - {id: higher, kind: safety, modes: [start], avoid: ["x >= 2.1"]}
"""


@pytest.fixture(scope="module")
def drop(tmp_path_factory):
    folder = tmp_path_factory.mktemp("drop")
    (folder / "drop.yaml").write_text(MODEL)
    (folder / "props.yaml").write_text(PROPERTIES)
    model = load_model(folder / "drop.yaml")
    return model, {p.id: bind(p, model) for p in load_properties(folder / "props.yaml")}


def landing_speed(x0):
    """Closed form of ``x'' = -1`` from rest at ``x0``: the speed at ``x = 0``."""
    return -np.sqrt(2 * x0)


def test_the_landing_speeds_of_the_closed_form(drop):
    model, props = drop
    assert model.modes["start"].timeless and model.modes["stuck"].timeless
    assert landing_speed(2.0) > -2.2 and landing_speed(1.0) > -1.5

    fast = BACKEND.check(model, props["fast"])
    assert fast.status is Status.SAFE
    # one star in start, one chain in fall (not one per cell of start), and one star in stuck
    # per cell in which the fall lands (landing times sqrt(2 x0) in [sqrt(2), 2])
    landing_cells = int(np.ceil((2 - np.sqrt(2)) / fast.details["step"])) + 2
    assert fast.details["stars"] <= 2 + landing_cells
    assert "no time passes (start, stuck)" in fast.details["semantics"]

    slow = BACKEND.check(model, props["slow"])
    assert slow.status is Status.UNSAFE
    cex = slow.counterexample
    assert cex.violation_mode == "stuck"
    assert cex.violation_state[1] >= -1.5
    assert cex.violation_state[1] == pytest.approx(landing_speed(cex.initial_state[0]), abs=1e-2)


def test_the_entry_set_of_a_timeless_mode_is_checked(drop):
    model, props = drop
    assert BACKEND.check(model, props["higher"]).status is Status.SAFE
    assert BACKEND.check(model, props["high"]).status is not Status.SAFE
