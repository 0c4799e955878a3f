"""Nominal runs (the constant part of the DA runs), many at once.

A nominal run gives a DA run its step nodes and the nominal states for event detection and
refinement (:mod:`.event`). It is two adaptive DOP853 integrations of ``x' = f(x)`` from ``x0``:

* a coarse one at ``rtol = tol`` (``atol = tol max(1, |x0|)``): its accepted steps, each cut into
  ``refine`` equal steps, are the DA step nodes;
* a dense one at ``1e-12`` with the 7th-degree DOP853 interpolant on every step: the nominal state
  at any time (:class:`DenseSolution`).

The integrator is the step control of scipy's ``DOP853`` (Hairer, Norsett & Wanner, *Solving
ODEs I*, II.4 and II.10), written for a batch: runs are the rows of a ``(B, n)`` array, each with
its own time, step size and tolerance, and every stage evaluates ``f`` once on the rows still
running. For run ``b`` with step ``h``, error estimates ``e5 = h sum_i E5_i K_i / s``,
``e3 = h sum_i E3_i K_i / s`` (``s = atol + rtol max(|y|, |y_new|)``),

    err = |h| |e5/h|^2 / sqrt(n (|e5/h|^2 + 0.01 |e3/h|^2)),

the step is accepted when ``err < 1`` and the next step is ``h min(10, 0.9 err^(-1/8))``
(at most ``h`` right after a rejection); a rejected step is retried with
``h max(0.2, 0.9 err^(-1/8))``. The first step is the usual estimate from ``f(x0)`` and one Euler
step (``select_initial_step``). A row's arithmetic does not depend on the other rows: its sums
are matrix-vector products per row (so is the SIREN network's evaluation,
:meth:`reach.model.network.Siren.evaluate`), and ``err^(-1/8)`` is the C library's ``pow``, as
in scipy. A run in a batch is therefore bit for bit the run on its own, and takes scipy's steps
(tests/test_taylor_nominal.py); adaptive steps amplify last-bit differences in a flow's
evaluation (scipy evaluates ``x**2`` of a float by ``pow``, numpy's arrays by ``x*x``), so a run
can occasionally take a slightly different sequence of steps, each within the tolerance.

A run may stop at an urgent guard: ``stop(X) -> (k,)`` is positive until the run should end (the
guard's largest margin). The coarse run then ends where ``stop`` first crosses zero from above
(the root on the step's interpolant, by Brent's method to ``4 eps``, as ``solve_ivp`` finds a
terminal event) and goes on for one more step of the same length, so that the nodes bracket the
crossing and no work is spent past it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate._ivp import dop853_coefficients as dop
from scipy.optimize import brentq

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
EXPONENT = -1.0 / 8.0           # -1/(error estimator order + 1)
STAGES = dop.N_STAGES
A, B, E3, E5, D = dop.A[:STAGES, :STAGES], dop.B, dop.E3, dop.E5, dop.D
A_EXTRA = dop.A[STAGES + 1:]    # the three extra stages of the dense output
DENSE_TOL = 1e-12
EPS = np.finfo(float).eps


class DenseSolution:
    """The DOP853 interpolant of one run: ``solution(t)`` is ``(n,)`` for a scalar ``t``, ``(n, N)``
    for ``N`` times. On ``[t_k, t_{k+1}]``, with ``x = (t - t_k)/(t_{k+1} - t_k)``, the state is
    ``y_k + x(F_0 + (1 - x)(F_1 + x(F_2 + ... )))`` (the interval left of a node is used at the
    node, as scipy's ``OdeSolution`` does)."""

    def __init__(self, ts: np.ndarray, y_old: np.ndarray, F: np.ndarray):
        self.ts, self.y_old, self.F = ts, y_old, F        # (N + 1,), (N, n), (N, 7, n)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        seg = np.clip(np.searchsorted(self.ts, t, side="left") - 1, 0, len(self.F) - 1)
        x = ((t - self.ts[seg]) / (self.ts[seg + 1] - self.ts[seg]))[..., None]
        F = self.F[seg]
        y = np.zeros(np.shape(t) + self.y_old.shape[1:])
        for i in range(F.shape[-2]):
            y += F[..., F.shape[-2] - 1 - i, :]
            y *= x if i % 2 == 0 else 1 - x
        y += self.y_old[seg]
        return y.T


@dataclass
class Nominal:
    """The nominal (constant-part) run: dense solution and the step nodes of the DA runs."""

    solution: DenseSolution
    nodes: np.ndarray       # 0 = t_0 < t_1 < ... < t_N = T

    def grid(self, last: int | None = None) -> np.ndarray:
        """States at the nodes ``t_0..t_last`` (all by default): ``(last + 1, n)``."""
        last = len(self.nodes) - 1 if last is None else last
        return self.solution(self.nodes[: last + 1]).T

    def sharpen(self, k: int, score, samples: int = 64) -> float:
        """The time in ``[t_{k-1}, t_{k+1}]`` maximising ``score(states (n, N))`` on a dense sampling."""
        lo, hi = self.nodes[max(k - 1, 0)], self.nodes[min(k + 1, len(self.nodes) - 1)]
        times = np.linspace(lo, hi, samples + 1)
        return float(times[int(np.argmax(score(self.solution(times))))])


@dataclass
class NominalRun:
    """A request (:mod:`.lockstep`): the nominal run of ``f_numeric`` from ``x0`` over ``duration``
    (``stop``: see the module docstring, or None). Runs of the same flow and tolerance are
    answered as one batch."""

    f_numeric: object
    x0: np.ndarray
    duration: float
    tol: float
    stop: object = None

    batch = None            # no limit: a nominal batch is a few small arrays
    length = 0

    def key(self):
        return ("nominal", id(self.f_numeric), self.tol)

    @staticmethod
    def answer(requests: list["NominalRun"]) -> list[Nominal]:
        first = requests[0]
        return nominal_batch(first.f_numeric, np.array([r.x0 for r in requests], dtype=float),
                             np.array([r.duration for r in requests], dtype=float), first.tol,
                             [r.stop for r in requests])


def nominal(f_numeric, x0: np.ndarray, T: float, tol: float = 1e-9, refine: int = 2,
            stop=None) -> Nominal:
    """The nominal run of ``x' = f(x)`` from ``x0`` over ``[0, T]`` (module docstring)."""
    return nominal_batch(f_numeric, np.asarray(x0, dtype=float)[None, :], np.array([float(T)]), tol,
                         [stop], refine)[0]


def nominal_batch(f_numeric, x0: np.ndarray, T: np.ndarray, tol: float, stops: list,
                  refine: int = 2) -> list[Nominal]:
    """:func:`nominal` of the rows of ``x0`` ``(B, n)`` over ``[0, T_b]``, integrated together."""
    fun = _rows(f_numeric)
    scale = np.maximum(1.0, np.abs(x0))
    zero = np.zeros(len(x0))
    coarse = dop853(fun, zero, x0, T, tol, tol * scale, stops=stops)
    ends, times = T.copy(), [np.array(run.t) for run in coarse]
    stopped = [b for b, run in enumerate(coarse) if run.stopped]
    go_on = []
    for b in stopped:                                  # one step further than the crossing
        t = times[b]
        last_step = t[-1] - t[-2] if len(t) > 1 else T[b]
        ends[b] = min(T[b], t[-1] + last_step)
        if ends[b] > t[-1]:
            go_on.append((b, min(last_step, ends[b] - t[-1])))
    if go_on:
        idx = [b for b, _ in go_on]
        rest = dop853(fun, np.array([times[b][-1] for b in idx]), np.array([coarse[b].y for b in idx]),
                      ends[idx], tol, tol * scale[idx], first_step=np.array([h for _, h in go_on]))
        for b, run in zip(idx, rest):
            times[b] = np.concatenate([times[b], run.t[1:]])
    dense = dop853(fun, zero, x0, ends, DENSE_TOL, DENSE_TOL * scale, dense=True)
    out = []
    for t, run in zip(times, dense):
        nodes = np.concatenate([np.linspace(a, b, refine + 1)[:-1] for a, b in zip(t[:-1], t[1:])] + [t[-1:]])
        out.append(Nominal(DenseSolution(np.array(run.t), np.array(run.y_old), np.array(run.F)), nodes))
    return out


def _rows(f_numeric):
    """``f`` on a ``(k, n)`` array of states, one per row."""
    return lambda X: np.stack(f_numeric(list(X.T)), axis=1)


class NominalFailure(ArithmeticError):
    """The adaptive integration cannot go on (its step is below the spacing of the numbers)."""


class _Run:
    """One run's record: accepted times ``t``, the current state ``y`` and (dense) the interpolant
    data of each step; ``stopped`` when it ended at the ``stop`` crossing."""

    def __init__(self, t0: float, y0: np.ndarray):
        self.t, self.y, self.y_old, self.F, self.stopped = [t0], y0, [], [], False


#: accepted and rejected steps of one batch at most (the suite's runs take under 500): past them
#: the nominal run fails
MAX_STEPS = 20_000


def dop853(fun, t0: np.ndarray, y0: np.ndarray, t_end: np.ndarray, rtol: float, atol: np.ndarray,
           first_step: np.ndarray | None = None, dense: bool = False, stops: list | None = None) -> list[_Run]:
    """Adaptive DOP853 of the rows of ``y0`` from ``t0`` to ``t_end`` (module docstring): a
    :class:`_Run` per row. ``stops[b]`` (or None) ends run ``b`` at its guard crossing."""
    n_runs, n = y0.shape
    runs = [_Run(float(t), y.copy()) for t, y in zip(t0, y0)]
    t, y, t_end = t0.astype(float).copy(), y0.astype(float).copy(), np.asarray(t_end, dtype=float)
    f = fun(y)
    if not np.all(np.isfinite(f)):
        raise NominalFailure("the nominal run failed: the flow is not finite (or not real) at its start")
    h_abs = first_step.astype(float).copy() if first_step is not None else _initial_step(fun, t, y, t_end, f, rtol, atol)
    stops = stops or [None] * n_runs
    g = _margins(stops, y, np.arange(n_runs))
    active = t < t_end
    retry = np.zeros(n_runs, dtype=bool)
    K = np.empty((n_runs, STAGES + 1 + len(A_EXTRA), n))          # run b's stages are K[b]
    steps = 0
    while active.any():
        steps += 1
        if steps > MAX_STEPS:                   # sin(1e300 x): steps at the spacing of the numbers
            raise NominalFailure(f"the nominal run failed: more than {MAX_STEPS} steps (a flow that "
                                 "oscillates or changes faster than the horizon can be followed)")
        idx = np.flatnonzero(active)
        ti, yi, ha = t[idx], y[idx], h_abs[idx]
        min_step = 10 * np.abs(np.nextafter(ti, np.inf) - ti)
        if np.any(retry[idx] & ~(ha >= min_step)):         # a NaN step fails too, never loops
            raise NominalFailure("the nominal run failed: the step size it needs is below the spacing of "
                                 "the numbers (a stiff or overflowing flow)")
        ha = np.where(~retry[idx] & (ha < min_step), min_step, ha)
        t_new = np.minimum(ti + ha, t_end[idx])
        h = t_new - ti
        Ki = K[:len(idx)]
        Ki[:, 0] = f[idx]
        for s in range(1, STAGES):
            Ki[:, s] = fun(yi + _combine(Ki[:, :s], A[s, :s]) * h[:, None])
        y_new = yi + h[:, None] * _combine(Ki[:, :STAGES], B)
        Ki[:, STAGES] = f_new = fun(y_new)
        scale = atol[idx] + np.maximum(np.abs(yi), np.abs(y_new)) * rtol
        e5 = _norm(_combine(Ki[:, :STAGES + 1], E5) / scale) ** 2
        e3 = _norm(_combine(Ki[:, :STAGES + 1], E3) / scale) ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.where((e5 == 0) & (e3 == 0), 0.0, h * e5 / np.sqrt((e5 + 0.01 * e3) * n))
        # an overflowing state (inf, then NaN) is a rejected step: the step shrinks until it is
        # below the spacing of the numbers and the run fails, instead of NaN steps forever
        err = np.where(np.isfinite(err) & np.isfinite(y_new).all(axis=1), err, np.inf)
        factor = SAFETY * _power(err, EXPONENT)
        grow = np.where(err == 0, MAX_FACTOR, np.minimum(MAX_FACTOR, factor))
        shrink = np.maximum(MIN_FACTOR, factor)
        ok = err < 1
        grow = np.where(retry[idx], np.minimum(1.0, grow), grow)
        h_abs[idx] = h * np.where(ok, grow, shrink)
        retry[idx] = ~ok
        acc = np.flatnonzero(ok)
        if acc.size == 0:
            continue
        rows = idx[acc]
        g_new = _margins(stops, y_new[acc], rows)
        crossed = (g[rows] >= 0) & (g_new <= 0)
        F = None
        if dense or crossed.any():
            F = _interpolant(fun, Ki[acc], yi[acc], y_new[acc], h[acc])
        t[rows], y[rows], f[rows], g[rows] = t_new[acc], y_new[acc], f_new[acc], g_new
        active[rows] = t_new[acc] < t_end[rows]
        for j, b in enumerate(rows):
            run = runs[b]
            if crossed[j]:
                local = DenseSolution(np.array([ti[acc[j]], t_new[acc[j]]]), yi[acc[j]][None], F[j][None])
                root = brentq(lambda s: stops[b](local(s)[None, :])[0], ti[acc[j]], t_new[acc[j]],
                              xtol=4 * EPS, rtol=4 * EPS)
                run.t.append(root)
                run.y, run.stopped, active[b] = local(root), True, False
                continue
            run.t.append(float(t_new[acc[j]]))
            run.y = y_new[acc[j]]
            if dense:
                run.y_old.append(yi[acc[j]])
                run.F.append(F[j])
    return runs


def _interpolant(fun, K: np.ndarray, y: np.ndarray, y_new: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The DOP853 dense-output coefficients ``(k, 7, n)`` of accepted steps (three more stages)."""
    for s in range(STAGES + 1, STAGES + 1 + len(A_EXTRA)):
        K[:, s] = fun(y + _combine(K[:, :s], A_EXTRA[s - STAGES - 1, :s]) * h[:, None])
    dy, hh = y_new - y, h[:, None]
    F = np.empty((len(y), 7, y.shape[1]))
    F[:, 0] = dy
    F[:, 1] = hh * K[:, 0] - dy
    F[:, 2] = 2 * dy - hh * (K[:, STAGES] + K[:, 0])
    F[:, 3:] = hh[:, None, :] * np.matmul(D, K)
    return F


def _combine(K: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``sum_i w_i K[b, i]`` for every run ``b``: ``(k, n)``. A matrix-vector product per run (the
    runs stacked), so a run's sums do not depend on the other runs of the batch."""
    return np.matmul(K.transpose(0, 2, 1), weights)


def _power(x: np.ndarray, p: float) -> np.ndarray:
    """``x ** p`` element by element through the C library's ``pow`` (numpy's vectorised power may
    differ from it in the last bit, which would make a run's steps depend on the batch)."""
    return np.array([float(v) ** p if v > 0 else np.inf for v in x])


def _norm(X: np.ndarray) -> np.ndarray:
    """Euclidean norm of every row, as an inner product per row."""
    return np.sqrt(np.matmul(X[:, None, :], X[:, :, None])[:, 0, 0])


def _initial_step(fun, t, y, t_end, f, rtol, atol) -> np.ndarray:
    """First step sizes (Hairer, Norsett & Wanner, II.4; scipy's ``select_initial_step``)."""
    n = y.shape[1]
    length = np.abs(t_end - t)
    scale = atol + np.abs(y) * rtol
    d0 = _norm(y / scale) / n ** 0.5
    d1 = _norm(f / scale) / n ** 0.5
    h0 = np.where((d0 < 1e-5) | (d1 < 1e-5), 1e-6, 0.01 * d0 / np.where(d1 == 0, 1.0, d1))
    h0 = np.minimum(h0, length)
    f1 = fun(y + h0[:, None] * f)
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = _norm((f1 - f) / scale) / n ** 0.5 / h0
        h1 = np.where((d1 <= 1e-15) & (d2 <= 1e-15), np.maximum(1e-6, h0 * 1e-3),
                      _power(0.01 / np.maximum(d1, d2), 1.0 / 8.0))
    return np.where(length == 0, 0.0, np.minimum(np.minimum(100 * h0, h1), length))


def _margins(stops: list, X: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``stops[b](x)`` for the states ``X`` of runs ``rows`` (``inf`` for runs without a stop); each
    distinct stop function is evaluated once on its rows."""
    out = np.full(len(rows), np.inf)
    by_fn: dict = {}
    for j, b in enumerate(rows):
        if stops[b] is not None:
            by_fn.setdefault(stops[b], []).append(j)
    for fn, js in by_fn.items():
        out[js] = fn(X[js])
    return out
