"""The simulator's urgent-transition instants against independent crossing times, on three models.

* a bouncing ball (``x'' = -g``, urgent ``x <= 0, v <= 0`` with ``v := -0.5 v``), linear: the
  impacts in closed form, ``t_1 = (v_0 + s_0) / g`` with ``s_0 = sqrt(v_0^2 + 2 g x_0)``, then
  ``t_(k+1) = t_k + 2 (0.5^k s_0) / g``;
* SRA01 (ARCH, linear CWH with the mode-1 LQR): the docking instant, where ``x`` reaches
  ``-100`` m, as the root of ``[expm(A_cl t) x_0]_1 + 100`` (brentq);
* SRNA01 (the nonlinear orbital dynamics, simulated by RK4): the same instant from ``solve_ivp``
  (DOP853) with a terminal event on the equations of motion written out here.

The grid step is 1/2400 of the horizon (0.1 min, 1.04 ms), so an instant taken at a grid point
instead of the guard's first point would be off by up to a step; the bisection locates it to
``dt 2^-40``.
"""

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from arch import A_CL1, K1, MC, docking_event
from reach.model import load_model
from reach.model.simulate import Simulator

G, RESTITUTION, HORIZON = 9.81, 0.5, 2.5
BALL = f"""name: ball
description: a ball dropped near the floor, bouncing with restitution {RESTITUTION}
units: {{length: m, time: s, mass: kg}}
constants: {{g: {G}}}
state: [x, v]
modes:
  fall:
    flow: {{x: v, v: -g}}
transitions:
  bounce:
    from: fall
    to: fall
    urgent: true
    guard: ["x <= 0", "v <= 0"]
    reset: {{v: "-{RESTITUTION}*v"}}
initial:
  mode: fall
  box: {{x: [5, 10], v: [-2, 2]}}
horizon: {HORIZON}
"""

MU, R = 3.986e14 * 3600.0, 42164e3        # m^3/min^2, m


def orbital(t, s):
    """Eq. (1) of the rendezvous benchmark with the mode-1 gain, in metres and minutes."""
    x, y, vx, vy = s
    F = K1 @ s
    n2 = MU / R ** 3
    rc3 = ((R + x) ** 2 + y ** 2) ** 1.5
    return [vx, vy, n2 * x + 2 * np.sqrt(n2) * vy + MU / R ** 2 - MU / rc3 * (R + x) + F[0] / MC,
            n2 * y - 2 * np.sqrt(n2) * vx - MU / rc3 * y + F[1] / MC]


def first_switch(path):
    """Instant and states of the first change of mode along a recorded path."""
    t, mode, X = path
    j = int(np.flatnonzero(np.diff(mode) != 0)[0]) + 1
    assert t[j - 1] == t[j]                 # the event is seen before and after the jump
    return t[j], X[j - 1], X[j]


@given(x0=st.floats(5.0, 10.0), v0=st.floats(-2.0, 2.0))
@settings(max_examples=25)
def test_every_bounce_of_a_ball_at_its_closed_form_instant(tmp_path_factory, x0, v0):
    """Drops from 5-10 m: the bounces accumulate at ``(v_0 + 3 s_0) / g > 2.8`` s, after the
    horizon, so every run has finitely many."""
    path = tmp_path_factory.mktemp("ball") / "ball.yaml"
    path.write_text(BALL)
    sim = Simulator(load_model(path))
    t, _, X = sim.run(np.array([[x0, v0]]), record=True).path[0]
    # impacts: the recorded instant repeats, with the velocity flipped
    hits = [k for k in range(1, len(t)) if t[k] == t[k - 1] and X[k - 1, 1] < 0 < X[k, 1]]
    s = np.sqrt(v0 * v0 + 2 * G * x0)
    expected = [(v0 + s) / G]
    while expected[-1] + 2 * s * RESTITUTION ** len(expected) / G < HORIZON - 1e-3:
        expected.append(expected[-1] + 2 * s * RESTITUTION ** len(expected) / G)
    assert len(hits) >= len(expected) >= 1
    np.testing.assert_allclose(t[hits[:len(expected)]], expected, atol=1e-9)
    np.testing.assert_allclose(X[hits[:len(expected)], 0], 0.0, atol=1e-9)


INITIAL = [[-925.0, -425.0], [-880.0, -390.0], [-910.0, -380.0]]


def test_docking_instant_of_the_linear_arch_model():
    sim = Simulator(load_model("models/SRA01.yaml"))
    x0 = np.array([[x, y, 0.0, 0.0, 0.0] for x, y in INITIAL])
    traj = sim.run(x0, np.full(len(x0), 120.0), record=True)
    for i, start in enumerate(x0[:, :4]):
        when, before, after = first_switch(traj.path[i])
        truth = brentq(lambda t: (scipy.linalg.expm(A_CL1 * t) @ start)[0] + 100.0, 50.0, 120.0, xtol=1e-12)
        assert when == pytest.approx(truth, abs=1e-6)
        assert before[0] == pytest.approx(-100.0, abs=1e-6) and after[0] == pytest.approx(-100.0, abs=1e-6)


def test_docking_instant_of_the_nonlinear_arch_model():
    sim = Simulator(load_model("models/SRNA01.yaml"))
    x0 = np.array([[x, y, 0.0, 0.0, 0.0] for x, y in INITIAL])
    traj = sim.run(x0, record=True)
    for i, start in enumerate(x0[:, :4]):
        when, before, _ = first_switch(traj.path[i])
        sol = solve_ivp(orbital, [0, 200], start, method="DOP853", events=docking_event, rtol=1e-12, atol=1e-10)
        assert when == pytest.approx(sol.t_events[0][0], abs=1e-6)
        np.testing.assert_allclose(before[:2], sol.y_events[0][0][:2], atol=1e-4)


def test_runs_that_start_inside_a_guard_jump_at_once(tmp_path):
    """At t = 0, on the guard's boundary (x = 0, v < 0) and inside it, a ball launched by
    ``v := 5`` jumps at once; above the floor it does not. Several runs in one call; the
    horizon (0.5 s) ends before any later bounce (the flight lasts 2 * 5 / g = 1.02 s). The
    initial state is watched, then the state after the jump, both at t = 0."""
    path = tmp_path / "launch.yaml"
    path.write_text(BALL.replace('"-0.5*v"', '"5"').replace("horizon: 2.5", "horizon: 0.5"))
    sim = Simulator(load_model(path))
    x0 = np.array([[0.0, -1.0], [1.0, 0.0], [-0.5, -2.0], [6.0, -1.0]])
    traj = sim.run(x0, record=True)
    at_start = np.array([traj.path[i][2][traj.path[i][0] == 0.0][-1] for i in range(len(x0))])
    np.testing.assert_array_equal(at_start[:, 1], [5.0, 0.0, 5.0, -1.0])
    assert all(np.array_equal(traj.path[i][2][0], x0[i]) for i in range(len(x0)))
    assert traj.transitions == {0: ["bounce"], 1: ["bounce"], 2: ["bounce"], 3: []}   # 1 lands at 0.45 s
    np.testing.assert_allclose(traj.final_state[[0, 2], 1], 5.0 - G * 0.5)


def test_urgent_transitions_chain_at_the_same_instant(tmp_path):
    """``a -> b -> c`` with guards that already hold: the run passes through ``b`` and is in ``c``
    at t = 0, and its clock then runs from there (``x = 0.5 + t``)."""
    path = tmp_path / "chain.yaml"
    path.write_text("name: chain\nstate: [x]\n"
                    "modes: {a: {flow: {x: 1}}, b: {flow: {x: 1}}, c: {flow: {x: 1}}}\n"
                    "transitions:\n"
                    "  ab: {from: a, to: b, urgent: true, guard: ['x >= 0']}\n"
                    "  bc: {from: b, to: c, urgent: true, guard: ['x >= 0']}\n"
                    "initial: {mode: a, box: {x: 0.5}}\nhorizon: 1\n")
    model = load_model(path)
    traj = Simulator(model).run(np.array([[0.5], [0.5]]), record=True)
    c = list(model.modes).index("c")
    assert list(traj.final_mode) == [c, c]
    t, mode, X = traj.path[0]
    assert [list(model.modes)[m] for m in mode[:3]] == ["a", "b", "c"] and np.all(t[:3] == 0.0)
    assert traj.transitions[0] == ["ab", "bc"]
    np.testing.assert_allclose(traj.final_state[:, 0], 1.5)


@pytest.mark.parametrize("y0,jumps", [(-5e-5, False), (-1e-13, True), (0.0, True)])
def test_a_slab_crossed_between_grid_points_checks_its_other_rows_at_their_own_scale(tmp_path, y0, jumps):
    """``x == 1 & y >= 0`` (urgent), crossed by ``x' = 1`` between two grid points, with a state
    ``big = 1e7`` that no row of the guard reads: ``y = -5e-5`` misses the guard (a tolerance
    scaled by the whole state, 1e-11 (1 + 1e7) = 1e-4, took it for ``y >= 0``), ``y`` within
    the row's own tolerance (1e-11) or on it meets the guard at ``t = 1``."""
    path = tmp_path / "slab.yaml"
    path.write_text("name: slab\nstate: [x, y, big]\n"
                    "modes: {go: {flow: {x: 1, y: 0, big: 0}}, bad: {flow: {x: 0, y: 0, big: 0}}}\n"
                    "transitions:\n"
                    "  in: {from: go, to: bad, urgent: true, guard: ['x == 1', 'y >= 0']}\n"
                    f"initial: {{mode: go, box: {{x: 0, y: {y0}, big: 1e7}}}}\nhorizon: 3\n")
    traj = Simulator(load_model(path)).run(np.array([[0.0, y0, 1e7]]), record=True)
    assert traj.transitions[0] == (["in"] if jumps else [])
    if jumps:
        t, mode, X = traj.path[0]
        assert t[np.flatnonzero(mode == 1)[0]] == pytest.approx(1.0, abs=1e-9)
