"""star checks several safety properties of one model together (``check_many``): one
exploration against the union of their unsafe sets, each property on its own only where that
is not SAFE. Held against the closed form of a hysteresis band (``x' = -x + 2`` heating up to
1.5, ``x' = -x`` cooling down to 0.5): every run stays in ``[0.5, 1.5]`` and reaches both ends."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.star import BACKEND
from reach.checking import check_model
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

BAND = """
name: band
state: [x]
modes:
  heat:
    flow: {x: "-x + 2"}
    invariant: ["x <= 1.5"]
  cool:
    flow: {x: "-x"}
    invariant: ["x >= 0.5"]
transitions:
  - {from: heat, to: cool, guard: ["x >= 1.5"], urgent: true}
  - {from: cool, to: heat, guard: ["x <= 0.5"], urgent: true}
initial: {mode: heat, box: {x: [0.5, 0.6]}}
horizon: 10
"""
TOP, BOTTOM = 1.5, 0.5          # the band's ends: reached by every run (heat from 0.6 takes 1.4 < 10)


@pytest.fixture(scope="module")
def band(tmp_path_factory):
    folder = tmp_path_factory.mktemp("band")
    (folder / "m.yaml").write_text(BAND)
    return load_model(folder / "m.yaml"), folder


def bound_props(model, folder, requirements: dict) -> list:
    text = "properties:\n" + "".join(f"  - {{id: {k}, kind: safety, require: ['{v}']}}\n"
                                     for k, v in requirements.items())
    (folder / "p.yaml").write_text(text)
    return [bind(p, model) for p in load_properties(folder / "p.yaml")]


def test_properties_proved_together_share_one_exploration(band):
    model, folder = band
    props = bound_props(model, folder, {"high": "x <= 1.52", "low": "x >= 0.48"})
    results = check_model(BACKEND, model, props)
    assert [r.status for r in results] == [Status.SAFE, Status.SAFE]
    assert all("proved in one exploration" in r.details["together"] for r in results)
    assert results[0].seconds == results[1].seconds        # the shared time, split


def test_a_violated_property_is_found_and_the_others_still_proved(band):
    """The union is violated, so each property is checked on its own: the violated one is UNSAFE
    with its own replayed counterexample, the others SAFE."""
    model, folder = band
    props = bound_props(model, folder, {"high": "x <= 1.52", "tight": "x <= 1.45", "low": "x >= 0.48"})
    high, tight, low = check_model(BACKEND, model, props)
    assert (high.status, tight.status, low.status) == (Status.SAFE, Status.UNSAFE, Status.SAFE)
    assert tight.counterexample is not None and tight.property == "tight"
    assert "checked one by one" in high.details["together"]


@settings(max_examples=8)
@given(top=st.floats(1.3, 1.7), bottom=st.floats(0.3, 0.7))
def test_verdicts_together_agree_with_the_closed_form(band, top, bottom):
    """Whatever the bounds, a SAFE is only given to a bound at or beyond the band's end (the
    unsafe sets are strict: ``x <= 1.5`` holds) and an UNSAFE only to one inside it (margins
    below 1e-3 may be UNKNOWN)."""
    model, folder = band
    props = bound_props(model, folder, {"upper": f"x <= {top!r}", "lower": f"x >= {bottom!r}"})
    upper, lower = check_model(BACKEND, model, props)
    for result, margin in ((upper, top - TOP), (lower, BOTTOM - bottom)):
        if result.status is Status.SAFE:
            assert margin >= 0, (result.property, margin)
        elif result.status is Status.UNSAFE:
            assert margin < 0, (result.property, margin)
        else:
            assert abs(margin) < 1e-3, (result.property, margin, result.details.get("reason"))
