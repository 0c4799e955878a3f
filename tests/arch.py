"""Independent reference dynamics of the ARCH rendezvous benchmark, written out from the paper
(Chan & Mitra) and the published gains, with no use of the model loader: CWH (eq. 2) with the
mode-1 and mode-2 LQR gains, metres and minutes, and the passive drift after an abort."""

import numpy as np
from scipy.integrate import solve_ivp

N, MC = 0.00438138, 500.0                  # rad/min, kg
NEWTON = 3600.0                            # kg m/min^2 per newton
K1 = np.array([[-28.82867767694, 0.1004799482599, -1449.975419853, 0.004624472318875],
               [-0.08701567868523, -33.25619924505, 0.004624472318875, -1451.501346434]])
K2 = np.array([[-288.0287662715, 0.1312430397158, -9614.989795432, -3.41199964983e-07],
               [-0.1312430403689, -287.9999700959, -3.41199964983e-07, -9614.988297970]])
A_CWH = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [3 * N * N, 0, 0, 2 * N], [0, 0, -2 * N, 0]])
B = np.array([[0, 0], [0, 0], [1 / MC, 0], [0, 1 / MC]])
A_CL1 = A_CWH + B @ K1
A_CL2 = A_CWH + B @ K2
CORNERS = [np.array([x, y, 0.0, 0.0]) for x in (-925.0, -875.0) for y in (-425.0, -375.0)]
TOL = {"rtol": 1e-10, "atol": 1e-9}


def docking_event(t, s):
    """Zero where the chaser crosses the docking face ``x = -100`` m."""
    return s[0] + 100.0


docking_event.terminal, docking_event.direction = True, 1


def closest_passive_approach(x0, abort: float, horizon: float) -> float:
    """Smallest max-norm distance to the target in passive mode after an abort at ``abort`` min:
    solve_ivp through approach (to the docking face), rendezvous and the free drift."""
    first = solve_ivp(lambda t, s: A_CL1 @ s, [0, abort], np.asarray(x0, dtype=float)[:4],
                      events=docking_event, **TOL)
    second = solve_ivp(lambda t, s: A_CL2 @ s, [first.t[-1], abort], first.y[:, -1], **TOL)
    drift = solve_ivp(lambda t, s: A_CWH @ s, [abort, horizon], second.y[:, -1], dense_output=True, **TOL)
    t = np.linspace(abort, horizon, 60001)
    return float(np.min(np.max(np.abs(drift.sol(t)[:2]), axis=0)))
