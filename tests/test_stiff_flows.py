"""Stiff nonlinear flows in the simulator (reach.model.batch_nonlinear, Stability) and in replays
(reach.backends.montecarlo.replays.replay): explicit RK4 past its stability region grows
without bound, which must never make a violation. Held against the closed form of
x' = -1000 (x - 1) (+ y^2, y fixed), whose runs relax monotonically to 1 + y^2 / 1000."""

from __future__ import annotations

import json

import numpy as np
import yaml

import reach.model.batch_nonlinear as batch_nonlinear
import reach.model.simulate as simulate
from reach.backends.montecarlo.replays import replay
from reach.cli import main as cli
from reach.model import load_model
from reach.spec import bind, load_properties


def files(tmp_path, low=1.5, high=2.0, bound=2.5):
    model = {"name": "relax", "state": ["x", "y", "t"], "horizon": 24,
             "modes": {"go": {"flow": {"x": "-1000*(x - 1) + y**2", "y": 0, "t": 1}}},
             "initial": {"mode": "go", "box": {"x": [low, high], "y": [0, 0.01], "t": 0}}}
    props = {"properties": [{"id": "xmax", "kind": "safety", "modes": ["go"], "require": [f"x <= {bound}"]}]}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(props))
    return tmp_path / "m.yaml", tmp_path / "p.yaml"


def test_the_substeps_keep_rk4_stable_on_a_stiff_flow(tmp_path):
    """The Jacobian's spectral radius is 1000 at every state: at the default step 0.01 the
    substeps give h * 1000 <= 1.5, and the simulated runs agree with the closed form."""
    m, _ = files(tmp_path)
    model = load_model(m)
    sim = simulate.Simulator(model)
    assert sim.mode_substeps["go"] >= np.ceil(sim.dt * 1000 / batch_nonlinear.STABLE_STEP)
    x0 = np.array([[1.75, 0.005, 0.0], [2.0, 0.01, 0.0]])
    y = sim.propagate("go", x0, 0.5)
    exact = 1 + x0[:, 1] ** 2 / 1000 + (x0[:, 0] - 1 - x0[:, 1] ** 2 / 1000) * np.exp(-1000 * 0.5)
    assert np.allclose(y[:, 0], exact, rtol=0, atol=1e-9)


def test_monte_carlo_finds_no_violation_a_stiff_flow_does_not_make(tmp_path, capsys):
    """x <= 2.5 from x0 <= 2 holds (x falls to 1): it was UNSAFE, 1000 of 1000 runs, from RK4
    steps of h * 1000 = 5."""
    m, p = files(tmp_path)
    code = cli(["check", str(m), str(p), "-b", "montecarlo", "-o", "samples=200", "-o", "optimise=false", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert code == 3 and row["status"] == "unknown" and row["details"]["violating_runs"] == 0


def test_a_violation_only_the_coarse_integration_makes_does_not_replay(tmp_path, monkeypatch):
    """With the substeps left at 2 (a stiffness the estimates missed), the coarse replay from
    x0 = 1.75 "violates" x <= 2.5 at t = 0.01; a quarter of the step does not, so the replay
    is no violation and says why."""
    m, p = files(tmp_path)
    monkeypatch.setattr(simulate, "jacobian_radius", lambda rhs, X: float("nan"))
    monkeypatch.setattr(simulate.Simulator, "more_substeps", lambda self, mode, *states: False)
    model = load_model(m)
    prop = bind(load_properties(p)[0], model)
    from reach.backends.montecarlo.replays import _replay_simulator, _replay_with
    coarse = _replay_with(model, prop, [1.75, 0.005, 0.0], None, _replay_simulator(model, None, None), None, None)
    assert coarse.violated and coarse.time <= 0.02           # what the unstable steps make
    rep = replay(model, prop, [1.75, 0.005, 0.0], None)
    assert not rep.violated
    assert "comes from the integration of a nonlinear flow" in rep.trajectory["note"]


def test_a_kink_at_a_probe_is_no_stiffness(tmp_path):
    """v' = -sign(v) from v in [-1, 1]: the centre probe sits on the kink, where a difference
    quotient is a jump over the step (1e7), not a rate. The two steps disagree there, so the
    substeps stay at 2 (it asked for 10000, and a run took minutes)."""
    model = {"name": "friction", "state": ["x", "v", "t"], "horizon": 10,
             "modes": {"run": {"flow": {"x": "v", "v": "-sign(v)", "t": 1}}},
             "initial": {"mode": "run", "box": {"x": [0, 1], "v": [-1, 1], "t": 0}}}
    (tmp_path / "k.yaml").write_text(yaml.safe_dump(model))
    assert simulate.Simulator(load_model(tmp_path / "k.yaml")).mode_substeps == {"run": 2}


def stiffening(tmp_path, bound: float, horizon: float = 1.0):
    """x tracks 1 + z at the rate 20000 y, y = z = t: the Jacobian's spectral radius 20000 t is 0
    where the runs start and grows along them, past RK4's stability at the default steps."""
    model = {"name": "stiffening", "state": ["x", "y", "z"], "horizon": horizon,
             "modes": {"m": {"flow": {"x": "-20000*y*tanh(x - 1 - z)", "y": 1, "z": 1}}},
             "initial": {"mode": "m", "box": {"x": [1.5, 2], "y": [0, 0], "z": [0, 0]}}}
    props = {"properties": [{"id": "lag", "kind": "safety", "modes": ["m"], "require": [f"x - z >= {bound}"]}]}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "sp.yaml").write_text(yaml.safe_dump(props))
    return tmp_path / "s.yaml", tmp_path / "sp.yaml"


def stiff_reference_minimum(x0: float, horizon: float = 1.0) -> float:
    """min over [0, horizon] of x - z by an implicit integrator (Radau, rtol 1e-10)."""
    from scipy.integrate import solve_ivp
    sol = solve_ivp(lambda t, s: [-20000 * s[1] * np.tanh(s[0] - 1 - s[2]), 1, 1], (0, horizon), [x0, 0, 0],
                    method="Radau", rtol=1e-10, atol=1e-12, dense_output=True)
    grid = sol.sol(np.linspace(0, horizon, 20001))
    return float((grid[0] - grid[2]).min())


def test_substeps_follow_a_flow_that_stiffens_along_its_runs(tmp_path, capsys):
    """Set from the initial states alone, RK4 took 2 substeps, went unstable from t ~ 0.3 and
    ended near x - z = -3: an UNSAFE of x - z >= 0.9 (1000 of 1000 runs, replayed). The
    Jacobian is now looked at along the runs: the closest margin is the implicit integrator's."""
    m, p = stiffening(tmp_path, 0.9)
    exact = min(stiff_reference_minimum(x0) for x0 in (1.5, 2.0))
    assert 0.998 < exact < 0.999
    code = cli(["check", str(m), str(p), "-b", "montecarlo", "-o", "samples=60", "-o", "optimise=false", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert code == 3 and row["details"]["violating_runs"] == 0
    assert abs(row["report"]["closest_margin"] - (exact - 0.9)) < 1e-4


def test_a_replay_takes_the_substeps_its_own_states_ask_for(tmp_path, monkeypatch):
    """With the online look at the Jacobian switched off, the coarse replay and its quarter
    step both go unstable and "violate" x - z >= 0.9 (the true minimum is 0.9984); the finer
    run's substeps are then set from the states it visited, and it holds."""
    m, p = stiffening(tmp_path, 0.9, horizon=2.0)
    monkeypatch.setattr(simulate.Simulator, "more_substeps", lambda self, mode, *states: False)
    model = load_model(m)
    prop = bind(load_properties(p)[0], model)
    from reach.backends.montecarlo.replays import _replay_simulator, _replay_with
    for factor in (1, 4):
        sim = _replay_simulator(model, simulate.default_dt(model) / factor, None)
        assert _replay_with(model, prop, [2.0, 0.0, 0.0], None, sim, None, None).violated
    rep = replay(model, prop, [2.0, 0.0, 0.0], None)
    assert not rep.violated and rep.depth > 0.09
    assert "comes from the integration of a nonlinear flow" in rep.trajectory["note"]


def test_a_mode_too_stiff_for_rk4_is_not_integrated(tmp_path, capsys):
    """x' = -1e12 x: stable RK4 steps would need 1e9 substeps per grid step. The runs are not
    integrated at the 1000-substep cap (minutes, past the time budget, and unstable still): they
    are NaN at once and the result names the mode and a step that takes it."""
    model = {"name": "rigid", "state": ["x", "y"], "horizon": 10,
             "modes": {"a": {"flow": {"x": "-1e12*x + 0.001*x**2", "y": 1}}},
             "initial": {"mode": "a", "box": {"x": [0.5, 1], "y": [0, 0]}}}
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "rp.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "yb", "kind": "safety", "modes": ["a"], "require": ["y <= 5"]}]}))
    sim = simulate.Simulator(load_model(tmp_path / "r.yaml"))
    assert set(sim.too_stiff) == {"a"} and np.isnan(sim.propagate("a", np.array([[1.0, 0.0]]), sim.dt)).all()
    code = cli(["check", str(tmp_path / "r.yaml"), str(tmp_path / "rp.yaml"), "-b", "montecarlo", "--json"])
    (row,) = json.loads(capsys.readouterr().out)
    assert code == 3 and row["seconds"] < 30 and "mode 'a' is too stiff for RK4" in row["details"]["undefined"]
