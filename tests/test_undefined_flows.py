"""A flow that stops being real on some runs (a square root of a negative level): Monte Carlo's
NaN states are counted and named, not read as touching the unsafe set nor counted in the
violation bound; star's linearisation names the mode and what would help."""

from __future__ import annotations

import numpy as np

from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.star import BACKEND as STAR
from reach.report import line
from reach.result import Status
from model_files import load_files


# x' = -sqrt(x) from x0 in [0.5, 1] empties at t = 2 sqrt(x0) <= 2 < 3: after that the flow is not real
DRAINING_TANK = ("""
    name: tank
    state: [x]
    modes:
      drain: {flow: {x: "-sqrt(x)"}}
    initial: {mode: drain, box: {x: [0.5, 1]}}
    horizon: 3
""", """
    properties:
      - {id: low, kind: safety, modes: [drain], require: ["x >= -1"]}
""")


def test_runs_with_undefined_states_are_named_and_left_out_of_the_bound(tmp_path):
    """Before: "closest margin nan ... touching, not a violation" and every run counted in
    "P(violation) <= 0.003"."""
    model, props = load_files(tmp_path, *DRAINING_TANK)
    result = MONTECARLO.check(model, props["low"], {"samples": 200, "optimise": False, "search_rounds": 0})
    d = result.details
    assert result.status is Status.UNKNOWN
    assert d["undefined_runs"] == d["random_runs"] == 200
    assert not np.isnan(d["closest_depth"])
    assert d["violation_probability_upper_95"] == 1.0          # no run left to bound it with
    text = line(result, props["low"], model)
    assert "not a real number" in text and "touching" not in text


def test_star_names_the_mode_whose_flow_is_not_real_on_its_box(tmp_path):
    """The linearisation's box reaches x < 0, where the flow is not real: UNKNOWN, naming the mode
    and what would help."""
    model, props = load_files(tmp_path, *DRAINING_TANK)
    result = STAR.check(model, props["low"], {"finer_retry": False})
    reason = result.details["reason"]
    assert result.status is Status.UNKNOWN
    assert "mode 'drain'" in reason and "invariant that keeps" in reason
