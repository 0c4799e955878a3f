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
