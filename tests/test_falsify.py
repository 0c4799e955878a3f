"""Falsification by optimisation (reach.backends.montecarlo.falsify through the Monte Carlo back-end).

References are independent of the simulator: the SRA08 closed loop is integrated by solve_ivp
from the ARCH matrices written out here, the Passive drift is the exact CWH map ``expm(A s)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.montecarlo.falsify import Parameterisation, latin_hypercube
from reach.backends.montecarlo import BACKEND, replay, switch_window
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties
from model_files import load_files

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"

N_ORBIT, MC = 0.00438138, 500.0
A_CWH = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [3 * N_ORBIT ** 2, 0, 0, 2 * N_ORBIT], [0, 0, -2 * N_ORBIT, 0]])
B_CWH = np.array([[0, 0], [0, 0], [1 / MC, 0], [0, 1 / MC]])
K1 = np.array([[-28.82867767694, 0.1004799482599, -1449.975419853, 0.004624472318875],
               [-0.08701567868523, -33.25619924505, 0.004624472318875, -1451.501346434]])
K2 = np.array([[-288.0287662715, 0.1312430397158, -9614.989795432, -3.41199964983e-07],
               [-0.1312430403689, -287.9999700959, -3.41199964983e-07, -9614.988297970]])


def closed_loop(x0, until):
    """The ARCH closed loop (approach, then rendezvous once inside the octagon) to ``until``."""
    def octagon(t, z):
        x, y = z[0], z[1]
        return max(abs(x) - 100, abs(y) - 100, abs(x + y) - 141.1, abs(x - y) - 141.1)
    octagon.terminal, octagon.direction = True, -1
    A1, A2 = A_CWH + B_CWH @ K1, A_CWH + B_CWH @ K2
    s1 = solve_ivp(lambda t, z: A1 @ z, (0, until), x0, events=octagon, rtol=1e-11, atol=1e-10)
    if s1.t[-1] >= until:
        return s1.y[:, -1]
    s2 = solve_ivp(lambda t, z: A2 @ z, (s1.t[-1], until), s1.y[:, -1], rtol=1e-11, atol=1e-10)
    return s2.y[:, -1]


def passive_approach(x0, tau, horizon=240.0, h=0.01):
    """Smallest max(|x|, |y|) of the Passive drift from the abort at ``tau`` to the horizon."""
    z = closed_loop(np.asarray(x0, float), tau)
    steps = int(np.floor((horizon - tau) / h))
    E = scipy.linalg.expm(A_CWH * h)
    best = max(abs(z[0]), abs(z[1]))
    for _ in range(steps):
        z = E @ z
        best = min(best, max(abs(z[0]), abs(z[1])))
    end = scipy.linalg.expm(A_CWH * (horizon - tau - steps * h)) @ z
    return min(best, max(abs(end[0]), abs(end[1])))


def sra08_thin():
    model = load_model(ROOT / "models" / "SRA08.yaml")
    prop = bind(load_properties(DATA / "sra08_collision_thin.yaml")[0], model)
    return model, prop


@pytest.fixture(scope="module")
def sra08_results():
    model, prop = sra08_thin()
    return (model, prop, BACKEND.check(model, prop, {"optimise": False}), BACKEND.check(model, prop),
            BACKEND.check(model, prop))


def test_the_thin_sra08_box_is_violated_by_the_reference():
    """The 0.70 m box is violated: the reference drift from the corner (-875, -375) aborted near
    t = 212 min passes within 0.70 m; and only just: a coarse scan of the abort instants of every
    corner stays above 0.69 m."""
    taus = np.arange(211.90, 212.06, 0.02)
    best = min(passive_approach([-875, -375, 0, 0], tau) for tau in taus)
    assert best < 0.70
    coarse = min(passive_approach([x, y, 0, 0], tau) for x in (-925, -875) for y in (-425, -375)
                 for tau in (180.0, 200.0, 212.0, 225.0, 240.0))
    assert coarse > 0.69


def test_sampling_alone_misses_the_thin_violation(sra08_results):
    _, _, sampled, _, _ = sra08_results
    assert sampled.status is Status.UNKNOWN
    assert sampled.details["closest_depth"] > 0


def test_the_optimiser_finds_it_and_the_counterexample_replays(sra08_results):
    model, prop, _, optimised, _ = sra08_results
    assert optimised.status is Status.UNSAFE
    assert optimised.details["found_in"] == "optimiser"
    cex = optimised.counterexample
    rep = replay(model, prop, cex.initial_state, cex.switch_time, cex.dt)
    assert rep.violated and rep.depth < 0
    # the violating state, independently: closed loop to the abort, then the exact drift
    z = closed_loop(np.array(cex.initial_state[:4]), cex.switch_time)
    z = scipy.linalg.expm(A_CWH * (cex.violation_time - cex.switch_time)) @ z
    assert np.allclose(z, cex.violation_state[:4], rtol=1e-6, atol=1e-6)
    assert max(abs(z[0]), abs(z[1])) < 0.70


def test_the_optimiser_is_deterministic_for_a_seed(sra08_results):
    _, _, _, first, second = sra08_results
    assert first.counterexample.initial_state == second.counterexample.initial_state
    assert first.counterexample.switch_time == second.counterexample.switch_time
    assert first.details == second.details


def test_the_optimiser_searches_input_signals():
    """x' = u, u in [-1, 1]: only signals of a precise mean reach the thin box at the horizon;
    the optimiser finds one, and x(10) = x0 + sum of pieces x step, recomputed by hand."""
    model = load_model(DATA / "steered.yaml")
    prop = bind(load_properties(DATA / "steered_target.yaml")[0], model)
    assert BACKEND.check(model, prop, {"optimise": False}).status is Status.UNKNOWN
    result = BACKEND.check(model, prop)
    assert result.status is Status.UNSAFE
    cex = result.counterexample
    signal = cex.input_signal
    values = np.array(signal["values"])[:, 0]
    assert np.all(np.abs(values) <= 1)
    t = cex.violation_time
    full = int(np.floor(t / signal["step"] + 1e-9))
    x = cex.initial_state[0] + signal["step"] * values[:full].sum() + (t - full * signal["step"]) * values[full]
    assert 2.2699 <= x <= 2.2701
    assert replay(model, prop, cex.initial_state, None, cex.dt, signal).violated


def test_no_false_alarm_where_the_properties_hold():
    """SRA02's four rendezvous requirements hold (star proves them, test_star.py); the optimiser
    must not report any of them violated."""
    model = load_model(ROOT / "models" / "SRA02.yaml")
    props = [p for p in (bind(q, model) for q in load_properties(ROOT / "properties" / "rendezvous.yaml")) if p.modes]
    results = BACKEND.check_many(model, props, {"samples": 200, "search_rounds": 1, "generations": 8})
    assert [r.status for r in results] == [Status.UNKNOWN] * len(props)
    assert all(r.details["optimiser_runs"] > 0 for r in results)


SRA08 = load_model(ROOT / "models" / "SRA08.yaml")


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0, 1), min_size=3, max_size=3))
def test_the_unit_cube_map_round_trips(u):
    """encode(runs(u)) = u on SRA08: two free initial coordinates and the abort instant."""
    model = SRA08
    param = Parameterisation(model, switch_window(model), None, 0, False)
    assert param.dim == 3
    X, tau, _, _ = param.runs(np.array([u]))
    assert np.all(X >= model.initial.low) and np.all(X <= model.initial.high)
    assert np.allclose(param.encode(X, tau, None), [u], atol=1e-12)


def test_a_model_without_free_parameters_is_one_optimiser_run():
    """A single initial state, no window, no inputs: the optimiser has nothing to vary."""
    model = load_model(DATA / "tank.yaml")
    model.initial.low = model.initial.high.copy()
    prop = bind(load_properties(DATA / "tank_level.yaml")[0], model)
    result = BACKEND.check(model, prop, {"samples": 5})
    assert result.status is Status.UNKNOWN and result.details["optimiser_runs"] == 1


def test_a_property_of_a_mode_no_run_reaches_is_unknown(tmp_path):
    """x' = 1 from [0, 1] reaches the guard x >= 10 of mode 'far' after the horizon 5: no run
    visits the property's mode, so the search has no margin to descend (it used to fail on
    that); the answer is UNKNOWN, with no violation."""
    (tmp_path / "m.yaml").write_text(
        "name: far\nstate: [x]\nmodes:\n  near: {flow: {x: 1}}\n  far: {flow: {x: 1}}\n"
        "transitions: [{from: near, to: far, guard: ['x >= 10'], urgent: true}]\n"
        "initial: {mode: near, box: {x: [0, 1]}}\nhorizon: 5\n")
    (tmp_path / "p.yaml").write_text(
        "properties: [{id: low, kind: safety, modes: [far], require: ['x <= 1']}]\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    result = BACKEND.check(model, prop, {"samples": 20})
    assert result.status is Status.UNKNOWN and result.counterexample is None


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 60), st.integers(1, 8))
def test_the_latin_hypercube_is_scipys(seed, count, dim):
    """The initial population's Latin hypercube: the points of scipy.stats.qmc.LatinHypercube
    for the same generator, one per slice of every axis, and the generator left in the same
    state (the evolution that follows draws the same numbers)."""
    from scipy.stats import qmc

    ours_rng, ref_rng = np.random.default_rng(seed), np.random.default_rng(seed)
    ours = latin_hypercube(ours_rng, count, dim)
    ref = qmc.LatinHypercube(d=dim, rng=ref_rng).random(count)
    np.testing.assert_array_equal(ours, ref)
    assert ours_rng.random() == ref_rng.random()
    for axis in ours.T:
        assert np.array_equal(np.sort(np.floor(axis * count)), np.arange(count))


def _fake_search(objective, violation_below=-np.inf):
    """``(evaluate, best, batches)``: ``evaluate`` records each batch and keeps the best point in
    ``best`` as :func:`reach.backends.montecarlo.falsify.falsify`'s does (``violated`` below the threshold)."""
    best = {"depth": np.inf, "violated": False, "point": None}
    batches = []

    def evaluate(U):
        values = np.array([objective(u) for u in U])
        batches.append(U.shape[0])
        k = int(np.argmin(values))
        if values[k] < best["depth"] and not best["violated"]:
            best.update(depth=float(values[k]), point=U[k].copy(), violated=bool(values[k] <= violation_below))
        return values
    return evaluate, best, batches


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1.0, 2.0), min_size=3, max_size=8), st.integers(0, 2 ** 31))
def test_the_gradient_polish_reaches_the_projection_of_a_quadratic_minimum(centre, seed):
    """``rho(u) = |u - c|^2`` on the unit cube is least at the projection of ``c`` (coordinates
    outside ``[0, 1]`` held by a face, as a bang-bang signal's values are): the polish reaches it
    from a random start, simulating in batches only."""
    from reach.backends.montecarlo.falsify import Budget, _gradient_polish
    c = np.array(centre)
    evaluate, best, batches = _fake_search(lambda u: float(np.sum((u - c) ** 2)))
    start = np.random.default_rng(seed).random(c.size)
    f = evaluate(start[None, :])[0]
    _gradient_polish(evaluate, best, start, f, 4000, Budget())
    np.testing.assert_allclose(best["point"], np.clip(c, 0.0, 1.0), atol=2e-3)
    assert sum(batches[1:]) <= 4000 and all(b > 1 for b in batches[1:])


def test_the_gradient_polish_stops_at_the_first_violation():
    from reach.backends.montecarlo.falsify import Budget, _gradient_polish
    evaluate, best, batches = _fake_search(lambda u: float(u.sum() - 1.0), violation_below=0.0)
    start = np.full(4, 0.9)
    f = evaluate(start[None, :])[0]
    _gradient_polish(evaluate, best, start, f, 100_000, Budget())
    assert best["violated"] and best["depth"] <= 0.0
    assert len(batches) <= 1 + 2 * 30        # it stopped there, not at the budget or the step floor


def test_the_polish_starts_are_the_best_distinct_points():
    from reach.backends.montecarlo.falsify import DISTINCT, _distinct_best
    population = np.array([[0.5, 0.5], [0.51, 0.5], [0.9, 0.1], [0.5 + 2 * DISTINCT, 0.5], [0.0, 0.0]])
    energies = np.array([1.0, 0.5, 3.0, 2.0, 0.1])
    kept = _distinct_best(population, energies, np.array([0.0, 0.02]))
    # [0, 0] is too near the best run's point; [0.5, 0.5] too near [0.51, 0.5], which is better
    assert [tuple(u) for u, _ in kept] == [(0.51, 0.5), (0.5 + 2 * DISTINCT, 0.5), (0.9, 0.1)]
    assert [f for _, f in kept] == [0.5, 2.0, 3.0]


DRIVEN = """
name: driven
state: [x, v]
bounded_inputs:
  u: {range: [-1, 1], varying: true}
modes:
  run: {flow: {x: v, v: "-x - 0.1*v + u"}}
initial: {mode: run, box: {x: [-0.1, 0.1], v: 0}}
horizon: 30
"""


def _driven_reach() -> float:
    """The largest x over [0, 30] of x'' + 0.1 x' + x = u, |u| <= 1, |x0| <= 0.1, v0 = 0: by the
    maximum principle, max_t |e^{A t}_11| 0.1 + int_0^t |[e^{A (t - s)} B]_1| ds (quadrature)."""
    from scipy.integrate import quad
    A, B = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([0.0, 1.0])
    best = 0.0
    for t in np.linspace(25.0, 30.0, 51):
        forced = quad(lambda s: abs((scipy.linalg.expm(A * (t - s)) @ B)[0]), 0.0, t, limit=400)[0]
        best = max(best, 0.1 * abs(scipy.linalg.expm(A * t)[0, 0]) + forced)
    return best


@pytest.mark.parametrize("fraction, violated", [(0.99, True), (1.002, False)])
def test_a_resonant_input_is_found_by_the_extremal_signals(tmp_path, fraction, violated):
    """A lightly damped oscillator driven at resonance reaches x = 9.908 by t = 30 only under a
    bang-bang input switching every half period; uniform and one-switch signals stay far below
    (closest margin 1.4 at 99 %). The runs aimed by the maximum principle find a violation of
    x <= 0.99 of that reach, whose counterexample solve_ivp confirms under its own signal; above
    the reach nothing is found."""
    bound = fraction * _driven_reach()
    model, props = load_files(tmp_path, DRIVEN, "properties:\n  - {id: x_below, kind: safety, modes: [run], "
                                                f"require: [\"x <= {bound:.6f}\"]}}\n")
    (prop,) = props.values()
    result = BACKEND.check(model, prop, {"optimise": False, "search_rounds": 0})
    assert result.status is (Status.UNSAFE if violated else Status.UNKNOWN)
    if not violated:
        return
    cex = result.counterexample
    step, values = cex.input_signal["step"], np.array(cex.input_signal["values"])[:, 0]
    assert np.all(np.abs(values) == 1)                    # bang-bang
    state, t0 = np.array(cex.initial_state[:2]), 0.0
    for k, u in enumerate(values):
        t1 = min((k + 1) * step, cex.violation_time)
        if t1 <= t0:
            break
        run = solve_ivp(lambda t, y: [y[1], -y[0] - 0.1 * y[1] + u], (t0, t1), state, rtol=1e-10, atol=1e-12)
        state, t0 = run.y[:, -1], t1
    assert state[0] > bound


def test_an_instant_the_property_names_is_a_target_of_the_extremal_signals(tmp_path):
    """The same oscillator with a clock, unsafe only at the instant t == 17.3 (off the pieces'
    grid): the aimed run ends its last piece there, and its replay enters the unsafe set within
    0.5 % of the largest x(17.3) (quadrature, as above)."""
    from scipy.integrate import quad
    A, B, T = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([0.0, 1.0]), 17.3
    reach_T = 0.1 * abs(scipy.linalg.expm(A * T)[0, 0]) + quad(
        lambda s: abs((scipy.linalg.expm(A * (T - s)) @ B)[0]), 0.0, T, limit=400)[0]
    clocked = (DRIVEN.replace("state: [x, v]", "state: [x, v, t]")
               .replace('"-x - 0.1*v + u"}', '"-x - 0.1*v + u", t: 1}').replace("v: 0}", "v: 0, t: 0}"))
    model, props = load_files(tmp_path, clocked, "properties:\n  - {id: at_instant, kind: safety, modes: [run], "
                              f"avoid: [\"x >= {0.995 * reach_T:.6f}\", \"t >= {T}\", \"t <= {T}\"]}}\n")
    (prop,) = props.values()
    result = BACKEND.check(model, prop, {"optimise": False, "search_rounds": 0})
    assert result.status is Status.UNSAFE
    assert result.counterexample.violation_time == pytest.approx(T, abs=1e-9)
    assert replay(model, prop, result.counterexample.initial_state, None, result.counterexample.dt,
                  result.counterexample.input_signal).violated


def test_an_unsafe_window_past_the_horizon_leaves_no_aimed_run(tmp_path):
    """Every unsafe row's clock window (t in [30, 40]) lies past the horizon 20: no run is aimed
    and the check ends UNKNOWN (it was an internal error, stacking no signals)."""
    model, props = load_files(
        tmp_path,
        "name: late\nstate: [x, t]\nbounded_inputs:\n  u: {range: [-1, 1], varying: true}\n"
        "modes:\n  a: {flow: {x: u, t: 1}}\ninitial: {mode: a, box: {x: 0, t: 0}}\nhorizon: 20\n",
        "properties:\n  - {id: late, kind: safety, modes: [a], avoid: {box: {t: [30, 40], x: [5, 10]}}}\n")
    (prop,) = props.values()
    assert BACKEND.check(model, prop, {"optimise": False, "search_rounds": 0}).status is Status.UNKNOWN
