"""The rigorous mode of the taylor back-end: Taylor models and interval Jacobians enclose what they
claim at sampled points, the verified flow enclosure contains solve_ivp runs, and a SAFE from it
is consistent with simulated runs."""

import dataclasses
import warnings

import numpy as np
import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.montecarlo.event_sampling import outside_bounds, sample_extrema
from reach.backends.taylor import BACKEND
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.event import initial_state
from reach.backends.taylor.flow import compile_expressions, compile_numeric
from reach.backends.taylor.nominal import nominal
from reach.backends.taylor.problem import EventProblem
from reach.backends.taylor.interval import Jet
from reach.backends.taylor.tm import TM
from reach.backends.taylor.verified import _may_cross, at_sigma, enclose_stretch
from reach.checking import check_model, resolve_backend
from reach.model.loader import load_model
from reach.result import Status
from reach.spec.properties import bind, load_properties

warnings.filterwarnings("ignore", category=RuntimeWarning)


@pytest.fixture(scope="module")
def srna():
    return load_model("models/SRNA01.yaml")


def _contains(tm: TM, truth, points):
    """``truth - P`` lies in the remainder interval at every point (up to rounding)."""
    gap = truth - tm.poly(points)
    tol = 1e-12 * (1 + np.abs(truth))
    return np.all(gap >= tm.lo - tol) and np.all(gap <= tm.hi + tol)


@settings(max_examples=40, deadline=None)
@given(cx=st.floats(0.3, 2.0), fraction=st.floats(0.01, 0.9), cy=st.floats(-1.0, 1.0),
       sy=st.floats(0.01, 0.8), order=st.integers(1, 5))
def test_taylor_models_enclose_elementary_functions(cx, fraction, cy, sy, order):
    """For ``x = cx + sx xi1`` (positive) and ``y = cy + sy xi2`` every operation's model contains
    the function it models at random points of the box."""
    sx = fraction * cx
    alg = algebra(order, 2)
    x, y = TM(DA.var(alg, 0, cx, sx)), TM(DA.var(alg, 1, cy, sy))
    pts = np.random.default_rng(1).uniform(-1, 1, (400, 2))
    X, Y = cx + sx * pts[:, 0], cy + sy * pts[:, 1]
    cases = {
        "product": (x * y * y, X * Y * Y),
        "sin": ((x * y).sin(), np.sin(X * Y)),
        "cos": ((x + y).cos(), np.cos(X + Y)),
        "exp": (y.exp() * x, np.exp(Y) * X),
        "reciprocal": (1.0 / x, 1.0 / X),
        "sqrt": ((x + y * y).sqrt(), np.sqrt(X + Y * Y)),
        "power": (x ** -1.5, X ** -1.5),
        "log": (x.log(), np.log(X)),
    }
    for name, (tm, truth) in cases.items():
        assert _contains(tm, truth, pts), name
        lo, hi = tm.bound()
        assert np.all(truth >= lo - 1e-12) and np.all(truth <= hi + 1e-12), name


def test_a_blown_up_remainder_bounds_nothing_rather_than_nan():
    """A remainder of ``[-inf, inf]`` through a network layer's ``W a + b`` (midpoint ``inf - inf``)
    gives NaN inside the model; its bound is the whole line, never NaN (``max(-inf, nan)`` is
    ``-inf`` in Python, which would drop the component from an extremum)."""
    alg = algebra(2, 2)
    a = TM.stack([TM(DA.var(alg, 0, 1.0, 0.1), -np.inf, np.inf), TM(DA.var(alg, 1, 2.0, 0.1))])
    out = a.affine(np.array([[1.0, 0.5], [0.0, 1.0]]), np.array([0.0, 1.0]))
    lo, hi = out.bound()
    assert not np.isnan(lo).any() and not np.isnan(hi).any()
    assert lo[0] == -np.inf and hi[0] == np.inf
    assert max(-np.inf, float(hi[0])) == np.inf


def test_network_layers_in_taylor_models_enclose_the_layer():
    """``sin(W a + b)`` on a vector of Taylor models (the SIREN layer of eq. 29)."""
    rng = np.random.default_rng(3)
    alg = algebra(3, 2)
    inputs = [TM(DA.var(alg, 0, 0.2, 0.1)), TM(DA.var(alg, 1, -0.1, 0.1))]
    W, b = rng.normal(size=(6, 2)) * 3, rng.normal(size=6)
    out = TM.stack(inputs).affine(W, b).sin().unstack()
    pts = rng.uniform(-1, 1, (300, 2))
    Z = np.stack([0.2 + 0.1 * pts[:, 0], -0.1 + 0.1 * pts[:, 1]])
    truth = np.sin(W @ Z + b[:, None])
    for k, tm in enumerate(out):
        assert _contains(tm, truth[k], pts)


def test_interval_jacobian_contains_pointwise_jacobians(srna):
    mode = srna.modes["approach"]
    f = compile_expressions(mode.flow, srna.symbols)
    low = np.array([-950.0, -450.0, -2.0, -1.0, 0.0])
    high = np.array([-850.0, -350.0, 2.0, 1.0, 10.0])
    out = f(Jet.seed(low, high))
    glo, ghi = np.array([o.glo for o in out]), np.array([o.ghi for o in out])
    jac = sympy.lambdify([srna.symbols], sympy.Matrix(mode.flow).jacobian(srna.symbols))
    for z in np.random.default_rng(2).uniform(low, high, (200, 5)):
        J = np.array(jac(z), dtype=float)
        assert np.all(J >= glo - 1e-12 * np.abs(J)) and np.all(J <= ghi + 1e-12 * np.abs(J))
        value = np.array([float(v) for v in f(list(z))])
        assert np.all(value >= [o.lo for o in out]) and np.all(value <= [o.hi for o in out])


def test_verified_enclosure_contains_solve_ivp_runs(srna):
    """Nonlinear SRNA01 approach flow over 30 min from a 50 m x 50 m box: at every step end the
    DOP853 reference (rtol 1e-12) lies in the polynomial plus the proved error box."""
    mode = srna.modes["approach"]
    f = compile_expressions(mode.flow, srna.symbols)
    fn = compile_numeric(mode.flow, srna.symbols)
    center, half = np.array([-900.0, -400.0, 0.0, 0.0, 0.0]), np.array([25.0, 25.0, 0, 0, 0])
    T = 30.0
    run = nominal(fn, center, T)
    alg = algebra(4, 3)
    x0 = [DA.var(alg, 0, center[0], half[0]), DA.var(alg, 1, center[1], half[1])] + \
         [DA.const(alg, v) for v in center[2:]]
    enc = enclose_stretch(f, x0, run.nodes, rel_tol=1e-4)
    assert enc is not None and enc.steps[-1].t0 + enc.steps[-1].h == pytest.approx(T)
    error = np.max(enc.error_box)
    assert 0 < error < 1e-2
    xi = np.random.default_rng(5).uniform(-1, 1, (12, 2))
    ends = np.array([s.t0 + s.h for s in enc.steps])
    rhs = lambda t, x: np.array(fn(list(x)), dtype=float)
    for point in xi:
        x_start = center + half * np.r_[point, 0, 0, 0]
        ref = solve_ivp(rhs, (0, T), x_start, method="DOP853", rtol=1e-12, atol=1e-9, t_eval=ends).y.T
        for k, step in enumerate(enc.steps):
            tms = enc.tm_at_end(k)
            for i, tm in enumerate(tms):
                value = float(tm.poly(np.r_[point, 1.0][None, :])[0])
                assert tm.lo - 1e-6 <= ref[k, i] - value <= tm.hi + 1e-6


def test_defect_floor_is_accepted_and_the_enclosure_still_contains_runs():
    """A wide box of a strongly nonlinear flow (damped pendulum, x0 in [0, 1.2], order 3): the
    truncation in the deviations puts a floor under the defect that no step size removes; the
    steps go on at that floor and the enclosure (metric following the flow) contains solve_ivp runs."""
    x, v = sympy.symbols("x v")
    flow = [v, -sympy.sin(3 * x) - 0.5 * v]
    f, fn = compile_expressions(flow, [x, v]), compile_numeric(flow, [x, v])
    rhs = lambda t, y: np.array(fn(list(y)), dtype=float)
    alg = algebra(3, 2)
    x0 = [DA.var(alg, 0, 0.6, 0.6), DA.const(alg, 0.0)]
    T, rel_tol = 4.0, 1e-6
    enc = enclose_stretch(f, x0, np.array([0.0, 0.05, T]), rel_tol=rel_tol)
    assert enc is not None and enc.steps[-1].t0 + enc.steps[-1].h == pytest.approx(T)
    ratios = [np.max(s.defect / (rel_tol * s.rate_size)) for s in enc.steps]
    assert max(ratios) > 10                       # accepted above the tolerance: the floor
    ends = np.array([s.t0 + s.h for s in enc.steps])
    for xi in np.linspace(-1, 1, 9):
        ref = solve_ivp(rhs, (0, T), [0.6 + 0.6 * xi, 0.0], method="DOP853", rtol=1e-12, atol=1e-12,
                        t_eval=ends).y.T
        for k in range(len(enc.steps)):
            for i, tm in enumerate(enc.tm_at_end(k)):
                value = float(tm.poly(np.array([[xi, 1.0]]))[0])
                assert tm.lo - 1e-9 <= ref[k, i] - value <= tm.hi + 1e-9


def test_at_sigma_substitutes_the_time_variable():
    alg = algebra(3, 2)
    p = DA.var(alg, 0, 1.0, 2.0) * DA.var(alg, 1, 0.5, 1.5) + DA.var(alg, 1) ** 3
    for s in (-1.0, 0.3, 1.0):
        q = at_sigma(p, s)
        pts = np.random.default_rng(0).uniform(-1, 1, (50, 2))
        assert np.allclose(q(np.c_[pts[:, 0], np.full(50, 7.0)]), p(np.c_[pts[:, 0], np.full(50, s)]))


def test_rigorous_thrust_bound_is_safe_and_contains_simulated_runs(srna):
    """Rigorous mode on the first 20 min of SRNA01: SAFE, the bound contains the minimum of Fx
    over 500 simulated runs and the estimated bound, and is at most modestly wider."""
    model = dataclasses.replace(srna, horizon=20.0)
    prop = {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}["thrust_x_min"]
    rig = BACKEND.check(model, prop, {"remainder": "rigorous", "max_splits": 1, "e_tol": 1e-12})
    assert rig.status is Status.SAFE and rig.coverage == 1.0
    assert rig.details["remainder"].startswith("rigorous")
    rng = np.random.default_rng(11)
    x0 = model.initial.low + rng.random((500, model.n)) * (model.initial.high - model.initial.low)
    monitor, _, _ = sample_extrema(model, prop, x0, 0.01)
    rows = rig.details["subdomains"]
    assert outside_bounds(rows, x0, monitor.extrema(), [0, 1], prop.sense, monitor.slack) == 0
    for row in rows:
        lo, hi = row["bound"]
        e_lo, e_hi = row["estimated_bound"]
        assert lo <= e_lo + 1e-9 and (hi - lo) <= 3 * (e_hi - e_lo) + 1.0

def test_events_after_the_urgent_switch_contain_sampled_runs(srna):
    """Line-of-sight margin in the rendezvous mode, 20 min past the switch: the estimated maps
    (event past the guard crossing) and the rigorous sweep (entry states, then the rendezvous flow)
    both contain the sampled minimum of 120 simulated runs; the rigorous one proves the margin, its
    lower end within 2 % of the sampled minimum."""
    model = dataclasses.replace(srna, horizon=130.0)
    prop = {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}["los_upper_margin"]
    est = BACKEND.check(model, prop, {"max_splits": 0})
    rig = BACKEND.check(model, prop, {"max_splits": 0, "remainder": "rigorous"})
    assert est.status is Status.UNKNOWN and rig.status is Status.SAFE
    assert any(name.startswith("rendezvous:") for name in est.details["subdomains"][0]["candidates"])
    rng = np.random.default_rng(4)
    x0 = model.initial.low + rng.random((120, model.n)) * (model.initial.high - model.initial.low)
    monitor, _, _ = sample_extrema(model, prop, x0, 0.05)
    values = monitor.extrema()
    assert np.all(np.isfinite(values))                 # every run reached the rendezvous mode
    for result in (est, rig):
        lo, hi = result.bound
        assert values.min() >= lo - 1e-9 and values.max() <= hi + monitor.slack
    assert 0 < values.min() - rig.bound[0] <= 0.02 * values.min()


def test_splitting_on_the_bound_decides_more_of_the_box(srna):
    """A threshold inside the range of the smallest Fy: halving the undecided subdomains twice
    proves part of the box safe and part unsafe, and every sampled run stays inside its bound."""
    model = dataclasses.replace(srna, horizon=10.0)
    prop = {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}["thrust_y_min"]
    prop = dataclasses.replace(prop, value=-25.0)
    base = {"e_tol": 1e-12, "max_splits": 2, "remainder": "rigorous"}
    coarse = BACKEND.check(model, prop, base)
    fine = BACKEND.check(model, prop, {**base, "refine": 2})
    decided = lambda r: r.details["share_meeting_requirement"] + r.details["share_violating_requirement"]
    assert decided(coarse) < decided(fine) and fine.details["share_meeting_requirement"] > 0
    assert fine.details["subdomain_count"] > coarse.details["subdomain_count"]
    rng = np.random.default_rng(8)
    x0 = model.initial.low + rng.random((300, model.n)) * (model.initial.high - model.initial.low)
    monitor, _, _ = sample_extrema(model, prop, x0, 0.01)
    assert outside_bounds(fine.details["subdomains"], x0, monitor.extrema(), [0, 1], prop.sense, monitor.slack) == 0


def _dock(srna, points):
    """solve_ivp (DOP853, rtol 1e-10) runs of SRNA01 from the initial states ``points`` to the first
    instant the dock guard holds, then in the rendezvous mode to the horizon: per run the entry
    state and the largest rendezvous Fx on a dense grid of the dense output."""
    f = {m: compile_numeric(srna.modes[m].flow, srna.symbols) for m in ("approach", "rendezvous")}
    guard = [sympy.lambdify([srna.symbols], c.g) for c in srna.transitions[0].guard]
    Fx = sympy.lambdify([srna.symbols], sympy.sympify(srna.modes["rendezvous"].control["Fx"]))
    outside = lambda t, x: max(g(x) for g in guard)
    outside.terminal, outside.direction = True, -1
    entries, peaks = [], []
    for x0 in points:
        run = solve_ivp(lambda t, x: np.array(f["approach"](list(x)), dtype=float), (0, srna.horizon), x0,
                        method="DOP853", rtol=1e-10, atol=1e-10, events=outside)
        t_e, x_e = run.t_events[0][0], run.y_events[0][0]
        after = solve_ivp(lambda t, x: np.array(f["rendezvous"](list(x)), dtype=float), (t_e, srna.horizon),
                          x_e, method="DOP853", rtol=1e-10, atol=1e-10, dense_output=True)
        grid = np.linspace(t_e, min(t_e + 2.0, srna.horizon), 4001)
        entries.append(x_e)
        peaks.append(float(np.max(Fx(after.sol(grid)))))
    return np.array(entries), np.array(peaks)


def test_crossing_encloses_the_entry_states_of_solve_ivp_runs(srna):
    """The Taylor models of the states entering the rendezvous mode (whole initial box, one
    window step): for each of 25 runs from a grid of the box, some value of the slack variable puts
    the solve_ivp entry state inside every component's polynomial plus remainder; and the
    entry states are tight: x within 0.03 m of the face x = -100, and the rendezvous Fx over the
    models within 1 % of the sampled entry values (the interval hull of the window's steps gave Fx up to
    11049 against 9569)."""
    prop = {p.id: bind(p, srna) for p in load_properties("properties/rendezvous_events.yaml")}["thrust_x_max_rendezvous"]
    problem = EventProblem(srna, prop)
    low, high = srna.initial.low, srna.initial.high
    x0 = initial_state(algebra(4, 3), 0.5 * (low + high), 0.5 * (high - low), problem.uncertain)
    code = problem.code("approach")
    enc = problem._enclosure(code, x0, np.zeros(srna.n), srna.horizon, 1e-5, 1e-9)
    exit_ = code.exits[0]
    first = next(k for k in range(len(enc.steps)) if code.may_enter(exit_, enc.tm(k)))
    states = problem._crossing(code, exit_, enc, first, enc.steps[-1].t0 + enc.steps[-1].h)
    assert states is not None and states[0].poly.alg.nvars == 4        # xi1, xi2, slack, step time
    xi = np.array([(a, b) for a in np.linspace(-1, 1, 5) for b in np.linspace(-1, 1, 5)])
    entries, _ = _dock(srna, [low + 0.5 * (high - low) * (1 + np.r_[p, 0, 0, 0]) for p in xi])
    slack = np.linspace(-1, 1, 2001)
    for p, x_e in zip(xi, entries):
        points = np.c_[np.tile(p, (len(slack), 1)), slack, np.zeros(len(slack))]
        gaps = np.array([x_e[i] - tm.poly(points) for i, tm in enumerate(states)])     # (n, slack)
        inside = np.all([(g >= tm.lo - 1e-9) & (g <= tm.hi + 1e-9) for g, tm in zip(gaps, states)], axis=0)
        assert inside.any()
    lo, hi = states[0].bound()
    assert -100.03 <= lo <= -100 <= hi <= -99.97
    rendezvous = problem.code("rendezvous")
    fx = np.asarray(rendezvous.q_numeric(list(entries.T)))
    fx_lo, fx_hi = rendezvous.q(states).bound()
    assert fx_lo <= fx.min() and fx.max() <= fx_hi <= fx.max() + 0.01 * abs(fx.max())


def test_rigorous_rendezvous_thrust_is_within_one_percent_of_solve_ivp(srna):
    """Largest rendezvous Fx on SRNA01 (horizon cut to 115 min, a few minutes past the last entry;
    the largest Fx comes right after the entry): the rigorous bound over the whole box, one
    subdomain, contains the largest Fx of solve_ivp runs from the box's corners and its y = -375
    edge (where the extremum lies) and exceeds it by less than 1 %."""
    model = dataclasses.replace(srna, horizon=115.0)
    prop = {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}["thrust_x_max_rendezvous"]
    rig = BACKEND.check(model, prop, {"remainder": "rigorous", "max_splits": 0})
    low, high = model.initial.low, model.initial.high
    edge = [np.r_[x, high[1], 0, 0, 0] for x in np.linspace(low[0], high[0], 21)]
    corners = [np.r_[x, y, 0, 0, 0] for x in (low[0], high[0]) for y in (low[1], high[1])]
    _, peaks = _dock(model, edge + corners)
    assert rig.status is Status.SAFE
    assert peaks.max() <= rig.bound[1] <= 1.01 * peaks.max()


def test_guard_faces_that_cannot_be_crossed_are_ruled_out():
    """The square |x| <= 1, |y| <= 1 approached from the left: over states in [-1.5, -0.5] x
    [-0.5, 0.5] only the face x = -1 can be where a run enters; over [-1.5, -0.5] x [0.5, 1.5]
    the corner region, the face y = 1 can be too."""
    faces = [(np.array([1.0, 0.0]), -1.0), (np.array([-1.0, 0.0]), -1.0),
             (np.array([0.0, 1.0]), -1.0), (np.array([0.0, -1.0]), -1.0)]
    side = np.array([[-1.5, -0.5], [-0.5, 0.5]])
    corner = np.array([[-1.5, -0.5], [0.5, 1.5]])
    assert [_may_cross(faces, j, side) for j in range(4)] == [False, True, False, False]
    assert [_may_cross(faces, j, corner) for j in range(4)] == [False, True, True, False]


def test_refining_on_the_bound_never_widens_it_and_holds_sampled_runs(srna):
    """Smallest approach Fy over 10 min (a bound already decided): refine halves the subdomains
    that can hold the extremum; the outer (lower) end only rises, and sampled runs stay inside."""
    model = dataclasses.replace(srna, horizon=10.0)
    prop = {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}["thrust_y_min"]
    base = {"e_tol": 1e-12, "max_splits": 1, "remainder": "rigorous"}
    coarse = BACKEND.check(model, prop, base)
    fine = BACKEND.check(model, prop, {**base, "refine": 2})
    assert coarse.status is Status.SAFE and fine.status is Status.SAFE
    assert fine.details["subdomain_count"] > coarse.details["subdomain_count"]
    assert fine.bound[0] >= coarse.bound[0]
    rng = np.random.default_rng(9)
    x0 = model.initial.low + rng.random((300, model.n)) * (model.initial.high - model.initial.low)
    monitor, _, _ = sample_extrema(model, prop, x0, 0.01)
    assert outside_bounds(fine.details["subdomains"], x0, monitor.extrema(), [0, 1], prop.sense, monitor.slack) == 0
    assert monitor.extrema().min() >= fine.bound[0]


@pytest.mark.timeout(180)
def test_a_long_crossing_window_in_a_stiff_mode_falls_back_to_the_step_hull():
    """SRA03's abort window (t >= tau, tau in [120, 145]) is 28 min long in the stiff rendezvous
    mode: one polynomial step over it gives entry models with clock bounds of +-2e7 min, which
    would start the passive mode's stretch with a horizon of 2e7 min. Such entry models are
    replaced by the hull of the window's steps: the collision margin is bounded in seconds, its
    lower end finite and below the closest sampled margin of Monte Carlo runs."""
    model = load_model("models/SRA03.yaml")
    prop = {p.id: p for p in load_properties("properties/rendezvous.yaml")}["collision"]
    bound = bind(prop, model)
    rig = check_model(resolve_backend("taylor"), model, [bound], {"remainder": "rigorous", "max_splits": 0})[0]
    mc = check_model(resolve_backend("montecarlo"), model, [bound],
                     {"samples": 200, "optimise": False, "search_rounds": 0})[0]
    lo, _ = rig.details["margin_bound"]
    assert rig.status is not Status.UNSAFE
    assert -100.0 < lo <= mc.details["closest_depth"]


def test_no_refine_hint_where_only_the_switch_count_holds_the_bound_open(tmp_path):
    """A ball bouncing for 20 s switches more than taylor follows: the bound is open for that
    reason alone, which halving subdomains cannot change, so no -o refine hint is given."""
    import yaml

    from reach.model import load_model
    from reach.spec import bind, load_properties
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(
        {"name": "ball", "state": ["x", "v", "t"], "horizon": 20,
         "modes": {"fall": {"flow": {"x": "v", "v": -9.81, "t": 1}, "invariant": ["x >= 0"]}},
         "transitions": [{"from": "fall", "to": "fall", "guard": ["x <= 0", "v <= 0"], "reset": {"v": "-0.8*v"},
                          "urgent": True}],
         "initial": {"mode": "fall", "box": {"x": [10, 10.2], "v": 0, "t": 0}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "vmax", "kind": "event", "modes": ["fall"], "maximize": "v", "require": "<= 20"}]}))
    model = load_model(tmp_path / "m.yaml")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model), {"remainder": "rigorous"})
    assert "mode switches" in result.details["note"] and "-o refine" not in result.details["note"]
