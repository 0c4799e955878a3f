"""The taylor back-end: DA flows against exact and numerical references, event maps against
dense solve_ivp events, and the back-end's bounds against Monte Carlo runs of the simulator."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg
import sympy
from scipy.integrate import solve_ivp

from reach.backends.montecarlo.event_sampling import outside_bounds, sample_extrema
from reach.backends.taylor import BACKEND
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.event import event_map, initial_state, refine_time
from reach.backends.taylor.flow import compile_expressions, compile_numeric, flow_map
from reach.backends.taylor.nominal import nominal
from reach.model.loader import load_model
from reach.result import Status
from reach.spec.properties import bind, load_properties


@pytest.fixture(scope="module")
def srna():
    return load_model("models/SRNA01.yaml")


def events(model):
    return {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}


def rhs(model, mode):
    f = compile_numeric(model.modes[mode].flow, model.symbols)
    return lambda t, x: np.array(f(list(x)), dtype=float)


def test_compiled_flow_matches_lambdify_and_sympy_derivatives(srna):
    mode = srna.modes["approach"]
    f = compile_expressions(mode.flow, srna.symbols)
    point = np.array([-700.0, -300.0, 1.5, 0.7, 12.0])
    reference = sympy.lambdify([srna.symbols], mode.flow)(point)
    np.testing.assert_allclose([float(v) for v in f(list(point))], reference, rtol=1e-12)
    alg = algebra(2, 5)
    values = f(DA.variables(alg, point, np.ones(5)))
    for i, expr in enumerate(mode.flow):
        for j, s in enumerate(srna.symbols):
            exact = float(sympy.diff(expr, s).subs(dict(zip(srna.symbols, point))))
            assert values[i].c[1 + j] == pytest.approx(exact, rel=1e-10, abs=1e-14)


def test_cwh_flow_is_the_exact_linear_map():
    """Passive CWH: first-order coefficients are expm(A T), higher orders vanish."""
    model = load_model("models/SRA01.yaml")
    mode = model.modes["passive"]
    A, b = mode.linear
    f = compile_expressions(mode.flow, model.symbols)
    x0 = np.array([-300.0, 200.0, 1.0, -0.5, 0.0])
    T = 90.0
    run = nominal(compile_numeric(mode.flow, model.symbols), x0, T)
    x = flow_map(f, algebra(3, 4), x0, np.ones(5), [0, 1, 2, 3], run.nodes, T)
    phi = scipy.linalg.expm(A * T)
    C = np.stack([xi.c for xi in x])
    np.testing.assert_allclose(C[:4, 1:5], phi[:4, :4], rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(C[:, 0], phi @ x0 + [0, 0, 0, 0, T], rtol=1e-9, atol=1e-8)
    assert np.abs(C[:, 5:]).max() < 1e-12


def test_nonlinear_flow_matches_solve_ivp(srna):
    mode = srna.modes["approach"]
    f = compile_expressions(mode.flow, srna.symbols)
    center = np.array([-900.0, -400.0, 0.0, 0.0, 0.0])
    half = np.array([25.0, 25.0, 0.0, 0.0, 0.0])
    T = 30.0
    run = nominal(compile_numeric(mode.flow, srna.symbols), center, T)
    x = flow_map(f, algebra(4, 2), center, half, [0, 1], run.nodes, T)
    for xi in ([1.0, 1.0], [-1.0, 0.3], [0.5, -1.0]):
        x0 = center + half * np.r_[xi, 0, 0, 0]
        ref = solve_ivp(rhs(srna, "approach"), (0, T), x0, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
        got = np.array([float(v(np.array([xi]))[0]) for v in x])
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-7)


def test_event_time_and_map_match_a_dense_solve_ivp_event(srna):
    """Peak of vx in approach: dvx/dt = 0, refined (eqs. 5-9) and mapped (eqs. 10-14)."""
    mode = srna.modes["approach"]
    f = compile_expressions(mode.flow, srna.symbols)
    accel = compile_expressions([mode.flow[2]], srna.symbols)
    event = lambda x: accel(x)[0]
    center = np.array([-900.0, -400.0, 0.0, 0.0, 0.0])
    half = np.array([25.0, 25.0, 0.0, 0.0, 0.0])
    fun = rhs(srna, "approach")
    stop = lambda t, x: fun(t, x)[2]
    run = nominal(compile_numeric(mode.flow, srna.symbols), center, 20.0)
    k = int(np.argmax(run.grid()[:, 2]))
    t_e, x_e = refine_time(f, event, run.solution, run.nodes[k], 4)
    ref = solve_ivp(fun, (0, 20), center, method="DOP853", rtol=1e-12, atol=1e-12, events=stop)
    assert t_e == pytest.approx(ref.t_events[0][0], abs=1e-8)
    np.testing.assert_allclose(x_e, ref.y_events[0][0], rtol=1e-10, atol=1e-7)
    em = event_map(f, event, initial_state(algebra(4, 2), center, half, [0, 1]), run.nodes, t_e, 4)
    for xi in ([1.0, 1.0], [-1.0, 0.5], [0.3, -1.0]):
        ref = solve_ivp(fun, (0, 20), center + half * np.r_[xi, 0, 0, 0], method="DOP853",
                        rtol=1e-12, atol=1e-12, events=stop)
        assert em.time(np.array([xi]))[0] == pytest.approx(ref.t_events[0][0], abs=1e-8)
        got = np.array([float(v(np.array([xi]))[0]) for v in em.state])
        np.testing.assert_allclose(got, ref.y_events[0][0], rtol=1e-9, atol=1e-7)


def test_nominal_run_stops_one_step_past_the_urgent_guard(srna, monkeypatch):
    """The nominal run ends one accepted step after the first guard crossing; the crossing time
    and every candidate map are those of the run integrated to the horizon."""
    from reach.backends.taylor.problem import EventProblem, ModeCode

    problem = EventProblem(srna, events(srna)["thrust_x_min"])
    code = problem.code("approach")
    center = np.array([-900.0, -400.0, 0.0, 0.0, 0.0])
    half = np.array([20.0, 20.0, 0.0, 0.0, 0.0])
    short = nominal(code.f_numeric, center, srna.horizon, stop=code.stop(center))
    full = nominal(code.f_numeric, center, srna.horizon)
    assert short.nodes[-1] < 0.5 * full.nodes[-1]
    k_short, k_full = code.exit(short.grid())[0], code.exit(full.grid())[0]
    assert k_short >= len(short.nodes) - 3          # the crossing is in the last step
    def crossing(run, k):
        times = np.linspace(run.nodes[k - 1], run.nodes[k], 4097)
        inside = np.all(code.exits[0].margins(run.solution(times).T) <= 0, axis=1)
        return times[int(np.argmax(inside))]

    assert crossing(short, k_short) == pytest.approx(crossing(full, k_full), abs=1e-2)
    stopped = problem.candidates(center, half, 4, 1e-9)
    monkeypatch.setattr(ModeCode, "stop", lambda self, x0: None)
    unstopped = problem.candidates(center, half, 4, 1e-9)
    assert set(stopped) == set(unstopped)
    for name in stopped:
        scale = np.max(np.abs(unstopped[name].c))
        np.testing.assert_allclose(stopped[name].c, unstopped[name].c, rtol=0, atol=1e-8 * scale)


def test_supports_names_what_it_cannot_do(srna):
    props = {p.id: bind(p, srna) for p in load_properties("properties/rendezvous.yaml")}
    assert BACKEND.supports(srna, props["thrust"]) is None          # read as margin events
    ev = events(srna)["thrust_x_min"]
    assert BACKEND.supports(srna, ev) is None
    other = dataclasses.replace(ev, modes=["approach", "rendezvous"])
    assert BACKEND.supports(srna, other) is None
    assert BACKEND.supports(dataclasses.replace(srna, clocks=[]), other) is None   # taylor adds a clock
    abort = load_model("models/SRA02.yaml")
    assert BACKEND.supports(abort, events(abort)["thrust_x_min"]) is None   # switch time expanded
    # without the invariant t <= 125 some runs never abort: not a switch-time variable
    t = abort.symbols[abort.index("t")]
    free = {name: dataclasses.replace(m, invariant=[c for c in m.invariant if t not in c.g.free_symbols])
            for name, m in abort.modes.items()}
    unforced = dataclasses.replace(abort, modes=free)
    assert "does not force" in BACKEND.supports(unforced, events(unforced)["thrust_x_min"])


def test_thrust_events_on_srna01_are_bounded_and_never_claimed_safe(srna):
    result = BACKEND.check(srna, events(srna)["thrust_x_max"], {})
    assert result.status is Status.UNKNOWN and result.details["remainder"] == "estimated"
    lo, hi = result.bound
    # the largest Fx is at t = 0 (exact: Fx = -K1 x0 over the initial box)
    K = np.array([-28.82867767694, 0.1004799482599])
    corners = [K @ [x, y] for x in (-925, -875) for y in (-425, -375)]
    assert lo == pytest.approx(min(corners), rel=1e-9) and hi == pytest.approx(max(corners), rel=1e-9)
    assert "met" in result.details["requirement"]


def test_monte_carlo_events_lie_in_their_subdomain_bounds(srna):
    """1000 simulated runs: the minimum of Fx over each run is inside its subdomain's bound,
    with either remainder; the next-order bound is compared with the estimated one."""
    model = dataclasses.replace(srna, horizon=15.0)
    prop = events(model)["thrust_x_min"]
    results = {r: BACKEND.check(model, prop, {"e_tol": 1e-12, "max_splits": 2, "remainder": r})
               for r in ("estimated", "next-order")}
    rng = np.random.default_rng(7)
    x0 = model.initial.low + rng.random((1000, model.n)) * (model.initial.high - model.initial.low)
    monitor, _, _ = sample_extrema(model, prop, x0, 0.01)
    for remainder, result in results.items():
        rows = result.details["subdomains"]
        assert len(rows) == 4 and result.status is Status.UNKNOWN
        assert outside_bounds(rows, x0, monitor.extrema(), [0, 1], prop.sense, monitor.slack) == 0, remainder
    for est, nxt in zip(results["estimated"].details["subdomains"],
                        results["next-order"].details["subdomains"]):
        for name, (lo, hi, R) in est["candidates"].items():
            assert np.isfinite(nxt["candidates"][name][2])


POINT = """name: point
state: [th, w]
modes:
  swing: {flow: {th: w, w: "-sin(th)"}}
initial: {mode: swing, box: {th: 1, w: 0}}
horizon: 6
"""


@pytest.mark.parametrize("options", [{"remainder": "rigorous"}, {"remainder": "rigorous", "refine": 2}])
def test_a_point_initial_set_with_non_polynomial_terms(tmp_path, options):
    """A pendulum from the point (1 rad, 0): no expansion variable, so every power of the
    deviation is zero (``sin`` and a quotient must not build an empty product), and nothing is
    halved by ``refine``. Energy: |w| <= sqrt(2 (1 - cos 1)) = 0.9589 (reached at th = 0)."""
    from reach.checking import check_files
    (tmp_path / "m.yaml").write_text(POINT)
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: speed, kind: event, maximize: 'w / (1 + th**2)', require: '<= 0.97'}\n"
        "  - {id: low, kind: safety, require: ['w >= -0.97']}\n")
    results = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "taylor", options)
    assert [r.status.value for r in results] == ["SAFE", "SAFE"]
    truth = np.sqrt(2 * (1 - np.cos(1)))
    assert results[0].bound[0] <= truth <= results[0].bound[1] < truth + 0.01


TIMER_AT_HORIZON = """
name: timer_at_horizon
state: [x, v, c]
modes:
  a: {flow: {x: v, v: "-x", c: 1}, invariant: ["c <= 1.5"]}
  b: {flow: {x: v, v: "-2*x", c: 1}, invariant: ["c <= 1.5"]}
transitions:
  - {from: a, to: b, guard: ["c >= 1.5"], urgent: true, reset: {c: 0}}
  - {from: b, to: a, guard: ["c >= 1.5"], urgent: true, reset: {c: 0}}
initial: {mode: a, box: {x: [0.9, 1.1], v: [-0.1, 0.1], c: 0}}
horizon: HORIZON
"""


@pytest.mark.parametrize("horizon", [4.5, 4.4])
def test_a_timed_switch_at_the_horizon_is_an_answer(tmp_path, horizon):
    """A timer switch every 1.5 whose third falls at the horizon 4.5 (its event time refined a
    rounding past it) crashed on the run to the horizon it had not kept. Now an answer, whose
    margin interval holds x's largest value on 200 sampled runs' grids (solve_ivp)."""
    path, props = tmp_path / "m.yaml", tmp_path / "p.yaml"
    path.write_text(TIMER_AT_HORIZON.replace("HORIZON", str(horizon)))
    props.write_text('properties:\n  - {id: xmax, kind: safety, modes: [a, b], require: ["x <= 2"]}\n')
    model = load_model(path)
    (prop,) = [bind(p, model) for p in load_properties(props)]
    result = BACKEND.check(model, prop, {})
    assert result.status in (Status.SAFE, Status.UNKNOWN)
    rng = np.random.default_rng(0)
    largest = -np.inf
    for x0, v0 in zip(rng.uniform(0.9, 1.1, 200), rng.uniform(-0.1, 0.1, 200)):
        state, t = np.array([x0, v0]), 0.0
        for k, w2 in enumerate([1.0, 2.0, 1.0]):
            span = min(1.5, horizon - t)
            sol = solve_ivp(lambda _, y, w2=w2: [y[1], -w2 * y[0]], (0, span), state, rtol=1e-10, atol=1e-12,
                            dense_output=True)
            largest = max(largest, sol.sol(np.linspace(0, span, 200))[0].max())
            state, t = sol.y[:, -1], t + span
    low, high = result.details["margin_bound"]
    assert low <= 2 - largest <= high + 1e-9


def test_a_run_released_at_its_extremum_keeps_the_extremum_of_its_neighbours(tmp_path):
    """th' = w, w' = -th from th in [0.9, 1.1], w in [-0.1, 0.1]: the nominal run starts at rest
    at its maximum, but runs with w > 0 rise to hypot(th0, w0) (closed form), at most
    hypot(1.1, 0.1) = 1.10454, just after the start. The estimated bound on max th must hold it
    (it was [0.9, 1.1]), and th <= 1.102 is violated with a counterexample."""
    (tmp_path / "m.yaml").write_text("name: osc\nstate: [th, w]\nmodes:\n  m: {flow: {th: w, w: '-th'}}\n"
                                     "initial: {mode: m, box: {th: [0.9, 1.1], w: [-0.1, 0.1]}}\nhorizon: 1\n")
    (tmp_path / "p.yaml").write_text("properties:\n"
                                     "  - {id: ev, kind: event, modes: [m], maximize: th, require: '<= 1.102'}\n"
                                     "  - {id: cap, kind: safety, modes: [m], require: ['th <= 1.102']}\n")
    model = load_model(tmp_path / "m.yaml")
    event, cap = [bind(p, model) for p in load_properties(tmp_path / "p.yaml")]
    low, high = BACKEND.check(model, event, {}).bound
    assert low <= np.hypot(1.1, 0.1) <= high
    result = BACKEND.check(model, cap, {})
    assert result.status is Status.UNSAFE
