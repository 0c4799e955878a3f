"""Star verdicts on the ARCH abort that a wrong back-end could not all reach: SAFE and UNSAFE on
the same model, bracketing the true closest approach.

Reference (no loader, no simulator): solve_ivp through approach, rendezvous and the passive drift
(tests/arch.py) puts the closest max-norm approach of SRA02 (abort in [120, 125] min) to the
target at 8.84 m, reached from the corner (-875, -425) m with the abort at 125 min. So avoiding the
boxes of half-width 0.1 m and 8.5 m holds, and the 9.5 m box is hit: star must say SAFE, SAFE,
UNSAFE, the last with a counterexample that replays and that the reference confirms.
A back-end answering SAFE always fails the last; one answering UNSAFE always fails the first two;
an over-approximation looser than 0.3 m at the closest point fails the second.
"""

import numpy as np
import pytest

from arch import CORNERS, closest_passive_approach
from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties


def avoid_box(tmp_path, half_width):
    path = tmp_path / f"box_{half_width}.yaml"
    path.write_text(f"""description: passive collision with a box of half-width {half_width} m
properties:
  - id: box
    kind: safety
    modes: [passive]
    avoid: {{box: {{x: ["-{half_width}[m]", "{half_width}[m]"], y: ["-{half_width}[m]", "{half_width}[m]"]}}}}
""")
    return path


def test_reference_closest_approach_of_sra02():
    distances = {(tuple(c[:2]), abort): closest_passive_approach(c, abort, 240.0)
                 for c in CORNERS for abort in (120.0, 122.5, 125.0)}
    (corner, abort), closest = min(distances.items(), key=lambda item: item[1])
    assert corner == (-875.0, -425.0) and abort == 125.0
    assert closest == pytest.approx(8.84, abs=0.01)


@pytest.mark.parametrize("half_width, expected", [(0.1, Status.SAFE), (8.5, Status.SAFE), (9.5, Status.UNSAFE)])
def test_star_brackets_the_closest_approach(tmp_path, half_width, expected):
    model = load_model("models/SRA02.yaml")
    prop = bind(load_properties(avoid_box(tmp_path, half_width))[0], model)
    result = BACKEND.check(model, prop)
    assert result.status is expected, result.details
    if expected is Status.SAFE:
        assert result.counterexample is None and result.details.get("semantics")
        return
    cex = result.counterexample
    assert replay(model, prop, np.array(cex.initial_state), cex.switch_time).violated
    assert 120.0 <= cex.switch_time <= 125.0
    assert closest_passive_approach(cex.initial_state, cex.switch_time, 240.0) <= half_width
