"""Self-loops taken at one instant: star must not skip one whose reset is the identity on its
guard's face only up to a tolerance, nor trust an entry row proved from the jump the runs came
by without the size of the states. Each model's violation is a closed form at ``t = 0`` or just
after one jump; star answers UNSAFE (replayed) or UNKNOWN, never SAFE."""

from __future__ import annotations

import pytest

from reach.backends.star import BACKEND
from reach.result import Status
from tests.model_files import load_files

SHIFTED_ON_THE_FACE = """
name: shifted
state: [x, y]
modes:
  m: {flow: {x: "1", y: "0"}, invariant: ["x >= 7000000"]}
transitions:
  loop: {from: m, to: m, guard: ["x <= 7000000"], reset: {x: "2*x - 7000000", y: "y + 0.00000005"}}
initial: {mode: m, box: {x: [7000000, 7000000], y: [0, 0]}}
horizon: 5
"""
# at x = 7e6 (t = 0) the loop is enabled; x stays 7e6 and y gains 5e-8 per jump: y = 5e-8 > 1e-8

TINY_TERM_ON_A_LARGE_STATE = """
name: tiny_term
state: [x, y]
modes:
  a: {flow: {x: "0", y: "1"}, invariant: ["y <= 0"]}
  b: {flow: {x: "0", y: "1"}}
transitions:
  j1: {from: a, to: b, guard: ["y >= 0"], reset: {y: "y + 0.000000000000005*x"}}
  j2: {from: b, to: b, guard: ["y <= 0"], reset: {y: "1000000*y"}}
initial: {mode: a, box: {x: [-1000000000, -1000000000], y: [-1, -0.5]}}
horizon: 3
"""
# j1 at y = 0 lands at y = 5e-15 * (-1e9) = -5e-6, where j2 is enabled: y = -5 < -1.01


@pytest.mark.parametrize("model_text,modes,require", [(SHIFTED_ON_THE_FACE, "[m]", "y <= 0.00000001"),
                                                      (TINY_TERM_ON_A_LARGE_STATE, "[a, b]", "y >= -1.01")])
def test_never_safe(tmp_path, model_text, modes, require):
    props = f"""
    properties:
      - {{id: p, kind: safety, modes: {modes}, require: ["{require}"]}}
    """
    model, bound = load_files(tmp_path, model_text, props)
    result = BACKEND.check(model, bound["p"])
    assert result.status is not Status.SAFE, result.details
