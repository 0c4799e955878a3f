"""A sampled-data PD loop (torque recomputed every 0.5 s from the state, held between ticks)
over 40 s, against its closed form: per hold interval ``th(s) = th + w s + u s^2 / (2 J)``, and
every run is linear in the initial state, so each instant's extremes are at the corners of the
initial box. The tick successors keep their shape even after one of them had to be hulled,
which proves the true bounds; a bound the runs cross is never SAFE (the fixpoint check may
only lean on aggregates whose exploration ended)."""

import itertools

import numpy as np
import pytest

from reach.backends.star import BACKEND
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

MODEL = """
name: sampled-pd
state: [th, w, u, c]
constants: {J: 20, K1: 2.0, K2: 8.0, Ts: 0.5}
modes:
  run:
    flow: {th: w, w: "u/J", u: 0, c: 1}
    invariant: ["c <= Ts"]
transitions:
  - {from: run, to: run, guard: ["c >= Ts"], urgent: true, reset: {u: "-K1*th - K2*w", c: 0}}
initial: {mode: run, box: {th: [0.08, 0.12], w: [-0.01, 0.01], u: 0, c: 0}}
horizon: 40
"""


def _extremes(horizon=40.0, J=20.0, K1=2.0, K2=8.0, Ts=0.5):
    """Smallest and largest ``th`` over the runs from the initial box's corners (closed form)."""
    low, high = np.inf, -np.inf
    for th, w in itertools.product([0.08, 0.12], [-0.01, 0.01]):
        u, t = 0.0, 0.0
        while t < horizon - 1e-12:
            a = u / J
            s = [0.0, Ts]
            if a != 0 and 0 < -w / a < Ts:
                s.append(-w / a)
            values = [th + w * x + a * x * x / 2 for x in s]
            low, high = min(low, *values), max(high, *values)
            th, w, t = th + w * Ts + a * Ts * Ts / 2, w + a * Ts, t + Ts
            u = -K1 * th - K2 * w
    return low, high


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("loop") / "pd.yaml"
    path.write_text(MODEL)
    return load_model(path)


def _check(model, tmp_path, require):
    props = tmp_path / "p.yaml"
    modes = ", ".join(model.modes)
    props.write_text(f'properties:\n  - {{id: p, kind: safety, modes: [{modes}], require: ["{require}"]}}\n')
    (prop,) = [bind(p, model) for p in load_properties(props)]
    return BACKEND.check(model, prop, {})


def test_the_true_upper_bound_is_proved(model, tmp_path):
    low, high = _extremes()
    assert 0.1280 < high < 0.1281                     # the loop's overshoot, at the first tick
    assert _check(model, tmp_path, f"th <= {high * 1.023:.4f}").status == Status.SAFE


def test_a_lower_bound_the_undershoot_crosses_is_not_safe(model, tmp_path):
    low, _ = _extremes()
    assert -0.01048 < low < -0.01047                  # the undershoot, near t = 12.5
    result = _check(model, tmp_path, f"th >= {low * 0.974:.4f}")
    assert result.status == Status.UNSAFE
    assert result.counterexample is not None


TWO_AXIS = """
name: two-axis
state: [x, vx, y, vy, ux, uy, c]
modes:
  fly:
    flow: {x: vx, vx: ux, y: vy, vy: uy, ux: 0, uy: 0, c: 1}
    invariant: ["c <= 0.1"]
transitions:
  - {from: fly, to: fly, guard: ["c >= 0.1"], urgent: true,
     reset: {ux: "-2*x - 2*vx + 0.5*y", uy: "-2*y - 2*vy - 0.5*x", c: 0}}
initial:
  mode: fly
  box: {x: [0.9, 1.1], vx: [-0.1, 0.1], y: [0.4, 0.6], vy: 0, ux: 0, uy: 0, c: 0}
horizon: 5
"""


def _two_axis_low(samples=40):
    """Least ``x + y`` over the runs from the initial box's corners: between ticks the flow of
    (x, vx, y, vy) with the held (ux, uy) is linear, sampled at ``samples`` points per period
    (the curve is a cubic at most, so these points miss its minimum by far less than the test's
    margin), the tick reset is linear too."""
    import scipy.linalg

    A = np.zeros((6, 6))
    A[0, 1] = A[1, 4] = A[2, 3] = A[3, 5] = 1.0
    steps = [scipy.linalg.expm(A * s) for s in np.linspace(0.0, 0.1, samples + 1)]
    low = np.inf
    for x, vx, y in itertools.product([0.9, 1.1], [-0.1, 0.1], [0.4, 0.6]):
        z = np.array([x, vx, y, 0.0, 0.0, 0.0])
        for _ in range(50):
            low = min(low, min((E @ z)[0] + (E @ z)[2] for E in steps))
            z = steps[-1] @ z
            z[4], z[5] = -2 * z[0] - 2 * z[1] + 0.5 * z[2], -2 * z[2] - 2 * z[3] - 0.5 * z[0]
    return low


def test_a_coupled_two_axis_loop_ticking_mid_cell_is_proved(tmp_path):
    """Ticks every 0.1 s against cells of 5/60 s: a tick falls inside a bisected cell, whose
    successor carries the halves' coefficients; it keeps its shape (an interval hull of the
    7-state tick loses the coupling of the held torques to the state), so a bound 0.05 below
    the least x + y (about 3 % of its range) is proved, and one 0.001 above it is violated."""
    path = tmp_path / "two.yaml"
    path.write_text(TWO_AXIS)
    model = load_model(path)
    low = _two_axis_low()
    assert -0.1488 < low < -0.1486
    assert _check(model, tmp_path, f"x + y >= {low - 0.05:.4f}").status == Status.SAFE
    assert _check(model, tmp_path, f"x + y >= {low + 0.001:.4f}").status == Status.UNSAFE
