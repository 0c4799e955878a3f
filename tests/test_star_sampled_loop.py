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
    props.write_text(f'properties:\n  - {{id: p, kind: safety, modes: [run], require: ["{require}"]}}\n')
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
