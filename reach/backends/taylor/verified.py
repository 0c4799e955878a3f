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

Limit: ``mu`` needs the Jacobian's range over the states of a whole step. For a deep network
controller, interval (and Taylor-model remainder) enclosures of that range wrap at every layer; on
the CW SIREN transfer (five sine layers, omega = 30) the interval gradient of the network over a 1 mm
box is already 5 times wider than the gradient, so no enclosure closes there.

Soundness rests on: the Taylor-model enclosures, the interval Jacobian, Gronwall's lemma. Not
covered by directed rounding: floating-point rounding of coefficients, for which a relative
allowance ``ROUNDING`` of the enclosed magnitudes is added.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg

from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.interval import Jet
from reach.backends.taylor.tm import TM

ROUNDING = 1e-12              # relative allowance for floating-point rounding
SHIFTS = (1e-3, 1e-2, 1e-1, 1.0)   # Lyapunov shifts alpha, relative to the spectral radius


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

    The first step is the nominal run's first step; a step is accepted when its defect is at
    most ``rel_tol`` times the size of the rates (the time series converges on it). The time
    part of the defect scales as ``h^n``, so the next (or retried) step is ``0.9 h (rel_tol
    size/defect)^(1/n)``, at most doubling. Part of the defect does not shrink with ``h``: the
    order-``n`` truncation of ``f(P)`` in the deviations (large for a wide subdomain of a
    strongly nonlinear flow such as a network). When halving the step no longer halves the
    defect, that floor is accepted (the defect bound is sound whatever its size; it enters the
    error radius of phase 2) and later steps are held to twice the floor. ``stop(step)`` may end
    the sweep after a step."""
    X, steps = list(x0), []
    n = x0[0].alg.order
    t, end = float(nodes[0]), float(nodes[-1])
    h = float(nodes[1] - nodes[0]) if len(nodes) > 1 else end - t
    floor = 0.0                                  # the defect ratio that steps cannot go below
    while t < end * (1 - 1e-15) - 1e-300:
        h = min(h, end - t)
        threshold, previous = max(1.0, 2.0 * floor), None
        for _ in range(max_halvings + 1):
            step = polynomial_step(f, X, t, h)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = float(np.max(step.defect / (rel_tol * step.rate_size + 1e-300)))
            if np.isfinite(ratio) and ratio <= threshold:
                break
            if previous is not None and np.isfinite(ratio) and ratio > 0.5 * previous:
                floor, threshold = ratio, ratio          # the defect no longer shrinks with h
                break
            previous = ratio if np.isfinite(ratio) else None
            factor = 0.9 * (threshold / ratio) ** (1.0 / max(n, 1)) if np.isfinite(ratio) and ratio > 0 else 0.1
            h *= min(max(factor, 0.1), 0.5)
        else:
            raise ArithmeticError(f"the time series does not converge on a step at t = {t:g}")
        steps.append(step)
        X = [at_sigma(p, 1.0) for p in step.poly]
        t += step.h
        factor = 0.9 * (threshold / ratio) ** (1.0 / max(n, 1)) if ratio > 0 else 2.0
        h = step.h * min(max(factor, 0.5), 2.0)
        if stop is not None and stop(step):
            break
    return steps


def jacobian_box(f, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interval enclosure ``[Jc - Jr, Jc + Jr]`` of ``Df`` on the box ``[low, high]``."""
    out = f(Jet.seed(low, high))
    glo = np.array([o.glo for o in out])
    ghi = np.array([o.ghi for o in out])
    return 0.5 * (glo + ghi), 0.5 * (ghi - glo)


def lyapunov_metric(J0: np.ndarray, shift: float) -> np.ndarray | None:
    """``S`` with ``(J0 - a I)' S + S (J0 - a I) = -I``, ``a = max(0, max Re eig J0) + shift rho(J0)``."""
    eig = np.linalg.eigvals(J0)
    a = max(0.0, float(np.max(eig.real))) + shift * max(float(np.max(np.abs(eig))), 1e-12)
    A = J0 - a * np.eye(len(J0))
    try:
        S = scipy.linalg.solve_continuous_lyapunov(A.T, -np.eye(len(J0)))
    except (np.linalg.LinAlgError, ValueError):
        return None
    S = 0.5 * (S + S.T)
    w = np.linalg.eigvalsh(S)
    if not np.all(np.isfinite(S)) or w[0] <= 0:
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


def error_radii(f, steps: list[Step], shift: float):
    """Phase 2: the proved error radii at the step nodes and the error box of each step, or None
    if the a priori radius cannot be closed on some step.

    The metric follows the flow: before each step, the Lyapunov metric of the step's own
    Jacobian (shift ``shift``) replaces the current one when that lowers the growth over the
    step. Changing the metric at a node is sound: ``|e|_new = |T_new T_old^-1 T_old e| <=
    ||T_new T_old^-1||_2 |e|_old``. Returns ``(radii, boxes)``: ``radii[k]`` is the radius at
    ``t_k`` in step ``k``'s metric (``radii[-1]`` at the end, in the last one), ``boxes[k]``
    bounds ``|e_i|`` on step ``k``."""
    current, r, boxes = None, [0.0], []
    for step in steps:
        Jc0, Jr0 = jacobian_box(f, step.low, step.high)
        if not (np.all(np.isfinite(Jc0)) and np.all(np.isfinite(Jr0))):
            return None
        S_new = lyapunov_metric(Jc0, shift)
        rk = r[-1]
        if S_new is not None:
            T_new, Tinv_new, w_new = _metric_factors(S_new)
            if current is None:
                current = (S_new, T_new, Tinv_new, w_new)
            else:
                _, T, Tinv, _ = current
                factor = float(np.linalg.norm(T_new @ Tinv, 2))
                if np.log(max(factor, 1e-300)) + _log_norm(T_new, Tinv_new, Jc0, Jr0) * step.h < \
                        _log_norm(T, Tinv, Jc0, Jr0) * step.h:
                    current, rk = (S_new, T_new, Tinv_new, w_new), rk * factor
        if current is None:
            return None
        S, T, Tinv, w = current
        D = float(np.sqrt(step.defect @ np.abs(S) @ step.defect))
        rho = 2.0 * (rk + D * step.h) + 1e-300
        for _ in range(40):
            Jc, Jr = jacobian_box(f, step.low - w * rho, step.high + w * rho)
            if not (np.all(np.isfinite(Jc)) and np.all(np.isfinite(Jr))):
                return None
            mu = _log_norm(T, Tinv, Jc, Jr)
            if mu * step.h > 700:
                return None
            growth = np.exp(mu * step.h)
            phi = step.h if abs(mu * step.h) < 1e-12 else (growth - 1.0) / mu
            r_next = rk * growth + D * phi
            if max(rk, r_next) < rho:
                break
            rho = 2.0 * max(rk, r_next)
        else:
            return None
        boxes.append(w * max(rk, r_next))
        r.append(r_next)
    return np.array(r), boxes


def enclose_stretch(f, x0: list[DA], nodes: np.ndarray, stop=None, rel_tol: float = 1e-6) -> Enclosure | None:
    """The verified enclosure of the flow from the polynomial initial set ``x0`` (no remainder);
    of the metric shifts tried, the one with the smallest final error box is kept."""
    steps = polynomial_steps(f, x0, nodes, stop, rel_tol)
    best = None
    for shift in SHIFTS:
        out = error_radii(f, steps, shift)
        if out is not None and (best is None or np.max(out[1][-1]) < np.max(best[1][-1])):
            best = out
    if best is None:
        return None
    radii, boxes = best
    return Enclosure(steps, radii, np.array(boxes))
