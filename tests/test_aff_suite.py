"""The ARCH AFF instances of suite.yaml: the imported YAML is what the published SpaceEx files
import to, the models load, the Building BDU02 verdicts follow from closed forms, and star's
verdicts on the bouncing ball agree with the ball's closed form."""

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sl
import yaml
from scipy.integrate import solve_ivp

from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND as STAR
from reach.bench.suite import load_suite
from reach.model import load_model
from reach.model.spaceex import documents, load_spaceex
from reach.spec import bind, load_properties

ROOT = Path(__file__).resolve().parent.parent
SPACEEX = ROOT / "models" / "spaceex"
IMPORTED = SPACEEX / "imported"
#: suite instance -> (published model, cfg) under models/spaceex/
SOURCES = {
    "BLDC01-BDS01": ("Building/BLDC01.xml", "Building/BLDC01-BDS01.cfg"),
    "BLDF01-BDS01": ("Building/BLDF01.xml", "Building/BLDF01-BDS01.cfg"),
    "BLDF01-BDU01": ("Building/BLDF01.xml", "Building/BLDF01-BDU01.cfg"),
    "BLDC01-BDU02": ("Building/BLDC01.xml", "Building/BLDC01-BDU02.cfg"),
    "BLDF01-BDU02": ("Building/BLDF01.xml", "Building/BLDF01-BDU02.cfg"),
    "GRBX01-MES01": ("Gearbox/GRBX01-MES01.xml", "Gearbox/GRBX01-MES01.cfg"),
    "bball-height": ("BouncingBall/bball.xml", "BouncingBall/bball-height.cfg"),
    "bball-speed": ("BouncingBall/bball.xml", "BouncingBall/bball-speed.cfg"),
    "PLAD01-BND42": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42-forbidden.cfg"),
    "PLAD01-BND30": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND30-forbidden.cfg"),
    "PLAD01-BND42-h20": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42-h20-forbidden.cfg"),
    "PLAD01-BND30-h20": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND30-h20-forbidden.cfg"),
    "PLAN01-UNB50": ("Platoon/PLAN01-UNB.xml", "Platoon/PLAN01-UNB50-forbidden.cfg"),
    "PLAA01-BND50": ("Platoon/PLAA01-BND.xml", "Platoon/PLAA01-BND50-forbidden.cfg"),
    "PLAA01-BND50-h20": ("Platoon/PLAA01-BND.xml", "Platoon/PLAA01-BND50-h20-forbidden.cfg"),
    "SRA01-SR0-LOS": ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-LOS.cfg"),
    "SRA01-SR0-collision": ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-collision.cfg"),
    "SRNA01-SR0-LOS": ("Rendezvous_ARCH18/SRNA01-SR0_.xml", "Rendezvous_ARCH18/SRNA01-SR0_-LOS.cfg"),
    "filtered_oscillator-x07": ("FilteredOscillator/filtered_oscillator.xml",
                                "FilteredOscillator/filtered_oscillator-x07.cfg"),
    "filtered_oscillator-x06": ("FilteredOscillator/filtered_oscillator.xml",
                                "FilteredOscillator/filtered_oscillator-x06.cfg"),
    "DTN-2theta-30": ("Powertrain/drivetrain_2theta_30percent.xml",
                      "Powertrain/drivetrain_2theta_30percent-forbidden.cfg"),
    "ISSC01-ISS02": ("SpaceStation/iss_270.xml", "SpaceStation/ISSC01-ISS02-forbidden.cfg"),
    "ISSC01-ISU02": ("SpaceStation/iss_270.xml", "SpaceStation/ISSC01-ISU02-forbidden.cfg"),
}
#: the imported file's name where it is not the instance's
FILE = {"PLAD01-BND42": "PLAD01-BND42-forbidden", "PLAD01-BND30": "PLAD01-BND30-forbidden",
        "PLAD01-BND42-h20": "PLAD01-BND42-h20-forbidden", "PLAD01-BND30-h20": "PLAD01-BND30-h20-forbidden",
        "PLAN01-UNB50": "PLAN01-UNB50-forbidden", "PLAA01-BND50": "PLAA01-BND50-forbidden",
        "PLAA01-BND50-h20": "PLAA01-BND50-h20-forbidden",
        "SRA01-SR0-LOS": "SRA01-SR0_-LOS", "SRA01-SR0-collision": "SRA01-SR0_-collision",
        "SRNA01-SR0-LOS": "SRNA01-SR0_-LOS", "DTN-2theta-30": "drivetrain_2theta_30percent-forbidden",
        "ISSC01-ISS02": "ISSC01-ISS02-forbidden", "ISSC01-ISU02": "ISSC01-ISU02-forbidden"}
THRESHOLD = -0.00078                     # BDU02: forbidden x25 < -7.8e-4 at t = 20
T_END = 20.0


def test_suite_lists_every_imported_instance_with_its_files():
    suite = {inst.id: inst for inst in load_suite(ROOT / "suite.yaml").instances}
    for name in SOURCES:
        inst = suite[name]
        assert inst.model == IMPORTED / "models" / f"{FILE.get(name, name)}.yaml"
        assert inst.properties == IMPORTED / "properties" / f"{FILE.get(name, name)}.yaml"
        ids = {p.id for p in load_properties(inst.properties)}
        assert set(inst.expect) == ids


@pytest.mark.parametrize("name", sorted(SOURCES))
def test_imported_yaml_is_a_fresh_import_of_the_published_files(name, monkeypatch):
    xml, cfg = SOURCES[name]
    monkeypatch.chdir(ROOT)                  # the import notes the paths it was given
    docs = documents(f"models/spaceex/{xml}", f"models/spaceex/{cfg}")
    name = FILE.get(name, name)
    assert yaml.safe_load((IMPORTED / "models" / f"{name}.yaml").read_text()) == docs.model
    assert yaml.safe_load((IMPORTED / "properties" / f"{name}.yaml").read_text()) == docs.properties


@pytest.fixture(scope="module")
def building():
    """The BDU02 automata as imported (constant input: BLDC01; time-varying: BLDF01)."""
    return {name: load_spaceex(SPACEEX / SOURCES[name][0], SPACEEX / SOURCES[name][1])[0]
            for name in ("BLDC01-BDU02", "BLDF01-BDU02")}


def _split(model):
    """``(A, B, b, keep, u)``: ``x' = A x + B u + b`` over the states without the input u1."""
    (A, b), u = model.modes["Model"].linear, model.bounded_inputs[0].index
    keep = [i for i in range(len(model.state)) if i != u]
    return A[np.ix_(keep, keep)], A[keep, u], b[keep], keep, model.bounded_inputs[0]


def _x25_row(model, duration):
    """x25(duration) = c . (x0, u1, 1) for a constant input, from expm of the augmented system."""
    n = len(model.state)
    A, b = model.modes["Model"].linear
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    return sl.expm(duration * M)[model.state.index("x25")]


def test_bldc01_bdu02_exact_range_of_x25_at_20_misses_the_forbidden_set(building):
    model = building["BLDC01-BDU02"]
    u1 = model.bounded_inputs[0]
    assert not u1.varying and (u1.low, u1.high) == (0.8, 1.0) and model.initial.polytope is None
    row = _x25_row(model, T_END)
    c, c0 = row[:-1], row[-1]
    lo, hi = model.initial.low, model.initial.high
    low = c0 + np.minimum(c * lo, c * hi).sum()         # extremes of a linear form over a box
    high = c0 + np.maximum(c * lo, c * hi).sum()
    assert -1.9e-6 < low < -1.8e-6 and 4.3e-7 < high < 4.5e-7
    assert low > THRESHOLD * 100                         # far from -7.8e-4
    # the minimising vertex, integrated independently, lands where the closed form says
    vertex = np.where(c > 0, lo, hi)
    sol = solve_ivp(lambda t, x: model.modes["Model"].linear[0] @ x + model.modes["Model"].linear[1],
                    (0, T_END), vertex, method="LSODA", rtol=1e-10, atol=1e-13)
    assert sol.y[model.state.index("x25"), -1] == pytest.approx(low, abs=5e-9)


def test_bldf01_bdu02_bang_bang_input_reaches_the_forbidden_set(building):
    """With u1(t) time-varying, x25(20) = c . x0 + int_0^20 g(20 - s) u1(s) ds with
    g(r) = [expm(r A) B]_x25; the input 0.8 where g > 0 and 1 where g < 0 minimises it."""
    model = building["BLDF01-BDU02"]
    A, B, b, keep, u1 = _split(model)
    assert u1.varying and (u1.low, u1.high) == (0.8, 1.0)
    k, steps = keep.index(model.state.index("x25")), 2000
    h = T_END / steps
    step, v, low = sl.expm(h * A), sl.expm(h / 2 * A) @ B, 0.0
    for _ in range(steps):                                # midpoint rule in r = 20 - s
        g = v[k] * h
        low += min(u1.low * g, u1.high * g)
        v = step @ v
    n = len(keep)
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    c = sl.expm(T_END * M)[k, :n]
    lo, hi = model.initial.low[keep], model.initial.high[keep]
    low += sl.expm(T_END * M)[k, n] + np.minimum(c * lo, c * hi).sum()
    assert low < THRESHOLD - 1e-5                         # about -7.99e-4


def _ball(name):
    model = load_model(IMPORTED / "models" / f"{name}.yaml")
    prop = bind(load_properties(IMPORTED / "properties" / f"{name}.yaml")[0], model)
    return model, prop


def test_star_bouncing_ball_verdicts_match_the_closed_form():
    """Dropped from x0 (v = 0, g = 1) the ball lands with v = -sqrt(2 x0), then each bounce
    keeps the energy x + v^2/2 at most 0.75^2 times its value, so x <= x0 <= 10.2 always
    (x >= 10.5 unreachable) and v <= -4.5 happens exactly when x0 >= 10.125."""
    model, prop = _ball("bball-height")
    assert model.initial.high[model.state.index("x")] == 10.2
    assert STAR.check(model, prop, {}).status.value == "SAFE"
    model, prop = _ball("bball-speed")
    result = STAR.check(model, prop, {})
    assert result.status.value == "UNSAFE"
    cex = result.counterexample
    x0 = cex.initial_state[model.state.index("x")]
    assert np.sqrt(2 * x0) >= 4.5 - 1e-6
    assert replay(model, prop, cex.initial_state, cex.switch_time, cex.dt, cex.input_signal).violated


def test_drivetrain_initial_set_is_dtn02s_segment_scaled_by_0p3():
    """The ARCH-COMP DTN initial set for theta = 2 (JuliaReach's ARCH2022_AFF_RE Powertrain.jl)
    is the segment c + [-1, 1] g with c = (-0.0432, -11, 0, 30, 0, 30, 360, -0.0013, 30,
    -0.0013, 30), g = (0.0056, 4.67, 0, 10, 0, 10, 120, 0.0006, 10, 0.0006, 10). The published
    30 % file (Hyst's generator) is c' + [-0.3, 0.3] g with c' = c except x8 = x10 = -0.00132:
    Hyst places those two offsets 2e-5 rad lower than JuliaReach."""
    model, _ = _imported("DTN-2theta-30")
    c = np.array([-0.0432, -11, 0, 30, 0, 30, 360, -0.0013, 30, -0.0013, 30, 0])
    g = np.array([0.0056, 4.67, 0, 10, 0, 10, 120, 0.0006, 10, 0.0006, 10, 0])
    hyst = c.copy()
    hyst[[model.state.index("x8"), model.state.index("x10")]] = -0.00132
    P = model.initial.polytope
    for s, inside in ((-0.3, True), (0.3, True), (0.0, True), (0.31, False), (-1.0, False)):
        x = hyst + s * g
        member = np.all(P.A @ x <= P.b + 1e-9) and np.allclose(P.E @ x, P.f, atol=1e-12)
        assert member == inside
    assert not np.allclose(P.E @ c, P.f, atol=1e-6)            # JuliaReach's centre is not in it
    assert model.initial.mode == "negAngleInit" and model.horizon == 2.0


def _hylaa_bench():
    """benchmarks/hylaa_vs_star.py as a module (it is a script, not a package)."""
    import importlib.util

    spec_ = importlib.util.spec_from_file_location("hylaa_vs_star", ROOT / "benchmarks" / "hylaa_vs_star.py")
    bench = importlib.util.module_from_spec(spec_)
    spec_.loader.exec_module(bench)
    return bench


def test_hylaa_automaton_of_the_imported_bouncing_ball():
    """benchmarks/hylaa_vs_star.py turns the imported automaton into Hylaa's matrices over
    (x, v, 1): x' = v, v' = -1; the bounce guard x <= 0, v <= 0 (closed) and reset v := -0.75 v;
    the forbidden v <= -4.5 as a guard into the error mode; the initial box with 1 == 1."""
    bench = _hylaa_bench()
    model, prop = _ball("bball-speed")
    assert model.state == ["x", "v"]
    spec = bench.automaton_spec(model, prop, 0.1)
    assert np.allclose(spec["modes"]["always"]["A"], [[0, 1, 0], [0, 0, -1], [0, 0, 0]])
    (tr,) = spec["transitions"]
    assert np.allclose(tr["R"], [[1, 0, 0], [0, -0.75, 0], [0, 0, 1]])
    guard = {tuple(np.append(row, g)) for row, g in zip(tr["H"], tr["g"])}
    assert guard == {(1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0)}
    (err,) = spec["errors"]
    assert np.allclose(err["H"], [[0, 1, 0]]) and np.allclose(err["g"], [-4.5])
    (init,) = spec["initial"]
    H, g = np.array(init["H"]), np.array(init["g"])
    for point, inside in (([10.1, 0, 1], True), ([10.3, 0, 1], False), ([10.1, 0, 0], False)):
        assert bool(np.all(H @ point <= g + 1e-12)) is inside


def _imported(name):
    model = load_model(IMPORTED / "models" / f"{FILE.get(name, name)}.yaml")
    return model, [bind(p, model) for p in load_properties(IMPORTED / "properties" / f"{FILE.get(name, name)}.yaml")]


def _platoon_least_spacing(model, horizon, h=0.002):
    """The least e1, e2, e3 any lead acceleration aL(t) in [-9, 1] reaches by ``horizon`` (PLAD01).

    From the rest state x(0) = 0, e(T) = int_0^T g(T, s) aL(s) ds with g(T, s) the e row of
    Phi(T, s) B (Phi the transition matrix of the mode schedule: communication on [0, 5),
    [10, 15), ..., no communication between), so min e(T) = int min(-9 g, g) ds: bang-bang on
    the sign of g. Evaluated exactly for aL piecewise constant on steps of ``h`` (expm of the
    augmented step), for T on a grid of 0.25; returns the least value over the grid."""
    u = model.bounded_inputs[0]
    keep = [i for i, name in enumerate(model.state) if name not in ("t", "break_pattern_t", u.name)]
    rows = [keep.index(model.state.index(e)) for e in ("e1", "e2", "e3")]
    steps = []
    for name in ("communication__communication__loc1", "no_communication__no_communication__loc1"):
        A = model.modes[name].linear[0]
        n = len(keep)
        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n] = A[np.ix_(keep, keep)], A[keep, u.index]
        E = sl.expm(h * M)
        steps.append((E[:n, :n], E[:n, n]))
    least = np.zeros(3)
    for T in np.arange(0.25, horizon + 1e-9, 0.25):
        c, low = np.eye(len(keep))[rows], np.zeros(3)
        for k in range(int(round(T / h)) - 1, -1, -1):
            E, G = steps[int((k + 0.5) * h // 5) % 2]
            g = c @ G
            low += np.minimum(u.low * g, u.high * g)
            c = c @ E
        least = np.minimum(least, low)
    return least


def test_plad01_least_spacing_over_the_published_horizon_clears_30():
    """PLAD01-BND30 (e1, e2, e3 >= -30) is safe over the cfg's horizon 5: the least spacing the
    worst lead acceleration reaches is about -18.98 (e1 at t = 5); star agrees, and the worst
    Monte Carlo run stays above it."""
    model, props = _imported("PLAD01-BND30")
    assert model.horizon == 5.0 and model.bounded_inputs[0].varying
    least = _platoon_least_spacing(model, model.horizon)
    assert -19.0 < least[0] < -18.9 and least[1] > -6.1 and least[2] > -2.4
    assert all(STAR.check(model, prop, {}).status.value == "SAFE" for prop in props)


def test_plad01_over_the_reports_horizon_clears_30_and_star_proves_it_with_input_generators():
    """Over the reports' horizon 20 the least spacing is about -26.8 (e1 near t = 14; e2 -24.1):
    PLAD01-BND30 is safe. star proves it once the lead acceleration's effect crosses the
    switches as generators (``input_cells = 1``) and the time-triggered switches are taken at
    their instant; with the effect as one box per chain the corners it carries through the
    switch at t = 5 reach past -30 (UNKNOWN, never a wrong answer); by default, that undecided
    box is followed by a pass with the effect as generators, which proves it."""
    model, props = _imported("PLAD01-BND30-h20")
    assert model.horizon == 20.0
    least = _platoon_least_spacing(model, model.horizon)
    assert -27.0 < least[0] < -26.5 and -24.5 < least[1] < -23.5 and least[2] > -30
    assert all(STAR.check(model, prop, {"input_cells": 1}).status.value == "SAFE" for prop in props)
    assert STAR.check(model, props[1], {"input_cells": 0}).status.value == "UNKNOWN"
    default = STAR.check(model, props[1], {})
    assert default.status.value == "SAFE" and "input effect carried as generators" in default.details["semantics"]


def test_filtered_oscillator_x_flows_towards_plus_minus_0p7():
    """The closed form behind filtered_oscillator-x07/-x06: every location's x flow is
    x' = -2 (x - x*) with x* = +-0.7, so x stays in [-0.7, 0.7] from the initial x in [0.2, 0.3];
    in pp (x* = 0.7, y' = -(y + 0.7)) the corner x0 = 0.3, y0 = 0.1 reaches x = 0.6 at
    t = ln(4)/2 with y = -0.3 still above the switching line y = -x/1.4 (a solve_ivp run agrees)."""
    model, (prop,) = _imported("filtered_oscillator-x07")
    ix, iy = model.state.index("x"), model.state.index("y")
    targets = set()
    for mode in model.modes.values():
        A, b = mode.linear
        assert A[ix, ix] == -2 and not np.any(np.delete(A[ix], ix))
        targets.add(round(-b[ix] / A[ix, ix], 12))
    assert targets == {0.7, -0.7}
    (A, b) = model.modes[model.initial.mode].linear
    x0 = np.zeros(len(model.state))
    x0[ix], x0[iy] = 0.3, 0.1
    t_hit = np.log(4) / 2
    sol = solve_ivp(lambda t, x: A @ x + b, (0, t_hit), x0, rtol=1e-10, atol=1e-12)
    x, y = sol.y[ix, -1], sol.y[iy, -1]
    assert x == pytest.approx(0.6, abs=1e-8) and y == pytest.approx(-0.3, abs=1e-8) and y > -x / 1.4
    assert model.initial.mode.startswith("pp")


def test_hylaa_automaton_of_unguarded_hops_and_a_model_with_its_own_error_mode():
    """The filtered oscillator's hops have no guard: Hylaa gets the true row 0 <= 1 for each.
    The drivetrain has a mode named error: Hylaa's error mode is named apart from it, and the
    forbidden pieces (t >= 2 in three modes) become guards from those modes only."""
    bench = _hylaa_bench()
    model, prop, _ = bench.load_aff("filtered_oscillator-x06")
    spec = bench.automaton_spec(model, prop, 0.02)
    assert len(spec["transitions"]) == 4
    for tr in spec["transitions"]:
        assert not np.any(tr["H"]) and tr["g"] == [1.0]
    model, prop, _ = bench.load_aff("DTN-2theta-30")
    spec = bench.automaton_spec(model, prop, 5e-4)
    assert "error" in spec["modes"] and spec["error_mode"] not in spec["modes"]
    assert sorted(e["source"] for e in spec["errors"]) == ["deadzone", "negAngle", "negAngleInit"]
    t = model.state.index("t")
    for e in spec["errors"]:
        assert np.allclose(e["H"], [np.eye(len(spec["modes"]["error"]["A"]))[t] * -1]) and e["g"] == [-2.0]


def test_bench_plots_a_one_state_suite_model(tmp_path):
    """`reach bench` plots every suite model; the thermostat has the single state T."""
    from reach.bench.plots import plot_model_runs

    model = load_model(ROOT / "models" / "thermostat.yaml")
    assert model.state == ["T"]
    target = tmp_path / "thermostat_runs.png"
    plot_model_runs(model, target, runs=4)
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_iss_expected_verdicts_follow_from_the_linear_flow():
    """ISSC01 (270 states, constant inputs as states): y3 = c x is linear in the initial state, so
    at each instant its extremes over the initial polytope are LPs and over the polytope's box a
    closed form (a weaker bound). On a grid of 2001 instants over [0, 20] the box bound stays
    inside |y3| < 5e-4 (ISS02: safe), and one LP at t = 0.5 (where star's witness violates)
    brings y3 below -1.7e-4 (ISU02: unsafe) while the box keeps it above -5e-4."""
    from reach import lp
    from reach.model.constraints import halfspaces
    model, props, _ = load_spaceex(SPACEEX / "SpaceStation/iss_270.xml",
                                   SPACEEX / "SpaceStation/ISSC01-ISU02-forbidden.cfg")
    below = bind(props[1], model).pieces["Model"][0]           # y3 <= -1.7e-4 as c x <= g
    (c,), (g,) = halfspaces(below, model.symbols)
    assert g == pytest.approx(-1.7e-4)
    A, b = model.modes["Model"].linear
    n = len(model.state)
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    step = sl.expm(0.01 * M)
    low, high = model.initial.low, model.initial.high
    row, extremes = np.append(c, 0.0), []
    for _ in range(2001):                                      # row = (c, 0) e^{M t}: y3(t) = row (x0, 1)
        w, w0 = row[:-1], row[-1]
        extremes.append((w0 + np.minimum(w * low, w * high).sum(), w0 + np.maximum(w * low, w * high).sum()))
        row = row @ step
    extremes = np.array(extremes)
    assert -5e-4 < extremes[:, 0].min() and extremes[:, 1].max() < 5e-4
    row = np.append(c, 0.0) @ sl.expm(0.5 * M)
    P = model.initial.polytope
    res = lp.maximize(-row[:-1], P.A, P.b, A_eq=P.E, b_eq=P.f)
    assert res.optimal and -res.value + row[-1] < -1.7e-4
