"""A reset that reads a time-varying input takes the input's value at the jump, which the signal
may set anywhere in its range whatever it was before or will be after. Closed form: ``u`` in
[0, 1]; at t = 1 the jump sets ``y := u``, so ``y`` is any value of [0, 1] and ``y - u`` any of
[-1, 1] afterwards (u = 1 up to the jump, 0 after: y - u = 1); with ``y := y + u`` at t = 1 and
``y := y - u`` at t = 2, ``y`` is any value of [-1, 1]."""

import pytest

from reach.backends.star import BACKEND
from reach.result import Status
from model_files import load_files

ONE_JUMP = """
name: input-reset
state: [x, y]
bounded_inputs:
  u: {range: [0, 1], varying: true}
modes:
  a: {flow: {x: 1, y: 0}, invariant: ["x <= 1"]}
  b: {flow: {x: 1, y: 0}, invariant: ["x <= 3"]}
transitions:
  - {from: a, to: b, guard: ["x >= 1"], reset: {y: "u"}, urgent: true}
initial: {mode: a, box: {x: 0, y: 0}}
horizon: 3
"""

TWO_JUMPS = """
name: input-in-and-out
state: [x, y]
bounded_inputs:
  u: {range: [0, 1], varying: true}
modes:
  a: {flow: {x: 1, y: 0}, invariant: ["x <= 1"]}
  b: {flow: {x: 1, y: 0}, invariant: ["x <= 2"]}
  c: {flow: {x: 1, y: 0}, invariant: ["x <= 3"]}
transitions:
  - {from: a, to: b, guard: ["x >= 1"], reset: {y: "y + u"}, urgent: true}
  - {from: b, to: c, guard: ["x >= 2"], reset: {y: "y - u"}, urgent: true}
initial: {mode: a, box: {x: 0, y: 0}}
horizon: 3
"""


def _check(text, tmp_path, mode, require):
    props = f'properties: [{{id: p, kind: safety, modes: [{mode}], require: ["{require}"]}}]'
    model, bound = load_files(tmp_path, text, props)
    return BACKEND.check(model, bound["p"], {"finer_retry": False})


@pytest.mark.parametrize("text, mode, require", [
    (ONE_JUMP, "b", "y <= 1.001"), (ONE_JUMP, "b", "y - u <= 1.001"), (TWO_JUMPS, "c", "y <= 1.001")])
def test_true_bounds_under_an_input_read_by_a_reset_are_proved(text, mode, require, tmp_path):
    assert _check(text, tmp_path, mode, require).status == Status.SAFE


@pytest.mark.parametrize("text, mode, require", [
    (ONE_JUMP, "b", "y - u <= 0.5"), (TWO_JUMPS, "c", "y <= 0.5")])
def test_a_bound_only_a_changing_input_violates_is_not_safe(text, mode, require, tmp_path):
    """Held at one value, ``y - u`` is 0 after the jump (and ``y + u - u`` is 0): only a signal
    that changes across the jump violates, so a frozen input value would prove these."""
    assert _check(text, tmp_path, mode, require).status != Status.SAFE


def test_a_bound_a_held_input_violates_is_replayed(tmp_path):
    result = _check(ONE_JUMP, tmp_path, "b", "y <= 0.5")
    assert result.status == Status.UNSAFE
    assert result.counterexample is not None
