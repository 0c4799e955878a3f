"""VTXO formation models (seed 001): the sliding-mode automaton against its linear inner loop and
a solve_ivp reference, fsr against a sampler written here, and the SMC/PD ordering."""

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from reach.backends import fsr, montecarlo
from reach.backends.base import run
from reach.model.loader import load_model
from reach.model.simulate import Simulator
from reach.result import Status
from reach.spec.properties import bind, load_properties
from reach.stats import wilson

SMC = "models/vtxo_formation_smc.yaml"
LAYER = "models/vtxo_formation_smc_layer.yaml"
PD = "models/vtxo_formation_pd.yaml"
PROPS = "properties/vtxo_formation.yaml"


@pytest.fixture(scope="module")
def models():
    import os
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    old = os.getcwd()
    os.chdir(root)
    try:
        return {"smc": load_model(SMC), "layer": load_model(LAYER), "pd": load_model(PD)}
    finally:
        os.chdir(old)


def prop(model, pid, path=PROPS):
    return next(bind(p, model) for p in load_properties(path) if p.id == pid)


# ----------------------------------------------------------------- the closed loops, by hand

def inner_loop(c):
    """Closed loop inside the layer, derived on paper: e'' = -2 lam e' - lam^2 e per axis
    (the model term cancels the gravity gradient; K/phi = lam), e = rho - (0, 0, L)."""
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    for i, lam in enumerate((c["lam_t"], c["lam_t"], c["lam_z"])):
        A[3 + i, i] = -c["K"] * lam / ({0: c["phi_t"], 1: c["phi_t"], 2: c["phi_z"]}[i])
        A[3 + i, 3 + i] = -lam - c["K"] / ({0: c["phi_t"], 1: c["phi_t"], 2: c["phi_z"]}[i])
    b = -A[:, 2] * c["L"]
    return A, b


def pd_loop(c):
    """PD closed loop with the frozen gravity gradient diag(2, -1, -1) gg left in."""
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    for i, g in enumerate((2.0, -1.0, -1.0)):
        A[3 + i, i] = g * c["gg"] - c["kp_pd"]
        A[3 + i, 3 + i] = -c["kd_pd"]
    b = np.zeros(6)
    b[5] = c["kp_pd"] * c["L"]
    return A, b


def kick_cov(c, kp_t, kp_z):
    force = (c["sig_dist"] ** 2 + c["sig_thr"] ** 2) / c["msc"] ** 2
    return np.diag([force + (kp_t * c["sig_ifm"]) ** 2, force + (kp_t * c["sig_ifm"]) ** 2,
                    force + (kp_z * c["sig_rr"]) ** 2]) * c["dt"] ** 2


def smc_rhs(c):
    """The piecewise ODE of eqs. 64-67 with sat = clip (independent of the automaton)."""
    lam = np.array([c["lam_t"], c["lam_t"], c["lam_z"]])
    phi = np.array([c["phi_t"], c["phi_t"], c["phi_z"]])
    G = c["gg"] * np.array([2.0, -1.0, -1.0])
    ref = np.array([0.0, 0.0, c["L"]])

    def rhs(t, s):
        r, v = s[:3], s[3:]
        surface = v + lam * (r - ref)
        u = -G * r - lam * v - c["K"] * np.clip(surface / phi, -1.0, 1.0)
        return np.concatenate([v, G * r + u])

    return rhs, lam, phi, ref


# ----------------------------------------------------------------- tests

def test_design_numbers_follow_the_stated_rules(models):
    c = models["smc"].constants
    # r_w: leader radius 5 h from apogee (Kepler's equation, Table 9 elements)
    n = np.sqrt(c["mu"] / c["a_l"] ** 3)
    M = np.pi + n * 5 * 3600.0
    E = M
    for _ in range(60):
        E -= (E - c["e_l"] * np.sin(E) - M) / (1 - c["e_l"] * np.cos(E))
    assert c["r_w"] == pytest.approx(c["a_l"] * (1 - c["e_l"] * np.cos(E)), rel=1e-5)
    # balance condition K/phi = lam and precision phi/lam = eps (Slotine's boundary layer)
    assert c["K"] / c["phi_t"] == pytest.approx(c["lam_t"])
    assert c["phi_t"] / c["lam_t"] == pytest.approx(1e-3 / np.sqrt(2))
    assert c["phi_z"] / c["lam_z"] == pytest.approx(1.0)
    # gravity-gradient entries are tiny against both closed-loop stiffnesses
    assert 3.5e-9 < 1e-3 * c["kp_pd"] and c["kp_pd"] < c["lam_t"] ** 2


def test_inside_layer_flow_is_the_linear_closed_loop(models):
    A, b = inner_loop(models["smc"].constants)
    for name in ("smc", "layer"):
        A_m, b_m = models[name].modes["in_in_in"].linear
        np.testing.assert_allclose(A_m, A, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(b_m, b, rtol=1e-9, atol=1e-15)
    A_pd, b_pd = models["pd"].modes["pd"].linear
    np.testing.assert_allclose(A_pd, pd_loop(models["pd"].constants)[0], rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(b_pd, pd_loop(models["pd"].constants)[1], rtol=1e-9, atol=1e-15)
    # every mode's flow is the clip law wherever the mode's invariant holds
    rhs, lam, phi, ref = smc_rhs(models["smc"].constants)
    rng = np.random.default_rng(3)
    X = np.tile(ref, (4000, 2)) * np.r_[np.ones(3), np.zeros(3)]
    X[:, :3] += rng.normal(size=(4000, 3)) * np.array([2e-3, 2e-3, 3.0])
    X[:, 3:] += rng.normal(size=(4000, 3)) * np.array([1e-4, 1e-4, 5e-3])
    seen = set()
    for name, mode in models["smc"].modes.items():
        inside = np.all(mode.invariant_margins(X) <= 0, axis=1)
        if not inside.any():
            continue
        seen.add(name)
        want = np.array([rhs(0.0, x) for x in X[inside]])
        np.testing.assert_allclose(mode.rhs(X[inside]), want, rtol=1e-9, atol=1e-15)
    assert len(seen) >= 20


def test_saturation_switches_at_the_layer_and_matches_solve_ivp(models):
    model = models["smc"]
    c = model.constants
    rhs, lam, phi, ref = smc_rhs(c)
    x0 = np.array([5e-3, -3e-3, c["L"] + 1.5, 0.0, 0.0, 0.0])
    names = list(model.modes)
    # the run starts in the mode whose invariant holds at x0 (saturated on every axis)
    start, = [m for m in names if np.all(model.modes[m].invariant_margins(x0[None, :]) <= 0)]
    saved = model.horizon, model.initial.mode
    model.horizon, model.initial.mode = 400.0, start
    try:
        sim = Simulator(model)
        traj = sim.run(x0[None, :], record=True)
    finally:
        model.horizon, model.initial.mode = saved
    t, modes, X = traj.path[0]
    # the switches happen where s/phi = +-1
    changes = np.flatnonzero(modes[1:] != modes[:-1])
    assert changes.size >= 3                                    # x, y and z each enter the layer
    for j in changes:
        s = (X[j, 3:] + lam * (X[j, :3] - ref)) / phi
        before, after = names[modes[j]].split("_"), names[modes[j + 1]].split("_")
        axis = next(i for i in range(3) if before[i] != after[i])
        assert abs(abs(s[axis]) - 1.0) < 1e-6
    assert names[modes[-1]] == "in_in_in"
    # the same piecewise ODE by solve_ivp, with its own switching events
    events = []
    for i in range(3):
        for sign in (1.0, -1.0):
            ev = (lambda i, sign: lambda tt, s: s[3 + i] + lam[i] * (s[i] - ref[i]) - sign * phi[i])(i, sign)
            events.append(ev)
    ref_sol = solve_ivp(rhs, (0.0, 400.0), x0, method="DOP853", rtol=1e-12, atol=1e-15,
                        dense_output=True, events=events)
    switch_ref = np.sort(np.concatenate([e for e in ref_sol.t_events if e.size]))
    switch_sim = np.sort(t[changes])
    assert switch_sim.size == switch_ref.size
    np.testing.assert_allclose(switch_sim, switch_ref, atol=1e-3)
    want = ref_sol.sol(t).T
    err = np.abs(X - want)
    scale = np.array([1e-3, 1e-3, 1.0, 1e-4, 1e-4, 1e-2])
    assert np.max(err / scale) < 1e-6


def _sampler(A, b, cov, x0, steps, dt, samples, rng, ok, every=True):
    """Own loop: x <- expm(A dt) (x + E w) + c; ``ok(X)`` at every kick instant and at the end
    (``every``), or at the end only."""
    M = np.zeros((7, 7))
    M[:6, :6], M[:6, 6] = A, b
    E = scipy.linalg.expm(M * dt)
    Phi, c = E[:6, :6], E[:6, 6]
    X = np.tile(x0, (samples, 1))
    good = ok(X) if every else np.ones(samples, bool)
    chol = np.linalg.cholesky(cov)
    for _ in range(steps):
        X[:, 3:] += rng.normal(size=(samples, 3)) @ chol.T
        X = X @ Phi.T + c
        if every:
            good &= ok(X)
    return good if every else ok(X)


def _final_ok(*args):
    return _sampler(*args, every=False)


def _octagon(half):
    def ok(X):
        x, y = X[:, 0], X[:, 1]
        d = np.sqrt(2) * half
        return ((np.abs(x) <= half) & (np.abs(y) <= half) & (np.abs(x + y) <= d) & (np.abs(x - y) <= d)
                & (X[:, 2] >= 999.0) & (X[:, 2] <= 1000.999))
    return ok


def _property_file(tmp_path, half_mm, at, kind):
    text = f"""properties:
  - id: p
    kind: {kind}
    at: "{at}[s]"
    target: &s ["x <= {half_mm}[mm]", "x >= -{half_mm}[mm]", "y <= {half_mm}[mm]", "y >= -{half_mm}[mm]",
                "x + y <= sqrt(2)*{half_mm}[mm]", "x + y >= -sqrt(2)*{half_mm}[mm]",
                "x - y <= sqrt(2)*{half_mm}[mm]", "x - y >= -sqrt(2)*{half_mm}[mm]",
                "z >= 999[m]", "z <= 1000.999[m]"]
"""
    if kind == "reach_avoid":
        text += "    safe: *s\n"
    path = tmp_path / f"{kind}.yaml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("which, half_mm, at, kind", [
    ("pd", 0.9239, 1800, "reach"),             # the PD at a time: P ~ 0.04
    ("layer", 0.02, 60, "reach_avoid"),        # the SMC inner loop over 1 min, a 0.02 mm octagon
])
def test_fsr_against_an_independent_sampler(models, tmp_path, which, half_mm, at, kind):
    model = models[which]
    c = model.constants
    A, b = pd_loop(c) if which == "pd" else inner_loop(c)
    kp_t, kp_z = (c["kp_pd"], c["kp_pd"]) if which == "pd" else (c["lam_t"] ** 2, c["lam_z"] ** 2)
    p = prop(model, "p", _property_file(tmp_path, half_mm, at, kind))
    result = run(fsr.BACKEND, model, p, {"abs_error": 2e-3})
    lo, hi = result.probability
    samples = 6000
    sample = _final_ok if kind == "reach" else _sampler
    good = sample(A, b, kick_cov(c, kp_t, kp_z), model.initial.low, int(at), c["dt"], samples,
                  np.random.default_rng(11), _octagon(half_mm * 1e-3))
    s_lo, s_hi = wilson(int(good.sum()), samples, 0.999)
    assert 0.02 < good.mean() < 0.98                       # a probability that can be wrong
    assert s_lo <= hi and lo <= s_hi, (result.probability, (s_lo, s_hi))
    assert hi - lo < 0.02


def test_row_cap_keeps_an_honest_interval(models, tmp_path):
    model = models["layer"]
    p = prop(model, "p", _property_file(tmp_path, 0.02, 60, "reach_avoid"))
    problem = fsr.GaussianProblem.from_model(model, 60.0)
    from reach.model.constraints import halfspaces
    target, safe = halfspaces(p.target, p.symbols), halfspaces(p.safe, p.symbols)
    full, info_full = fsr.reach_avoid(problem, target, safe, abs_error=2e-3, max_rows=None)
    capped, info = fsr.reach_avoid(problem, target, safe, abs_error=2e-3, max_rows=20)
    assert info["kept"] <= 20 < info_full["kept"] and info["capped"] > 0
    assert capped.low <= full.high and full.low <= capped.high
    assert capped.high >= full.low        # fewer constraints: still an upper bound
    assert capped.width > full.width       # and the cut rows widen the interval downwards


def test_smc_meets_the_requirement_and_pd_does_not(models):
    smc, pd = models["smc"], models["pd"]
    r_smc = run(fsr.BACKEND, smc, prop(smc, "alignment_window"))
    r_pd = run(fsr.BACKEND, pd, prop(pd, "alignment_window"), {"max_rows": 100})
    assert r_smc.status == Status.SAFE and r_smc.probability[0] >= 0.99
    assert r_smc.details["stay"]["leave_bound"] < 1e-6
    assert r_pd.status == Status.UNKNOWN and r_pd.details["verdict"] == "violated"
    assert r_pd.probability[1] < r_smc.probability[0]
    # per-time reading: the PD is inside the octagon a few per cent of the time
    end = run(fsr.BACKEND, pd, prop(pd, "alignment_at_end"))
    assert end.probability[1] < 0.2


def test_monte_carlo_ordering_on_the_switched_model(models, tmp_path):
    path = _property_file(tmp_path, 0.9239, 300, "reach_avoid")
    smc, pd = models["smc"], models["pd"]
    r_smc = run(montecarlo.BACKEND, smc, prop(smc, "p", path), {"samples": 40})
    r_pd = run(montecarlo.BACKEND, pd, prop(pd, "p", path), {"samples": 200})
    assert r_smc.status == Status.UNKNOWN and r_pd.status == Status.UNKNOWN   # sampling never says SAFE
    assert r_pd.probability[1] < r_smc.probability[0]
