"""Sampling polytopic initial sets and piecewise-constant input signals (for Monte Carlo).

Polytope ``P = {x : A x <= b, E x == f}``. Points are drawn in the coordinates of its affine
hull: ``x = x0 + N z`` with ``E x0 = f`` and ``N`` an orthonormal basis of ``null(E)``, so
``P = {z : (A N) z <= b - A x0}`` is full-dimensional in ``z``.

* *extremes first*: every vertex when the hull's dimension ``d`` and the number of facets are
  small (brute force: each ``d``-subset of facets solved as equalities, kept when feasible),
  else LP maximisers along the coordinate axes and random directions (each an extreme point);
  then one point per facet (the mean of the vertices on it) and the mean of the vertices;
* *uniform interior*: hit-and-run (Smith 1984): from an interior point, a uniform random
  direction, a uniform point on the chord through ``P``; chains are run in parallel and only
  their state after a burn-in of ``30 d + 50`` steps is kept (one chain per sample).

Time-varying inputs ``u(t) in [lo, hi]`` are sampled as piecewise-constant signals with pieces of
length ``step``: constant at each corner of the input box, bang-bang signals (each piece at a
random corner) and one-switch signals (a corner, then the opposite one from a piece start on)
for the structured states, uniform pieces for the random ones.

Choices among transitions enabled at one jump (:class:`reach.model.simulate.Branches`): each
structured run once per branch, taking the same branch at every jump, uniform choices for the
random ones (:func:`branch_plan`).
"""

from __future__ import annotations

import itertools
from math import comb

import numpy as np
import scipy.linalg

from reach import lp
from reach.errors import InputError
from reach.model.automaton import HybridAutomaton, LinearSet

MAX_SUBSETS = 4000
MAX_PIECES = 100_000
TOL = 1e-9
SWITCH_SIGNAL_RUNS = 2000   # one-switch input signals of the structured round, about (structured_signals)
CHOICE_SLOTS = 8        # choice values per run where transitions may be enabled together (Branches)


class PolytopeSampler:
    """Points of ``P`` (see the module docstring); ``low, high`` its bounding box."""

    def __init__(self, P: LinearSet, low: np.ndarray, high: np.ndarray):
        self.P = P
        n = P.A.shape[1]
        if P.E.shape[0]:
            x0, *_ = np.linalg.lstsq(P.E, P.f, rcond=None)
            self.N = scipy.linalg.null_space(P.E)
        else:
            x0, self.N = (low + high) / 2, np.eye(n)
        self.x0 = x0
        self.G = P.A @ self.N                     # constraints G z <= h in hull coordinates
        self.h = P.b - P.A @ x0
        keep = np.linalg.norm(self.G, axis=1) > TOL  # rows constant on the hull
        self.G, self.h = self.G[keep], self.h[keep]
        self.d = self.N.shape[1]
        self.vertices = self._vertices()
        self.centre_z = self._centre()

    def to_x(self, Z: np.ndarray) -> np.ndarray:
        return self.x0 + Z @ self.N.T

    def to_z(self, X: np.ndarray) -> np.ndarray:
        return (X - self.x0) @ self.N

    def contains(self, X: np.ndarray) -> np.ndarray:
        scale = 1.0 + np.abs(X).max(axis=1)
        ok = np.all(X @ self.P.A.T - self.P.b <= TOL * scale[:, None], axis=1)
        if self.P.E.shape[0]:
            ok &= np.all(np.abs(X @ self.P.E.T - self.P.f) <= 1e-7 * scale[:, None], axis=1)
        return ok

    # ------------------------------------------------------------ extreme points
    def _vertices(self) -> np.ndarray:
        d, k = self.d, self.G.shape[0]
        if d == 0:
            return np.zeros((1, 0))
        if comb(k, d) <= MAX_SUBSETS:
            found = []
            for rows in itertools.combinations(range(k), d):
                M = self.G[list(rows)]
                if abs(np.linalg.det(M)) < 1e-12:
                    continue
                z = np.linalg.solve(M, self.h[list(rows)])
                if np.all(self.G @ z <= self.h + 1e-9 * (1 + np.abs(self.h))):
                    found.append(z)
            if found:
                return _unique(np.array(found))
        directions = np.vstack([np.eye(d), -np.eye(d), np.random.default_rng(0).normal(size=(4 * d, d))])
        points = []
        for c in directions:
            res = lp.maximize(c, self.G, self.h)
            if res.optimal:
                points.append(res.x)
        return _unique(np.array(points).reshape(-1, d))

    def _centre(self) -> np.ndarray:
        """An interior point: the mean of the extreme points, pulled in by the Chebyshev LP."""
        if self.d == 0:
            return np.zeros(0)
        norms = np.linalg.norm(self.G, axis=1)
        c = np.zeros(self.d + 1)
        c[-1] = 1.0
        res = lp.maximize(c, np.hstack([self.G, norms[:, None]]), self.h,
                          bounds=[(None, None)] * self.d + [(0, None)])
        if res.optimal:
            return res.x[:-1]
        return self.vertices.mean(axis=0)

    def structured(self) -> np.ndarray:
        """Vertices, then one point per facet, then the centre (in state coordinates)."""
        V = self.vertices
        points = [V]
        if self.d and V.shape[0] > 1:
            tight = np.abs(V @ self.G.T - self.h) <= 1e-9 * (1 + np.abs(self.h))
            for j in range(self.G.shape[0]):
                if tight[:, j].sum() >= 2:
                    points.append(V[tight[:, j]].mean(axis=0, keepdims=True))
        points.append(self.centre_z[None, :])
        return self.to_x(np.concatenate(points))

    # ------------------------------------------------------------ interior
    def uniform(self, count: int, rng) -> np.ndarray:
        """``count`` points by parallel hit-and-run chains from the centre."""
        Z = np.repeat(self.centre_z[None, :], count, axis=0)
        if self.d == 0:
            return self.to_x(Z)
        for _ in range(30 * self.d + 50):
            Z = self._step(Z, rng)
        return self.to_x(Z)

    def _step(self, Z, rng):
        u = rng.normal(size=Z.shape)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        Gu = u @ self.G.T                               # (N, k)
        slack = self.h[None, :] - Z @ self.G.T          # >= 0
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = slack / Gu
        t_hi = np.min(np.where(Gu > TOL, ratio, np.inf), axis=1, initial=np.inf)
        t_lo = np.max(np.where(Gu < -TOL, ratio, -np.inf), axis=1, initial=-np.inf)
        t_hi, t_lo = np.maximum(t_hi, 0.0), np.minimum(t_lo, 0.0)
        t = t_lo + (t_hi - t_lo) * rng.random(Z.shape[0])
        return Z + t[:, None] * u

    def pull_inside(self, X: np.ndarray) -> np.ndarray:
        """``X`` projected on the hull, then shrunk towards the centre until inside ``P``."""
        Z = self.to_z(X)
        c = self.centre_z
        D = Z - c
        GD = D @ self.G.T
        slack = self.h - self.G @ c
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.min(np.where(GD > TOL, slack[None, :] / GD, np.inf), axis=1, initial=np.inf)
        lam = np.clip(lam, 0.0, 1.0) * (1 - 1e-12)
        return self.to_x(c + lam[:, None] * D)


def _unique(Z: np.ndarray) -> np.ndarray:
    if Z.shape[0] == 0:
        return Z
    scale = 1.0 + np.abs(Z).max()
    keys = np.round(Z / (1e-9 * scale))
    _, first = np.unique(keys, axis=0, return_index=True)
    return Z[np.sort(first)]


# ---------------------------------------------------------------- input signals

def input_step(model: HybridAutomaton, dt: float, step: float | None) -> float:
    """The signals' piece length: ``step`` (default horizon / 20) as a multiple of ``dt``."""
    step = model.horizon / 20.0 if step is None else float(step)
    step = dt * max(1, int(round(step / dt)))
    if model.horizon / step > MAX_PIECES:
        raise InputError(f"input_step {step:g} cuts the horizon into more than {MAX_PIECES} pieces",
                         field="--option input_step")
    return step


def pieces(model: HybridAutomaton, step: float) -> int:
    return int(np.ceil(model.horizon / step - 1e-9)) + 1


def _input_box(model: HybridAutomaton):
    U = model.varying_inputs
    return np.array([u.low for u in U]), np.array([u.high for u in U])


def input_signals(model: HybridAutomaton, count: int, step: float, rng) -> np.ndarray:
    """``(count, K, m)`` uniform values of the varying inputs on the pieces ``[k step, (k+1) step)``."""
    lo, hi = _input_box(model)
    return lo + (hi - lo) * rng.random((count, pieces(model, step), lo.size))


def structured_signals(model: HybridAutomaton, states: int, step: float, rng):
    """Signals for ``states`` structured initial states: each state with each of the ``C``
    constant corners of the input box (at most 16) and with a bang-bang signal (every piece at a
    random corner); the first few states also with every one-switch signal, a corner held up to
    a piece start and the opposite corner from there on (``C (K - 1)`` signals; the worst input
    of a linear system against a linear bound is bang-bang, and often switches once), as many
    states as ``SWITCH_SIGNAL_RUNS`` allows, at least one. Returns ``(values (R, K, m), owner
    (R,), once (R,))``, ``owner`` the state index of each signal, ``once`` whether it is a
    one-switch signal."""
    lo, hi = _input_box(model)
    K, m = pieces(model, step), lo.size
    corners = np.array(list(itertools.product([0, 1], repeat=m))[:16])
    C = corners.shape[0]
    pick = np.empty((states, C + 1, K, m), dtype=int)
    pick[:, :C] = corners[None, :, None, :]
    pick[:, C] = rng.integers(0, 2, size=(states, K, m))
    picks, owner = [pick.reshape(states * (C + 1), K, m)], [np.repeat(np.arange(states), C + 1)]
    once_rows = 0
    if K > 1:
        after = np.arange(K)[None, :] >= np.arange(1, K)[:, None]            # (K - 1 switch pieces, K)
        once = np.where(after[None, :, :, None], 1 - corners[:, None, None, :], corners[:, None, None, :])
        once = once.reshape(C * (K - 1), K, m)
        switching = min(states, max(1, SWITCH_SIGNAL_RUNS // once.shape[0]))
        picks.append(np.tile(once, (switching, 1, 1)))
        owner.append(np.repeat(np.arange(switching), once.shape[0]))
        once_rows = switching * once.shape[0]
    owner = np.concatenate(owner)
    return (np.where(np.concatenate(picks) == 1, hi, lo), owner,
            np.arange(owner.size) >= owner.size - once_rows)


# ---------------------------------------------------------------- branches

def branch_plan(options: int, structured: int, X, tau, signal, rng):
    """``(X, tau, signal, choice, structured)`` with choice values
    (:class:`reach.model.simulate.Branches`, ``CHOICE_SLOTS`` per run): each of the first
    ``structured`` runs repeated ``options`` (``B``) times, copy ``k`` with the value ``(k +
    1/2) / B`` in every slot -- the ``k``-th enabled transition at every jump, and where only
    ``m < B`` are enabled the ``floor(m (k + 1/2) / B)``-th, which steps by ``m / B <= 1`` with
    ``k``, so each of the ``m`` is still taken by some copy; the other runs (``tau``, ``signal``
    rows kept with theirs) with uniform values."""
    order = np.r_[np.repeat(np.arange(structured), options), np.arange(structured, X.shape[0])]
    branch = np.tile(np.arange(options), structured)
    choice = np.concatenate([np.repeat(((branch + 0.5) / options)[:, None], CHOICE_SLOTS, axis=1),
                             rng.random((X.shape[0] - structured, CHOICE_SLOTS))])
    if signal is not None:
        signal = (signal[0], signal[1][order], None if signal[2] is None else signal[2][order])
    return X[order], None if tau is None else tau[order], signal, choice, structured * options
