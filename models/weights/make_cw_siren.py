"""Generate time-optimal CW rendezvous trajectories and train the SIREN guidance network.

Reproduces section 4.1 of Evans & Armellin's Taylor-ADS paper (the network of
``models/cw_siren.yaml``) at a CPU-friendly size. Run from the repository root::

    pip install -e '.[train]'
    python models/weights/make_cw_siren.py           # writes cw_siren.npz, cw_siren_test.npz

Scenario (the paper gives neither the mean motion nor the thrust; the choice is documented here
and in the model file). Planar Clohessy-Wiltshire motion about a geostationary orbit,
``n = 7.2921e-5 rad/s`` (period 23.93 h), constant thrust acceleration ``a`` of steerable
direction ``alpha``::

    x'' = 3 n^2 x + 2 n y' + a alpha_x,        y'' = -2 n x' + a alpha_y.

The nominal initial state (500, -500) m at rest is the centre of the paper's domain (its safe
strip x in [0.45, 0.54125] km, y in [-0.65, -0.35] km and the +-[55, 150] m uncertainty). ``a``
is chosen so that the minimum time from it to the origin at rest is the paper's nominal 3.34 h:
``a = 2.396255e-5 m/s^2`` (:func:`thrust_for_time`; printed by every run).

Why GEO. The orbit was chosen by comparing the optimal transfers (same nominal start, same
3.34 h) of two candidates:

    orbit        n (rad/s)  n T   a (m/s^2)  max |r|  max |v|   turns    T over the box
    400 km LEO   1.1314e-3  13.6  2.626e-4   11.4 km  4.8 m/s   518 deg  2.55-3.65 h, jump
    GEO          7.2921e-5  0.88  2.396e-5   707 m    0.114 m/s 138 deg  2.95-3.73 h, smooth

(max |r|, max |v|: along the nominal transfer; turns: of the thrust direction; T over the box:
minimum time on a 12 x 3 grid of starts at rest.)

In LEO the flight is 2.2 revolutions and the minimum time jumps from 2.6 h to 2.9 h across
x = 455..465 m (the optimal extremal family changes), so the feedback has a fold inside the box
and the event's 5 m / 0.01 m/s scale is 1/2300 and 1/480 of the excursion; a network trained
there (mean test error 0.53 deg) came no closer than L = 6.7 (4.3 m, 0.036 m/s) from the
nominal start. In GEO the flight is a short arc and the feedback is close to the double
integrator's, smooth over the box, with the event's scale 1/140 and 1/11 of the excursion.

Rendezvous complete. The model stops the thrust (mode ``arrived``, free CW drift) the first time
``L = dx^T M dx`` of eq. (30) is at most 0.9; the network only has to bring the state into that
set, which is why the terminal approach is sampled densely below.

Time-optimal control (Pontryagin). With ``H = 1 + lambda^T (A x + a B alpha)`` the costate is
``lambda(t) = expm(-A^T t) lambda_0`` and ``alpha = -lambda_v / |lambda_v|``. In time-to-go
``tau = T - t`` and with ``p = -lambda(T)`` the direction is ``alpha(tau) = B^T Phi(tau)^T p /
|B^T Phi(tau)^T p|`` (``Phi(tau) = expm(A tau)``, analytic for CW) and the state is::

    x(tau) = -a Phi(-tau) I(tau),      I(tau) = int_0^tau Phi(s) B alpha(s) ds.

``I`` is the gradient of the support function ``h(p) = int_0^T |B^T Phi(s)^T p| ds`` of the set
of states reachable from rest in time ``T`` with unit thrust, so finding ``p`` with
``-Phi(T) x_0 = a I(T; p)`` is the convex problem ``min h(p)`` on ``p . d = 1``
(``d = -Phi(T) x_0``, ``a = 1 / multiplier``); for this normal linear system every such extremal
is time-optimal. The thrust for a given time comes from that problem; the trajectories of the
dataset come from Newton shooting on ``(p, T)``, continued from the nearest solved neighbour
(the convex solve plus a root in ``T`` is the fallback). The optimal feedback ``x -> alpha`` is
time-invariant, so every state along an optimal trajectory with its direction is a sample.

Dataset (seed 20240611). Box trajectories: initial states in x in [430, 570] m,
y in [-680, -320] m, two thirds at rest, one third with velocities in +-0.02 m/s; each
trajectory is split into 80 equal segments of its time of flight with one uniformly drawn state
per segment (the paper uses ``k = 100``), plus 60 states with the time-to-go log-uniform in
[10 s, 3000 s] (``TERMINAL``): the final approach that decides the event (on the optimal
trajectory L = 0.9 is reached about 400 s before the end; below ~10 s the direction field is
steeper than the network can follow and the samples would only fight each other). Near-target
trajectories (half as many): initial states with position in +-60 m and velocity in +-0.03 m/s
(``NEAR``), ``k = 20`` plus 40 terminal states, so that the feedback is learned in every
direction around the target, where the closed loop wanders off the box trajectories. Training:
1600 box + 800 near-target trajectories (272 000 states); validation: 160 + 80 trajectories
(``k = 16`` + 12 terminal, ``k = 4`` + 8 terminal); test: 1000 box trajectories with ``k = 1``
(the paper's test set shape).

Network (eq. 29): 4 inputs scaled to [-1, 1] over the training states -> 5 hidden layers of 32
neurons ``y_i = sin(omega (W_i x_i + b_i))`` -> a linear layer of 2 outputs, ``omega = 30``.
SIREN initialisation: ``W_1 ~ U(-1/M_1, 1/M_1)``, ``W_i ~ U(-sqrt(6/M_i)/omega,
sqrt(6/M_i)/omega)``. AdamW (no AMSGrad), MSE loss on ``alpha``, batch 1000, learning rate 1e-4
cut by 0.6 when the validation loss has not improved by 1 % for 10 epochs (the paper's
settings; 1e-3 diverged after the first epoch), as many epochs as fit in 14 minutes
(``--minutes``, at most ``--epochs`` = 400) on 2.7e5 instead of 1e7 samples. Training runs
single-threaded on the CPU (torch 2.13.0, ``pip install -e '.[train]'``); ``--dataset FILE``
caches the generated states.

RESULTS of the shipped run (two CPU cores shared with other jobs)
    generation: 1600 + 800 near-target + 160 + 80 + 1000 trajectories, 272000 training states,
                66 s (5 convex fallbacks)
    training:   400 epochs, 576 s; final loss train 5.08e-04, validation 6.62e-04
    test set:   mean angular error 0.565 deg, 95th percentile 1.854 deg
    closed loop (models/cw_siren.yaml, eps = 0.01): from the nominal start the run switches to
                ``arrived`` at 3.201 h (L = 0.9) and drifts to min L = 0.721 at 3.27 h; 1000
                uniform starts in the box: all arrive, min L in [0.662, 0.763] at 2.90 h to
                3.64 h. DOP853 (rtol 1e-9) of the nominal, transfer to the guard then arrived to
                4 h: 80 steps, 1528 evaluations, under 1 s. taylor back-end, one subdomain
                (max_splits=0, order 4, estimated remainder): bound [-168.1, 0.900], 24 s.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.integrate import cumulative_simpson
from scipy.optimize import brentq, minimize, root

N_MEAN = 7.2921e-5                                  # rad/s, geostationary orbit
X_NOMINAL = np.array([500.0, -500.0, 0.0, 0.0])    # m, m/s
T_NOMINAL = 3.34 * 3600.0                           # s
SEED = 20240611
TERMINAL = (10.0, 3000.0)                           # s, time-to-go range of the terminal states
NEAR = (60.0, 0.03)                                 # m, m/s: half-widths of the near-target starts
GRID = 2001                                         # quadrature nodes over a time of flight
OMEGA = 30.0
HIDDEN = [32] * 5

HERE = Path(__file__).resolve().parent


# ------------------------------------------------------------------ CW optimal control
# Dimensionless: time in 1/n, length in m (velocities v/n, accelerations a/n^2).

def to_unit(x):
    return np.asarray(x, dtype=float) * np.array([1.0, 1.0, 1.0 / N_MEAN, 1.0 / N_MEAN])


def from_unit(x):
    return np.asarray(x, dtype=float) * np.array([1.0, 1.0, N_MEAN, N_MEAN])


A_UNIT = np.array([[0.0, 0, 1, 0], [0, 0, 0, 1], [3, 0, 0, 2], [0, 0, -2, 0]])


def stm(t):
    """CW transition matrix ``Phi(t) = expm(A t)`` (n = 1), shape ``t.shape + (4, 4)``."""
    t = np.asarray(t, dtype=float)
    s, c, z, o = np.sin(t), np.cos(t), np.zeros_like(t), np.ones_like(t)
    rows = [[4 - 3 * c, z, s, 2 * (1 - c)],
            [6 * (s - t), o, -2 * (1 - c), 4 * s - 3 * t],
            [3 * s, z, c, 2 * s],
            [-6 * (1 - c), z, -2 * s, 4 * c - 3]]
    return np.stack([np.stack(r, -1) for r in rows], -2)


def thrust_columns(t):
    """``Phi(t) B``: the columns of ``Phi`` on ``vx`` and ``vy``, each ``(len(t), 4)``."""
    s, c = np.sin(t), np.cos(t)
    return (np.stack([s, -2 * (1 - c), c, -2 * s], -1),
            np.stack([2 * (1 - c), 4 * s - 3 * t, 2 * s, 4 * c - 3], -1))


def direction(p, tau):
    """Optimal thrust direction at time-to-go ``tau`` and the integrand ``Phi B alpha``."""
    c2, c3 = thrust_columns(tau)
    primer = np.stack([c2 @ p, c3 @ p], -1)
    norm = np.linalg.norm(primer, axis=-1, keepdims=True)
    alpha = primer / norm
    return alpha, c2 * alpha[:, :1] + c3 * alpha[:, 1:], norm[:, 0]


def simpson_weights(T):
    """Nodes and weights of Simpson's rule on ``GRID`` equal steps over ``[0, T]``."""
    w = np.ones(GRID)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return np.linspace(0.0, T, GRID), w * T / (3 * (GRID - 1))


def support(p, T, jacobian=False):
    """``I(T; p)`` and ``h(p)`` by Simpson's rule; with ``jacobian`` also ``dI/dp`` and the
    integrand at ``T``. ``dI/dp = int (Phi B beta)(Phi B beta)^T / |B^T Phi^T p|`` with ``beta``
    the unit vector normal to ``alpha``."""
    tau, w = simpson_weights(T)
    alpha, g, norm = direction(p, tau)
    I, h = w @ g, w @ norm
    if not jacobian:
        return I, h
    c2, c3 = thrust_columns(tau)
    v = -c2 * alpha[:, 1:] + c3 * alpha[:, :1]
    return I, h, (v * (w / norm)[:, None]).T @ v, g[-1]


def thrust_for_time(x0, T):
    """``(a, p)``: the thrust with minimum time ``T`` from ``x0`` (dimensionless), by the convex
    problem ``min h(p)`` on ``p . d = 1``."""
    d = -stm(T) @ x0
    base = d / (d @ d)
    Q = np.linalg.svd(d[None, :])[2][1:].T

    def fun(z):
        I, h = support(base + Q @ z, T)
        return h, Q.T @ I

    z = minimize(fun, np.zeros(3), jac=True, method="BFGS", options={"gtol": 1e-12}).x
    p = base + Q @ z
    I, _ = support(p, T)
    return float((d @ d) / (I @ d)), p / np.linalg.norm(p)


def shoot(x0, a, guess):
    """``(p, T)`` of the time-optimal transfer from ``x0`` by Newton on ``(q, T)``, ``p = q/|q|``
    (analytic Jacobian), or None."""
    scale = 1.0 + np.abs(x0).max()

    def fun(z):
        q, T = z[:4], z[4]
        r = np.linalg.norm(q)
        I, _, dI, g = support(q / r, T, jacobian=True)
        back = stm(-T)
        F = np.r_[(-a * back @ I - x0) / scale, q @ q - 1.0]
        J = np.zeros((5, 5))
        J[:4, :4] = -a * back @ dI @ (np.eye(4) - np.outer(q, q) / r ** 2) / r / scale
        J[:4, 4] = a * (A_UNIT @ back @ I - back @ g) / scale
        J[4, :4] = 2 * q
        return F, J

    sol = root(fun, np.r_[guess[0], guess[1]], jac=True, method="hybr", options={"xtol": 1e-12})
    if not sol.success or np.max(np.abs(fun(sol.x)[0])) > 1e-9 or sol.x[4] <= 0:
        return None
    q = sol.x[:4]
    return q / np.linalg.norm(q), float(sol.x[4])


def solve_robust(x0, a, T_hint):
    """Fallback: the time whose thrust is ``a`` (monotone in ``T``), then its ``p``."""
    gap = lambda T: thrust_for_time(x0, T)[0] - a
    lo, hi = 0.5 * T_hint, 1.5 * T_hint
    while gap(lo) < 0:
        lo *= 0.7
    while gap(hi) > 0:
        hi *= 1.4
    T = brentq(gap, lo, hi, xtol=1e-12)
    return thrust_for_time(x0, T)[1], T


def trajectory(a, p, T):
    """States (dimensionless) and directions on the quadrature grid, with time-to-go."""
    tau = np.linspace(0.0, T, GRID)
    alpha, g, _ = direction(p, tau)
    I = cumulative_simpson(g, x=tau, axis=0, initial=0.0)
    states = -a * np.einsum("kij,kj->ki", stm(-tau), I)
    return tau, states, alpha


class Solver:
    """Time-optimal transfers to the origin, continued from the nearest solved neighbour."""

    def __init__(self, a):
        self.a = a
        self.starts, self.solutions = [], []
        p, T = thrust_for_time(to_unit(X_NOMINAL), T_NOMINAL * N_MEAN)[1], T_NOMINAL * N_MEAN
        self.add(to_unit(X_NOMINAL), (p, T))
        self.fallbacks = 0

    def add(self, x0, solution):
        self.starts.append(x0)
        self.solutions.append(solution)

    def solve(self, x0):
        S = np.array(self.starts)
        order = np.argsort(np.linalg.norm(S - x0, axis=1))[:3]
        for k in order:
            out = shoot(x0, self.a, self.solutions[k])
            if out is not None:
                break
        else:
            self.fallbacks += 1
            out = solve_robust(x0, self.a, self.solutions[order[0]][1])
        self.add(x0, out)
        return out


def initial_states(count, rng):
    """Initial states around the verification domain: two thirds at rest."""
    X = np.zeros((count, 4))
    X[:, 0] = rng.uniform(430.0, 570.0, count)
    X[:, 1] = rng.uniform(-680.0, -320.0, count)
    moving = rng.random(count) < 1 / 3
    X[moving, 2:] = rng.uniform(-0.02, 0.02, (moving.sum(), 2))
    return X


def near_target_states(count, rng):
    """Initial states around the target (every direction of the final approach)."""
    X = np.zeros((count, 4))
    X[:, :2] = rng.uniform(-NEAR[0], NEAR[0], (count, 2))
    X[:, 2:] = rng.uniform(-NEAR[1], NEAR[1], (count, 2))
    return X


def sample_states(solver, X0, k, terminal, rng):
    """``k`` states per trajectory (one per time segment) and ``terminal`` near the end, with
    their optimal directions (the trajectory's own time-to-go, when shorter than the terminal
    one, is sampled uniformly instead)."""
    states, alphas = [], []
    for x0 in X0:
        p, T = solver.solve(to_unit(x0))
        tau, Y, alpha = trajectory(solver.a, p, T)
        t_pick = (np.arange(k) + rng.random(k)) * T / k
        if terminal:
            t_end = np.exp(rng.uniform(np.log(TERMINAL[0]), np.log(TERMINAL[1]), terminal)) * N_MEAN
            t_pick = np.r_[t_pick, np.where(t_end < T, t_end, rng.random(terminal) * T)]
        idx = np.clip(np.rint(t_pick / T * (GRID - 1)).astype(int), 1, GRID - 1)
        states.append(from_unit(Y[idx]))
        alphas.append(alpha[idx])
    return np.concatenate(states), np.concatenate(alphas)


# ------------------------------------------------------------------ network

def build_net(torch, n_in, n_out):
    """SIREN (eq. 29) with the initialisation of Sitzmann et al."""
    nn = torch.nn

    class Sine(nn.Module):
        def __init__(self, layer):
            super().__init__()
            self.layer = layer

        def forward(self, x):
            return torch.sin(OMEGA * self.layer(x))

    layers, width = [], n_in
    for i, h in enumerate(HIDDEN + [n_out]):
        lin = nn.Linear(width, h)
        bound = 1.0 / width if i == 0 else np.sqrt(6.0 / width) / OMEGA
        nn.init.uniform_(lin.weight, -bound, bound)
        nn.init.uniform_(lin.bias, -bound, bound)
        layers.append(Sine(lin) if i < len(HIDDEN) else lin)
        width = h
    return nn.Sequential(*layers)


def export(net, offset, scale):
    """The plain arrays of ``cw_siren.npz``: W1..W6, b1..b6, omega, input_offset/scale."""
    linears = [m.layer if hasattr(m, "layer") else m for m in net]
    arrays = {}
    for i, lin in enumerate(linears, start=1):
        arrays[f"W{i}"] = lin.weight.detach().double().numpy()
        arrays[f"b{i}"] = lin.bias.detach().double().numpy()
    arrays.update(omega=np.array(OMEGA), input_offset=offset, input_scale=scale)
    return arrays


def forward_numpy(arrays, X):
    """Forward pass of the exported arrays on states ``X (N, 4)``: outputs ``(N, 2)``."""
    h = (X - arrays["input_offset"]) / arrays["input_scale"]
    layers = sum(1 for k in arrays if k.startswith("W"))
    for i in range(1, layers):
        h = np.sin(arrays["omega"] * (h @ arrays[f"W{i}"].T + arrays[f"b{i}"]))
    return h @ arrays[f"W{layers}"].T + arrays[f"b{layers}"]


def angular_error(pred, alpha):
    """Angles (rad) between predicted outputs and the optimal unit directions."""
    cos = np.sum(pred * alpha, axis=1) / np.linalg.norm(pred, axis=1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def train(data, epochs, minutes, rng_seed):
    import torch

    torch.set_num_threads(1)
    torch.manual_seed(rng_seed)
    (Xt, At), (Xv, Av) = data
    lo, hi = Xt.min(axis=0), Xt.max(axis=0)
    offset, scale = (hi + lo) / 2, (hi - lo) / 2
    tx = torch.tensor((Xt - offset) / scale, dtype=torch.float32)
    ta = torch.tensor(At, dtype=torch.float32)
    vx = torch.tensor((Xv - offset) / scale, dtype=torch.float32)
    va = torch.tensor(Av, dtype=torch.float32)
    net = build_net(torch, 4, 2)
    opt = torch.optim.AdamW(net.parameters(), lr=1e-4, amsgrad=False)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.6, patience=10, threshold=0.01)
    loss_fn = torch.nn.MSELoss()
    start = time.perf_counter()
    for epoch in range(1, epochs + 1):
        perm = torch.randperm(tx.shape[0])
        total = 0.0
        for i in range(0, tx.shape[0], 1000):
            j = perm[i:i + 1000]
            opt.zero_grad()
            loss = loss_fn(net(tx[j]), ta[j])
            loss.backward()
            opt.step()
            total += loss.item() * j.numel()
        with torch.no_grad():
            val = loss_fn(net(vx), va).item()
        sched.step(val)
        train_loss = total / tx.shape[0]
        if epoch % 10 == 0 or epoch == 1:
            print(f"epoch {epoch:4d}  train {train_loss:.3e}  val {val:.3e}  "
                  f"lr {opt.param_groups[0]['lr']:.1e}  {time.perf_counter() - start:.0f} s", flush=True)
        if time.perf_counter() - start > 60 * minutes:
            break
    print(f"training: {epoch} epochs, {time.perf_counter() - start:.0f} s; "
          f"final loss train {train_loss:.2e}, validation {val:.2e}")
    return export(net, offset, scale)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectories", type=int, default=1600)
    parser.add_argument("--epochs", type=int, default=400)
    parser.add_argument("--minutes", type=float, default=14.0, help="training wall-clock limit")
    parser.add_argument("--out", type=Path, default=HERE)
    parser.add_argument("--dataset", type=Path, help="cache of the generated states (.npz): read if present")
    args = parser.parse_args()

    rng = np.random.default_rng(SEED)
    a = thrust_for_time(to_unit(X_NOMINAL), T_NOMINAL * N_MEAN)[0]
    print(f"n = {N_MEAN:.6e} rad/s, a = {a * N_MEAN ** 2:.6e} m/s^2 "
          f"(minimum time {T_NOMINAL / 3600:.2f} h from {X_NOMINAL.tolist()})")
    if args.dataset and args.dataset.is_file():
        with np.load(args.dataset) as d:
            train_set, val_set, test_set = [(d[f"{k}_x"], d[f"{k}_alpha"]) for k in ("train", "val", "test")]
    else:
        start = time.perf_counter()
        solver = Solver(a)
        near = args.trajectories // 2
        pairs = [sample_states(solver, initial_states(args.trajectories, rng), 80, 60, rng),
                 sample_states(solver, near_target_states(near, rng), 20, 40, rng)]
        train_set = tuple(np.concatenate(v) for v in zip(*pairs))
        pairs = [sample_states(solver, initial_states(args.trajectories // 10, rng), 16, 12, rng),
                 sample_states(solver, near_target_states(near // 10, rng), 4, 8, rng)]
        val_set = tuple(np.concatenate(v) for v in zip(*pairs))
        test_set = sample_states(solver, initial_states(1000, rng), 1, 0, rng)
        print(f"generation: {args.trajectories} + {near} near-target + {args.trajectories // 10} + "
              f"{near // 10} + 1000 trajectories, {len(train_set[0])} training states, "
              f"{time.perf_counter() - start:.0f} s ({solver.fallbacks} convex fallbacks)", flush=True)
        if args.dataset:
            np.savez(args.dataset, **{f"{k}_{v}": arr for k, pair in
                                      zip(("train", "val", "test"), (train_set, val_set, test_set))
                                      for v, arr in zip(("x", "alpha"), pair)})

    arrays = train((train_set, val_set), args.epochs, args.minutes, SEED)
    err = angular_error(forward_numpy(arrays, test_set[0]), test_set[1])
    print(f"test set: mean angular error {np.degrees(err.mean()):.3f} deg, "
          f"95th percentile {np.degrees(np.percentile(err, 95)):.3f} deg")
    np.savez(args.out / "cw_siren.npz", **arrays)
    np.savez(args.out / "cw_siren_test.npz", states=test_set[0], directions=test_set[1],
             mean_angular_error=np.array(err.mean()), thrust_acceleration=np.array(a * N_MEAN ** 2),
             mean_motion=np.array(N_MEAN))


if __name__ == "__main__":
    main()
