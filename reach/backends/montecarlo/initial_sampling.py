"""Sampling polytopic initial sets and piecewise-constant input signals (for Monte Carlo).

Polytope ``P = {x : A x <= b, E x == f}``. Points are drawn in the coordinates of its affine
hull: ``x = x0 + N z`` with ``E x0 = f`` and ``N`` an orthonormal basis of ``null(E)``, so
``P = {z : (A N) z <= b - A x0}`` is full-dimensional in ``z``.

* *extremes first*: every vertex when the hull's dimension ``d`` and the number of facets are
  small (brute force: each ``d``-subset of facets solved as equalities, kept when feasible),
  else LP maximisers along the coordinate axes and random directions (each an extreme point);
  then one point per facet (the mean of the vertices on it) and the mean of the vertices;
* *uniform interior*: by rejection from the bounding box where ``P`` fills at least
  :data:`MIN_ACCEPTANCE` of the box, equalities only on coordinates the box pins (``t == 0``):
  exactly uniform, a few products per sample (the ISS's initial box cut by its outputs'
  ranges); else by hit-and-run (Smith 1984): from an interior point, a random direction, a
  uniform point on the chord through ``P``; chains are run in parallel and only their state
  after a burn-in of ``30 d + 50`` steps is kept (one chain per sample). The directions are
  normal with the extreme points' covariance (hit-and-run in coordinates where ``P`` is about
  round: a thin strip is crossed along its length as fast as across), and the coordinates are
  those of ``P``'s own affine hull: the equalities, and the inequalities that pin a direction
  (a box side of width 0, two opposite rows, an inequality that holds with equality all over
  ``P``), across which a chord has length 0 and a chain would never move.

Time-varying inputs ``u(t) in [lo, hi]`` are sampled as piecewise-constant signals with pieces of
length ``step``: constant at each corner of the input box, bang-bang signals (each piece at a
random corner) and one-switch signals (a corner, then the opposite one from a piece start on)
for the structured states, uniform pieces for the random ones; for a linear initial mode, also
bang-bang signals aimed into the unsafe set by the maximum principle (:func:`extremal_runs`).

Choices among transitions enabled at one jump (:class:`reach.model.simulate.Branches`): each
structured run once per branch, taking the same branch at every jump, uniform choices for the
random ones (:func:`branch_plan`).
"""

from __future__ import annotations

import itertools
from functools import cached_property
from math import comb

import numpy as np
import scipy.linalg

from reach import lp
from reach.errors import InputError
from reach.model.automaton import HybridAutomaton, LinearSet
from reach.model.constraints import affine_magnitudes

MAX_SUBSETS = 4000
MAX_PIECES = 10_000     # pieces of a sampled input signal over the horizon (each run holds them all)
TOL = 1e-9
SWITCH_SIGNAL_RUNS = 2000   # one-switch input signals of the structured round, about (structured_signals)
CHOICE_SLOTS = 8        # choice values per run where transitions may be enabled together (Branches)
#: the least share of its bounding box a polytope must fill to be sampled by rejection from the
#: box (at most 1 / MIN_ACCEPTANCE draws per point on average)
MIN_ACCEPTANCE = 0.1


class PolytopeSampler:
    """Points of ``P`` (see the module docstring); ``low, high`` its bounding box."""

    def __init__(self, P: LinearSet, low: np.ndarray, high: np.ndarray):
        self.P = P
        self.low, self.high = np.asarray(low, float), np.asarray(high, float)
        self.drawn_by = None                      # how the last uniform() drew its points (law())
        E, f = P.E, P.f
        pinned = _pinned_rows(P.A, P.b)          # a x <= b with -a x <= -b: a x == b
        if pinned.size:
            E, f = np.vstack([E, P.A[pinned]]), np.concatenate([f, P.b[pinned]])
        self._hull(E, f)
        if self.d and self._radius() <= TOL * (1.0 + np.abs(self.h).max(initial=0.0)):
            implicit = self._implicit_rows()    # flat without a pinned pair (x <= y, y <= x)
            if implicit.size:
                self._hull(np.vstack([E, P.A[implicit]]), np.concatenate([f, P.b[implicit]]))

    def _hull(self, E, f):
        """Coordinates ``x = x0 + N z`` of the affine hull ``E x = f`` and the rows ``G z <= h``
        of ``A x <= b`` in them (rows constant on the hull dropped). The hull must be the
        polytope's own: where the inequalities pin a direction too (a box side ``t: 0``, an
        implicit equality), a hit-and-run chord across it has length 0 and a chain never moves."""
        P, n = self.P, self.P.A.shape[1]
        if E.shape[0]:
            x0, *_ = np.linalg.lstsq(E, f, rcond=None)
            self.N = scipy.linalg.null_space(E)
        else:
            x0, self.N = (self.low + self.high) / 2, np.eye(n)
        self.x0 = x0
        self.G = P.A @ self.N                     # constraints G z <= h in hull coordinates
        self.h = P.b - P.A @ x0
        keep = np.linalg.norm(self.G, axis=1) > TOL  # rows constant on the hull
        self.G, self.h = self.G[keep], self.h[keep]
        self.d = self.N.shape[1]
        self.__dict__.pop("vertices", None)
        self.__dict__.pop("centre_z", None)

    def _radius(self) -> float:
        """The radius of the largest ball in ``G z <= h`` (Chebyshev LP); 0 if none is found,
        infinite where the solver gives no answer."""
        norms = np.linalg.norm(self.G, axis=1)
        c = np.zeros(self.d + 1)
        c[-1] = 1.0
        try:
            res = lp.maximize(c, np.hstack([self.G, norms[:, None]]), self.h,
                              bounds=[(None, None)] * self.d + [(0, None)])
        except lp.LPError:
            return np.inf                       # no answer: the hull found so far stands
        return float(res.x[-1]) if res.optimal else 0.0

    def _implicit_rows(self) -> np.ndarray:
        """The rows of ``A x <= b`` that hold with equality all over ``P`` (an LP each: their
        least value on ``P`` is their bound)."""
        P = self.P
        args = dict(A_eq=P.E if P.E.shape[0] else None, b_eq=P.f if P.E.shape[0] else None)
        found = []
        for i, (row, bound) in enumerate(zip(P.A, P.b)):
            try:
                res = lp.minimize(row, P.A, P.b, **args)
            except lp.LPError:
                continue
            if res.optimal and bound - res.value <= TOL * (1.0 + abs(bound)):
                found.append(i)
        return np.array(found, dtype=int)

    def to_x(self, Z: np.ndarray) -> np.ndarray:
        return self.x0 + Z @ self.N.T

    def to_z(self, X: np.ndarray) -> np.ndarray:
        return (X - self.x0) @ self.N

    def contains(self, X: np.ndarray) -> np.ndarray:
        """Whether each state of ``X`` lies in ``P`` up to rounding of each row's own size
        (``TOL``, equalities ``1e-7``, times ``1 + m``, ``m`` the magnitude the row combines:
        :func:`reach.model.constraints.affine_magnitudes`), not the state's largest coordinate."""
        ok = np.all(X @ self.P.A.T - self.P.b <= TOL * (1.0 + self._magnitudes[0](X)), axis=1)
        if self.P.E.shape[0]:
            ok &= np.all(np.abs(X @ self.P.E.T - self.P.f) <= 1e-7 * (1.0 + self._magnitudes[1](X)), axis=1)
        return ok

    @cached_property
    def _magnitudes(self) -> tuple:
        """The row magnitudes of ``A x <= b`` and of ``E x == f``."""
        return affine_magnitudes(self.P.A, self.P.b), affine_magnitudes(self.P.E, self.P.f)

    # ------------------------------------------------------------ extreme points
    @cached_property
    def vertices(self) -> np.ndarray:
        """The extreme points (hull coordinates), found on first use: a containment test needs
        none (on the ISS's 273-dimensional polytope they are 1638 LPs)."""
        return self._vertices()

    @cached_property
    def centre_z(self) -> np.ndarray:
        return self._centre()

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
        """``count`` points by rejection from the bounding box where ``P`` fills enough of it,
        else by parallel hit-and-run chains from the centre; :meth:`law` says which."""
        self.drawn_by = "point" if self.d == 0 else "rejection"
        if self.d:
            X = self._rejection(count, rng)
            if X is not None:
                return X
            self.drawn_by = "hit-and-run"
        Z = np.repeat(self.centre_z[None, :], count, axis=0)
        if self.d == 0:
            return self.to_x(Z)
        for _ in range(self.burn_in):
            Z = self._step(Z, rng)
        return self.to_x(Z)

    @property
    def burn_in(self) -> int:
        """Hit-and-run steps per point: ``30 d + 50``."""
        return 30 * self.d + 50

    def law(self) -> str:
        """The law of the points the last :meth:`uniform` drew, in words: exactly uniform by
        rejection; by hit-and-run, uniform in the limit of the chain (exactly on a segment,
        where each step is a uniform point of the whole chord)."""
        if self.drawn_by == "point":
            return "the polytope's single point"
        if self.drawn_by == "rejection":
            return "uniform over the polytope (rejection from its bounding box: exact)"
        exact = "exact on a segment" if self.d == 1 else "the chain's law tends to uniform"
        return f"uniform over the polytope (hit-and-run, {self.burn_in} steps per point: {exact})"

    def _rejection(self, count: int, rng) -> np.ndarray | None:
        """``count`` uniform points of ``P`` drawn uniformly in its bounding box and kept when
        inside (exactly uniform on ``P``); None where the box is not finite or a first batch
        keeps less than :data:`MIN_ACCEPTANCE` (an equality other than a coordinate pinned by
        the box, ``t == 0``, keeps next to nothing)."""
        if not (np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high))):
            return None
        kept, total = [], 0
        for _ in range(int(np.ceil(2 / MIN_ACCEPTANCE))):
            X = self.low + (self.high - self.low) * rng.random((count, self.low.size))
            inside = X[self.contains(X)]
            if not kept and inside.shape[0] < MIN_ACCEPTANCE * count:
                return None
            kept.append(inside)
            total += inside.shape[0]
            if total >= count:
                return np.concatenate(kept)[:count]
        return None

    @cached_property
    def _rounding(self) -> np.ndarray:
        """``L`` with ``L L^T`` the covariance of the extreme points (plus a small multiple of
        the identity): hit-and-run directions ``L g``, ``g`` standard normal, are isotropic in
        coordinates where the polytope is about round, so a chain crosses a thin strip's length
        as fast as its width. Any fixed law of directions that gives ``u`` and ``-u`` the same
        density keeps the uniform law stationary (each step is uniform on a chord of a line
        drawn independently of where on it the point lies)."""
        V = self.vertices
        C = np.cov(V.T).reshape(self.d, self.d) if V.shape[0] > 1 else np.zeros((self.d, self.d))
        C = C + (1e-9 * np.trace(C) / self.d + 1e-300) * np.eye(self.d)
        try:
            return np.linalg.cholesky(C)
        except np.linalg.LinAlgError:
            return np.eye(self.d)

    def _step(self, Z, rng):
        u = rng.normal(size=Z.shape) @ self._rounding.T
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


def _pinned_rows(A, b) -> np.ndarray:
    """Rows ``i`` of ``A x <= b`` with an opposite row ``j`` (``A_j = -c A_i``, ``c > 0``) and
    ``b_i + b_j / c`` at most rounding: together they say ``A_i x == b_i`` (a box side of width
    0, ``t: 0``)."""
    A, b = np.asarray(A, float), np.asarray(b, float)
    if not A.shape[0]:
        return np.zeros(0, dtype=int)
    norms = np.linalg.norm(A, axis=1)
    ok = norms > TOL
    U = np.where(ok[:, None], A / np.where(ok, norms, 1.0)[:, None], 0.0)
    c = np.where(ok, b / np.where(ok, norms, 1.0), np.inf)
    opposite = (U @ U.T <= -1 + 1e-12) & (c[:, None] + c[None, :] <= TOL * (1.0 + np.abs(c)[:, None]))
    return np.flatnonzero(np.any(opposite, axis=1) & ok)


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
    if step is not None and float(step) < dt * (1 - 1e-9):
        raise InputError(f"input_step {float(step):g} is shorter than the simulation step {dt:g} "
                         "(a piece lasts at least one step; -o dt sets that)", field="--option input_step")
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


EXTREMAL_PIECES = 1000    # pieces over the horizon of the extremal signals (extremal_runs)
EXTREMAL_TARGETS = 48     # target instants per direction, besides the pieces' time windows (extremal_runs)
EXTREMAL_DIRECTIONS = 8   # unsafe rows followed (extremal_runs)
MAX_ROWS = 64             # unsafe rows weighed (extremal_runs)


def extremal_runs(model: HybridAutomaton, prop, starts: np.ndarray, dt: float):
    """Runs aimed into ``prop``'s unsafe set by the time-varying inputs (Pontryagin's maximum
    principle for a linear flow), or None where the initial mode's flow is not linear or
    ``prop`` has no linear unsafe piece there that the inputs move.

    Write the initial mode's flow as ``x' = A x + b + B u`` (``B`` the columns of the varying
    inputs, which the model carries as states of flow 0). For a row ``h x <= g`` of an unsafe
    piece, a run gets deepest along ``c = -h`` at an instant ``T`` by maximising
    ``c^T x(T) = c^T e^{A T} x0 + int_0^T c^T e^{A (T - s)} (b + B u(s)) ds``: the initial
    state the corner of the initial box (of a polytope: the start among ``starts``, its
    structured states, vertices first) with the largest ``c^T e^{A T} x0``, and per input ``u_i`` at its upper end on a piece where the
    piece's share of the integral, ``int c^T e^{A (T - s)} B_i ds``, is positive, at its lower
    end elsewhere: the best signal constant on pieces ``[k h, (k + 1) h)``. With ``T = J h +
    d`` the share of a whole piece ``k < J`` is ``c^T e^{A d} Phi^(J - 1 - k) W_h`` and that of
    the piece holding ``T`` is ``c^T W_d`` (``Phi = e^{A h}``, ``W_d = int_0^d e^{A r} dr B``,
    both from one exponential of ``[[A, B], [0, 0]]``). ``h`` cuts the horizon into about
    ``EXTREMAL_PIECES`` pieces (a multiple of ``dt``); ``T`` runs over ``EXTREMAL_TARGETS``
    piece ends, the horizon, and the ends of the time window a global clock's rows give the
    piece (an instant ``t == 20`` is one target); ``c`` runs over the rows (at most
    ``EXTREMAL_DIRECTIONS``, those the inputs move most over the horizon). After ``T`` the
    input is held. Jumps are not followed: past one the run is a guess like any sampled one,
    and only its replay decides.

    Returns ``(owners (R,), states (R, n), step h, values (R, K, m))``, ``owners`` the row of
    ``starts`` whose switch time and choices a run takes (the start itself for a polytope)."""
    U = model.varying_inputs
    linear = model.modes[model.initial.mode].linear
    pieces_hs = prop.halfspace_pieces(model.initial.mode) if hasattr(prop, "halfspace_pieces") else None
    if not U or linear is None or not pieces_hs:
        return None
    A, _ = linear
    inputs = [u.index for u in U]
    B = A[:, inputs].copy()
    A = A.copy()
    A[:, inputs] = 0.0
    n, m = B.shape
    augmented = np.zeros((n + m, n + m))
    augmented[:n, :n], augmented[:n, n:] = A, B

    def flow_over(d: float):                    # (e^{A d}, W_d)
        E = scipy.linalg.expm(augmented * d)
        return E[:n, :n], E[:n, n:]

    h = dt * max(1, int(round(model.horizon / EXTREMAL_PIECES / dt)))
    K = pieces(model, h)
    Phi, W = flow_over(h)

    def backward(c, count: int) -> np.ndarray:  # c^T Phi^j, j < count, inputs' own coordinates dropped
        out = np.empty((count, n))
        out[0] = c
        for j in range(1, count):
            out[j] = out[j - 1] @ Phi
        out[:, inputs] = 0.0
        return out

    directions = []                             # (c, the piece's time window)
    for H, g in pieces_hs:
        window = _clock_window(model, H, g)
        directions += [(-row, window) for row in H]
    directions = directions[:MAX_ROWS]
    if not directions:
        return None
    moved = np.zeros(len(directions))           # the inputs' reach along each c over the horizon
    rows = np.array([c for c, _ in directions])
    for _ in range(K):                          # all rows at once, nothing kept (W's rows of the
        moved += np.abs(rows @ W).sum(axis=1)   # inputs' own coordinates are 0: they have no flow)
        rows = rows @ Phi
    if not moved.max(initial=0.0) > 0:
        return None
    order = np.argsort(-moved, kind="stable")
    order = order[moved[order] > TOL * moved.max()][:EXTREMAL_DIRECTIONS]
    backs = {r: backward(directions[r][0], K) for r in order}
    lo, hi = _input_box(model)
    grid = h * np.unique(np.linspace(1, K - 1, EXTREMAL_TARGETS).round())
    box = (model.initial.low, model.initial.high) if model.initial.is_box else None
    owners, states, signals = [], [], []
    for r in order:
        c, (first, last) = directions[r]
        instants = np.unique(np.r_[grid, model.horizon, first, last].clip(h * 1e-6, model.horizon))
        instants = instants[(instants >= first - 1e-9 * h) & (instants <= last + 1e-9 * h)]
        for T in instants:
            J = min(int(np.floor(T / h + 1e-9)), K - 1)
            d = max(T - J * h, 0.0)
            if d <= 1e-9 * h:                   # a piece end
                back, holding = backs[r], np.zeros((0, m))
            else:
                E_d, W_d = flow_over(d)
                back, holding = backward(c @ E_d, J + 1), (c @ W_d)[None]
            share = np.concatenate([back[J - 1::-1] @ W if J else np.zeros((0, m)), holding])
            toward = back[J]
            values = np.where(share > 0, hi, lo)
            signals.append(np.concatenate([values, np.repeat(values[-1:], K - values.shape[0], axis=0)]))
            owner = int(np.argmax(starts @ toward))               # largest c^T e^{A T} x0
            owners.append(owner)
            states.append(starts[owner] if box is None else np.where(toward > 0, box[1], box[0]))
    if not signals:                             # every row's time window lies past the horizon
        return None
    return np.array(owners), np.array(states), h, np.stack(signals)


def _clock_window(model: HybridAutomaton, H: np.ndarray, g: np.ndarray) -> tuple[float, float]:
    """``[first, last]``: the instants a piece ``H x <= g`` allows by its rows on the global clock
    alone (the whole horizon if the model has none)."""
    first, last = 0.0, float(model.horizon)
    clock = model.global_clock
    if clock is None:
        return first, last
    for row, bound in zip(H, g):
        a = row[clock]
        if a == 0 or np.any(np.delete(row, clock)):
            continue
        if a > 0:
            last = min(last, bound / a)
        else:
            first = max(first, bound / a)
    return first, last


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
