"""Sampling event properties (the Monte Carlo referee of the taylor back-end) against a closed
form: on SRA01 the largest Fx in approach is reached at t = 0, at a corner of the initial box."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from model_files import load_files
from reach.backends.montecarlo.event_sampling import outside_bounds, replay_event, sample_extrema
from reach.backends.montecarlo import BACKEND
from reach.cli import main
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
    result = BACKEND.check(sra01, prop, {"samples": 200})
    corners = [K1_X @ [x, y] for x in (-925, -875) for y in (-425, -375)]
    assert result.status is Status.UNKNOWN
    lo, hi = result.details["sampled_range"]
    assert hi == pytest.approx(max(corners), rel=1e-12)
    assert lo >= min(corners) - 1e-9
    assert result.details["closest_margin"] == pytest.approx(10 * NEWTON - max(corners), rel=1e-12)
    assert result.details["violation_probability_upper_95"] < 0.02


def test_violated_event_gives_a_counterexample_that_replays(sra01, tmp_path):
    prop = bind(load_properties(event(tmp_path, 7))[0], sra01)
    result = BACKEND.check(sra01, prop, {"samples": 100})
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


# ---------------------------------------------------------------- polytopes and input signals

TRIANGLE = """
    name: triangle
    state: [x, y]
    modes:
      a: {flow: {x: "0", y: "0"}}
    initial:
      mode: a
      box: {x: [0, 1], y: [0, 1]}
      constraints: ["x + y <= 1"]
    horizon: 1
"""


@pytest.mark.parametrize("limit, status", [(1.5, Status.UNKNOWN), (0.9, Status.UNSAFE)])
def test_an_event_on_a_polytopic_initial_set_samples_only_inside_it(tmp_path, limit, status):
    """max x + y over the triangle is 1 (its corners off the diagonal are outside): a bound above
    1 is never broken, one below it is, at a state of the triangle."""
    model, props = load_files(tmp_path, TRIANGLE, f"""
        properties:
          - {{id: s, kind: event, modes: [a], maximize: "x + y", require: "<= {limit}"}}
    """)
    result = BACKEND.check(model, props["s"], {"samples": 300, "optimise": False})
    assert result.status is status
    assert result.details["sampled_range"][1] <= 1 + 1e-9
    if status is Status.UNSAFE:
        x0 = result.counterexample.initial_state
        assert 0.9 < sum(x0) <= 1 + 1e-9 and min(x0) >= -1e-12


DOUBLE_INTEGRATOR = """
    name: di
    state: [x, v]
    bounded_inputs:
      u: {range: [-1, 1], varying: true}
    modes:
      a: {flow: {x: "v", v: "u"}}
    initial:
      mode: a
      box: {x: [0, 0], v: [0, 0]}
    horizon: 3
"""


def _q_closed_form(t, switch):
    """2 v - x at ``t`` from rest under u = -1 before ``switch``, +1 after."""
    v = np.where(t < switch, -t, -switch + (t - switch))
    x = np.where(t < switch, -t ** 2 / 2, -switch ** 2 / 2 - switch * (t - switch) + (t - switch) ** 2 / 2)
    return 2 * v - x


@pytest.mark.parametrize("limit, status", [(2.4, Status.UNSAFE), (2.55, Status.UNKNOWN)])
def test_an_event_under_a_varying_input_is_broken_by_a_switching_signal_that_replays(tmp_path, capsys,
                                                                                   limit, status):
    """q = 2 v - x of a double integrator from rest, |u| <= 1, t <= 3: q(T) = int_0^T (2 - T + s)
    u(s) ds, largest at T = 3 with u = -1 before s = 1 and +1 after: 2.5, while every constant
    input stays at or below 2. Only a switching signal breaks q <= 2.4; its counterexample
    carries the signal and replays (``reach replay``), and its extremum is one the closed form
    allows."""
    assert _q_closed_form(np.array(3.0), 1.0) == pytest.approx(2.5)
    model, props = load_files(tmp_path, DOUBLE_INTEGRATOR, f"""
        properties:
          - {{id: q, kind: event, modes: [a], maximize: "2*v - x", require: "<= {limit}"}}
    """)
    result = BACKEND.check(model, props["q"], {"samples": 200})
    assert result.status is status
    assert result.details["sampled_range"][1] <= 2.5 + 1e-9
    if status is Status.UNKNOWN:
        return
    cex = result.counterexample
    values = np.array(cex.input_signal["values"])[:, 0]
    assert set(np.round(values, 12)) == {-1.0, 1.0}                       # it switches
    rep = replay_event(model, props["q"], cex.initial_state, cex.dt, signal=(cex.input_signal["step"],
                                                                            values[None, :, None], None))
    assert rep.violated and limit < rep.value <= 2.5 + 1e-9
    path = tmp_path / "cex.json"
    cex.save(path)
    assert main(["replay", str(path)]) == 1
    assert "replayed: di violates 'q'" in capsys.readouterr().out


@given(m=st.integers(1, 3), K=st.integers(2, 12), states=st.integers(1, 40))
@settings(max_examples=40, deadline=None)
def test_structured_signals_hold_corners_and_switch_once_to_the_opposite_corner(m, K, states):
    """Every structured signal takes corner values only; each state has its C constant corners
    and a bang-bang signal; the first state also every one-switch signal (a corner, then the
    opposite one from piece k on, 1 <= k < K), and those are the signals marked ``once``."""
    from types import SimpleNamespace

    from reach.backends.montecarlo.initial_sampling import structured_signals

    inputs = [SimpleNamespace(low=-1.0 - j, high=2.0 + j) for j in range(m)]
    model = SimpleNamespace(varying_inputs=inputs, horizon=float(K - 1))
    values, owner, once = structured_signals(model, states, 1.0, np.random.default_rng(0))
    assert values.shape[1:] == (K, m) and owner.shape == (values.shape[0],)
    lo, hi = np.array([u.low for u in inputs]), np.array([u.high for u in inputs])
    assert np.all((values == lo) | (values == hi))
    C = 2 ** m
    assert np.all(np.bincount(owner, minlength=states) >= C + 1)
    changes = np.count_nonzero(np.any(np.diff(values, axis=1) != 0, axis=2), axis=1)
    assert once.any() and np.all(changes[once] == 1)          # marked: the one-switch signals
    assert np.all(np.bincount(owner[~once], minlength=states) == C + 1)
    first = {v.tobytes() for v in values[owner == 0]}
    for corner in itertools.product([0, 1], repeat=m):
        c = np.where(np.array(corner) == 1, hi, lo)
        assert np.tile(c, (K, 1)).tobytes() in first
        for k in range(1, K):
            switched = np.where(np.arange(K)[:, None] >= k, lo + hi - c, c)
            assert switched.tobytes() in first
