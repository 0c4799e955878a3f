"""Runs that leave their flow's domain (a square root of a negative level) have NaN states: they
are counted and named, not read as touching the unsafe set nor counted in the violation bound."""

from __future__ import annotations

import numpy as np

from reach.backends.montecarlo import BACKEND
from reach.report import line
from reach.result import Status
from model_files import load_files


def test_runs_with_undefined_states_are_named_and_left_out_of_the_bound(tmp_path):
    """x' = -sqrt(x) from x0 in [0.5, 1] empties at t = 2 sqrt(x0) <= 2 < 3: after that the flow is
    not real. Before: "closest margin nan ... touching, not a violation" and every run counted in
    "P(violation) <= 0.003"."""
    model, props = load_files(tmp_path, """
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
    result = BACKEND.check(model, props["low"], {"samples": 200, "optimise": False, "search_rounds": 0})
    d = result.details
    assert result.status is Status.UNKNOWN
    assert d["undefined_runs"] == d["random_runs"] == 200
    assert not np.isnan(d["closest_depth"])
    assert d["violation_probability_upper_95"] == 1.0          # no run left to bound it with
    text = line(result, props["low"], model)
    assert "not a real number" in text and "touching" not in text
