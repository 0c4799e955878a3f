"""Dynamics against independent references: the CWH closed form, solve_ivp, the ARCH matrices,
and LQR gains against an independent Riccati solve."""

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from reach.model import load_model
from reach.model.simulate import Simulator

# ARCH closed-loop rows for (vx', vy') in [x, y, vx, vy] (../shared/ANCHORS.md)
ARCH_MODE1 = [[-0.057599765881773, 0.000200959896519766, -2.89995083970656, 0.00877200894463775],
              [-0.000174031357370456, -0.0665123984901026, -0.00875351105536225, -2.90300269286856]]
ARCH_MODE2 = [[-0.575999943070835, 0.000262486079431672, -19.2299795908647, 0.00876275931760007],
              [-0.000262486080737868, -0.575999940191886, -0.00876276068239993, -19.2299765959399]]
ARCH_PASSIVE = [[0.0000575894721132, 0, 0, 0.00876276], [0, 0, -0.00876276, 0]]


def cwh_closed_form(x0, n, t):
    """Clohessy-Wiltshire solution of the planar CWH equations (x radial, y along-track)."""
    x, y, vx, vy = x0
    c, s = np.cos(n * t), np.sin(n * t)
    return np.array([
        (4 - 3 * c) * x + s / n * vx + 2 / n * (1 - c) * vy,
        6 * (s - n * t) * x + y - 2 / n * (1 - c) * vx + (4 * s - 3 * n * t) / n * vy,
        3 * n * s * x + c * vx + 2 * s * vy,
        -6 * n * (1 - c) * x - 2 * s * vx + (4 * c - 3) * vy,
    ])


def test_closed_loop_matrices_equal_the_arch_ones():
    model = load_model("models/SRA02.yaml")
    for mode, rows in [("approach", ARCH_MODE1), ("rendezvous", ARCH_MODE2), ("passive", ARCH_PASSIVE)]:
        A, b = model.modes[mode].linear
        np.testing.assert_allclose(A[2:4, :4], rows, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(A[:2, 2:4], np.eye(2))
        assert b[4] == 1.0 and np.all(b[:4] == 0)


def test_passive_flow_matches_the_cwh_closed_form_and_solve_ivp():
    model = load_model("models/SRA08.yaml")            # abort window [0, 240]: passive from t = 0
    x0 = np.array([-900.0, -400.0, 1.3, -0.7, 0.0])
    traj = Simulator(model).run(x0[None], np.array([0.0]), record=True)
    t, modes, states = traj.path[0]
    assert set(modes[t > 0]) == {list(model.modes).index("passive")}
    n = model.constants["n"]
    exact = cwh_closed_form(x0[:4], n, 240.0)
    np.testing.assert_allclose(states[-1, :4], exact, rtol=1e-9, atol=1e-7)
    A, b = model.modes["passive"].linear
    sol = solve_ivp(lambda _, z: A @ z + b, [0, 240], x0, method="DOP853", rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(states[-1], sol.y[:, -1], rtol=1e-8, atol=1e-6)


def _hybrid_reference(model, x0, tau):
    """Independent hybrid simulation with solve_ivp events: dock at the octagon, abort at tau."""
    A1, b1 = model.modes["approach"].linear
    A2, b2 = model.modes["rendezvous"].linear
    A3, b3 = model.modes["passive"].linear

    def octagon(_, z):
        x, y = z[0], z[1]
        return max(abs(x), abs(y), abs(x + y) - 41.1, abs(x - y) - 41.1) - 100.0
    octagon.terminal = True
    first = solve_ivp(lambda _, z: A1 @ z + b1, [0, tau], x0, events=octagon, rtol=1e-12, atol=1e-10,
                      method="DOP853")
    t_dock = first.t_events[0][0]
    second = solve_ivp(lambda _, z: A2 @ z + b2, [t_dock, tau], first.y[:, -1], rtol=1e-12, atol=1e-10,
                       method="DOP853")
    third = solve_ivp(lambda _, z: A3 @ z + b3, [tau, model.horizon], second.y[:, -1], rtol=1e-12,
                      atol=1e-10, method="DOP853")
    return t_dock, third.y[:, -1]


def test_hybrid_run_matches_an_event_located_solve_ivp():
    model = load_model("models/SRA03.yaml")
    x0 = np.array([-912.0, -388.0, 0.0, 0.0, 0.0])
    traj = Simulator(model).run(x0[None], np.array([131.7]), record=True)
    t, modes, states = traj.path[0]
    t_dock = t[np.flatnonzero(modes == 1)[0]]
    ref_dock, ref_final = _hybrid_reference(model, x0, 131.7)
    assert t_dock == pytest.approx(ref_dock, abs=1e-6)
    assert 108.8 <= t_dock <= 111.6                     # ANCHORS: switch at 108.8-111.6 min
    np.testing.assert_allclose(traj.final_state[0], ref_final, rtol=1e-6, atol=1e-5)


def test_nonlinear_rk4_matches_solve_ivp():
    model = load_model("models/SRNA01.yaml")
    x0 = np.array([-900.0, -400.0, 0.0, 0.0, 0.0])
    f = model.modes["approach"].rhs
    traj = Simulator(model).run(x0[None], record=True)
    t, modes, states = traj.path[0]
    k = np.flatnonzero(np.isclose(t, 100.0))[0]
    sol = solve_ivp(lambda _, z: f(z[None])[0], [0, 100], x0, method="DOP853", rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(states[k], sol.y[:, -1], rtol=1e-8, atol=1e-7)


def test_lqr_gain_matches_an_independent_riccati_solve():
    model = load_model("models/rendezvous_si_bryson.yaml")
    n = model.constants["n"]
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [3 * n ** 2, 0, 0, 2 * n], [0, 0, -2 * n, 0]])
    B = np.array([[0, 0], [0, 0], [1 / 500, 0], [0, 1 / 500]])
    for mode, maxima in [("approach", [1250, 1082, 0.4167, 0.4167]), ("rendezvous", [125, 125, 0.0625, 0.0625])]:
        Q = np.diag(1 / np.array(maxima, float) ** 2)
        R = np.diag([1 / 10.0 ** 2] * 2)
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
        K = np.linalg.solve(R, B.T @ P)
        np.testing.assert_allclose(model.modes[mode].controller.gain, -K, rtol=1e-7, atol=1e-12)


def test_brysons_rule_reproduces_the_arch_gains():
    """The first-principles SI design lands on the ARCH gains (converted to SI units)."""
    model = load_model("models/rendezvous_si_bryson.yaml")
    to_si = np.array([1 / 3600, 1 / 3600, 1 / 60, 1 / 60])
    K1 = np.array([[-28.8287, 0.1005, -1449.9754, 0.0046], [-0.087, -33.2562, 0.00462, -1451.5013]]) * to_si
    K2 = np.array([[-288.0288, 0.1312, -9614.9898, 0], [-0.1312, -288, 0, -9614.9883]]) * to_si
    for mode, K in [("approach", K1), ("rendezvous", K2)]:
        gain = model.modes[mode].controller.gain
        big = np.abs(K) > 1e-3 * np.abs(K).max(axis=1, keepdims=True)
        assert np.max(np.abs(gain - K)[big] / np.abs(K)[big]) < 1e-4
