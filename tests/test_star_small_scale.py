"""star on quantities far below 1 (attitude rates in rad/s, angles in rad): a strict bound is
read at the scale of the quantity, not with an absolute floor of 1e-9.

``w' = -w + 1e-6`` from ``w0`` in [0, 1e-7] beside ``x' = 1`` from 7e6: ``w(t) = 1e-6 + (w0 -
1e-6) e^{-t}``, largest at ``t = 2`` from ``w0 = 1e-7``: ``1e-6 - 9e-7 e^{-2} = 8.78e-7``. A
bound 1e-4 below it is exceeded by 8.8e-11, which the floor of 1e-9 read as a touch (SAFE)."""

from __future__ import annotations

import math

import pytest
import yaml

from reach.backends.star import BACKEND
from model_files import load_files

TRUE_MAX = 1e-6 - 9e-7 * math.exp(-2.0)


def _verdict(tmp_path, model: dict, require: str, options: dict | None = None) -> str:
    """star's verdict on ``model`` (a YAML document) for the bound ``require`` in mode m."""
    model, props = load_files(tmp_path, yaml.safe_dump(model), yaml.safe_dump(
        {"properties": [{"id": "p", "kind": "safety", "modes": ["m"], "require": [require]}]}))
    return BACKEND.check(model, props["p"], options or {}).status.value


def _check(tmp_path, flow_w: str, w0, require: str):
    return _verdict(tmp_path, {"name": "small", "state": ["x", "w"], "horizon": 2,
                               "modes": {"m": {"flow": {"x": 1, "w": flow_w}}},
                               "initial": {"mode": "m", "box": {"x": [7.0e6, 7.001e6], "w": w0}}}, require)


@pytest.mark.parametrize("factor", [1 - 1e-4, 1 - 1e-2])
def test_a_small_quantity_past_its_strict_bound_is_never_safe(tmp_path, factor):
    assert _check(tmp_path, "-w + 1e-6", [0, 1e-7], f"w <= {TRUE_MAX * factor!r}") != "SAFE"


def test_a_small_quantity_within_its_bound_is_safe(tmp_path):
    assert _check(tmp_path, "-w + 1e-6", [0, 1e-7], f"w <= {TRUE_MAX * (1 + 1e-2)!r}") == "SAFE"


def test_a_drift_of_5e_10_past_zero_is_never_safe(tmp_path):
    """The tester's ``th' = 5e-10`` from 0 against ``th <= 0``: SAFE before."""
    assert _check(tmp_path, "5e-10", 0, "w <= 0") != "SAFE"


def test_a_quantity_that_only_touches_zero_is_safe(tmp_path):
    """``w' = -5e-10`` from 0 meets ``w = 0`` at t = 0 only: the touch of a strict bound."""
    assert _check(tmp_path, "-5e-10", 0, "w <= 0") == "SAFE"


def test_a_wide_set_does_not_widen_a_strict_bounds_tolerance(tmp_path):
    """A box of +-1e6 cut by ``x - y <= 1e-3`` against ``x <= y``: the point (1e-3, 0) violates
    it by 1e-3. Read at the size of the segment's terms (1e6) alone, that depth was a touch."""
    wide = {"name": "wide", "state": ["x", "y"], "horizon": 1, "modes": {"m": {"flow": {"x": 0, "y": 0}}},
            "initial": {"mode": "m", "box": {"x": [-1e6, 1e6], "y": [-1e6, 1e6]}, "constraints": ["x - y <= 1e-3"]}}
    assert _verdict(tmp_path, wide, "x <= y", {"max_seconds": 20}) != "SAFE"
