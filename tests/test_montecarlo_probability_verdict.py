"""A sampled probability is a violation (exit 1) only when an interval at
``reach.stats.VERDICT_CONFIDENCE`` lies wholly below the threshold, not its 95 % interval.

Double integrator ``x' = v``, kicks ``N(0, 0.01)`` on ``v`` each second from ``x = 0, v = 1``:
the kicks at ``t = 0..9`` give ``x(10) = 10 + sum_k (10 - k) w_k``, variance ``0.01
sum_{j=1}^{10} j^2 = 3.85``, so ``P(8 <= x(10) <= 12) = 2 Phi(2 / sqrt(3.85)) - 1 = 0.69194``
(fsr agrees). With
1000 samples and seed 0 the 95 % interval was [0.630, 0.689]: a threshold 7e-4 below the truth
was called violated on every run."""

from __future__ import annotations

import json
import math

import pytest
import yaml
from scipy.stats import norm

from reach.cli import main

TRUTH = float(2 * norm.cdf(2 / math.sqrt(0.01 * sum(j * j for j in range(1, 11)))) - 1)


def _files(tmp_path, at_least: float):
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "stoch_di", "state": ["x", "v", "t"], "horizon": 10,
        "modes": {"m": {"flow": {"x": "v", "v": 0, "t": 1}}},
        "initial": {"mode": "m", "box": {"x": 0, "v": 1, "t": 0}},
        "disturbance": {"gaussian": {"mean": [0], "cov": [0.01]}, "enters": ["v"], "step": 1}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"properties": [{
        "id": "p", "kind": "reach", "at": 10, "target": {"box": {"x": [8, 12]}},
        "probability": {"at_least": at_least}}]}))
    return str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml")


def test_fsr_agrees_with_the_closed_form(tmp_path, capsys):
    model, props = _files(tmp_path, TRUTH - 1e-3)
    assert main(["check", model, props, "-b", "fsr", "--json"]) == 0
    [row] = json.loads(capsys.readouterr().out)
    assert row["probability"][0] - 1e-6 <= TRUTH <= row["probability"][1] + 1e-6


@pytest.mark.parametrize("margin", [7e-4, 1e-2])
def test_a_threshold_just_below_the_truth_is_not_a_violation(tmp_path, margin):
    model, props = _files(tmp_path, TRUTH - margin)
    assert main(["check", model, props, "-b", "montecarlo"]) == 3


def test_a_threshold_far_above_the_truth_is_a_violation(tmp_path):
    model, props = _files(tmp_path, min(1.0, TRUTH + 0.15))
    assert main(["check", model, props, "-b", "montecarlo"]) == 1
