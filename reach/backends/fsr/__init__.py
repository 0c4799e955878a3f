"""The fsr back-end: forward stochastic reach and reach-avoid (Vinod et al.; Crane et al., the seed).

Model. One linear mode ``x' = A x + b`` (controller substituted) with i.i.d. kicks
``w ~ N(mu, Sigma)`` added to the ``enters`` states at ``t_k = k * step < at``; discretised
exactly into ``x[k+1] = Phi (x[k] + G w[k]) + c`` (:mod:`reach.model.ltv`, seed eq. 4), with
``x[k]`` the state at ``t_k`` before its kick, as the Monte Carlo simulator observes it.

Reach, ``P(x(at) in S)`` with ``S = {H x <= g}`` (eqs. 5, 11): ``x[K] ~ N(m[K], P[K])`` by the
moment recursion (eqs. 12-14), and the probability is the Gaussian polytope integral of
:mod:`reach.sets.gaussian`.

Reach-avoid, ``P(x(at) in S and x(t_k) in safe for every k < K)``: the stacked trajectory is
Gaussian, so the answer is one Gaussian polytope integral over the rows ``(k, h)`` (one per
constraint and step) with ``Cov(h_j x[j], h_k x[k]) = h_k Psi(k, j) P[j] h_j^T`` for ``j <= k``
(Markov structure: the kicks after ``t_j`` are independent of ``x[j]``). Made fast by structure:

* *dropping*: each one-sided constraint has a marginal violation probability ``q``; the
  smallest are dropped while their sum stays within ``drop_budget``. Dropping only enlarges
  the event, and by Boole's inequality the dropped constraints remove at most ``sum q``, so
  ``P in [P_kept - sum q, P_kept]`` rigorously;
* the kept rows are integrated either by Genz's method on their stacked covariance with
  variable prioritisation (``method: genz``, the default), or by *sequential conditioning*
  along time (``method: markov``): each quasi-Monte Carlo path carries only the conditional
  mean of the state; the conditional covariance, shared by all paths, is updated by scalar
  Kalman steps ``C <- C - C h h^T C / (h C h^T)`` and propagated by ``Phi`` between steps, so
  a row costs ``O(n)`` per path instead of ``O(rows)``. Measured on the tight LQR-1 corridor
  (1003 rows, 141 kept; benchmarks/fsr_vs_montecarlo.py): Genz with dropping reaches an
  interval width of 1.1e-3 in 0.2 s (6e-4 in 1 s); without dropping it keeps 515 rows (all
  with a non-zero violation probability) and reaches 2e-3 in 1.2 s; sequential conditioning
  reaches 1.9e-3 in 5.6 s, its fixed time order leaving far more variance than Genz's
  prioritisation, which outweighs its cheaper rows. Genz with dropping is the default.

The interval reported is the integration interval (:class:`~reach.sets.gaussian.Probability`)
widened downwards by the Boole sum. Verdict for ``probability: {at_least: p}``: SAFE when the
lower end is ``>= p``; otherwise UNKNOWN (there is no single counterexample run to give for a
probability) with ``details["verdict"]`` ``violated`` (upper end ``< p``) or ``undecided``.

Row cap. When more than ``max_rows`` rows survive the dropping, only ``max_rows`` of them,
evenly spaced in time, are integrated; the others are dropped too and their marginal violation
probabilities join the Boole sum. The kept event still contains the true one, so the upper end
stays an upper bound, and the lower end stays rigorous (it may become 0 when the dropped rows are
likely to fail: then the answer is an upper bound, which is what decides a violated requirement).

Switched models: staying in the initial mode. A model with several modes is accepted when its
initial mode ``M`` (``x' = A x + b``, invariant ``S = {H x <= g}``) can only be left through urgent
transitions and ``S`` is *forward invariant with strict inflow* under ``M``'s flow: on every facet
``h_i x = g_i`` of ``S``, ``h_i (A x + b) < 0`` (checked exactly when ``h_i`` is a left eigenvector of
``A``, by an LP otherwise), no outgoing guard meets the interior of ``S``, and the initial point is
interior. Then between kicks a run cannot leave the interior, so it leaves ``M`` only if a
post-kick state ``x[k] + G w[k]`` is outside the interior. With ``B = sum_k sum_i P(h_i (x[k] + G
w[k]) >= g_i)`` (Boole, Gaussian marginals of the linear system of ``M``), the model's probability
lies in ``[P_M - B, P_M + B]`` where ``P_M`` is the probability computed on ``M`` alone: on the event
"never leaves", the switched runs and the runs of ``M`` coincide. This is the sliding-mode
boundary layer of the VTXO models (``|s_i| <= phi_i`` decays as ``s_i' = -lam_i s_i`` inside).

A reach property from an initial box (the state uniformly distributed over it, as the Monte Carlo
back-end samples it) is one randomised QMC integral over the box and the kicks' Genz variables
together (:func:`reach.sets.gaussian.uniform_shift_probability`): the box moves the target's bounds,
the kicks are integrated as above. Non-Gaussian laws go through :mod:`.fourier`, from a model on
request with ``method: fourier`` (the initial box's sinc factors). Its interval is a bound
where the Gaussian kicks spread every direction of the target (the frequency sum's truncation is
then bounded); otherwise the truncation is only estimated, and the result is UNKNOWN with
``P in [0, 1]`` and the estimate in the details. A polytope initial set (not a box) is refused.
A row whose variance is negligible against the largest row's but not against its own mean and
bounds is integrated both as deterministic and as spread, and the hull of the two intervals
reported (:func:`reach.sets.gaussian.deterministic`). A bounded input with a
range is nondeterministic (any value, the worst deciding), not distributed: averaging over it
could call SAFE a requirement that fails for one value, so such a model is unsupported.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from reach.backends.base import unsupported
from reach.backends.fsr import fourier
from reach.backends.options import option_error, parse_options, ranged
from reach.model.ltv import KickedLinearSystem
from reach.model.constraints import halfspaces
from reach.result import Result, Status
from reach.sets.gaussian import (ZERO_VARIANCE, Probability, box_probability, deterministic, fixed_meets,
                                 interval_form, mass_and_draw, normal_mass, polytope_probability, randomized_qmc,
                                 uniform_shift_probability)
from reach.spec.properties import BoundReach, BoundReachAvoid, article

NAME = "fsr"
METHODS = ("auto", "genz", "markov", "fourier")   # auto: genz (over the initial box too, where it is one)


@dataclass
class Options:
    abs_error: float = ranged(1e-3, 1e-9, 0.5)         # target half-width of the integration error
    drop_budget: float | None = None  # Boole budget for dropped constraints (default abs_error / 10)
    method: str = "auto"             # auto | genz | markov | fourier
    seed: int = 0
    max_points: int = ranged(2 ** 22, 1, 2 ** 30)       # quasi-Monte Carlo evaluations at most
    max_frequencies: int = ranged(fourier.MAX_FREQUENCIES, 1, 10 ** 8)  # Fourier path: frequency vectors at most
    max_rows: int = ranged(1000, 1, 100_000)            # reach-avoid: constraint rows integrated at most (row cap)

    @classmethod
    def from_dict(cls, options: dict | None) -> "Options":
        opts = cls(**parse_options(cls, options, "fsr"))
        if opts.method not in METHODS:
            raise option_error("fsr", "method", f"must be one of {', '.join(METHODS)}")
        return opts


# ------------------------------------------------------------------ the stochastic model

@dataclass
class GaussianProblem:
    """The discretised model with its Gaussian kicks and initial state ``N(x0, P0)``."""

    system: KickedLinearSystem
    x0: np.ndarray
    P0: np.ndarray
    w_mean: np.ndarray
    w_cov: np.ndarray

    @classmethod
    def from_model(cls, model, at: float) -> "GaussianProblem":
        A, b = model.modes[model.initial.mode].linear
        dist = model.disturbance
        G = np.zeros((model.n, len(dist.enters)))
        G[dist.enters, np.arange(len(dist.enters))] = 1.0
        system = KickedLinearSystem.from_continuous(A, b, G, dist.step, at)
        x0 = 0.5 * (model.initial.low + model.initial.high)
        return cls(system, x0, np.zeros((model.n, model.n)), dist.mean, dist.cov)

    def moments(self):
        """Means and covariances at the kicks and at ``at``; ArithmeticError when they overflow
        (a non-finite mean or covariance bounds no probability, and NaN rows would read as
        satisfied constraints)."""
        means, covs = self.system.moments(self.x0, self.P0, self.w_mean, self.w_cov)
        finite = np.isfinite(means).all(axis=-1) & np.isfinite(covs).all(axis=(-2, -1))
        if not finite.all():
            k = int(np.argmin(finite))
            raise ArithmeticError(f"the state's mean or covariance overflows at kick {k} of {len(finite) - 1}")
        return means, covs


def reach(problem: GaussianProblem, H, g, abs_error: float = 1e-3, seed: int = 0,
          max_points: int = 2 ** 22) -> Probability:
    """``P(H x[K] <= g)`` (eqs. 11-15)."""
    means, covs = problem.moments()
    return polytope_probability(means[-1], covs[-1], H, g, abs_error=abs_error, rng=seed,
                                max_points=max_points)


@dataclass
class _Rows:
    """One-dimensional constraints ``lower <= h . x[step] <= upper`` sorted by step."""

    step: np.ndarray
    h: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def _rows(K: int, target, safe) -> _Rows:
    Tt, lt, ut = interval_form(*target)
    Ts, ls, us = interval_form(*safe)
    steps = [np.repeat(np.arange(K), Ts.shape[0]), np.full(Tt.shape[0], K)]
    return _Rows(np.concatenate(steps).astype(int), np.vstack([np.tile(Ts, (K, 1)), Tt]),
                 np.concatenate([np.tile(ls, K), lt]), np.concatenate([np.tile(us, K), ut]))


def reach_avoid(problem: GaussianProblem, target, safe, abs_error: float = 1e-3,
                drop_budget: float | None = None, method: str = "genz", seed: int = 0,
                max_points: int = 2 ** 22, max_rows: int | None = None):
    """``P(H_t x[K] <= g_t and H_s x[k] <= g_s for k < K)`` and a dict describing the work.

    ``target`` and ``safe`` are ``(H, g)`` pairs; see the module docstring for the method.
    """
    budget = abs_error / 10 if drop_budget is None else drop_budget
    means, covs = problem.moments()
    K = problem.system.steps
    rows = _rows(K, target, safe)
    mu = np.einsum("ri,ri->r", rows.h, means[rows.step])
    var = np.einsum("ri,rij,rj->r", rows.h, covs[rows.step], rows.h)
    fixed, ambiguous = deterministic(mu, var, rows.lower, rows.upper)

    def integrate(fixed):
        """The probability and the work done, with the rows ``fixed`` taken as deterministic."""
        info = {"rows": int(mu.size), "method": method}
        if np.any(fixed & ~fixed_meets(mu, rows.lower, rows.upper)) or np.any(rows.lower > rows.upper):
            info.update(kept=0, dropped=int(mu.size), boole=0.0, reason="a deterministic constraint fails")
            return Probability(0.0, 0.0, 0.0), info
        sd = np.sqrt(np.where(fixed, 1.0, var))
        q_low = np.where(fixed, 0.0, ndtr((rows.lower - mu) / sd))      # P(h.x < lower)
        q_high = np.where(fixed, 0.0, ndtr((mu - rows.upper) / sd))     # P(h.x > upper)
        sides = np.concatenate([q_low, q_high])
        order = np.argsort(sides, kind="stable")
        dropped = np.zeros(sides.size, bool)
        dropped[order[np.cumsum(sides[order]) <= budget]] = True
        lower = np.where(dropped[:mu.size], -np.inf, rows.lower)
        upper = np.where(dropped[mu.size:], np.inf, rows.upper)
        keep = np.isfinite(lower) | np.isfinite(upper)
        capped = 0
        if max_rows is not None and np.count_nonzero(keep) > max_rows:
            alive = np.flatnonzero(keep)                 # in time order
            chosen = alive[np.unique(np.round(np.linspace(0, alive.size - 1, max_rows)).astype(int))]
            cut = np.setdiff1d(alive, chosen)
            capped = int(cut.size)
            dropped[cut] |= np.isfinite(rows.lower[cut])
            dropped[mu.size + cut] |= np.isfinite(rows.upper[cut])
            lower[cut], upper[cut] = -np.inf, np.inf
            keep[cut] = False
        boole = float(min(1.0, np.sum(sides[dropped])))
        kept = _Rows(rows.step[keep], rows.h[keep], lower[keep], upper[keep])
        info.update(kept=int(keep.sum()), dropped=int(mu.size - keep.sum()), boole=boole, capped=capped)
        if not np.any(keep):
            p = Probability(1.0, 1.0, 1.0)
        elif method == "genz":
            mean_k, cov_k = _stacked(problem.system, means, covs, kept)
            p = box_probability(mean_k, cov_k, kept.lower, kept.upper, abs_error=abs_error, rng=seed,
                                max_points=max_points)
        else:
            p = _sequential(problem, means, covs, kept, abs_error, seed, max_points)
        info["points"] = p.points
        return Probability(p.value, max(0.0, p.low - boole), p.high, p.dimension, p.points), info

    if np.any(ambiguous):                       # both readings count (reach.sets.gaussian.deterministic)
        (p1, _), (p2, info) = integrate(fixed | ambiguous), integrate(fixed)
        info["ambiguous_rows"] = int(ambiguous.sum())
        return Probability(p2.value, min(p1.low, p2.low), max(p1.high, p2.high), p2.dimension,
                           p1.points + p2.points), info
    return integrate(fixed)


def _stacked(system: KickedLinearSystem, means, covs, rows: _Rows):
    """Mean and covariance of ``(h_r . x[step_r])_r`` (rows sorted by step), Markov recursion."""
    D = rows.step.size
    S = np.zeros((D, D))
    W = np.zeros((system.n, 0))             # columns Psi(k, step_s) P[step_s] h_s^T
    k_now = 0
    for k in np.unique(rows.step):
        for i in range(k_now, k):
            W = system.Phi[i] @ W
        k_now = k
        here = np.flatnonzero(rows.step == k)
        W = np.hstack([W, covs[k] @ rows.h[here].T])
        S[here, :W.shape[1]] = rows.h[here] @ W
    S = np.tril(S) + np.tril(S, -1).T
    return np.einsum("ri,ri->r", rows.h, means[rows.step]), S


def _sequential(problem: GaussianProblem, means, covs, rows: _Rows, abs_error, seed, max_points):
    """Sequential conditioning along time (module docstring); randomised QMC over the rows."""
    system = problem.system
    kick_cov = system.G @ problem.w_cov @ system.G.T
    D = rows.step.size
    C = covs[0].copy()
    k_now = 0
    plan = []                                # per row: propagator since the previous row, h, gain, sd
    for r in range(D):
        k = rows.step[r]
        Psi = np.eye(system.n)
        for i in range(k_now, k):
            Psi = system.Phi[i] @ Psi
            C = system.Phi[i] @ (C + kick_cov) @ system.Phi[i].T
        k_now = k
        Ch = C @ rows.h[r]
        s2 = float(rows.h[r] @ Ch)
        # deterministic as in reach.sets.gaussian.deterministic (an ambiguous row counts as spread)
        own = max(abs(means[k] @ rows.h[r]), *(abs(v) for v in (rows.lower[r], rows.upper[r]) if np.isfinite(v)))
        fixed = s2 <= 0 or (s2 <= ZERO_VARIANCE * max(float(np.trace(covs[k])), 1e-300)
                            and s2 <= ZERO_VARIANCE * own ** 2)
        s = 0.0 if fixed else np.sqrt(s2)
        gain = Ch / s if s > 0 else np.zeros(system.n)
        if s > 0:
            C = C - np.outer(Ch, Ch) / s2
            C = 0.5 * (C + C.T)
        plan.append((Psi, rows.h[r], gain, s, means[k] @ rows.h[r], rows.lower[r], rows.upper[r]))

    def integrand(W):
        N = W.shape[0]
        delta = np.zeros((N, system.n))
        weight = np.ones(N)
        for r, (Psi, h, gain, s, centre, lo, hi) in enumerate(plan):
            delta = delta @ Psi.T
            nu = centre + delta @ h
            if s == 0.0:
                weight *= fixed_meets(nu, lo, hi)
                continue
            a, b = (lo - nu) / s, (hi - nu) / s
            if r < D - 1:
                mass, v = mass_and_draw(a, b, W[:, r])
                delta += np.outer(v, gain)
            else:
                mass = normal_mass(a, b)
            weight *= mass
        return weight.mean()

    if D == 1:
        value = float(integrand(np.zeros((1, 1))))
        return Probability(value, max(0.0, value - 1e-12), min(1.0, value + 1e-12))
    return randomized_qmc(integrand, D - 1, abs_error, max_points, np.random.default_rng(seed))


# ------------------------------------------------------------------ staying in the initial mode

def stay_region(model, tol: float = 1e-9):
    """``((H, g), None)`` if runs of ``model`` can leave the initial mode only through a post-kick
    state outside the interior of its invariant ``H x <= g`` (module docstring), else ``(None, why)``."""
    mode = model.modes[model.initial.mode]
    if mode.linear is None:
        return None, f"the flow of mode '{mode.name}' is nonlinear"
    region = mode.invariant_halfspaces
    if region is None or not mode.invariant:
        return None, f"mode '{mode.name}' has no polyhedral invariant bounding the stay"
    H, g = (np.atleast_2d(np.asarray(a, dtype=float)) for a in region)
    g = g.ravel()
    norms = np.linalg.norm(H, axis=1)
    H, g = H / norms[:, None], g / norms
    A, b = mode.linear
    for i, (h, bound) in enumerate(zip(H, g)):
        if _inflow(A, b, H, g, h, bound) >= -tol * (1.0 + abs(bound)):
            return None, f"the invariant of '{mode.name}' is not entered strictly at its facet {i}"
    for tr in model.outgoing(mode.name):
        if not tr.urgent:
            return None, f"transition '{tr.name}' out of '{mode.name}' is not urgent"
        guard = model.guard_halfspaces(tr)
        if guard is None:
            return None, f"the guard of '{tr.name}' is not a polytope"
        if not _misses_interior(guard, H, g, tol):
            return None, f"the guard of '{tr.name}' meets the interior of the invariant of '{mode.name}'"
    x0 = model.initial.low
    if np.any(H @ x0 >= g - tol * (1.0 + np.abs(g))):
        return None, "the initial point is not inside the invariant of the initial mode"
    return (H, g), None


def _inflow(A, b, H, g, h, bound) -> float:
    """``max h (A x + b)`` over the facet ``h x = bound`` of ``{H x <= g}`` (``h`` unit)."""
    row = h @ A
    alpha = float(row @ h)
    if np.linalg.norm(row - alpha * h) <= 1e-12 * max(1.0, np.linalg.norm(row)):
        return alpha * bound + float(h @ b)        # h is a left eigenvector: constant on the facet
    from reach import lp
    res = lp.maximize(row, H, g, A_eq=h[None, :], b_eq=np.array([bound]))
    return res.support_value() + float(h @ b)


def _misses_interior(guard, H, g, tol) -> bool:
    """True if the polyhedron ``guard`` has no point with ``H x < g``."""
    Gm, gm = (np.atleast_2d(np.asarray(a, dtype=float)) for a in guard)
    gm = gm.ravel()
    for row, value in zip(Gm, gm):                  # exact test: the guard lies beyond a facet
        norm = np.linalg.norm(row)
        if norm == 0:
            continue
        u, c = row / norm, value / norm
        if np.any((np.linalg.norm(H + u, axis=1) <= 1e-12) & (g >= -c - tol * (1.0 + abs(c)))):
            return True
    from reach import lp
    n = H.shape[1]
    A_ub = np.vstack([np.hstack([Gm, np.zeros((Gm.shape[0], 1))]), np.hstack([H, np.ones((H.shape[0], 1))])])
    res = lp.maximize(np.append(np.zeros(n), 1.0), A_ub, np.concatenate([gm, g]),
                      bounds=[(None, None)] * n + [(None, 1.0)])
    return res.infeasible or (res.optimal and res.value <= tol)


def leave_bound(problem: GaussianProblem, H, g) -> float:
    """``sum_k sum_i P(h_i (x[k] + G w[k]) >= g_i)`` over the kicks: Boole bound on leaving."""
    means, covs = problem.moments()
    K = problem.system.steps
    G = problem.system.G
    m = means[:K] + G @ problem.w_mean
    P = covs[:K] + G @ problem.w_cov @ G.T
    mu = m @ H.T                                                   # (K, rows)
    var = np.einsum("ri,kij,rj->kr", H, P, H)
    sd = np.sqrt(np.maximum(var, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(sd > 0, ndtr((mu - g) / np.where(sd > 0, sd, 1.0)), (mu >= g).astype(float))
    return float(min(1.0, np.sum(q)))


# ------------------------------------------------------------------ the back-end

class FsrBackend:
    name = NAME

    def supports(self, model, prop) -> str | None:
        if not isinstance(prop, (BoundReach, BoundReachAvoid)):
            others = "the taylor or montecarlo back-ends" if prop.kind == "event" else \
                "the star, taylor or montecarlo back-ends"
            return f"fsr computes reach and reach-avoid probabilities; {article(prop.kind)} property is for {others}"
        if model.disturbance is None:
            return ("deterministic model (no disturbance): there is no distribution to integrate; "
                    "use the star or taylor back-end")
        ranged = [u.name for u in model.bounded_inputs if u.high > u.low]
        if ranged:       # any value of its range, not a distribution over it: a worst case, not an average
            return (f"bounded input{'s' if len(ranged) > 1 else ''} {', '.join(ranged)} may take any value of "
                    f"{'their ranges' if len(ranged) > 1 else 'its range'}, which fsr would average over; fix "
                    f"{'them' if len(ranged) > 1 else 'it'} to one value (range [v, v]) per check, or use montecarlo")
        mode = model.modes[model.initial.mode]
        if mode.linear is None:
            return f"the flow of mode '{mode.name}' is nonlinear; fsr needs a linear closed loop"
        if len(model.modes) != 1 or model.transitions:
            why = stay_region(model)[1]
            if why is not None:
                return f"fsr handles one linear mode, or the stay in the initial mode; here {why}"
        elif mode.invariant:
            return f"mode '{mode.name}' has an invariant, which would truncate the distribution"
        if halfspaces(prop.target, prop.symbols) is None:
            return "the target is not a polytope (nonlinear constraint)"
        if isinstance(prop, BoundReachAvoid) and halfspaces(prop.safe, prop.symbols) is None:
            return "the safe set is not a polytope (nonlinear constraint)"
        point = np.array_equal(model.initial.low, model.initial.high)
        if not point and not model.initial.is_box:
            return ("the initial set is a polytope, not a box: fsr takes a point, or a box with the state "
                    "uniform over it; montecarlo samples a polytope")
        if not point and isinstance(prop, BoundReachAvoid):
            return "reach-avoid from a distributed (box) initial state is not supported; use a point"
        if not point and (len(model.modes) != 1 or model.transitions):
            return "a switched model needs a point initial state (the stay bound is for a point)"
        return None

    def check(self, model, prop, options: dict | None = None) -> Result:
        opts = Options.from_dict(options)
        start = time.perf_counter()
        target = halfspaces(prop.target, prop.symbols)
        point = np.array_equal(model.initial.low, model.initial.high)
        problem = GaussianProblem.from_model(model, prop.at)
        details = {"kicks": problem.system.steps, "step": model.disturbance.step,
                   "semantics": "kicks at k*step < at, states observed before the kick"}
        try:
            problem.moments()
        except ArithmeticError as exc:
            details["reason"] = f"{exc}: no probability is bounded"
            return Result(NAME, model.name, prop.id, Status.UNKNOWN, time.perf_counter() - start,
                          probability=(0.0, 1.0), details=details)
        if isinstance(prop, BoundReach):
            if not point and opts.method != "fourier":
                T, lower, upper = interval_form(*target)
                box = fourier.UniformLaw(model.initial.low, model.initial.high)
                kicks = fourier.GaussianLaw(problem.w_mean, problem.w_cov)
                z = fourier.ProjectedSum.of(problem.system, T, box, kicks)
                wide = np.flatnonzero(box.halfwidth > 0)
                p = uniform_shift_probability(z.mean, z.kick_cov, lower, upper, z.D0[:, wide], box.halfwidth[wide],
                                              abs_error=opts.abs_error, max_points=opts.max_points, rng=opts.seed)
                details.update(method="genz", dimension=p.dimension, points=p.points,
                               initial="uniform over the initial box",
                               error="randomised QMC over the initial box and the kicks, 3.5 standard errors")
            elif opts.method == "fourier":
                initial = (fourier.point_law(problem.x0) if point
                           else fourier.UniformLaw(model.initial.low, model.initial.high))
                T, lower, upper = interval_form(*target)
                z = fourier.ProjectedSum.of(problem.system, T, initial,
                                            fourier.GaussianLaw(problem.w_mean, problem.w_cov))
                p = fourier.box_probability(z, lower, upper, tol=opts.abs_error,
                                            max_frequencies=opts.max_frequencies)
                details.update(method="fourier", frequencies=p.points,
                               initial="point" if point else "uniform over the initial box",
                               error="periodisation bound + truncation " + ("bound" if p.rigorous else "estimate"))
            else:
                p = reach(problem, *target, abs_error=opts.abs_error, seed=opts.seed,
                          max_points=opts.max_points)
                details.update(method="genz", dimension=p.dimension, points=p.points,
                               error="randomised QMC, 3.5 standard errors")
        else:
            if opts.method == "fourier":
                return unsupported(NAME, model, prop, "the fourier method computes reach probabilities only")
            safe = halfspaces(prop.safe, prop.symbols)
            method = "markov" if opts.method == "markov" else "genz"
            p, info = reach_avoid(problem, target, safe, abs_error=opts.abs_error,
                                  drop_budget=opts.drop_budget, method=method, seed=opts.seed,
                                  max_points=opts.max_points, max_rows=opts.max_rows)
            details.update(info)
            details["error"] = "randomised QMC, 3.5 standard errors, plus Boole bound of dropped constraints"
        if len(model.modes) != 1 or model.transitions:
            region, _ = stay_region(model)
            exit_bound = leave_bound(problem, *region)
            details["stay"] = {
                "mode": model.initial.mode, "leave_bound": exit_bound,
                "argument": ("probability computed on the initial mode's linear flow; its invariant is "
                             "forward invariant with strict inflow and no guard meets its interior, so "
                             "a run switches only if a post-kick state leaves it; interval widened by "
                             "the Boole bound on that (both sides)")}
            p = Probability(p.value, max(0.0, p.low - exit_bound), min(1.0, p.high + exit_bound),
                            p.dimension, p.points)
        status, verdict = _verdict(p, prop.at_least)
        details["estimate"] = p.value
        bounds = (p.low, p.high)
        if isinstance(p, fourier.Inversion) and p.high - p.low > 2 * p.shell:
            estimated = [max(0.0, p.value - p.shell), min(1.0, p.value + p.shell)]
            details["estimated_interval"] = estimated
            why = ("no Gaussian kick spreads every direction of the target, so the truncation has no bound"
                   if not p.rigorous else f"the truncation bound is still {p.high - p.value:.3g} at "
                   f"{p.points} frequencies (option max_frequencies)")
            details["reason"] = (f"P is about {p.value:.6g} (in [{estimated[0]:.6g}, {estimated[1]:.6g}] as far as "
                                 f"the frequency sum's truncation is estimated), but {why}")
        if not getattr(p, "rigorous", True):     # fourier.Inversion: an estimate bounds nothing
            status, verdict, bounds = Status.UNKNOWN, "undecided", (0.0, 1.0)
        details["verdict"] = verdict
        return Result(NAME, model.name, prop.id, status, time.perf_counter() - start,
                      probability=bounds, details=details)


def _verdict(p: Probability, at_least):
    if at_least is None:
        return Status.UNKNOWN, "no threshold"
    if p.low >= at_least:
        return Status.SAFE, "holds"
    if p.high < at_least:
        return Status.UNKNOWN, "violated"
    return Status.UNKNOWN, "undecided"


BACKEND = FsrBackend()
