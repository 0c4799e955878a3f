"""A Zeno run ends: a bouncing ball with restitution 0.8 takes infinitely many bounces before the
accumulation instant t* (closed form); the simulator stops it there, counted as blocked."""

import math

import numpy as np
import yaml

from reach.model import load_model
from reach.model.simulate import Simulator

G, E, X0, V0 = 9.81, 0.8, 0.05, -2.0


def accumulation_time() -> float:
    """First impact t1 from x0 + v0 t - g t^2 / 2 = 0, then flights 2 e^k |v1| / g, k >= 1."""
    t1 = (V0 + math.sqrt(V0 ** 2 + 2 * G * X0)) / G
    v1 = abs(V0 - G * t1)
    return t1 + 2 * E * v1 / G / (1 - E)


def test_a_zeno_ball_stops_at_its_accumulation_instant(tmp_path):
    doc = {"name": "zeno_ball", "state": ["x", "v"], "horizon": 3,
           "modes": {"fly": {"flow": {"x": "v", "v": -G}, "invariant": ["x >= 0"]}},
           "transitions": [{"from": "fly", "to": "fly", "guard": ["x <= 0", "v <= 0"],
                            "reset": {"v": f"-{E}*v"}, "urgent": True}],
           "initial": {"mode": "fly", "box": {"x": X0, "v": V0}}}
    (tmp_path / "ball.yaml").write_text(yaml.safe_dump(doc))
    sim = Simulator(load_model(tmp_path / "ball.yaml"))
    traj = sim.run(np.array([[X0, V0]]))
    t_star = accumulation_time()
    assert 0.3 < t_star < 3.0
    assert t_star - 3 * sim.dt <= traj.blocked_at[0] <= t_star + 1e-9
    # a ball that loses no energy is not Zeno: it runs to the horizon
    doc["transitions"][0]["reset"] = {"v": "-v"}
    (tmp_path / "elastic.yaml").write_text(yaml.safe_dump(doc))
    assert np.isnan(Simulator(load_model(tmp_path / "elastic.yaml")).run(np.array([[X0, V0]])).blocked_at[0])


def _counter(tmp_path, tick: dict, horizon: float, name: str = "counter"):
    """A counter: ``tick`` adds one to n and restarts the clock c at once (urgent, no guard);
    ``wait`` lets c run to 1 and hands back to ``tick``. n = k + 1 on (k, k + 1)."""
    doc = {"name": name, "state": ["n", "c"], "horizon": horizon,
           "modes": {"tick": tick, "wait": {"flow": {"n": 0, "c": 1}, "invariant": ["c <= 1"]}},
           "transitions": [{"from": "tick", "to": "wait", "reset": {"n": "n + 1", "c": 0}, "urgent": True},
                           {"from": "wait", "to": "tick", "guard": ["c >= 1"], "urgent": True}],
           "initial": {"mode": "tick", "box": {"n": 0, "c": 0}}}
    (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(doc))
    return load_model(tmp_path / f"{name}.yaml")


def test_a_counter_passes_again_and_again_through_a_mode_where_no_time_passes(tmp_path):
    """Each pass through ``tick`` comes back at one instant to ``wait``, the mode the run just
    left, in another state (n one higher, c = 0): a jump that changes the state, not a Zeno
    cycle. Closed form: n = 6 on (5, 5.5], with the run never blocked, whether ``tick`` is
    timeless (SpaceEx ``flow false``) or has zero rates."""
    for tick in ({"flow": False}, {"flow": {"n": 0, "c": 0}}):
        sim = Simulator(_counter(tmp_path, tick, 5.5))
        traj = sim.run(np.array([[0.0, 0.0]]))
        assert np.isnan(traj.blocked_at[0])
        assert traj.final_state[0, 0] == 6.0 and abs(traj.final_state[0, 1] - 0.5) < 1e-9


def test_jumps_at_one_instant_that_never_repeat_a_state_end_as_zeno(tmp_path):
    """Two modes where no time passes hand a run back and forth, n one higher each time:
    infinitely many jumps at t = 0. The run is blocked there, after MAX_JUMPS_AT_INSTANT."""
    from reach.model.simulate import MAX_JUMPS_AT_INSTANT
    doc = {"name": "spin", "state": ["n"], "horizon": 1,
           "modes": {"a": {"flow": False}, "b": {"flow": False}},
           "transitions": [{"from": "a", "to": "b", "reset": {"n": "n + 1"}},
                           {"from": "b", "to": "a", "reset": {"n": "n + 1"}}],
           "initial": {"mode": "a", "box": {"n": 0}}}
    (tmp_path / "spin.yaml").write_text(yaml.safe_dump(doc))
    traj = Simulator(load_model(tmp_path / "spin.yaml")).run(np.array([[0.0]]))
    assert traj.blocked_at[0] == 0.0 and traj.final_state[0, 0] == MAX_JUMPS_AT_INSTANT


def test_an_equality_guard_on_the_invariant_boundary_is_taken_there(tmp_path):
    """SpaceEx's ``x == 2`` (imported as ``x >= 2, x <= 2``) out of ``x <= 2`` (urgent): the guard holds only at the instant the
    run reaches the boundary, at no grid point. A sawtooth x' = 1 from x0, reset x := x - 1 at
    x = 2: closed form x(T) = 1 + frac(x0 - 1 + T) for x0 in [1, 2), with floor(x0 - 1 + T)
    jumps; no run is blocked, on the block path or the general one, nor with zero-rate modes
    between (a timeless mode ``hold`` with an equality guard ``y == 0``)."""
    doc = {"name": "saw", "state": ["x", "y"], "horizon": 4.3,
           "modes": {"up": {"flow": {"x": 1, "y": 0}, "invariant": ["x <= 2"]},
                     "hold": {"flow": False}},
           "transitions": [{"from": "up", "to": "hold", "guard": ["x >= 2", "x <= 2"], "urgent": True},
                           {"from": "hold", "to": "up", "guard": ["y >= 0", "y <= 0"], "reset": {"x": "x - 1"},
                            "urgent": True}],
           "initial": {"mode": "up", "box": {"x": [1, 1.9], "y": 0}}}
    (tmp_path / "saw.yaml").write_text(yaml.safe_dump(doc))
    model = load_model(tmp_path / "saw.yaml")
    x0 = np.linspace(1.0, 1.9, 7)
    for general in (False, True):
        sim = Simulator(model)
        if general:
            sim.tables = dict.fromkeys(model.modes)
        traj = sim.run(np.column_stack([x0, np.zeros_like(x0)]))
        assert np.all(np.isnan(traj.blocked_at))
        expected = 1.0 + np.mod(x0 - 1.0 + 4.3, 1.0)
        np.testing.assert_allclose(traj.final_state[:, 0], expected, atol=1e-6)


def test_a_deadline_stops_the_runs_under_way_where_they_are(tmp_path):
    """A ``deadline`` already past: every run stops at its start, counted as blocked and cut;
    none given: they run to the horizon."""
    import time

    path = tmp_path / "m.yaml"
    path.write_text("name: d\nstate: [x]\nmodes: {a: {flow: {x: 1}, invariant: ['x <= 100']}}\ninitial: {mode: a, box: {x: [0, 1]}}\n"
                    "horizon: 2\n")
    sim = Simulator(load_model(path))
    X = np.array([[0.0], [0.5], [1.0]])
    stopped = sim.run(X, deadline=time.time() - 1.0)
    assert stopped.cut == 3 and np.all(stopped.blocked_at == 0.0) and np.array_equal(stopped.final_state, X)
    free = sim.run(X)
    assert free.cut == 0 and np.all(np.isnan(free.blocked_at)) and np.allclose(free.final_state, X + 2.0)
