"""The Monte Carlo referee: counterexamples that replay, honest UNKNOWNs, statistics."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from reach.backends.montecarlo import BACKEND, replay
from reach.checking import check_files
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties
from reach.stats import clopper_pearson_upper, wilson

FAST = {"samples": 200, "search_rounds": 1, "search_size": 50}


def test_thrust_bound_of_7N_is_violated_with_a_replaying_counterexample():
    (result,) = check_files("models/SRA01.yaml", "properties/thrust_7N.yaml", "montecarlo", FAST)
    assert result.status == Status.UNSAFE
    cex = result.counterexample
    assert cex.violation_time == 0.0 and cex.violation_mode == "approach"
    # independent check: the published gains at the violating state ask for more than 7 N
    K1 = np.array([[-28.8287, 0.1005, -1449.9754, 0.0046], [-0.087, -33.2562, 0.00462, -1451.5013]])
    assert np.abs(K1 @ np.array(cex.violation_state[:4])).max() / 3600 > 7.0
    model = load_model(cex.model_file)
    prop = bind(load_properties(cex.property_file)[0], model)
    assert replay(model, prop, cex.initial_state, cex.switch_time, cex.dt).violated


def test_safe_instance_is_unknown_with_an_upper_bound_never_safe():
    results = check_files("models/SRA01.yaml", "properties/rendezvous.yaml", "montecarlo", FAST)
    assert [r.status for r in results] == [Status.UNKNOWN] * 4
    for r in results:
        assert r.details["violation_probability_upper_95"] == pytest.approx(1 - 0.05 ** (1 / 200), rel=1e-6)
        assert r.details["closest_depth"] >= -1e-9        # LOS is touched at docking, x = -100
    # thrust margin: 10 N - 7.40 N at the worst corner (ANCHORS), in kg m/min^2
    assert results[0].details["closest_depth"] / 3600 == pytest.approx(10 - 7.40, abs=0.01)


def test_the_time_budget_stops_the_sampling_the_search_and_the_optimiser():
    """``max_seconds`` bounds the whole check: with a budget spent before the runs begin the
    structured runs stop where they are (cut, named in the note: before, they ran to the
    horizon whatever the budget, 80 s against 20 on a chattering model), no i.i.d. run is
    simulated, there is no search generation and no optimiser run, the answer stays UNKNOWN,
    the violation bound counts the runs actually sampled (none: 1), and the note names the
    budget and how many runs it left unsampled."""
    opts = {**FAST, "search_rounds": 3, "generations": 2, "population": 10, "polish": 5}
    (free,) = check_files("models/SRA01.yaml", "properties/rendezvous.yaml", "montecarlo", opts, only=["los"])
    (cut,) = check_files("models/SRA01.yaml", "properties/rendezvous.yaml", "montecarlo",
                         {**opts, "max_seconds": 1e-9}, only=["los"])
    assert free.status == cut.status == Status.UNKNOWN
    assert free.details["search_runs"] == 3 * 50 and free.details["optimiser_runs"] > 0
    assert cut.details["search_runs"] == 0 and "optimiser_runs" not in cut.details
    assert free.details["random_runs"] == 200 and cut.details["random_runs"] == 0
    assert cut.details["violation_probability_upper_95"] == 1.0
    assert "option max_seconds" in cut.details["note"] and "after 0 of 200 random runs" in cut.details["note"]
    assert cut.details["cut_runs"] == cut.details["structured_runs"] and "cut short" in cut.details["note"]
    assert "cut_runs" not in free.details
    assert free.details["closest_depth"] <= cut.details["closest_depth"]


def test_late_abort_collides_with_the_0p2_box_and_misses_the_0p1_box():
    (hit,) = check_files("models/SRU01.yaml", "properties/collision_box_0p2.yaml", "montecarlo", FAST)
    assert hit.status == Status.UNSAFE and hit.counterexample.switch_time == 260.0
    assert max(abs(v) for v in hit.counterexample.violation_state[:2]) < 0.2
    miss = check_files("models/SRU01.yaml", "properties/rendezvous.yaml", "montecarlo", FAST,
                       only=["collision"])[0]
    assert miss.status == Status.UNKNOWN
    assert 0.15 < 0.1 + miss.details["closest_depth"] < 0.2     # closest max-norm distance, metres


def test_same_seed_same_answer_and_the_seed_draws_uniform_runs():
    """The seed fixes the answer; another seed draws other runs. The draws themselves are
    uniform on the initial box and the abort window (Kolmogorov-Smirnov against scipy's
    uniform law), and a tenth of the runs of an unforced window never switch (binomial)."""
    from reach.backends.montecarlo import random_plan, switch_window

    def depth(seed):
        (r,) = check_files("models/SRA02.yaml", "properties/rendezvous.yaml", "montecarlo",
                           {**FAST, "seed": seed}, only=["velocity"])
        assert r.status == Status.UNKNOWN and r.details["seed"] == seed
        return r.details["closest_depth"]

    assert depth(0) == depth(0) != depth(1)
    model = load_model("models/SRA07.yaml")
    window = switch_window(model)
    assert window == (50.0, 150.0, True)
    X, tau = random_plan(model, window, 4000, np.random.default_rng(3))
    X2, tau2 = random_plan(model, window, 4000, np.random.default_rng(3))
    assert np.array_equal(X, X2) and np.array_equal(tau, tau2)
    low, high = model.initial.low, model.initial.high
    for i in np.flatnonzero(high > low):
        assert stats.kstest(X[:, i], stats.uniform(low[i], high[i] - low[i]).cdf).pvalue > 1e-4
    assert np.all(X[:, high == low] == low[high == low])
    assert stats.kstest(tau, stats.uniform(50.0, 100.0).cdf).pvalue > 1e-4
    _, tau = random_plan(model, (50.0, 150.0, False), 4000, np.random.default_rng(4))
    never = int(np.isnan(tau).sum())
    assert stats.binomtest(never, 4000, 0.1).pvalue > 1e-4


def test_nonlinear_model_runs_on_its_own_dynamics():
    (r,) = check_files("models/SRNA01.yaml", "properties/rendezvous.yaml", "montecarlo",
                       {"samples": 50, "search_rounds": 0}, only=["velocity"])
    assert r.status == Status.UNKNOWN and r.details["closest_depth"] > 0


def test_gaussian_kicks_give_the_analytic_reach_probability(tmp_path):
    """A free particle kicked by N(0, s^2) k times: x ~ N(0, k s^2), P(|x| <= a) in closed form."""
    (tmp_path / "m.yaml").write_text(
        "name: kicked\nstate: [x]\nmodes: {free: {flow: {x: 0}}}\ninitial: {mode: free, box: {x: 0}}\n"
        "horizon: 10\ndisturbance: {gaussian: {cov: [[0.25]]}, enters: [x], step: 1}\n")
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - id: near\n    kind: reach\n    at: 10\n    target: {box: {x: [-1, 1]}}\n")
    (r,) = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo", {"samples": 40000})
    exact = 2 * stats.norm.cdf(1 / np.sqrt(10 * 0.25)) - 1      # kicks at t = 0, 1, ..., 9
    lo, hi = r.probability
    standard_error = np.sqrt(exact * (1 - exact) / 40000)
    assert abs(r.details["estimate"] - exact) < 3.3 * standard_error     # a 99.9 % two-sided check
    assert hi - lo == pytest.approx(2 * 1.96 * standard_error, rel=0.05)


def test_pictured_runs_of_a_kicked_model_carry_its_kicks(tmp_path):
    """The runs kept for pictures are drawn as the checked ones are, kicks included: a free
    particle started at 0 and kicked by N(0, 0.25) at t = 0, ..., 9 ends at x ~ N(0, 2.5)."""
    (tmp_path / "m.yaml").write_text(
        "name: kicked\nstate: [x]\nmodes: {free: {flow: {x: 0}}}\ninitial: {mode: free, box: {x: 0}}\n"
        "horizon: 10\ndisturbance: {gaussian: {cov: [[0.25]]}, enters: [x], step: 1}\n")
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - id: wide\n    kind: safety\n    modes: [free]\n    require: [\"abs(x) <= 100\"]\n")
    (r,) = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo",
                       {"samples": 200, "keep_sets": True, "search_rounds": 0})
    ends = np.array([p.points[-1, 0] for p in r.sets if p.kind == "run" and p.t1 >= 9.99])
    assert ends.size >= 20
    # the sample variance of n draws of N(0, 2.5): (n - 1) s^2 / 2.5 ~ chi2(n - 1)
    low, high = stats.chi2.ppf([1e-4, 1 - 1e-4], ends.size - 1) * 2.5 / (ends.size - 1)
    assert low < ends.var(ddof=1) < high


def test_confidence_intervals():
    assert clopper_pearson_upper(0, 1000) == pytest.approx(1 - 0.05 ** (1 / 1000), rel=1e-9)
    lo, hi = wilson(640, 1000)
    assert lo < 0.64 < hi and hi - lo == pytest.approx(2 * 1.96 * np.sqrt(0.64 * 0.36 / 1000), rel=0.02)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 10 ** 6), st.floats(0, 1), st.sampled_from([0.5, 0.9, 0.95, 0.99, 0.999]))
def test_confidence_bounds_are_the_scipy_stats_quantiles(n, fraction, confidence):
    """The Clopper-Pearson bound is the Beta(f + 1, n - f) quantile and the Wilson interval's z
    the normal quantile, as scipy.stats computes them."""
    f = min(n - 1, int(fraction * n))
    assert clopper_pearson_upper(f, n, confidence) == pytest.approx(
        stats.beta.ppf(confidence, f + 1, n - f), rel=1e-12, abs=1e-300)
    z = stats.norm.ppf(0.5 + confidence / 2)
    p = f / n
    centre = (p + z ** 2 / (2 * n)) / (1 + z ** 2 / n)
    half = z * np.sqrt(p * (1 - p) / n + z ** 2 / (4 * n ** 2)) / (1 + z ** 2 / n)
    assert wilson(f, n, confidence) == pytest.approx((max(0.0, centre - half), min(1.0, centre + half)), rel=1e-12)


def test_cli_check_json_and_replay(tmp_path):
    out = subprocess.run([sys.executable, "-m", "reach", "check", "SRA01", "properties/thrust_7N.yaml",
                          "--json", "-o", "samples=100", "-o", "search_rounds=0",
                          "--counterexamples", str(tmp_path)], capture_output=True, text=True)
    assert out.returncode == 1, out.stderr       # a violation
    rows = json.loads(out.stdout)
    assert rows[0]["property"] == "thrust_7N" and rows[0]["status"] == "unsafe" and rows[0]["seconds"] > 0
    replayed = subprocess.run([sys.executable, "-m", "reach", "replay", rows[0]["counterexample_file"]],
                              capture_output=True, text=True)
    assert replayed.returncode == 1 and replayed.stdout.startswith("replayed:")
    # the same run against the 10 N bound does not violate it
    data = json.loads(open(rows[0]["counterexample_file"]).read())
    (tmp_path / "other.json").write_text(json.dumps(dict(data, property_file="properties/rendezvous.yaml",
                                                         property="thrust")))
    other = subprocess.run([sys.executable, "-m", "reach", "replay", str(tmp_path / "other.json")],
                           capture_output=True, text=True)
    assert other.returncode == 3 and other.stdout.startswith("NOT replayed")
    # a tampered counterexample (start moved out of the initial set) is no run of the model
    data["initial_state"] = [-500.0, -200.0, 0.0, 0.0, 0.0]
    (tmp_path / "tampered.json").write_text(json.dumps(data))
    tampered = subprocess.run([sys.executable, "-m", "reach", "replay", str(tmp_path / "tampered.json")],
                              capture_output=True, text=True)
    assert tampered.returncode == 2
    assert tampered.stderr.strip().endswith("tampered.json: initial_state: x = -500 is outside the initial set "
                                            "(x in [-925, -875])")


@pytest.mark.parametrize("args, message", [
    (["check", "NOPE", "properties/rendezvous.yaml"], "no model named 'NOPE'"),
    (["check", "SRA01", "properties/rendezvous.yaml", "-b", "magic"], "unknown back-end 'magic'"),
    (["check", "SRA01", "properties/missing.yaml"], "properties/missing.yaml: no such file"),
    (["replay", "suite.yaml"], "a counterexample file must be a .json file"),
])
def test_cli_bad_input_is_one_line_and_exit_2(args, message):
    out = subprocess.run([sys.executable, "-m", "reach", *args], capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and message in out.stderr and "Traceback" not in out.stderr


COUNTER = """
name: counter
state: [n, c]
modes:
  tick: {flow: false}
  wait: {flow: {n: 0, c: 1}, invariant: ["c <= 1"]}
transitions:
  - {from: tick, to: wait, reset: {n: "n + 1", c: 0}, urgent: true}
  - {from: wait, to: tick, guard: ["c >= 1"], urgent: true}
initial: {mode: tick, box: {n: 0, c: 0}}
horizon: 5.5
"""


@pytest.mark.parametrize("backend", ["montecarlo", "star"])
def test_a_counter_through_a_mode_where_no_time_passes_is_caught_and_replays(tmp_path, backend):
    """n = k + 1 on (k, k + 1] (closed form): the bound n <= 5.5 fails at t = 5, n <= 6.5 holds.
    Each pass through ``tick`` returns at one instant to ``wait``, one higher."""
    (tmp_path / "counter.yaml").write_text(COUNTER)
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: n6, kind: safety, require: ['n <= 5.5']}\n"
                                     "  - {id: n7, kind: safety, require: ['n <= 6.5']}\n")
    options = FAST if backend == "montecarlo" else {}
    bad, good = check_files(tmp_path / "counter.yaml", tmp_path / "p.yaml", backend, options)
    assert bad.status == Status.UNSAFE
    assert good.status == (Status.SAFE if backend == "star" else Status.UNKNOWN)
    cex = bad.counterexample
    assert abs(cex.violation_time - 5.0) < 1e-6 and cex.violation_state[0] == 6.0
    prop = bind(load_properties(tmp_path / "p.yaml")[0], load_model(tmp_path / "counter.yaml"))
    assert replay(load_model(tmp_path / "counter.yaml"), prop, cex.initial_state, cex.switch_time, cex.dt).violated


def test_the_earliest_may_switch_is_a_structured_run(tmp_path):
    """x' = 1 from 0, a may-switch anywhere in x in [1, 3] to a mode where y' = 1 + u, u in
    [-0.5, 0.5]: y(4) is largest, 0.5 + 3 * 1.5 = 5, switching at t = 1 with u = 0.5 throughout.
    The structured runs that leave at the first piece start a guard holds (t = 1, where x' = 1's
    exponential gives x = 1 up to rounding) find y <= 4.99 violated; the counterexample replays."""
    (tmp_path / "m.yaml").write_text(
        "name: may\nstate: [x, y]\nbounded_inputs:\n  u: {range: [-0.5, 0.5], varying: true}\n"
        "modes:\n  a: {flow: {x: 1, y: u}, invariant: [\"x <= 3\"]}\n  b: {flow: {x: 0, y: \"1 + u\"}}\n"
        "transitions:\n  - {from: a, to: b, guard: [\"x >= 1\"]}\n"
        "initial: {mode: a, box: {x: 0, y: 0}}\nhorizon: 4\n")
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: y_bad, kind: safety, require: [\"y <= 4.99\"]}\n")
    (r,) = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo",
                       {"samples": 200, "search_rounds": 0, "optimise": False})
    assert r.status == Status.UNSAFE and r.counterexample.violation_mode == "b"
    cex = r.counterexample
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    again = replay(model, prop, cex.initial_state, None, cex.dt, cex.input_signal)
    assert again.violated and 4.99 < again.state[1] <= 5.0 + 1e-9


def test_a_model_whose_own_step_is_too_fine_names_its_field(tmp_path):
    """A disturbance step of 1e-12 s cuts the 500 s horizon into 5e14 grid steps: bad input
    naming the model file and ``disturbance.step``, not an option the user never gave."""
    import re

    from reach.errors import InputError

    text = re.sub(r"(\n  step: )[^\n]*", r"\g<1>1e-12", Path("models/fsr_burn.yaml").read_text(), count=1)
    (tmp_path / "m.yaml").write_text(text)
    with pytest.raises(InputError) as info:
        check_files(tmp_path / "m.yaml", "properties/fsr_burn.yaml", "montecarlo")
    assert info.value.field == "disturbance.step" and info.value.file == str(tmp_path / "m.yaml")
    assert "a longer step" in info.value.message
