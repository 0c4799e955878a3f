"""Verified enclosure of a run stretch: polynomial flow plus a proved error radius (rigorous mode).

On a subdomain (scaled deviations ``xi in [-1, 1]^m``) the flow on each step ``[t_k, t_k + h]`` is
the polynomial ``P_k(xi, sigma)`` of order ``n`` in ``xi`` and the scaled step time ``sigma in [-1, 1]``
(``t = t_k + h (sigma + 1)/2``), built by Picard iteration (eq. 6, in time and deviations) from
``P_{k-1}(xi, 1)``; the piecewise polynomial ``x~(xi, t)`` is continuous and exact at ``t = 0``.

Error bound. The defect ``delta = dx~/dt - f(x~)`` is enclosed on the whole step by Taylor-model
arithmetic (:mod:`.tm`). The error ``e = x - x~`` solves ``e' = Jbar e - delta`` with ``Jbar`` the mean
of ``Df`` on the segment ``[x~, x]``. In the norm ``|v|_S = sqrt(v' S v)`` the logarithmic norm gives
``d|e|/dt <= mu_S(Jbar) |e| + |delta|_S``, so with ``mu >= mu_S(Df(z))`` on a box ``Z`` holding every
such segment and ``D >= sup |delta|_S``, Gronwall's lemma bounds the error radius on the step by

    r(t_k + tau) <= r_k exp(mu tau) + D (exp(mu tau) - 1)/mu,

whose largest value on the step is ``max(r_k, r_{k+1})``. ``Z`` is the range of ``x~`` on the step
widened by ``w rho`` (``w_i = sqrt((S^-1)_ii)``, since ``|e_i| <= w_i |e|_S``) for an a priori radius
``rho``, accepted once ``max(r_k, r_{k+1}) < rho`` (an error leaving the ball first would contradict the
bound up to its exit). ``mu`` comes from the interval Jacobian ``[Jc - Jr, Jc + Jr]`` on ``Z``
(:mod:`.interval`): ``mu_2(T Jc T^-1) + || |T| Jr |T^-1| ||_2``, ``T = S^(1/2)``. The metric ``S`` solves the
Lyapunov equation of a step's Jacobian shifted by ``alpha`` and follows the flow: at a node it is
replaced by the metric of the next step's Jacobian when that lowers the growth, the radius carried
over by ``||T_new T_old^-1||_2``. Several shifts are tried and the one with the smallest final error
kept (any choice of metrics gives a valid bound). Following the flow pays on long arcs whose
Jacobian turns (SRNA01 line-of-sight margin: rigorous lower end 0.360 with the start metric, 0.377).

A stretch may start from a Taylor model ``x0 + [-b, b]`` (the states entering a mode): the
error then starts at the radius ``sqrt(b' |S| b)`` instead of 0. Those entry states come from
:func:`crossing`: the window in which runs may cross the guard is taken as one step, the entry
instant solved for as a polynomial in the deviations (eqs. 13-14) with a proved residual, and the
state there kept as a polynomial in the deviations and one slack variable. On SRNA01 the interval
hull of the window's step boxes, which this replaces, made the entry into the rendezvous mode
wider than the runs by a time-decorrelated box (Fx max 3.069 N against 2.658 N sampled, all of it
present on the entry box before the rendezvous flow: its error radius there is 1e-6 m).

Limit: ``mu`` needs the Jacobian's range over the states of a whole step. For a deep network
controller, interval (and Taylor-model remainder) enclosures of that range wrap at every layer; on
the CW SIREN transfer (five sine layers, omega = 30) the interval gradient of the network over a 1 mm
box is already 5 times wider than the gradient, so no enclosure closes there.

Soundness rests on: the Taylor-model enclosures, the interval Jacobian, Gronwall's lemma, and for
entry states the mean value theorem and a linear program that rules out guard faces (solved with a
margin far above the solver's tolerance). Not covered by directed rounding: floating-point
rounding of coefficients, for which a relative allowance ``ROUNDING`` of the enclosed magnitudes
is added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.linalg
import scipy.optimize

from reach.backends.taylor.bound import polynomial_range
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.event import solve_event
from reach.backends.taylor.interval import Jet
from reach.backends.taylor.tm import TM, _imul

ROUNDING = 1e-12              # relative allowance for floating-point rounding
MIN_STEP = 1e-8               # shortest step of a stretch, relative to its duration
SHIFTS = (1e-3, 1e-2, 1e-1, 1.0)   # Lyapunov shifts alpha, relative to the spectral radius
# the least ratio of a Lyapunov metric's smallest eigenvalue to its largest: below it the sign of
# the smallest is rounding (a nilpotent Jacobian, spectral radius 0, gives condition numbers of 1e24)
MIN_METRIC_RATIO = 1e-12


@lru_cache(maxsize=None)
def _sigma_tables(order: int, nvars: int):
    """For each monomial: the index of the same monomial without its ``sigma`` (last variable)
    power, and that power."""
    alg = algebra(order, nvars)
    power = alg.exps[:, -1]
    base = alg.exps.copy()
    base[:, -1] = 0
    target = np.array([alg.index[tuple(e)] for e in base])
    return target, power


@lru_cache(maxsize=None)
def _shift_tables(order: int, nvars: int, var: int):
    """For each monomial ``xi^b y^p`` (``y``: the variable ``var``) and each ``j <= p``: its
    index, the index of ``xi^b y^j``, ``p`` and ``j`` (the binomial expansion of ``(c + r y)^p``)."""
    alg = algebra(order, nvars)
    rows = []
    for k, e in enumerate(alg.exps):
        for j in range(e[var] + 1):
            f = e.copy()
            f[var] = j
            rows.append((k, alg.index[tuple(f)], e[var], j))
    source, target, power, j = np.array(rows, dtype=int).T
    return source, target, power, j, np.array([math.comb(a, b) for a, b in zip(power, j)], dtype=float)


def variable_in(p: DA, var: int, centre: float, radius: float) -> DA:
    """``p`` with its variable ``var`` replaced by ``centre + radius y``: ``p`` on the slice
    ``[centre - radius, centre + radius]`` of that variable, in the same algebra (the degree of
    no term grows); a linear map of the coefficients."""
    source, target, power, j, binomial = _shift_tables(p.alg.order, p.alg.nvars, var)
    weight = binomial * float(centre) ** (power - j) * float(radius) ** j
    c = np.zeros_like(p.c)
    np.add.at(c.T, target, (p.c[..., source] * weight).T)
    return DA(p.alg, c)


def sigma_in(p: DA, centre: float, radius: float) -> DA:
    """``p(xi, centre + radius sigma)``: the step's time (the last variable) restricted to a
    slice (:func:`variable_in`)."""
    return variable_in(p, p.alg.nvars - 1, centre, radius)


def at_sigma(p: DA, value: float) -> DA:
    """``p(xi, sigma = value)`` as a DA in the same algebra (no ``sigma`` terms left)."""
    target, power = _sigma_tables(p.alg.order, p.alg.nvars)
    c = np.zeros_like(p.c)
    np.add.at(c.T, target, (p.c * float(value) ** power).T)
    return DA(p.alg, c)


@dataclass
class Step:
    t0: float
    h: float
    poly: list            # P_k(xi, sigma), one DA per state
    low: np.ndarray       # range of P_k on the step
    high: np.ndarray
    defect: np.ndarray    # |delta_i| bounds on the step


@dataclass
class Enclosure:
    """The verified stretch: steps, the error radius at each node (in that step's metric) and
    the bound of ``|e_i|`` on each step."""

    steps: list[Step]
    radius: np.ndarray                 # len(steps) + 1
    error_box: np.ndarray              # (len(steps), n): |e_i| bound on each step
    crossing_models = True             # :func:`crossing` may start from its steps (a class constant)

    def tm(self, k: int) -> list[TM]:
        """Taylor models of the true state on step ``k`` (polynomial + error box)."""
        step, e = self.steps[k], self.error_box[k]
        return [TM(p, -ei, ei) for p, ei in zip(step.poly, e)]

    def tm_at_end(self, k: int) -> list[TM]:
        step, e = self.steps[k], self.error_box[k]
        return [TM(at_sigma(p, 1.0), -ei, ei) for p, ei in zip(step.poly, e)]


def polynomial_step(f, X: list[DA], t0: float, h: float) -> Step:
    """``P_k`` by ``n + 1`` Picard passes from the polynomial state ``X`` at ``t0``, with the bounds
    of its range and of its defect on the step."""
    alg = X[0].alg
    s, n = alg.nvars - 1, alg.order
    P = list(X)
    for _ in range(n + 1):
        G = [r.integrate(s) for r in f(P)]
        P = [x + (G_i - at_sigma(G_i, -1.0)) * (0.5 * h) for x, G_i in zip(X, G)]
    F = f([TM(p) for p in P])
    defect, size = [], []
    for p, Fi in zip(P, F):
        lo, hi = (TM(p.derivative(s) * (2.0 / h)) - Fi).bound()
        flo, fhi = Fi.bound()
        defect.append(max(abs(lo), abs(hi)))
        size.append(max(abs(flo), abs(fhi)))
    defect = np.array(defect) + ROUNDING * np.array(size)
    ranges = [TM(p).bound() for p in P]
    step = Step(t0, h, P, np.array([r[0] for r in ranges]), np.array([r[1] for r in ranges]), defect)
    step.rate_size = np.array(size)
    return step


def polynomial_steps(f, x0: list[DA], nodes: np.ndarray, stop=None, rel_tol: float = 1e-6,
                     max_halvings: int = 12) -> list[Step]:
    """Phase 1: the polynomials ``P_k`` and their defect bounds from ``nodes[0]`` to ``nodes[-1]``.

    The first step is the nominal run's first step; a step is accepted when its defect ratio
    ``r`` (its defect over ``rel_tol`` times the size of the rates) is at most the threshold
    (1 at first). The defect is modelled as ``r(h) = F + c h^n``: the time part of the
    truncated Picard series scales as ``h^n``, and the floor ``F`` does not shrink with ``h``:
    the order-``n`` terms of ``f(P)`` in the deviations alone, which the integral lifts to order
    ``n + 1`` and the algebra drops, and the truncation remainder of ``f(P)`` (large for a wide
    subdomain of a strongly nonlinear flow such as a network; 2.07e-5 = 2.02e-5 + 4.8e-7 on the
    cubic term of an undamped Duffing oscillator from a box of width 0.2 x 0.4 at t = 0.13). The next (or retried) step is ``0.9 h
    (threshold/r)^(1/n)``, at most doubling, which is right where ``F`` is negligible. Where it
    is not, that rule shortens every accepted step by the same factor (``r`` stays put) and the
    step size collapses geometrically; so before an accepted step shortens the next one, the
    step is also taken at ``h/2`` (:func:`_floor`): when that does not halve ``r`` (it would
    fall by ``2^-n``), the half step's ratio is taken as the floor ``F``. A floor, also when a
    rejected step's retry at a shorter step no longer halves ``r``, is accepted (the defect bound
    is sound whatever its size; it enters the error radius of phase 2) and later steps are held
    to twice it. ``stop(step)`` may end the sweep after a step. A step shorter than
    ``MIN_STEP`` of the stretch (before its last step) ends the sweep with ArithmeticError
    (Van der Pol's flow from a wide box: 15,000 steps down to 1e-320 before, 1.4 s to give up
    now)."""
    X, steps = list(x0), []
    n = x0[0].alg.order
    t, end = float(nodes[0]), float(nodes[-1])
    h = float(nodes[1] - nodes[0]) if len(nodes) > 1 else end - t
    floor = 0.0                                  # the defect ratio that steps cannot go below
    shortest = MIN_STEP * (end - t)
    growth = lambda threshold, ratio: 0.9 * (threshold / ratio) ** (1.0 / max(n, 1)) if ratio > 0 else 2.0
    while t < end * (1 - 1e-15) - 1e-300:
        if h < shortest < end - t:
            raise ArithmeticError(f"the step size collapsed to {h:.3g} at t = {t:g} (the defect does not "
                                  "shrink with the step)")
        h = min(h, end - t)
        threshold, previous = max(1.0, 2.0 * floor), None
        for _ in range(max_halvings + 1):
            step = polynomial_step(f, X, t, h)
            ratio = _defect_ratio(step, rel_tol)
            if np.isfinite(ratio) and ratio <= threshold:
                break
            if previous is not None and np.isfinite(ratio) and ratio > 0.5 * previous:
                floor, threshold = ratio, ratio          # the defect no longer shrinks with h
                break
            previous = ratio if np.isfinite(ratio) else None
            factor = growth(threshold, ratio) if np.isfinite(ratio) else 0.1
            h *= min(max(factor, 0.1), 0.5)
        else:
            raise ArithmeticError(f"the time series does not converge on a step at t = {t:g}")
        if growth(threshold, ratio) < 1.0 and floor < ratio:
            half = _floor(f, X, t, step.h, ratio, rel_tol)
            if half is not None:
                floor = max(floor, half)
                threshold = max(threshold, 2.0 * floor)
        steps.append(step)
        X = [at_sigma(p, 1.0) for p in step.poly]
        t += step.h
        h = step.h * min(max(growth(threshold, ratio), 0.5), 2.0)
        if stop is not None and stop(step):
            break
    return steps


def _defect_ratio(step: Step, rel_tol: float) -> float:
    """The step's defect over ``rel_tol`` times the size of the rates, its largest component."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.max(step.defect / (rel_tol * step.rate_size + 1e-300)))


def _floor(f, X: list[DA], t: float, h: float, ratio: float, rel_tol: float) -> float | None:
    """The defect ratio of the step from ``X`` at ``t`` of length ``h/2`` where it is more than
    half ``ratio`` (the ratio at ``h``), else None. A defect ``c h^n`` falls by ``2^-n`` from
    ``h`` to ``h/2``; one that keeps more than half is mostly the floor ``F`` of ``r(h) = F + c
    h^n``, and ``r(h/2) = F + c (h/2)^n`` bounds it from above (:func:`polynomial_steps`)."""
    half = _defect_ratio(polynomial_step(f, X, t, 0.5 * h), rel_tol)
    return half if np.isfinite(half) and half > 0.5 * ratio else None


def jacobian_box(f, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interval enclosure ``[Jc - Jr, Jc + Jr]`` of ``Df`` on the box ``[low, high]``."""
    out = f(Jet.seed(low, high))
    glo = np.array([o.glo for o in out])
    ghi = np.array([o.ghi for o in out])
    return 0.5 * (glo + ghi), 0.5 * (ghi - glo)


def lyapunov_metric(J0: np.ndarray, shift: float) -> np.ndarray | None:
    """``S`` with ``(J0 - a I)' S + S (J0 - a I) = -I``, scaled to largest eigenvalue 1, for the
    shift ``a = max(0, max Re eig J0) + shift s``; None where no such ``S`` is positive definite
    beyond rounding.

    The scale ``s`` is the spectral radius ``rho(J0)`` (at least 1e-12), else (no positive
    definite ``S`` for it) the spectral norm ``||J0||_2``. Any ``a > max Re eig J0`` makes
    ``J0 - a I`` Hurwitz and ``S`` positive definite, so ``mu_S(J0) = a - 1/(2 lambda_max(S))``
    before scaling; only the conditioning depends on ``s``. A nilpotent ``J0 != 0`` (the double
    integrator ``h' = v, v' = -g`` of a bouncing ball) has ``rho = 0``: a shift of 1e-12 leaves
    ``S`` singular (condition 1e24), while ``||J0||_2`` sets the time scale of its growth
    (``e^{J0 t} = I + J0 t``). A metric from either is a metric, so the error bound stays valid
    (module docstring)."""
    eig = np.linalg.eigvals(J0)
    base = max(0.0, float(np.max(eig.real)))
    S = _shifted_lyapunov(J0, base + shift * max(float(np.max(np.abs(eig))), 1e-12))
    norm = float(np.linalg.norm(J0, 2))
    if S is None and norm > 0:
        S = _shifted_lyapunov(J0, base + shift * norm)
    return S


def _shifted_lyapunov(J0: np.ndarray, a: float) -> np.ndarray | None:
    """The solution ``S`` of ``(J0 - a I)' S + S (J0 - a I) = -I`` scaled to largest eigenvalue 1,
    or None where it is not positive definite beyond ``MIN_METRIC_RATIO``."""
    A = J0 - a * np.eye(len(J0))
    try:
        S = scipy.linalg.solve_continuous_lyapunov(A.T, -np.eye(len(J0)))
    except (np.linalg.LinAlgError, ValueError):
        return None
    S = 0.5 * (S + S.T)
    if not np.all(np.isfinite(S)):
        return None
    w = np.linalg.eigvalsh(S)
    if w[0] <= MIN_METRIC_RATIO * w[-1]:      # not positive definite beyond rounding
        return None
    return S / w[-1]


def _metric_factors(S: np.ndarray):
    """``T = S^(1/2)``, ``T^-1`` and the error-box weights ``w_i = sqrt((S^-1)_ii)`` of a metric."""
    w_eig, V = np.linalg.eigh(S)
    T = V @ np.diag(np.sqrt(w_eig)) @ V.T
    Tinv = V @ np.diag(1.0 / np.sqrt(w_eig)) @ V.T
    return T, Tinv, np.sqrt(np.diag(np.linalg.inv(S)))


def _log_norm(T: np.ndarray, Tinv: np.ndarray, Jc: np.ndarray, Jr: np.ndarray) -> float:
    """Bound of ``mu_S(J)`` over the interval matrix ``[Jc - Jr, Jc + Jr]``."""
    M = T @ Jc @ Tinv
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1]) + float(np.linalg.norm(np.abs(T) @ Jr @ np.abs(Tinv), 2))


@dataclass
class _Track:
    """The error bound of :func:`error_radii` under one Lyapunov shift: the current metric
    ``(S, T, T^-1, w)``, the radii at the nodes and the error box of each step."""

    shift: float
    metric: tuple | None = None
    radii: list = field(default_factory=lambda: [0.0])
    boxes: list = field(default_factory=list)


def error_radii(f, steps: list[Step], initial_error: np.ndarray | None = None):
    """Phase 2: the proved error radii at the step nodes and the error box of each step, under
    the metric shift (of :data:`SHIFTS`) with the smallest final error box; None if the a priori
    radius cannot be closed on some step for any shift.

    ``initial_error`` bounds ``|e_i|`` at the first node (zero when the polynomial start is
    exact); in the first metric it is the radius ``sqrt(b' |S| b)``, ``b`` the bounds, since
    ``e' S e <= sum_ij |S_ij| |e_i| |e_j|``.

    The metric follows the flow: before each step, the Lyapunov metric of the step's own
    Jacobian (shift ``shift``) replaces the current one when that lowers the growth over the
    step. Changing the metric at a node is sound: ``|e|_new = |T_new T_old^-1 T_old e| <=
    ||T_new T_old^-1||_2 |e|_old``. The shifts run in lockstep and share the interval Jacobians:
    on each step one on the step's range and one on that range widened by the largest ``w rho``
    of the shifts still to close (a box holding every shift's ``Z`` is a valid ``Z`` for each;
    this halves the sweep's Jacobian evaluations, which were half of its time on SRNA01).
    Returns ``(radii, boxes)``: ``radii[k]`` is the radius at ``t_k`` in step ``k``'s metric
    (``radii[-1]`` at the end, in the last one), ``boxes[k]`` bounds ``|e_i|`` on step ``k``."""
    tracks = [_Track(shift) for shift in SHIFTS]
    for step in steps:
        Jc0, Jr0 = jacobian_box(f, step.low, step.high)
        if not (np.all(np.isfinite(Jc0)) and np.all(np.isfinite(Jr0))):
            return None
        pending = []                 # [track, radius at t_k, defect bound, a priori radius]
        for track in tracks:
            S_new = lyapunov_metric(Jc0, track.shift)
            rk = track.radii[-1]
            if S_new is not None:
                T_new, Tinv_new, w_new = _metric_factors(S_new)
                if track.metric is None:
                    track.metric = (S_new, T_new, Tinv_new, w_new)
                else:
                    _, T, Tinv, _ = track.metric
                    factor = float(np.linalg.norm(T_new @ Tinv, 2))
                    if np.log(max(factor, 1e-300)) + _log_norm(T_new, Tinv_new, Jc0, Jr0) * step.h < \
                            _log_norm(T, Tinv, Jc0, Jr0) * step.h:
                        track.metric, rk = (S_new, T_new, Tinv_new, w_new), rk * factor
            if track.metric is None:
                continue
            S = track.metric[0]
            if len(track.radii) == 1 and initial_error is not None:
                track.radii[0] = rk = float(np.sqrt(initial_error @ np.abs(S) @ initial_error))
            D = float(np.sqrt(step.defect @ np.abs(S) @ step.defect))
            pending.append([track, rk, D, 2.0 * (rk + D * step.h) + 1e-300])
        closed = []
        for _ in range(40):
            if not pending:
                break
            widen = np.max([track.metric[3] * rho for track, _, _, rho in pending], axis=0)
            Jc, Jr = jacobian_box(f, step.low - widen, step.high + widen)
            if not (np.all(np.isfinite(Jc)) and np.all(np.isfinite(Jr))):
                break
            open_ = []
            for item in pending:
                track, rk, D, rho = item
                _, T, Tinv, w = track.metric
                mu = _log_norm(T, Tinv, Jc, Jr)
                if mu * step.h > 700:
                    continue
                growth = np.exp(mu * step.h)
                phi = step.h if abs(mu * step.h) < 1e-12 else (growth - 1.0) / mu
                r_next = rk * growth + D * phi
                if max(rk, r_next) < rho:
                    track.boxes.append(w * max(rk, r_next))
                    track.radii.append(r_next)
                    closed.append(track)
                else:
                    item[3] = 2.0 * max(rk, r_next)
                    open_.append(item)
            pending = open_
        tracks = closed
        if not tracks:
            return None
    best = min(tracks, key=lambda track: np.max(track.boxes[-1]))
    return np.array(best.radii), best.boxes


def enclose_stretch(f, x0: list[DA], nodes: np.ndarray, stop=None, rel_tol: float = 1e-6,
                    initial_error: np.ndarray | None = None) -> Enclosure | None:
    """The verified enclosure of the flow from the initial set ``x0 + [-b, b]`` (``b`` the
    ``initial_error``, zero by default); of the metric shifts tried, the one with the smallest
    final error box is kept."""
    steps = polynomial_steps(f, x0, nodes, stop, rel_tol)
    out = error_radii(f, steps, initial_error)
    if out is None:
        return None
    radii, boxes = out
    return Enclosure(steps, radii, np.array(boxes))


def compose(p: DA, args: list[TM]) -> TM:
    """``p(args)`` as a Taylor model: every monomial is the Taylor-model product of its parent
    monomial and one argument (each product encloses the terms its truncation drops), and the
    monomials are summed with ``p``'s coefficients."""
    alg = p.alg
    values = [args[0].const_like(1.0)]
    for k in range(1, alg.size):
        values.append(values[alg.parent[k]] * args[alg.step[k]])
    return TM.weighted_sum(p.c, values)


def crossing(f, x_start: list[DA], start_error: np.ndarray, h: float, faces) -> list[TM] | None:
    """Taylor models of the states in which runs first enter a guard ``{a_j . x + b_j <= 0}``
    (``faces``: the ``(a_j, b_j)``), for runs that enter it in the window ``[t_s, t_s + h]``;
    None when the argument below does not apply.

    ``x_start`` is the polynomial state at ``t_s`` in the deviations ``xi`` (and an unused step
    time), ``start_error`` bounds ``|e_i|`` there. The caller guarantees the window: every run is
    outside the guard at ``t_s`` (no earlier step can meet it) and every run has left the mode by
    ``t_s + h`` (each is inside some urgent guard there); a run that enters the guard does so in
    the window. The window is one step: ``P(xi, sigma)`` with
    error box ``E`` (:func:`polynomial_step`, :func:`error_radii`), so the true state is
    ``x = P + e``, ``|e_i| <= E_i``. A run enters the guard at the first instant all faces are
    ``<= 0``, on a face ``j`` with ``g_j = 0``. A face can be that face only if ``{g_j = 0, g_k <= 0
    for all k}`` meets the interval hull of the window's states (a linear program, solved with a
    margin); if only one face can, it is the one crossed; with ``G = a_j . P + b_j`` (a polynomial)
    the entry instant ``s`` satisfies ``|G(xi, s)| <= eps = |a_j| . E`` and, if ``dG/dsigma`` keeps
    its sign on the window (range ``[c_lo, c_hi]`` not containing 0), it is unique.

    The root ``s*(xi)`` of ``G`` is expanded as a polynomial by inverting ``(xi, sigma) -> (xi, G)``
    (eqs. 13-14, :func:`.event.solve_event`). Its residual ``rho(xi) = G(xi, s*(xi))`` is enclosed
    by Taylor-model composition, and by the mean value theorem (``s*`` and ``s`` both in
    ``[-1, 1]``, which is checked for ``s*``) the entry instant is ``s = s*(xi) + d``,
    ``d in ([-eps, eps] - rho) / [c_lo, c_hi]``. With ``d`` written ``d_mid + d_rad v`` for one more
    variable ``v in [-1, 1]``, the entry state ``P(xi, s*(xi) + d_mid + d_rad v) + [-E, E]`` is a
    Taylor model in ``(xi, v)`` (and the next stretch's step time, unused): unlike the interval
    hull of the window's states, it keeps the state components tied to one another and to the
    entry instant. Its order-``n`` terms are bounded (eq. 27) into the remainder: the next
    stretch's Picard steps cannot integrate the rates of order-``n`` terms of the start within the
    order-``n`` algebra, so they would leave a defect that no step size removes (about
    ``|Df| |order-n part|``, 1.5e-4 m/min^2 on SRNA01's entry into rendezvous, which stalled the
    step control). A relative ``ROUNDING`` allowance is added to ``eps`` and to the result."""
    alg = x_start[0].alg
    m = alg.nvars - 1
    step = polynomial_step(f, x_start, 0.0, h)
    out = error_radii(f, [step], start_error)
    if out is None:
        return None
    error = out[1][0]
    hull = np.array([TM(p, -e, e).bound() for p, e in zip(step.poly, error)])
    open_faces = [j for j in range(len(faces)) if _may_cross(faces, j, hull)]
    if len(open_faces) != 1:
        return None
    a, b = (np.asarray(v, dtype=float) for v in faces[open_faces[0]])
    G = DA.weighted_sum(a, step.poly) + float(b)
    c_lo, c_hi = polynomial_range(G.derivative(m))
    if not (np.isfinite(c_lo) and np.isfinite(c_hi)) or c_lo <= 0 <= c_hi:
        return None
    s_star, _ = solve_event(step.poly, G)
    s_lo, s_hi = polynomial_range(s_star)
    if not (-1 <= s_lo and s_hi <= 1):                 # NaN fails too
        return None
    target = algebra(alg.order, m + 2)
    xi = [TM(DA.var(target, j)) for j in range(m)]
    s_star = s_star.embed(target)
    rho_lo, rho_hi = compose(G, xi + [TM(s_star)]).bound()
    if not (np.isfinite(rho_lo) and np.isfinite(rho_hi)):
        return None
    eps = float(np.abs(a) @ error) * (1 + ROUNDING) + ROUNDING * max(abs(rho_lo), abs(rho_hi))
    d_lo, d_hi = _imul(-eps - rho_hi, eps - rho_lo, 1.0 / c_hi, 1.0 / c_lo)
    s = TM(s_star + DA.var(target, m, 0.5 * (d_lo + d_hi), 0.5 * (d_hi - d_lo)))
    top = target.degree == alg.order
    entry = []
    for p, e in zip(step.poly, error):
        x = compose(p, xi + [s])
        lo, hi = x.bound()
        slack = e + ROUNDING * max(abs(lo), abs(hi))
        c = x.poly.c.copy()
        c[~top] = 0.0
        top_lo, top_hi = polynomial_range(DA(target, c))
        c = x.poly.c.copy()
        c[top] = 0.0
        entry.append(TM(DA(target, c), x.lo + top_lo - slack, x.hi + top_hi + slack))
    return entry


def _may_cross(faces, j: int, hull: np.ndarray) -> bool:
    """Whether ``{a_j . x + b_j = 0, a_k . x + b_k <= 0 for all k}`` meets the box ``hull`` (rows
    ``[lo, hi]``): the linear program is solved with every constraint relaxed by a margin of
    ``1e-7`` of its scale (at least HiGHS's feasibility tolerance, 1e-7); an error within the
    tolerance, or any status but "infeasible", answers "may cross", so "empty" is a safe answer."""
    A = np.array([a for a, _ in faces], dtype=float)
    b = np.array([b for _, b in faces], dtype=float)
    scale = 1.0 + np.abs(b) + np.abs(A) @ np.max(np.abs(hull), axis=1)
    margin = 1e-7 * scale
    rows = np.vstack([A, -A[j:j + 1]])
    limits = np.r_[margin - b, margin[j] + b[j]]
    box = [(lo - 1e-7 * (1 + abs(lo)), hi + 1e-7 * (1 + abs(hi))) for lo, hi in hull]
    out = scipy.optimize.linprog(np.zeros(len(hull)), A_ub=rows, b_ub=limits, bounds=box, method="highs")
    return out.status != 2
