"""A state every run holds at one value (flow 0 everywhere, never reset, one initial value:
SpaceEx's constant ``k == 0.1`` given in the cfg) makes ``-k (x - 30)`` affine: the simulator
takes the exact linear path for it (reach.model.simulate.fixed_parameters, linear_with).
Reference: the closed form ``x(t) = 30 + (x0 - 30) e^(-k t)``."""

import numpy as np
import pytest

from reach.model import load_model
from reach.model.simulate import Simulator

MODEL = """name: cooling
state: [x, k]
modes:
  a: {{flow: {{x: "-k*(x - 30)", k: 0}}}}
transitions: {transitions}
initial: {{mode: a, box: {{x: [10, 20], k: {k}}}}}
horizon: 5
"""


@pytest.mark.parametrize("k,transitions,linear", [
    ("0.1", "[]", True),                                                     # one value: linear path
    ("[0.1, 0.2]", "[]", False),                                             # a range: each run its own
    ("0.1", '[{from: a, to: a, guard: ["x >= 25"], reset: {k: "2*k"}}]', False),   # reset: not fixed
])
def test_a_parameter_held_at_one_value_takes_the_linear_path(tmp_path, k, transitions, linear):
    (tmp_path / "m.yaml").write_text(MODEL.format(k=k, transitions=transitions))
    model = load_model(tmp_path / "m.yaml")
    sim = Simulator(model)
    assert ("a" in sim.generators) is linear
    lo, hi = model.initial.low, model.initial.high
    X = np.column_stack([np.linspace(10, 20, 7), np.linspace(lo[1], hi[1], 7)])
    traj = sim.run(X)
    exact = 30 + (X[:, 0] - 30) * np.exp(-X[:, 1] * 5.0)
    np.testing.assert_allclose(traj.final_state[:, 0], exact, rtol=1e-7)
