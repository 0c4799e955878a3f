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


def simple(backend, status, instance="I", prop="p", **extra):
    r = row(backend, status, instance)
    r["property"] = prop
    r.update(extra)
    return r


def test_errors_and_timeouts_fail_with_their_message():
    checks = cross_check([simple("star", "error", details={"error": "LP failed"}), simple("fsr", "timeout")])
    assert [c["level"] for c in checks] == ["fail", "fail"]
    assert checks[0]["message"] == "I with star: error: LP failed"
    assert checks[1]["message"] == "I with fsr: timeout: "


def test_expected_verdicts_are_enforced_with_their_source():
    found = failures([simple("star", "safe", expected="unsafe", source="ARCH")])
    assert found == ["I/p: star says SAFE, expected unsafe (ARCH)"]
    unsafe = simple("montecarlo", "unsafe", instance="SRA01-7N", prop="thrust_7N", expected="safe",
                    source="paper", counterexample=counterexample(VIOLATING))
    assert failures([unsafe]) == ["SRA01-7N/thrust_7N: montecarlo says UNSAFE, expected safe (paper)"]
    notes = [c for c in cross_check([simple("star", "unknown", expected="unsafe")]) if c["level"] == "note"]
    assert [n["message"] for n in notes] == ["I/p: expected unsafe, but no back-end produced a counterexample"]
    found = cross_check([simple("montecarlo", "unsafe", instance="SRA01-7N", prop="thrust_7N", expected="unsafe",
                                counterexample=counterexample(VIOLATING))])
    assert found == []


def test_whole_instance_rows_are_not_property_checks():
    """Rows for property "*" (a whole-instance error) skip the property checks; later ones do not."""
    found = failures([simple("star", "unsafe", prop="*"), simple("fsr", "unsafe", prop="q")])
    assert found == ["I/q: fsr says UNSAFE without a counterexample that replays"]


@pytest.mark.parametrize("gap, apart", [(0.0, False), (0.5e-9, False), (2e-9, True), (0.01, True)])
def test_probability_intervals_overlap_up_to_rounding(gap, apart):
    for first, second in (("fsr", "montecarlo"), ("montecarlo", "fsr")):
        low = {"fsr": [0.60, 0.62], "montecarlo": [0.62 + gap, 0.70]}
        found = failures([simple(first, "unknown", probability=low[first]),
                          simple(second, "unknown", probability=low[second])])
        assert len(found) == int(apart)
        if apart:
            assert found[0].startswith(f"I/p: probability intervals of {first} ")


def test_every_pair_of_probability_intervals_is_compared_once():
    found = failures([simple("a", "unknown", probability=[0.1, 0.3]), simple("b", "unknown", probability=[0.25, 0.6]),
                      simple("c", "unknown", probability=[0.5, 0.7])])
    assert found == ["I/p: probability intervals of a [0.1000, 0.3000] and c [0.5000, 0.7000] do not overlap"]


def test_sampled_extrema_against_bounds_use_the_sense_and_the_grid_slack():
    """``within_bound``: strict on the outer side, the grid slack on the inner side."""
    bound = simple("taylor", "unknown", bound=[0.0, 1.0])
    sampled = lambda **d: simple("montecarlo", "unknown", details={"sampled_range": [0.5, 1.05], **d})
    # a minimum may be overshot on its upper (inner) side by the slack, a maximum may not
    assert failures([bound, sampled(sense="min", grid_slack=0.1)]) == []
    assert len(failures([bound, sampled(sense="max", grid_slack=0.1)])) == 1
    assert len(failures([bound, sampled(grid_slack=0.1)])) == 1          # "max" unless said
    assert len(failures([bound, sampled(sense="min")])) == 1             # no slack unless said
    assert "excludes sampled values in [0.5, 1.05]" in failures([bound, sampled(sense="min")])[0]


def test_replays_use_the_counterexample_switch_time():
    """SRU01 with the 0.2 m box: the collision happens after the abort at 260 min; without the
    recorded abort the run never leaves the controlled modes and no collision replays."""
    cex = {"model_file": "models/SRU01.yaml", "property_file": "properties/collision_box_0p2.yaml",
           "property": "collision_0p2", "initial_state": [-875.0, -425.0, 0.0, 0.0, 0.0],
           "switch_time": 260.0, "dt": None}
    r = simple("montecarlo", "unsafe", instance="SRU01", prop="collision_0p2", counterexample=cex)
    assert failures([r, simple("star", "safe", instance="SRU01", prop="collision_0p2")]) == [
        "SRU01/collision_0p2: star says SAFE but montecarlo found a counterexample that replays"]
    assert len(failures([{**r, "counterexample": {**cex, "switch_time": None}}])) == 1


def test_replays_use_the_counterexample_grid(tmp_path):
    """A run crossing a slab 1e-4 wide at unit speed: seen on the recorded 1e-5 grid, missed by
    the default grid (horizon / 2400), whose points straddle the slab."""
    (tmp_path / "m.yaml").write_text("name: line\nstate: [x]\nmodes: {go: {flow: {x: 1}}}\n"
                                     "initial: {mode: go, box: {x: 0}}\nhorizon: 1\n")
    (tmp_path / "p.yaml").write_text("properties:\n  - id: slab\n    kind: safety\n    modes: [go]\n"
                                     "    avoid: {box: {x: [0.50001, 0.50011]}}\n")
    cex = {"model_file": str(tmp_path / "m.yaml"), "property_file": str(tmp_path / "p.yaml"), "property": "slab",
           "initial_state": [0.0], "switch_time": None, "dt": 1e-5}
    r = simple("montecarlo", "unsafe", prop="slab", counterexample=cex)
    assert failures([r]) == []
    assert failures([{**r, "counterexample": {**cex, "dt": None}}]) == [
        "I/slab: montecarlo says UNSAFE without a counterexample that replays"]


def test_messages_without_a_source_and_with_several_refuting_back_ends():
    assert failures([simple("star", "safe", expected="unsafe")]) == ["I/p: star says SAFE, expected unsafe ()"]
    unsafe = dict(instance="SRA01-7N", prop="thrust_7N", counterexample=counterexample(VIOLATING))
    assert failures([simple("montecarlo", "unsafe", expected="safe", **unsafe)]) == [
        "SRA01-7N/thrust_7N: montecarlo says UNSAFE, expected safe ()"]
    found = failures([simple("montecarlo", "unsafe", **unsafe), simple("taylor", "unsafe", **unsafe),
                      simple("star", "safe", instance="SRA01-7N", prop="thrust_7N")])
    assert found == ["SRA01-7N/thrust_7N: star says SAFE but montecarlo, taylor found a counterexample that replays"]


@pytest.mark.parametrize("order", [0, 1])
def test_intervals_exactly_the_rounding_allowance_apart_overlap(order):
    """[0, 0] and [1e-9, 0.5]: ``1e-9 - 1e-9 == 0.0`` exactly, the limiting case that still overlaps."""
    rows = [simple("fsr", "unknown", probability=[0.0, 0.0]), simple("montecarlo", "unknown", probability=[1e-9, 0.5])]
    assert failures(rows[::-1] if order else rows) == []
