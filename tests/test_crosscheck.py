"""The bench cross-check "SAFE from one back-end while another has a counterexample that replays",
on result rows that carry a genuine counterexample.

Reference: the thrust the ARCH mode-1 gain asks for at ``t = 0`` (``u = K x``, a closed form).
From the corner ``x = -925 m, y = -425 m`` at rest, ``|Fx| = 7.40 N > 7 N``, so the run violates
``thrust_7N`` at once; from ``(-500, -200)`` it asks for 4 N and decays (the replay finds no
violation). The cross-check replays each counterexample itself.
"""

import numpy as np
import pytest

from arch import K1, NEWTON
from reach.backends.montecarlo import replay
from reach.bench.crosscheck import cross_check
from reach.model import load_model
from reach.spec import bind, load_properties

MODEL, PROPS = "models/SRA01.yaml", "properties/thrust_7N.yaml"
VIOLATING, HARMLESS = [-925.0, -425.0, 0.0, 0.0, 0.0], [-500.0, -200.0, 0.0, 0.0, 0.0]


def counterexample(state):
    return {"model_file": MODEL, "property_file": PROPS, "property": "thrust_7N",
            "initial_state": state, "switch_time": 120.0, "dt": None}


def row(backend, status, instance="SRA01-7N", cex=None):
    return {"instance": instance, "property": "thrust_7N", "backend": backend, "status": status,
            "seconds": 1.0, "details": {}, "expected": None, "probability": None, "bound": None,
            "counterexample": cex}


def failures(rows):
    return [c["message"] for c in cross_check(rows) if c["level"] == "fail"]


def test_the_counterexamples_are_what_the_closed_form_says():
    assert np.max(np.abs(K1 @ np.array(VIOLATING[:4]))) / NEWTON == pytest.approx(7.40, abs=0.01)
    assert np.max(np.abs(K1 @ np.array(HARMLESS[:4]))) / NEWTON < 4.1
    model = load_model(MODEL)
    prop = bind(load_properties(PROPS)[0], model)
    assert replay(model, prop, VIOLATING, 120.0).violated
    assert not replay(model, prop, HARMLESS, 120.0).violated


def test_safe_against_a_replayed_counterexample_fails_the_run():
    found = failures([row("star", "safe"), row("montecarlo", "unsafe", cex=counterexample(VIOLATING))])
    assert len(found) == 1
    assert "star says SAFE but montecarlo found a counterexample that replays" in found[0]
    assert found[0].startswith("SRA01-7N/thrust_7N")
    # the order of the rows does not matter, and every SAFE is named
    found = failures([row("montecarlo", "unsafe", cex=counterexample(VIOLATING)), row("star", "safe"),
                      row("fsr", "safe"), row("taylor", "unknown")])
    assert sorted(m.split(": ")[1].split(" ")[0] for m in found) == ["fsr", "star"]


def test_a_counterexample_that_does_not_replay_does_not_refute_a_safe():
    found = failures([row("star", "safe"), row("montecarlo", "unsafe", cex=counterexample(HARMLESS))])
    assert len(found) == 1 and "montecarlo says UNSAFE without a counterexample that replays" in found[0]


def test_unknown_beside_a_replayed_counterexample_and_other_instances_are_fine():
    assert failures([row("star", "unknown"), row("montecarlo", "unsafe", cex=counterexample(VIOLATING))]) == []
    assert failures([row("star", "safe", instance="other"),
                     row("montecarlo", "unsafe", cex=counterexample(VIOLATING))]) == []
