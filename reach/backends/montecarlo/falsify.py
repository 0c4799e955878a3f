"""Falsification by optimisation: minimise the robustness of a safety property over the run's
free parameters, as S-TaLiRo and Breach do.

The robustness of one run is its smallest depth ``rho = min_t depth(x(t))`` into the unsafe set
(:class:`reach.backends.montecarlo.monitors.SafetyMonitor`; positive is a margin, at most 0 a violation),
or for an event property the margin of the run's extremum from the requirement
(:class:`reach.backends.montecarlo.event_sampling.EventMonitor`; below 0 a violation).
A run is fixed by a point ``u`` of the unit cube ``[0, 1]^d``, the concatenation of

* the free initial coordinates, ``x0_i = low_i + u_i (high_i - low_i)`` (a polytopic initial set:
  the point of its bounding box pulled inside the polytope);
* the switch instant of the may-transition window, ``tau = lo + u (hi - lo)``;
* the values of the time-varying inputs on each piece ``[k step, (k+1) step)`` of the signal,
  ``v_kj = ulo_j + u (uhi_j - ulo_j)``;
* where several transitions can be enabled at one jump, the run's choice values
  (:class:`reach.model.simulate.Branches`), ``u`` itself (a little below 1 at most).

``rho(u)`` is minimised by differential evolution (``scipy.optimize.differential_evolution``,
vectorised: a whole generation is one :meth:`Simulator.run`), its initial population the runs
closest to the unsafe set so far plus a Latin hypercube (ended early where a generation's
robustness values all agree to a relative 1e-9: a flat landscape), then polished by a batched
projected gradient descent (forward differences, a line search along the two steepest descents
in the max-norm) from the best run and from the best distinct points of the final population
(the landscape of a hybrid run has kinks where a jump moves across a signal piece, and descent
stops at them), or for at most two parameters by a batched grid refinement around the best
run: a few simulations of many runs instead of many of one. The search stops at the
first violating run. A violation found here is only a candidate: the back-end replays it alone
before it reports UNSAFE.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from reach.backends.montecarlo.initial_sampling import PolytopeSampler
from reach.model.simulate import Branches

NO_VISIT = 1e12        # robustness of a run that never enters a mode of the property
FLAT = 1e-9            # a generation whose robustness values agree to this (relative) ends the evolution
GRID_DIM = 2           # up to this many parameters the polish is a batched grid refinement
GRID_ROUNDS = 5
FD_STEP = 1e-3         # widest forward-difference step of the gradient polish (unit cube)
MIN_STEP = 1e-7        # the gradient polish ends when its trust radius shrinks below this
LINE_STEPS = 8         # step lengths r, r/2, ..., r 2^-7 tried along each descent direction
POLISH_STARTS = 3      # the gradient polish starts from the best run and the best distinct points of
DISTINCT = 0.05        # the final population (max-norm distance in the unit cube), sharing the runs


@dataclass
class Budget:
    generations: int = 20      # differential evolution generations
    population: int = 40       # candidates per generation
    polish: int = 1000         # polish runs (grid refinement or gradient descent, batched)
    deadline: float = math.inf  # time.perf_counter() past which the search stops with what it has

    def spent(self) -> bool:
        return time.perf_counter() > self.deadline

    def wall(self) -> float:
        """The deadline as a ``time.time()`` instant (the simulator's: runs under way stop there)."""
        return math.inf if math.isinf(self.deadline) else time.time() + (self.deadline - time.perf_counter())


class Parameterisation:
    """The map ``u in [0, 1]^d -> (x0, tau, input values)`` of the module docstring."""

    def __init__(self, model, window, step: float | None, pieces: int, switching: bool, choices: int = 0):
        self.model = model
        low, high = model.initial.low, model.initial.high
        self.low, self.high = low, high
        varying = [u.index for u in model.varying_inputs]          # set by the signal instead
        self.free = np.setdiff1d(np.flatnonzero(high > low), varying)
        self.sampler = None if model.initial.is_box else PolytopeSampler(model.initial.polytope, low, high)
        self.window = window
        self.ulo = np.array([u.low for u in model.varying_inputs])
        self.uhi = np.array([u.high for u in model.varying_inputs])
        self.step, self.pieces, self.switching, self.choices = step, pieces, switching, choices
        self.dim = self.free.size + (window is not None) + self.pieces * self.ulo.size + choices

    def runs(self, U: np.ndarray):
        """``(X0 (S, n), tau (S,) or None, signal or None, choice values (S, choices) or None)``
        of the rows of ``U`` (S, d)."""
        U = np.clip(np.atleast_2d(U), 0.0, 1.0)
        S = U.shape[0]
        X = np.tile((self.low + self.high) / 2, (S, 1))
        f = self.free.size
        X[:, self.free] = self.low[self.free] + U[:, :f] * (self.high - self.low)[self.free]
        if self.sampler is not None:
            X = self.sampler.pull_inside(X)
        tau = None
        if self.window is not None:
            lo, hi, _ = self.window
            tau = lo + U[:, f] * (hi - lo)
            f += 1
        signal = None
        if self.step is not None:
            m = self.ulo.size
            V = self.ulo + U[:, f:f + self.pieces * m].reshape(S, self.pieces, m) * (self.uhi - self.ulo)
            switch = np.zeros((S, self.pieces), dtype=bool) if self.switching else None
            signal = (self.step, V, switch)
            f += self.pieces * m
        choice = np.minimum(U[:, f:], 1.0 - 1e-12) if self.choices else None
        return X, tau, signal, choice

    def encode(self, X: np.ndarray, tau, signal, choice=None) -> np.ndarray:
        """The unit-cube points of runs given as initial states, switch instants, signals and
        choice values (a run that never switches is put at the middle of the window)."""
        parts = [(X[:, self.free] - self.low[self.free]) / (self.high - self.low)[self.free]]
        if self.window is not None:
            lo, hi, _ = self.window
            t = np.where(np.isnan(tau), (lo + hi) / 2, tau)
            parts.append(((t - lo) / (hi - lo) if hi > lo else np.zeros_like(t))[:, None])
        if self.pieces and self.ulo.size:
            V = signal[1][:, :self.pieces]
            parts.append(((V - self.ulo) / np.where(self.uhi > self.ulo, self.uhi - self.ulo, 1.0))
                         .reshape(X.shape[0], -1))
        if self.choices:
            parts.append(choice)
        return np.clip(np.concatenate(parts, axis=1), 0.0, 1.0)


@dataclass
class Outcome:
    """The optimiser's best run (the first violating one if any) and what it cost."""

    X: np.ndarray                 # (1, n)
    tau: np.ndarray | None        # (1,)
    signal: tuple | None          # one run's signal
    choice: np.ndarray | None     # (1, choices): its choice values
    monitor: object               # its SafetyMonitor
    violated: bool
    runs: int


def falsify(model, prop, window, sim, monitor_factory, elite, budget: Budget, seed: int,
            step: float | None = None, pieces: int = 0, switching: bool = False, choices: int = 0) -> Outcome:
    """Minimise the robustness of ``prop`` (see the module docstring).

    ``monitor_factory(count)`` makes a monitor for ``count`` runs (``min_depth`` per run and
    ``first_violation()``: a SafetyMonitor or an EventMonitor); ``elite`` is
    ``(X, tau, signal, choice)`` of the runs closest to the unsafe set so far (seeds of the
    population); ``choices`` the number of choice values per run (0: none).
    """
    param = Parameterisation(model, window, step, pieces, switching, choices)
    best = {"depth": np.inf, "run": None, "violated": False, "runs": 0}
    wall = budget.wall()

    def evaluate(U: np.ndarray) -> np.ndarray:
        X, tau, signal, choice = param.runs(U)
        monitor = monitor_factory(X.shape[0])
        sim.run(X, tau, observers=[monitor], signal=signal,
                branches=None if choice is None else Branches(values=choice), deadline=wall)
        best["runs"] += X.shape[0]
        hit = monitor.first_violation()
        i = hit if hit is not None else int(np.argmin(monitor.min_depth))
        if (best["run"] is None or (hit is not None and not best["violated"])
                or monitor.min_depth[i] < best["depth"]):      # the first run stands until a closer one
            if not best["violated"]:
                best.update(depth=float(monitor.min_depth[i]), violated=hit is not None,
                            run=(X[i:i + 1], None if tau is None else tau[i:i + 1], _row(signal, i),
                                 None if choice is None else choice[i:i + 1], monitor, i))
        return np.where(np.isfinite(monitor.min_depth), monitor.min_depth, NO_VISIT)

    if param.dim == 0:
        evaluate(np.zeros((1, 0)))
        return _outcome(best)
    rng = np.random.default_rng(seed)
    size = max(5, budget.population)
    seeds = param.encode(*elite)[: size // 2]
    fill = latin_hypercube(rng, size - seeds.shape[0], param.dim)
    init = np.concatenate([seeds, fill])
    evolved = scipy.optimize.differential_evolution(
        lambda U: evaluate(U.T), [(0.0, 1.0)] * param.dim, init=init, maxiter=budget.generations,
        vectorized=True, updating="deferred", polish=False, tol=FLAT, atol=FLAT,
        seed=rng, callback=lambda intermediate_result: best["violated"] or budget.spent())
    if best["violated"] or budget.polish <= 0 or budget.spent():
        return _outcome(best)
    start = param.encode(*best["run"][:4])[0]
    if param.dim <= GRID_DIM:
        _grid_polish(evaluate, best, start, budget)
        return _outcome(best)
    starts = [(start, best["depth"])] + _distinct_best(evolved.population, evolved.population_energies, start)
    for u, f in starts[:POLISH_STARTS]:
        _gradient_polish(evaluate, best, u, f, budget.polish // POLISH_STARTS, budget)
        if best["violated"] or budget.spent():
            break
    return _outcome(best)


def _distinct_best(population: np.ndarray, energies: np.ndarray, other: np.ndarray) -> list:
    """The final population's points from best to worst, ``(u, rho(u))``, each farther than
    :data:`DISTINCT` (max-norm) from ``other`` and from those before it."""
    kept: list = []
    for k in np.argsort(energies, kind="stable"):
        u = population[k]
        if all(np.abs(u - v).max() > DISTINCT for v in [other] + [p for p, _ in kept]):
            kept.append((u, float(energies[k])))
    return kept


def latin_hypercube(rng: np.random.Generator, count: int, dim: int) -> np.ndarray:
    """``count`` points of ``[0, 1]^dim``, one in each of the ``count`` slices ``[(k-1)/count,
    k/count)`` of every axis: point ``i`` is ``(pi_j(i) - u_ij) / count`` with ``pi_j`` a random
    permutation of ``1..count`` per axis and ``u_ij`` uniform on ``[0, 1)``. The draws come from
    a child of ``rng`` (``rng.spawn(1)``), in the order of ``scipy.stats.qmc.LatinHypercube(dim,
    rng=rng).random(count)``, so the points are that sampler's (without importing scipy.stats)."""
    child = rng.spawn(1)[0]
    u = child.uniform(size=(count, dim))
    perms = np.tile(np.arange(1, count + 1), (dim, 1))
    for row in perms:
        child.shuffle(row)
    return (perms.T - u) / count


def _grid_polish(evaluate, best, start: np.ndarray, budget: Budget) -> None:
    """The polish of a search over at most :data:`GRID_DIM` parameters, batched: in each of
    :data:`GRID_ROUNDS` rounds a grid of ``G^d`` points (``G^d <= budget / rounds``) spanning
    ``centre +- w`` is one :meth:`Simulator.run`; the best point so far becomes the centre and
    ``w`` shrinks to the grid's spacing (``w`` starts at 0.05)."""
    d = start.size
    G = max(3, int(np.floor((budget.polish / GRID_ROUNDS) ** (1.0 / d))))
    centre, w = start.copy(), 0.05
    for _ in range(GRID_ROUNDS):
        axes = [np.clip(np.linspace(c - w, c + w, G), 0.0, 1.0) for c in centre]
        U = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
        values = evaluate(U)
        if best["violated"] or budget.spent():
            return
        k = int(np.argmin(values))
        if values[k] <= best["depth"]:
            centre = U[k]
        w *= 2.0 / (G - 1)


def _gradient_polish(evaluate, best, start: np.ndarray, value: float, runs: int, budget: Budget) -> None:
    """The polish of a search over more than :data:`GRID_DIM` parameters: projected descent on
    the unit cube in a trust radius ``r``, every simulation batched. From the best point ``u``
    (robustness ``f``), one :meth:`Simulator.run` of ``d`` rows gives the forward differences
    ``g_j = (rho(u + h_j e_j) - f) / h_j`` (``h_j = +-min(FD_STEP, r)``, stepping inwards; a
    coordinate whose step leaves every mode of the property unvisited gets ``g_j = 0``, and so
    does one a face of the cube holds: ``u_j = 1`` and ``g_j < 0``, or ``u_j = 0`` and ``g_j >
    0``); a second run tries the points ``clip(u - a D)`` for the steepest descents in the
    max-norm ``D = g / |g|_inf`` and ``D = sign(g)`` (the bang-bang direction that a
    box-constrained signal's optimum usually takes) and the step lengths ``a = r 2^-k``, ``k = 0
    .. LINE_STEPS - 1``. The best point becomes ``u`` if it lowers ``f``, and ``r`` twice its
    step; otherwise ``r`` halves below the shortest step tried. The polish ends after
    ``budget.polish`` runs, once ``r`` is below :data:`MIN_STEP`, at a violation, or when the
    time budget is spent."""
    u, f, d, radius = start.copy(), value, start.size, 0.5
    lengths = 2.0 ** -np.arange(LINE_STEPS)
    used = 0
    while used + d + 2 * LINE_STEPS <= runs and radius >= MIN_STEP:
        h = min(FD_STEP, radius)
        steps = np.where(u + h <= 1.0, h, -h)
        values = evaluate(u + np.diag(steps))
        used += d
        if best["violated"] or budget.spent():
            return
        g = np.where(values < NO_VISIT, (values - f) / steps, 0.0)
        g[((u >= 1.0) & (g < 0.0)) | ((u <= 0.0) & (g > 0.0))] = 0.0    # held by the cube's faces
        scale = np.abs(g).max()
        if scale == 0.0 or not np.isfinite(scale):
            radius /= 4.0
            continue
        directions = np.stack([g / scale, np.sign(g)])
        trial = np.clip(u - (radius * lengths[:, None, None] * directions[None]).reshape(-1, d), 0.0, 1.0)
        values = evaluate(trial)
        used += trial.shape[0]
        if best["violated"] or budget.spent():
            return
        k = int(np.argmin(values))
        if values[k] < f:
            u, f, radius = trial[k], float(values[k]), min(1.0, 2.0 * radius * lengths[k // 2])
        else:
            radius *= lengths[-1] / 2.0


def _row(signal, i: int):
    if signal is None:
        return None
    step, V, switch = signal
    return step, V[i:i + 1], None if switch is None else switch[i:i + 1]


def _outcome(best) -> Outcome:
    X, tau, signal, choice, monitor, i = best["run"]
    one = type(monitor).__new__(type(monitor))        # the chosen run's row of the batch monitor
    one.__dict__.update({k: (v[i:i + 1] if isinstance(v, np.ndarray) else v) for k, v in monitor.__dict__.items()})
    return Outcome(X, tau, signal, choice, one, best["violated"], best["runs"])
