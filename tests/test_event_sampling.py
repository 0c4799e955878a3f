"""Sampling event properties (the Monte Carlo referee of the taylor back-end) against a closed
form: on SRA01 the largest Fx in approach is reached at t = 0, at a corner of the initial box."""

import numpy as np
import pytest

from reach.backends.event_sampling import check_events, outside_bounds, replay_event, sample_extrema
from reach.backends.montecarlo import structured_plan
from reach.model.loader import load_model
from reach.result import Status
from reach.spec.properties import bind, load_properties

K1_X = np.array([-28.82867767694, 0.1004799482599])     # Fx = K1[0] . [x, y] at rest (ARCH gain)
NEWTON = 3600.0                                          # kg m/min^2


def event(tmp_path, limit_newton):
    path = tmp_path / "fx.yaml"
    path.write_text(f"""properties:
  - id: fx_max
    kind: event
    modes: [approach]
    maximize: Fx
    require: "<= {limit_newton}[N]"
""")
    return path


@pytest.fixture(scope="module")
def sra01():
    return load_model("models/SRA01.yaml")


def test_sampled_maximum_is_the_corner_value(sra01, tmp_path):
    prop = bind(load_properties(event(tmp_path, 10))[0], sra01)
    structured, _ = structured_plan(sra01, None)
    (result,) = check_events(sra01, [prop], 200, 0, None, structured)
    corners = [K1_X @ [x, y] for x in (-925, -875) for y in (-425, -375)]
    assert result.status is Status.UNKNOWN
    lo, hi = result.details["sampled_range"]
    assert hi == pytest.approx(max(corners), rel=1e-12)
    assert lo >= min(corners) - 1e-9
    assert result.details["closest_margin"] == pytest.approx(10 * NEWTON - max(corners), rel=1e-12)
    assert result.details["violation_probability_upper_95"] < 0.02


def test_violated_event_gives_a_counterexample_that_replays(sra01, tmp_path):
    prop = bind(load_properties(event(tmp_path, 7))[0], sra01)
    structured, _ = structured_plan(sra01, None)
    (result,) = check_events(sra01, [prop], 100, 0, None, structured)
    assert result.status is Status.UNSAFE
    cex = result.counterexample
    assert cex.violation_time == 0.0 and cex.violation_mode == "approach"
    again = replay_event(sra01, prop, cex.initial_state, cex.dt)
    assert again.violated and again.value == pytest.approx(K1_X @ cex.initial_state[:2], rel=1e-12)
    inside = replay_event(sra01, prop, [-875.0, -375.0, 0, 0, 0], cex.dt)   # the mildest corner
    assert not inside.violated


def test_monitor_keeps_the_extremum_per_run_in_the_listed_modes(sra01, tmp_path):
    prop = bind(load_properties(event(tmp_path, 10))[0], sra01)
    x0 = np.array([[-900.0, -400.0, 0, 0, 0], [-925.0, -425.0, 0, 0, 0]])
    monitor, _, _ = sample_extrema(sra01, prop, x0)
    assert np.allclose(monitor.extrema(), [K1_X @ x[:2] for x in x0], rtol=1e-12)
    assert np.all(monitor.time == 0.0)


def test_outside_bounds_counts_per_subdomain_with_the_slack_on_the_inner_side():
    rows = [{"low": np.array([0.0]), "high": np.array([0.5]), "bound": (1.0, 2.0)},
            {"low": np.array([0.5]), "high": np.array([1.0]), "bound": (3.0, 4.0)}]
    x0 = np.array([[0.1, 9.0], [0.2, 9.0], [0.7, 9.0], [0.9, 9.0]])      # second state is certain
    # a maximum: above the upper end is outside; below the lower end is tolerated by the slack
    values = np.array([1.5, 0.95, 3.5, 4.2])
    assert outside_bounds(rows, x0, values, [0], "max", slack=0.1) == 1
    assert outside_bounds(rows, x0, values, [0], "max", slack=0.0) == 2
    # a minimum: below the lower end is outside; the slack tolerates above the upper end
    assert outside_bounds(rows, x0, np.array([1.5, 2.05, 2.9, 3.0]), [0], "min", slack=0.1) == 1
    with pytest.raises(ValueError, match="cover"):
        outside_bounds(rows[:1], x0, values, [0], "max", slack=0.0)
