"""A switching group that no run leaves, bounded around its mean flow by a small-gain argument.

When the group's differential inclusion (:mod:`.switching`) leaves a check UNKNOWN, star tries
this bound before answering. It applies where the initial mode belongs to a switching group
that is *closed*: every transition out of a member enters a member and resets nothing. Every
run up to the horizon then solves, almost everywhere,

    x' = A_s x + b_s + B_s u~,      s = sigma(t) a member, |u~| <= u_r (any measurable signal),

(``u~ = u - u_c`` the time-varying inputs about their centre, :class:`.transitions._LinearModel`;
invariants and guards only remove runs). With the members' means ``A_m, b_m, B_m`` and
differences ``D_i = A_i - A_m``, ``d_i = b_i - b_m``, ``E_i = B_i - B_m``, nonzero only on the
rows ``R`` (``r`` of them, ``S`` the columns of the identity on ``R``), split every run as
``x = y + delta``:

* ``y`` is the run of the mean flow ``y' = A_m y + b_m + B_m u~`` from the same initial state
  with the same input. Its reachable set at ``t`` has the exact support function (``P(t) =
  e^{A_m t}``, ``c(t)`` the run from the centre ``c_0`` of the initial box with the input at
  its centre, ``G_0`` the box's radii as generators)

      rho_t(l) = l.c(t) + |l P(t) G_0| 1 + int_0^t |l P(r) B_m| u_r dr,

  a zonotope (one generator per initial side and, per step, per input) that is never formed:
  only its supports in the few directions below are, the integral per grid step ``h`` by the
  chord of ``l P(r) B_m`` plus ``h^3/12`` times a bound of its second derivative
  ``l A_m^2 P(r) B_m`` (:meth:`.flowpipe.AffineFlow.cell_growth` gives ``K`` with
  ``|e^{A_m s} e| <= K |e|``, ``0 <= s <= h``).
* ``delta(0) = 0`` and ``delta' = A_m delta + S v`` with ``v = (D_s x + d_s + E_s u~)_R``, so by
  variation of constants ``delta(t) = int_0^t P(t - r) S v(r) dr``.

Within a step. Over step ``k`` (``[t_k, t_k + h]``), ``|y(s) - y(t_k)| <= m_k`` with
``m_k = (I - h |A_m|)^{-1} h (f_k + |B_m| u_r)``, ``f_k >= |A_m y + b_m|`` over the set at
``t_k`` (the fixed point of the Picard map on boxes, in closed form: the largest deviation
``m`` up to ``s`` obeys ``m <= h f + h |A_m| m + h |B_m| u_r``; the inverse is a Neumann series
of non-negative terms, bounded with its tail). Along a direction ``l`` the run is within
``(h/2) |l| (|A_m| m_k + |B_m| u_r)`` of the chord between its two grid states (the part of
``y'`` that is constant over the step cancels in the chord; the rest is at most that), so
``l.y`` over the step lies between the extremes of the two grid sets widened by that.

The members' difference. At ``s`` in step ``k`` the run is in one member ``i`` (``lam_i = 1``
for it, 0 for the others), so with ``p_{i,k} = (D_i c_k + d_i)_R`` and ``p_k`` their mean
(zero up to rounding),

    v = sum_i lam_i p_{i,k} + v_s = p_k + sum_i g_i a_{i,k} + v_s,   g_i = 2 lam_i - 1 in [-1, 1],
    a_{i,k} = (p_{i,k} - p_k) / 2,  |v_s| <= nu_k = sigma_k + max_i |(D_i delta)_R|,
    sigma_k = |p_k| + max_i (|(D_i)_R (y_k - c_k)| + |(D_i)_R| m_k + |(E_i)_R| u_r)

(componentwise; ``|(D_i)_R (y_k - c_k)|`` is the support of the centred set at ``t_k``). The
``a_{i,k}`` are one generator per member and step with a coefficient ``g_i(s)`` shared by the
rows of ``R``; the rest is a box.

The bound. For ``s`` in step ``k``, splitting ``int_0^s`` into steps, with the lags ``s - r``
of step ``m`` in ``L_j = [max(0, (j - 1) h), (j + 1) h]`` (``j = k - m``),

    |l.delta(s)| <= h sum_{m <= k} ( sum_i max_{L_{k-m}} |l P S a_{i,m}| + max_{L_{k-m}} |l P S| nu_m ).

Over ``L_j`` the functions ``l P(tau) S (.)`` are bounded by their samples at ``j - 1, j, j + 1``
plus ``h^2/8 |l A_m^2| K^2 |P_{j-1} S| |.|`` (chord on each half and the curvature bound). In
the rows ``(D_i)_R`` this bounds ``nu`` by itself -- a Volterra inequality with non-negative
kernel --, and by induction over the steps ``nu_k <= zeta_k`` with

    zeta_k = (I - h U_0)^{-1} ( sigma_k + max_i [ centre part + h sum_{m < k} U^(i)_{k-m} zeta_m ] ),

``U^(i)_j`` the kernel bound in the rows of ``D_i``, ``U_0`` their largest at lag 0 (``nu_k``
is finite since a run is bounded on a step, and ``(I - h U_0)^{-1} >= 0``). So a switching
signal is a bounded input, fed back through a stable filter: the bound grows by the loop gain
``int |(D_i)_R P(r) S| dr`` instead of compounding per step as a set that re-wraps the
difference each step does (a zonotope that adds ``h D_i Z`` every step as new generators, kept
at 200 by Girard's reduction, bounds e2 of PLAA01 by -63 at t = 8 and keeps falling).

The check. An unsafe piece ``H x <= g`` (rows normalised) is excluded on step ``k`` if one of
its rows ``l`` has ``l.x > g`` (``>=`` for a piece of strict rows) over the step's lower bound

    min(l.c_k - rho^c_k(l), l.c_{k+1} - rho^c_{k+1}(l)) - (h/2)|l|(|A_m| m_k + |B_m| u_r) - delta_k(l),

``rho^c`` the centred support; every piece of every member is checked on every step (the run
may be in any member), up to the first grid point at or beyond the horizon (measured from the
initial clock's lower end, or 0). SAFE only if every piece is excluded on every step.

Rounding. Matrix exponentials ``P(t_j)`` and the centre run come from ``scipy.linalg.expm``,
each on its own, so no error accumulates along the grid; the exponentials themselves are taken
as computed (not enclosed, as elsewhere in star). The Neumann inverses are bounded with their
tails; sums of non-negative terms are within a relative ``1e-12`` of exact. Every bound is
pushed out by a relative :data:`ROUNDING` of the magnitudes summed into it, the centre's
counted as ``|P(t_k)| |c_0| + |psi(t_k)|`` (not ``|c_k|``: at an unstable equilibrium the two
terms cancel, and the computed centre is off by ~1e-15 of their size, far more than 1e-9 of
``|c_k|``), and the members' difference at the centre alike. The steps start at ``hull_steps / 8`` over the
horizon and double while a piece is not excluded, up to ``hull_steps``; the cost is quadratic
in the steps (the convolutions above).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from reach import lp
from reach.backends.star.flowpipe import AffineFlow, _abs_chord_integral
from reach.backends.star.switching import SwitchingModel, group_pieces
from reach.backends.star.transitions import _Piece, _unsafe_pieces

#: relative allowance for rounding of every bound the check uses (as elsewhere in star)
ROUNDING = 1e-9

#: columns of the centre part computed at a time (memory: ``steps`` x this many numbers)
CHUNK = 256

#: a Neumann series ``sum M^k`` is used only for ``||M||_inf`` at most this (a longer step is
#: refused: the closed forms it feeds would be loose anyway)
NEUMANN_NORM = 0.9

#: the one-sentence argument a SAFE from this bound adds to its semantics
ARGUMENT = ("every run stays in a closed switching group, so it is the mean flow's run y (exact "
            "support) plus delta = int e^{A_m (t-s)} w(s) ds, w = (A_i - A_m) x + ... the members' "
            "difference, bounded per step by one generator per member and a box that a Volterra "
            "inequality (non-negative kernel, induction over the steps) bounds through delta itself; "
            "between grid points by the chord plus (h/2)|y'| spread; rounding pushed out by 1e-9 of the "
            "magnitudes summed (matrix exponentials taken as computed)")


def closed_group(model, data: SwitchingModel) -> tuple[str, ...] | None:
    """The switching group of the initial mode if no run can leave it: every transition out of
    a member enters a member and resets nothing; else None."""
    group = data.group_of.get(model.initial.mode)
    if group is None:
        return None
    for tr in model.transitions:
        if tr.source in group and (tr.target not in group or tr.reset):
            return None
    return group


class _Flowpipe:
    """The mean flow's grid, its supports and the members' differences for ``steps`` steps of
    length ``h`` (module doc)."""

    def __init__(self, data: SwitchingModel, group, box, h: float, steps: int):
        n = data.n
        flows = [data.flows[m] for m in group]
        self.A = np.mean([f.A for f in flows], axis=0)
        self.b = np.mean([f.b for f in flows], axis=0)
        with_input = [f for f in flows if f.B is not None]
        p = with_input[0].B.shape[1] if with_input else 0
        self.B = np.mean([f.B if f.B is not None else np.zeros((n, p)) for f in flows], axis=0)
        self.u_r = with_input[0].u_radius if with_input else np.zeros(0)
        D = np.array([f.A - self.A for f in flows])
        d = np.array([f.b - self.b for f in flows])
        E = np.array([(f.B if f.B is not None else np.zeros((n, p))) - self.B for f in flows])
        self.rows = np.flatnonzero(np.any(D != 0, axis=(0, 2)) | np.any(d != 0, axis=0)
                                   | np.any(E != 0, axis=(0, 2)))
        self.D, self.d, self.E = D[:, self.rows], d[:, self.rows], E[:, self.rows]
        self.S = np.eye(n)[:, self.rows]
        self.h, self.steps, self.n = h, steps, n
        self.c0, self.G0 = box.center, np.diag(box.radius)[:, box.radius > 0]
        aug = np.zeros((steps + 1, n + 1, n + 1))
        aug[:, :n, :n], aug[:, :n, n] = self.A, self.b
        E_t = expm(aug * (h * np.arange(steps + 1))[:, None, None])
        self.P = E_t[:, :n, :n]                              # e^{A_m t_j}, j = 0..steps
        self.c = self.P @ self.c0 + E_t[:, :n, n]            # the centre run at the grid points
        # the magnitudes summed into each centre: its rounding scales with them, not with |c|
        # (an unstable equilibrium cancels terms of e^{A t} c0 and the input part to ~1e15)
        self.c_size = np.abs(self.P) @ np.abs(self.c0) + np.abs(E_t[:, :n, n])
        self.K = AffineFlow(self.A, self.b).cell_growth(h)   # |e^{A_m s} e| <= K |e|, s <= h
        self.A2 = self.A @ self.A

    def spread(self, L: np.ndarray) -> np.ndarray:
        """``rho^c_k(l)`` for every row ``l`` of ``L`` and grid point ``k``: the support of the
        mean flow's set about its centre run, ``|l P_k G_0| 1`` plus the input's integral
        (chords plus curvature, summed over the steps): ``(steps + 1, rows)``."""
        LP = np.einsum("qa,kab->kqb", L, self.P)
        out = np.abs(LP @ self.G0).sum(axis=2)
        if self.u_r.size and np.any(self.B):
            u = LP @ self.B                                              # (steps + 1, q, p)
            chord = _abs_chord_integral(u[:-1], u[1:], self.h)
            curve = self.h ** 3 / 12 * np.einsum("qa,ab,kbp->kqp", np.abs(L @ self.A2), self.K,
                                                  np.abs(self.P[:-1] @ self.B))
            step = (chord + curve) @ self.u_r
            out[1:] += np.cumsum(step, axis=0)
        return out * (1 + ROUNDING)

    def movement(self) -> np.ndarray:
        """``m_k`` (module doc) for every step: ``(steps, n)``."""
        absA = np.abs(self.A)
        f = np.abs(self.c[:-1] @ self.A.T + self.b) + self.spread(self.A)[:-1]
        inverse = _neumann(self.h * absA)
        return (self.h * (f + np.abs(self.B) @ self.u_r)) @ inverse.T * (1 + ROUNDING)

    def kernel(self, L: np.ndarray):
        """For every row ``l`` of ``L``: the samples ``l P_j S`` (``(steps + 1, q, r)``) and the
        curvature allowance over a lag range ``L_j`` per unit ``|.|`` (``(steps + 1, q, r)``)."""
        u = np.einsum("qa,jab->jqb", L, self.P @ self.S)
        K2 = self.K @ self.K
        before = np.abs(self.P[np.maximum(np.arange(self.steps + 1) - 1, 0)] @ self.S)
        slack = self.h ** 2 / 8 * np.einsum("qa,ab,jbr->jqr", np.abs(L @ self.A2), K2, before)
        return u, slack


def _lagged_max(x: np.ndarray) -> np.ndarray:
    """``max(x_{j-1}, x_j, x_{j+1})`` along the first axis (the ends clipped)."""
    out = x.copy()
    out[1:] = np.maximum(out[1:], x[:-1])
    out[:-1] = np.maximum(out[:-1], x[1:])
    return out


def _neumann(M: np.ndarray) -> np.ndarray:
    """An entrywise upper bound of ``(I - M)^{-1} = sum_k M^k`` for ``M >= 0`` with
    ``||M||_inf <= NEUMANN_NORM``: the partial sum until its terms are below 1e-18 of it,
    plus the tail bound ``||M||^{k+1} / (1 - ||M||)`` on every entry. ArithmeticError if the
    norm is larger (a step too long for the flow)."""
    norm = float(np.abs(M).sum(axis=1).max()) if M.size else 0.0
    if not norm <= NEUMANN_NORM:
        raise ArithmeticError(f"a hull step is too long for the flow (||h M|| = {norm:.3g})")
    total, term, power = np.eye(M.shape[0]), np.eye(M.shape[0]), 1.0
    while power > 1e-18:
        term, power = term @ M, power * norm
        total = total + term
    return total * (1 + ROUNDING) + power * norm / (1 - norm)


def _anti_diagonal_sums(u: np.ndarray, slack: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``sum_{m <= k} ( max_{j' in {j-1, j, j+1}} |u_{j'} . a_m| + slack_j . |a_m| )``,
    ``j = k - m``, for every ``k``: ``u``, ``slack`` ``(steps + 1, r)``, ``a`` ``(steps, r)``."""
    steps = a.shape[0]
    out = np.zeros(steps)
    for first in range(0, steps, CHUNK):
        cols = slice(first, min(steps, first + CHUNK))
        W = _lagged_max(np.abs(u @ a[cols].T)) + slack @ np.abs(a[cols]).T     # (steps + 1, chunk)
        for offset, m in enumerate(range(cols.start, cols.stop)):
            out[m:] += W[:steps - m, offset]
    return out


def _centre_parts(u, slack, a) -> np.ndarray:
    """The centre part of ``|l.delta|`` (module doc, without the factor ``h``) for every row
    of ``u`` (``(steps + 1, q, r)``), summed over the members ``a`` (``(members, steps, r)``):
    ``(steps, q)``."""
    return np.array([sum(_anti_diagonal_sums(u[:, q], slack[:, q], a_i) for a_i in a)
                     for q in range(u.shape[1])]).T


def _initial_box(data: SwitchingModel, model):
    """The initial set's interval hull over the explored states: the box itself, or, with a
    polytope, its maxima certified by weak duality (:func:`reach.lp.maximize_many`), pushed
    out by a relative :data:`ROUNDING`."""
    from reach.sets import Box

    box = data.initial_box(model.initial.low, model.initial.high)
    if getattr(model.initial, "polytope", None) is None:
        return box
    star = data.initial_star(model.initial)
    values = lp.maximize_many(np.vstack([star.basis, -star.basis]), star.predicate.A, star.predicate.b,
                              (star.box.low, star.box.high))
    if not np.all(np.isfinite(values)):
        raise ArithmeticError("the initial set's bounds are not certified")
    n = star.dim
    high, low = star.center + values[:n], star.center - values[n:]
    pad = ROUNDING * (1 + np.abs(low) + np.abs(high))
    return Box(low - pad, high + pad)


def _pieces(data: SwitchingModel, prop, group) -> list[_Piece] | None:
    """The unsafe pieces of every member (over the explored states), or None if a member is
    forbidden as a whole (a piece with no rows: the hull cannot exclude it)."""
    pieces = _unsafe_pieces(prop)
    if data.added_clock:
        pieces = {mode: [_Piece(data.widen(p.H, p.g)[0], p.g, p.strict, p.label) for p in ps]
                  for mode, ps in pieces.items()}
    pieces = group_pieces(pieces, data.groups)
    out = []
    for mode in group:
        for p in pieces.get(mode) or []:
            if not p.H.shape[0]:
                return None
            if not any(q is p for q in out):
                out.append(p)
    return out


def bound(data: SwitchingModel, group, box, pieces: list[_Piece], duration: float, steps: int) -> list[dict]:
    """For every piece: the least over the steps of its best row's margin ``lower - g``
    (``margin``; the piece is excluded on every step iff it is positive, or zero for a strict
    piece) and, per row, the least lower bound of ``l.x`` (``least``) (module doc)."""
    h = duration / steps
    fp = _Flowpipe(data, group, box, h, steps)
    members = len(group)
    r = fp.rows.size
    m = fp.movement()                                             # (steps, n)
    drift = np.abs(fp.A) @ m.T                                    # |A_m| m_k: (n, steps)
    if fp.u_r.size:
        drift = drift + (np.abs(fp.B) @ fp.u_r)[:, None]
    # the members' difference: centre generators and the y-part of its box
    p = np.einsum("irn,kn->ikr", fp.D, fp.c[:-1]) + fp.d[:, None, :]          # (members, steps, r)
    p_mean = p.mean(axis=0)
    a = (p - p_mean) / 2
    Drows = fp.D.reshape(members * r, fp.n)
    spread_D = fp.spread(Drows)[:-1].reshape(steps, members, r)
    sigma = spread_D + np.einsum("irn,kn->kir", np.abs(fp.D), m)
    if fp.u_r.size:
        sigma = sigma + (np.abs(fp.E) @ fp.u_r)[None]
    sigma = sigma.max(axis=1) + np.abs(p_mean)                    # (steps, r)
    sigma += ROUNDING * (np.abs(fp.D) @ fp.c_size[:-1].T).max(axis=0).T + ROUNDING * np.abs(fp.d).max(axis=0)
    zeta = np.zeros((steps, r))
    if r:
        uD, slackD = fp.kernel(Drows)                              # (steps + 1, members r, r)
        UD = _lagged_max(np.abs(uD)) + slackD
        centre_D = h * _centre_parts(uD, slackD, a)                # (steps, members r)
        inverse = _neumann(h * UD[0].reshape(members, r, r).max(axis=0))
        for k in range(steps):
            history = h * np.einsum("mqr,mr->q", UD[k:0:-1], zeta[:k]) if k else np.zeros(members * r)
            own = (centre_D[k] + history).reshape(members, r).max(axis=0)
            zeta[k] = inverse @ (sigma[k] + own) * (1 + ROUNDING)
    out = []
    for piece in pieces:
        rows = piece.H
        lc = fp.c @ rows.T                                         # (steps + 1, q)
        rho = fp.spread(rows)
        lower = np.minimum(lc[:-1] - rho[:-1], lc[1:] - rho[1:]) - h / 2 * (np.abs(rows) @ drift).T
        c_size = fp.c_size @ np.abs(rows).T
        size = c_size[:-1] + c_size[1:] + rho[:-1] + rho[1:]
        if r:
            u, slack = fp.kernel(rows)
            U = _lagged_max(np.abs(u)) + slack                     # (steps + 1, q, r)
            delta = h * _centre_parts(u, slack, a)
            delta += h * np.array([sum(np.convolve(U[:steps, q, j], zeta[:, j])[:steps] for j in range(r))
                                   for q in range(rows.shape[0])]).T
            lower -= delta
            size += delta
        lower -= ROUNDING * size
        margin = lower - piece.g                                   # (steps, q)
        out.append({"piece": piece.label, "strict": piece.strict,
                    "margin": float(margin.max(axis=1).min()),
                    "least": [float(v) for v in lower.min(axis=0)], "limit": [float(v) for v in piece.g]})
    return out


def proved(entry: dict) -> bool:
    """Whether a piece's bound (:func:`bound`) excludes it on every step."""
    return entry["margin"] > 0 or (entry["strict"] and entry["margin"] >= 0)


def attempts(hull_steps: int) -> list[int]:
    """The step counts tried: ``hull_steps / 8``, doubled while below ``hull_steps``, then
    ``hull_steps``."""
    counts = [max(1, hull_steps // 8)]
    while counts[-1] * 2 < hull_steps:
        counts.append(counts[-1] * 2)
    if counts[-1] != hull_steps:
        counts.append(hull_steps)
    return counts


def check_hull(model, prop, opt) -> dict | None:
    """The hull's report for ``prop`` (``details.hull``), or None where it does not apply (no
    closed switching group holds the initial mode, or a member is forbidden as a whole).
    ``proved`` says whether every piece is excluded on every step of the last attempt."""
    data = SwitchingModel.of(model)
    group = closed_group(model, data) if data.linear else None
    if group is None:
        return None
    pieces = _pieces(data, prop, group)
    if pieces is None:
        return None
    box = _initial_box(data, model)
    start = min(0.0, float(box.low[data.clock]))
    duration = float(model.horizon) - start
    if not duration > 0:
        return None
    report = {"group": list(group), "proved": False, "argument": ARGUMENT, "tried": []}
    for steps in attempts(opt.hull_steps):
        try:
            bounds = bound(data, group, box, pieces, duration, steps)
        except ArithmeticError as failure:
            report["tried"].append({"steps": steps, "outcome": str(failure)})
            continue
        done = all(proved(b) for b in bounds)
        least = min(b["margin"] for b in bounds) if bounds else np.inf
        report["tried"].append({"steps": steps, "outcome": "every piece excluded" if done else
                                f"a piece not excluded (least margin {least:.6g})"})
        report.update({"steps": steps, "step": duration / steps, "bounds": bounds,
                       "generators": {"initial": int(np.count_nonzero(box.radius)),
                                      "per_step": {"inputs": int(np.count_nonzero(
                                          _input_radius(data, group))), "members": len(group)}}})
        if done:
            report["proved"] = True
            break
    return report


def _input_radius(data: SwitchingModel, group) -> np.ndarray:
    """The radii of the time-varying inputs the group's members read (none: empty)."""
    flows = [data.flows[m] for m in group if data.flows[m].B is not None]
    return flows[0].u_radius if flows else np.zeros(0)
