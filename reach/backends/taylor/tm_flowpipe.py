"""Taylor-model flowpipes: validated integration of ``x' = f(x)`` from a box of initial states,
with symbolic remainders in a QR-preconditioned frame (Berz & Makino; Lohner; Chen, Abraham &
Sankaranarayanan, Flow*).

Variables. A run starts at ``x_i(0) = c_i + r_i xi_j`` for the ``j``-th uncertain state ``i``
(``xi in [-1, 1]^m``). Every step works in the algebra of the variables ``(xi, eps, sigma)``:

* ``xi`` (``m`` of them), the initial deviations: a run is one value of ``xi``;
* ``eps in [-1, 1]^q``, one per state that carries an error (all but the ``exact`` states, whose
  rate is a known constant such as a clock's 1): the symbolic remainder of the step's start;
* ``sigma in [-1, 1]``, the scaled time of the step, ``t = t_k + h (sigma + 1)/2``.

Frame. At a step node ``t_k`` the state of the run ``xi`` is known to satisfy

    x(t_k; xi) in { p_k(xi) + A_k r : r in [r_mid - r_rad, r_mid + r_rad] }          (F)

with ``p_k`` a polynomial of order ``n`` in ``xi`` and ``A_k`` a ``q x q`` matrix acting on the error
states (exact states: ``x_i in p_{k,i} + [c_lo, c_hi]``, an interval that holds only their rounding
allowances; it widens the start of the next Picard image). Hence some ``eps(xi) in [-1, 1]^q`` gives

    x(t_k; xi) = X0(xi, eps(xi)),   X0(xi, eps) = p_k(xi) + A_k (r_mid + r_rad * eps),

a polynomial with no interval part: the error of the earlier steps enters the step as the
variables ``eps``, and the field (a network controller included) acts on it in Taylor-model
arithmetic like on any other variable, so its image keeps its signs and correlations instead of
being wrapped by interval arithmetic at every layer.

Step (Picard iteration and its validation). ``P(xi, eps, sigma)`` is the order-``n`` fixed point of
the truncated Picard operator ``P = X0 + int_{t_k}^t f(P)``, reached after ``n + 1`` passes in DA
arithmetic (the part of degree ``d`` of the image depends only on the parts of degree ``< d``). An
interval vector ``J`` is accepted when, in Taylor-model arithmetic (:mod:`.tm`),

    X0 + int_{t_k}^t f(P + J) dt  subset  P + J      for every (xi, eps, sigma).            (V)

The integral of a Taylor model ``F = F_poly + [lo, hi]`` is the antiderivative of ``F_poly`` in
``sigma`` (times ``h/2``, from ``sigma = -1``), the terms it would raise above order ``n`` enclosed
by ``|c| h / (b + 1)`` (a monomial ``c xi^a eps^e sigma^b`` integrates to at most that in size), plus
``[min(0, lo) h, max(0, hi) h]``. Why (V) proves the enclosure: fix ``xi`` and the run's
``eps(xi)``; the set ``K`` of continuous functions ``y`` on ``[t_k, t_k + h]`` with
``y(t) - P(t) in J`` is convex, closed and bounded, and the Picard operator
``T y = x(t_k) + int f(y)`` maps ``K`` into itself by (V) (each Taylor model bounds its function
pointwise, for every value of its variables). ``T(K)`` is equicontinuous (``f`` is bounded on the
compact set of values), so ``T`` is compact and has a fixed point in ``K`` (Schauder); it is the
solution, which is unique since ``f`` is smooth. So ``x(t; xi) in P(xi, eps(xi), sigma) + J``
on the whole step. A ``J`` is found by inflation: start from a guess (the last step's ``J``
scaled to the new step) or from the image of ``J = 0``, and replace ``J`` by the hull of ``J`` and
twice its image until (V) holds; the step is halved when it does not within a few tries.

The field on ``P + J`` (the left side of (V)) is evaluated with ``J`` as first-order symbols
(:class:`LinearTM`): ``f(P + mid J + rad J delta)``, ``delta in [-1, 1]^q`` free at every time, gives
``f(P) + G(xi, eps, sigma) delta + s`` with ``G`` the Taylor models of ``Df(P) diag(rad J)`` and ``s``
the second-order part, and ``G delta`` is bounded only after the network, by ``sum_j |G_ij|``. A plain
Taylor-model remainder would be wrapped at each sine layer instead (``|W| rad`` on 32 neurons, five
times): on CW SIREN its image of ``J`` is about ``10^4`` times the true derivative, so no ``J``
closes for steps of more than a fraction of a second.

End of step (QR preconditioning). At ``sigma = 1``, ``x(t_{k+1}; xi) in E(xi, eps) + J_end`` with
``E = P(., ., 1)`` and ``J_end`` the Picard image's enclosure there (tighter than ``J``). Split
``E(xi, eps) = E(xi, 0) + Phi eps + N(xi, eps)`` (``Phi``: the terms linear in ``eps`` alone; ``N``:
every other term that holds an ``eps``). The error of the run is ``e = Phi eps + N + J_end`` with
``N + J_end`` in an interval box ``[n_lo, n_hi]``. With ``Phi Pi = Q R`` (QR with column pivoting,
Lohner's method) the new frame is ``A_{k+1} = Q``, ``p_{k+1} = E(xi, 0)`` and, with ``C = Q^T``,

    r = A^-1 e in  |C Phi| [-1, 1]  +  C [n_lo, n_hi]  (midpoint-radius),

so the error is carried in an orthonormal frame that follows the flow's linear part: the box of
``r`` is the image box of a nearly triangular map, and stretched or rotated error sets are not
re-boxed along the state axes at every step (the wrapping effect). ``C`` is only approximately
the inverse of the floating-point ``Q``: with ``eta = || I - C Q ||_inf < 1``, ``|A^-1 e - C e|_inf <=
eta / (1 - eta) ||C||_inf |e|_inf``, which is added to ``r_rad``.

Floating-point rounding. The polynomial coefficients are computed in round-to-nearest, as in
:mod:`.tm`; a relative allowance ``ROUNDING`` of the magnitudes involved is added wherever an
enclosure is formed: to ``J``'s image in (V) (of ``|X0| + h |f|``), to ``J_end`` and to ``r_rad``
(of the error's magnitude) — the convention of :mod:`.verified`.

Step size (accuracy only; every accepted step is validated): the new error ``J_end`` per unit
time is held near a per-state tolerance (:meth:`TMFlow.run`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.linalg

from reach.backends.taylor.bound import polynomial_range
from reach.backends.taylor.da import DA, algebra, integer_power
from reach.backends.taylor.tm import TM, _imul, scaled_sum
from reach.backends.taylor.verified import at_sigma

ROUNDING = 1e-12          # relative allowance for floating-point rounding
INFLATIONS = 6            # tries to find a remainder J that satisfies (V) before halving the step
MAX_HALVINGS = 30


@lru_cache(maxsize=None)
def _tables(order: int, m: int, q: int):
    """Monomial classes of the algebra ``(xi_1..xi_m, eps_1..eps_q, sigma)``: ``xi_only`` (no
    ``eps``, no ``sigma``), ``eps_linear[j]`` (the monomial ``eps_j``) and ``eps_rest`` (every
    other monomial with an ``eps`` and no ``sigma``)."""
    e = algebra(order, m + q + 1).exps
    s = m + q
    no_sigma = e[:, s] == 0
    has_eps = e[:, m:s].sum(axis=1) > 0
    eps_linear = np.array([1 + m + j for j in range(q)], dtype=int)
    rest = no_sigma & has_eps
    rest[eps_linear] = False
    return np.flatnonzero(no_sigma & ~has_eps), eps_linear, np.flatnonzero(rest)


def integrate(F: TM, h: float) -> TM:
    """``int_{t_k}^t F dt`` with ``t = t_k + h (sigma + 1)/2`` (``sigma``: the last variable), a
    Taylor model of the same order: the antiderivative of the polynomial from ``sigma = -1``, the
    terms above the order enclosed by ``|c| h/(b + 1)``, the remainder by ``[min(0, lo) h,
    max(0, hi) h]``."""
    alg = F.alg
    s = alg.nvars - 1
    G = F.poly.integrate(s)
    poly = (G - at_sigma(G, -1.0)) * (0.5 * h)
    top = alg.degree == alg.order
    dropped = (np.abs(F.poly.c[..., top]) * (h / (alg.exps[top, s] + 1.0))).sum(axis=-1)
    lo = np.minimum(F.lo, 0.0) * h - dropped
    hi = np.maximum(F.hi, 0.0) * h + dropped
    return TM(poly, lo, hi)


def _trailing(t: TM) -> TM:
    """``t`` with a trailing axis of length 1 (to multiply Taylor models of shape ``S + (d,)``)."""
    lo, hi = np.asarray(t.lo, dtype=float), np.asarray(t.hi, dtype=float)
    return TM(DA(t.alg, t.poly.c[..., None, :]), lo[..., None], hi[..., None])


def _abs_bound(t: TM) -> np.ndarray:
    lo, hi = t.bound()
    return np.maximum(np.abs(lo), np.abs(hi))


class LinearTM:
    """A Taylor model with a first-order symbolic remainder: ``v + g . delta + [slo, shi]``.

    ``v`` is a Taylor model (batch shape ``S``), ``g`` Taylor models of shape ``S + (d,)`` and
    ``delta in [-1, 1]^d`` free symbols (they may take other values at every time of the step).
    The modelled function lies in ``v + g . delta + s`` for every value of the Taylor models'
    variables and every ``delta``. The field on ``P + J`` is evaluated on the seeds
    ``P_i + mid(J_i) + rad(J_i) delta_i``, so the remainder ``J`` reaches the output through the
    Taylor models of the derivatives, which keep their signs through a network's layers; only the
    second-order part ``s`` is wrapped by interval arithmetic (a plain Taylor model wraps ``J``
    itself at every layer: on CW SIREN by about ``10^5`` against the true derivative):

    * ``(va + ga.delta + sa)(vb + gb.delta + sb) = va vb + (va gb + vb ga).delta + s`` with
      ``s = (ga.delta)(gb.delta) + sa (vb + gb.delta) + sb (va + ga.delta) + sa sb`` in intervals;
    * ``phi(v + w) = phi(v) + phi'(v) g.delta + phi'(v) s + phi''(z)/2 w^2`` with ``w = g.delta + s``
      and ``z`` between ``v`` and ``v + w`` (Taylor's theorem with the Lagrange remainder).
    """

    __slots__ = ("v", "g", "slo", "shi")
    __array_priority__ = 300

    def __init__(self, v: TM, g: TM, slo=0.0, shi=0.0):
        self.v, self.g = v, g
        self.slo = np.broadcast_to(np.asarray(slo, dtype=float), v.shape).copy()
        self.shi = np.broadcast_to(np.asarray(shi, dtype=float), v.shape).copy()

    @classmethod
    def seed(cls, P: list, lo: np.ndarray, hi: np.ndarray, symbolic: list[int]) -> list["LinearTM"]:
        """``P_i + mid_i + rad_i delta_j`` for the ``j``-th state ``i`` of ``symbolic``, and
        ``P_i + [lo_i, hi_i]`` (a plain Taylor-model remainder) for the others."""
        alg = P[0].alg
        mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
        out = []
        for i, p in enumerate(P):
            g = np.zeros(len(symbolic))
            if i in symbolic:
                g[symbolic.index(i)] = rad[i]
                v = TM(p + float(mid[i]))
            else:
                v = TM(p, lo[i], hi[i])
            out.append(cls(v, TM(DA.const(alg, g))))
        return out

    @property
    def width(self) -> int:
        return self.g.shape[-1]

    @property
    def shape(self):
        return self.v.shape

    def const_like(self, value) -> "LinearTM":
        value = np.asarray(value, dtype=float)
        alg = self.v.alg
        return LinearTM(TM(DA.const(alg, value)), TM(DA.const(alg, np.zeros(value.shape + (self.width,)))))

    def _delta_size(self) -> np.ndarray:
        """``G`` with ``g . delta in [-G, G]``."""
        return _abs_bound(self.g).sum(axis=-1)

    def hull(self):
        """An interval containing the modelled values."""
        lo, hi = self.v.bound()
        G = self._delta_size()
        return lo - G + self.slo, hi + G + self.shi

    def enclose(self) -> TM:
        """A Taylor model (without ``delta``) of the modelled function: ``v`` widened by the
        bounds of ``g . delta`` and ``s``."""
        G = self._delta_size()
        return self.v.widen(-G + self.slo, G + self.shi)

    # ------------------------------------------------------------ arithmetic
    def __add__(self, other):
        if isinstance(other, LinearTM):
            return LinearTM(self.v + other.v, self.g + other.g, self.slo + other.slo, self.shi + other.shi)
        return LinearTM(self.v + other, self.g, self.slo, self.shi)

    __radd__ = __add__

    def __neg__(self):
        return LinearTM(-self.v, -self.g, -self.shi, -self.slo)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if not isinstance(other, LinearTM):
            c = np.asarray(other, dtype=float)
            lo, hi = _imul(self.slo, self.shi, c, c)
            return LinearTM(self.v * c, self.g * (c[..., None] if c.ndim else c), lo, hi)
        a, b = self, other
        Ga, Gb = a._delta_size(), b._delta_size()
        alo, ahi = a.v.bound()
        blo, bhi = b.v.bound()
        s1 = _imul(-Ga, Ga, -Gb, Gb)
        s2 = _imul(a.slo, a.shi, blo - Gb, bhi + Gb)
        s3 = _imul(b.slo, b.shi, alo - Ga, ahi + Ga)
        s4 = _imul(a.slo, a.shi, b.slo, b.shi)
        g = _trailing(a.v) * b.g + _trailing(b.v) * a.g
        return LinearTM(a.v * b.v, g, s1[0] + s2[0] + s3[0] + s4[0], s1[1] + s2[1] + s3[1] + s4[1])

    __rmul__ = __mul__

    def __truediv__(self, other):
        if isinstance(other, LinearTM):
            return self * other ** -1.0
        return self * (1.0 / np.asarray(other, dtype=float))

    def __rtruediv__(self, other):
        return (self ** -1.0) * other

    def _chain(self, value: TM, slope: TM, curvature) -> "LinearTM":
        """``phi(self)`` from the Taylor models of ``phi(v)``, ``phi'(v)`` and
        ``curvature(lo, hi)``, an interval containing ``phi''`` on ``[lo, hi]``."""
        G = self._delta_size()
        W = G + np.maximum(np.abs(self.slo), np.abs(self.shi))
        vlo, vhi = self.v.bound()
        clo, chi = curvature(vlo - W, vhi + W)
        dlo, dhi = slope.bound()
        first = _imul(dlo, dhi, self.slo, self.shi)
        second = _imul(clo, chi, 0.0 * W, 0.5 * W * W)
        return LinearTM(value, _trailing(slope) * self.g, first[0] + second[0], first[1] + second[1])

    def __pow__(self, p):
        if np.ndim(p) == 0 and float(p).is_integer() and p >= 0:
            return integer_power(self, int(p))
        p = float(p)

        def curvature(lo, hi):
            if np.any(lo <= 0):
                return np.full_like(lo, -np.inf), np.full_like(lo, np.inf)
            a, b = lo ** (p - 2), hi ** (p - 2)
            return _imul(np.minimum(a, b), np.maximum(a, b), p * (p - 1), p * (p - 1))

        return self._chain(self.v ** p, self.v ** (p - 1) * p, curvature)

    def sqrt(self):
        return self ** 0.5

    def sin(self):
        return self._chain(self.v.sin(), self.v.cos(), _unit)

    def cos(self):
        return self._chain(self.v.cos(), -self.v.sin(), _unit)

    def exp(self):
        e = self.v.exp()
        return self._chain(e, e, lambda lo, hi: (np.exp(lo), np.exp(hi)))

    def log(self):
        def curvature(lo, hi):
            if np.any(lo <= 0):
                return np.full_like(lo, -np.inf), np.full_like(lo, np.inf)
            return -1.0 / lo ** 2, -1.0 / hi ** 2

        return self._chain(self.v.log(), self.v ** -1.0, curvature)

    weighted_sum = staticmethod(scaled_sum)

    # ------------------------------------------------------------ vectors (network layers)
    @staticmethod
    def stack(items: list["LinearTM"]) -> "LinearTM":
        return LinearTM(TM.stack([x.v for x in items]), TM.stack([x.g for x in items]),
                        np.stack([x.slo for x in items]), np.stack([x.shi for x in items]))

    def affine(self, W, b=None) -> "LinearTM":
        """``W a + b``: ``s`` maps by midpoint and radius."""
        W = np.asarray(W, dtype=float)
        mid, rad = 0.5 * (self.slo + self.shi), 0.5 * (self.shi - self.slo)
        m, r = W @ mid, np.abs(W) @ rad
        return LinearTM(self.v.affine(W, b), self.g.affine(W), m - r, m + r)

    def unstack(self) -> list["LinearTM"]:
        return [LinearTM(v, g, lo, hi) for v, g, lo, hi in
                zip(self.v.unstack(), self.g.unstack(), self.slo, self.shi)]


def _unit(lo, hi):
    return -np.ones_like(lo), np.ones_like(hi)


def picard_image(f, X0: list[DA], P: list[DA], lo: np.ndarray, hi: np.ndarray, h: float, symbolic: list[int],
                 carried=None):
    """The Picard image ``X0 + int f(P + [lo, hi])`` as Taylor models (one per state), and the
    enclosure ``[elo, ehi]`` of its difference from ``P`` over the whole step, with the rounding
    allowance: (V) holds for ``J = [lo, hi]`` iff ``lo <= elo`` and ``ehi <= hi``. The remainders
    of the ``symbolic`` states enter the field as the symbols of :class:`LinearTM`; ``carried``
    (``(lo, hi)``, per state) widens the start ``X0`` (the rounding carried by the exact states)."""
    F = [Fi.enclose() for Fi in f(LinearTM.seed(P, lo, hi, symbolic))]
    clo, chi = (np.zeros(len(X0)), np.zeros(len(X0))) if carried is None else carried
    image = [TM(x0, a, b) + integrate(Fi, h) for x0, a, b, Fi in zip(X0, clo, chi, F)]
    elo, ehi = _difference(image, P)
    size = np.array([_magnitude(x0) for x0 in X0]) + h * np.array([_magnitude(Fi) for Fi in F])
    return image, elo - ROUNDING * size, ehi + ROUNDING * size


def validate(f, X0: list[DA], P: list[DA], lo, hi, h: float, symbolic: list[int]) -> bool:
    """Whether ``J = [lo, hi]`` satisfies (V): the Picard operator maps ``P + J`` into itself
    (for a start ``X0`` without interval part)."""
    _, elo, ehi = picard_image(f, X0, P, np.asarray(lo, float), np.asarray(hi, float), h, symbolic)
    return bool(np.all(elo >= lo) and np.all(ehi <= hi))


def _difference(image: list[TM], P: list[DA]):
    """Interval enclosure of ``image - P`` over every ``(xi, eps, sigma)``."""
    ends = [(Ii - TM(p)).bound() for Ii, p in zip(image, P)]
    return np.array([e[0] for e in ends], dtype=float), np.array([e[1] for e in ends], dtype=float)


def _magnitude(x) -> float:
    """A bound of ``|x|`` over the box (a DA or a Taylor model)."""
    lo, hi = (x if isinstance(x, TM) else TM(x)).bound()
    return float(max(abs(lo), abs(hi)))


@dataclass
class Segment:
    """One validated step ``[t0, t0 + h]``: every run ``xi`` satisfies ``x(t) in P(xi, eps, sigma)
    + [lo, hi]`` on the step for some ``eps in [-1, 1]^q``, and ``x(t0 + h) in end`` (Taylor models
    in ``(xi, eps)``, the same ``eps``)."""

    t0: float
    h: float
    poly: list            # P_i(xi, eps, sigma), DA
    lo: np.ndarray        # J
    hi: np.ndarray
    end: list             # TM(E_i, J_end) at sigma = 1

    def tm(self) -> list[TM]:
        """Taylor models of the state on the whole step."""
        return [TM(p, a, b) for p, a, b in zip(self.poly, self.lo, self.hi)]

    def box_at(self, xi: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
        """Enclosure at ``t0 + h`` of the state of the run ``xi`` (a point of ``[-1, 1]^m``): the
        end models with ``xi`` substituted, bounded over ``eps``."""
        alg = self.end[0].alg
        args = [DA.const(alg, float(v)) for v in xi] + [DA.var(alg, j) for j in range(m, alg.nvars)]
        lo, hi = [], []
        for x in self.end:
            plo, phi = polynomial_range(x.poly.compose(args))
            lo.append(plo + x.lo)
            hi.append(phi + x.hi)
        return np.array(lo), np.array(hi)


@dataclass
class Flowpipe:
    """The validated steps from ``t = 0``, and how the integration ended: ``"horizon"``,
    ``"stopped"`` (by the caller's ``stop``) or ``"failed"`` (``why``: the step, time and sizes)."""

    segments: list = field(default_factory=list)
    status: str = "horizon"
    why: str = ""
    error_radius: list = field(default_factory=list)    # |A r| bound per state at each node

    @property
    def t_end(self) -> float:
        return self.segments[-1].t0 + self.segments[-1].h if self.segments else 0.0


class TMFlow:
    """Taylor-model flowpipe of ``x' = f(x)`` (``f``: a field compiled by
    :func:`.flow.compile_expressions`, evaluable on DAs and Taylor models) from the box
    ``center +- half_width`` (non-zero widths: the uncertain states).

    ``exact``: states whose rate is a constant (clocks); they carry no error variable, only an
    interval (sound for any state, but wrapped: meant for the rounding of a clock). ``tol``:
    per-state tolerance of the error a step may add per unit time (step-size control only; every
    step is validated whatever its error)."""

    def __init__(self, f, center, half_width, order: int = 4, exact=(), tol=None):
        self.f = f
        self.center = np.asarray(center, dtype=float)
        self.half_width = np.asarray(half_width, dtype=float)
        self.n = len(self.center)
        self.uncertain = [i for i in range(self.n) if self.half_width[i] > 0]
        self.errors = [i for i in range(self.n) if i not in set(exact)]
        self.m, self.q = len(self.uncertain), len(self.errors)
        self.order = order
        self.alg = algebra(order, self.m + self.q + 1)
        self.tol = np.full(self.n, np.inf) if tol is None else np.asarray(tol, dtype=float)
        self.xi_only, self.eps_linear, self.eps_rest = _tables(order, self.m, self.q)

    # ------------------------------------------------------------ frames
    def initial_frame(self):
        """``(p, A, r_mid, r_rad, carried)`` of the initial box: ``p_i = c_i + r_i xi_j``, no error.
        ``carried`` (``(lo, hi)`` per state) is the interval the exact states carry (their
        rounding allowances; zero for the error states, whose error is in ``r``)."""
        p = [DA.var(self.alg, self.uncertain.index(i), c, self.half_width[i]) if i in self.uncertain
             else DA.const(self.alg, c) for i, c in enumerate(self.center)]
        return p, np.eye(self.q), np.zeros(self.q), np.zeros(self.q), (np.zeros(self.n), np.zeros(self.n))

    def start_polynomials(self, frame) -> list[DA]:
        """``X0(xi, eps) = p(xi) + A (r_mid + r_rad eps)`` on the error states."""
        p, A, rmid, rrad, _ = frame
        X0 = [DA(self.alg, x.c.copy()) for x in p]
        shift = A @ rmid
        for row, i in enumerate(self.errors):
            X0[i].c[0] += shift[row]
            X0[i].c[self.eps_linear] += A[row] * rrad
        return X0

    def reframe(self, end: list[TM]):
        """The frame (F) at the step's end from the end models ``E + J_end`` (QR preconditioning,
        module docstring)."""
        p = []
        for x in end:
            c = np.zeros(self.alg.size)
            c[self.xi_only] = x.poly.c[self.xi_only]
            p.append(DA(self.alg, c))
        rows = self.errors
        Phi = np.array([end[i].poly.c[self.eps_linear] for i in rows]).reshape(self.q, self.q)
        nlo, nhi = np.zeros(self.q), np.zeros(self.q)
        for row, i in enumerate(rows):
            c = np.zeros(self.alg.size)
            c[self.eps_rest] = end[i].poly.c[self.eps_rest]
            lo, hi = polynomial_range(DA(self.alg, c))
            nlo[row], nhi[row] = lo + end[i].lo, hi + end[i].hi
        Q, _, _ = scipy.linalg.qr(Phi, pivoting=True)
        C = Q.T
        nmid, nrad = 0.5 * (nlo + nhi), 0.5 * (nhi - nlo)
        rmid = C @ nmid
        rrad = np.abs(C @ Phi).sum(axis=1) + np.abs(C) @ nrad
        e_size = np.abs(Phi).sum(axis=1).max() + np.max(np.abs(nmid) + nrad)
        eta = np.abs(np.eye(self.q) - C @ Q).sum(axis=1).max() + ROUNDING
        if eta >= 0.5:
            raise ArithmeticError("the preconditioning frame is singular")
        rrad = rrad + (eta / (1.0 - eta) * np.abs(C).sum(axis=1).max() + ROUNDING) * e_size
        clo, chi = np.zeros(self.n), np.zeros(self.n)
        for i in set(range(self.n)) - set(rows):      # exact states: any eps terms join the interval
            c = np.zeros(self.alg.size)
            with_eps = np.r_[self.eps_linear, self.eps_rest]
            c[with_eps] = end[i].poly.c[with_eps]
            lo, hi = polynomial_range(DA(self.alg, c))
            clo[i], chi[i] = lo + end[i].lo, hi + end[i].hi
        return p, Q, rmid, rrad, (clo, chi)

    # ------------------------------------------------------------ one step
    def picard_polynomial(self, X0: list[DA], h: float) -> list[DA]:
        """The fixed point ``P`` of the truncated Picard operator (``n + 1`` passes)."""
        s = self.alg.nvars - 1
        P = list(X0)
        for _ in range(self.order + 1):
            G = [r.integrate(s) for r in self.f(P)]
            P = [x + (g - at_sigma(g, -1.0)) * (0.5 * h) for x, g in zip(X0, G)]
        return P

    def step(self, X0: list[DA], t0: float, h: float, guess=None, carried=None) -> Segment | None:
        """The validated step from ``X0`` (widened by ``carried``) at ``t0``, or None if no remainder
        satisfies (V). The search for ``J`` starts from ``guess`` (an interval box), else from the
        image of ``J = 0``."""
        P = self.picard_polynomial(X0, h)
        lo, hi = (np.zeros(self.n), np.zeros(self.n)) if guess is None else guess
        for _ in range(INFLATIONS + 1):
            with np.errstate(over="ignore", invalid="ignore"):
                image, elo, ehi = picard_image(self.f, X0, P, lo, hi, h, self.errors, carried)
            if not (np.all(np.isfinite(elo)) and np.all(np.isfinite(ehi))):
                return None
            if np.all(elo >= lo) and np.all(ehi <= hi):
                return Segment(t0, h, P, lo, hi, self._end(image, P))
            mid, rad = 0.5 * (elo + ehi), 0.5 * (ehi - elo)
            lo, hi = np.minimum(lo, mid - 2.0 * rad), np.maximum(hi, mid + 2.0 * rad)
        return None

    def _end(self, image: list[TM], P: list[DA]) -> list[TM]:
        """``TM(E, J_end)`` at ``sigma = 1`` from the accepted Picard image."""
        out = []
        for Ii, p in zip(image, P):
            E = at_sigma(p, 1.0)
            d = TM(at_sigma(Ii.poly, 1.0) - E, Ii.lo, Ii.hi)
            lo, hi = d.bound()
            allowance = ROUNDING * _magnitude(Ii)
            out.append(TM(E, lo - allowance, hi + allowance))
        return out

    # ------------------------------------------------------------ the sweep
    def run(self, horizon: float, h0: float, stop=None, h_min: float = 1e-6) -> Flowpipe:
        """Steps from ``t = 0`` to ``horizon`` (first step ``h0``); ``stop(segment)`` may end the
        sweep after a step (returns True).

        Step size: ``rate`` is the largest new error of a step per unit time over ``tol``. A step
        with ``rate <= threshold`` is accepted and the next one scaled by ``(threshold /
        rate)^(1/(n+1))`` (between 1/2 and 2). A larger rate halves the step, unless halving
        lowered it by less than a quarter: that rate is then a floor (the truncation in ``xi`` and
        ``eps`` adds error in proportion to the time, whatever the step) and becomes the
        threshold of the later steps (times 1.25)."""
        frame = self.initial_frame()
        out = Flowpipe()
        t, h, k = 0.0, float(h0), 0
        n1 = self.order + 1
        threshold, guess = 1.0, None
        while t < horizon * (1 - 1e-15):
            h = min(h, horizon - t)
            X0 = self.start_polynomials(frame)
            seg, rate, halvings = None, np.inf, 0
            while True:
                trial = self.step(X0, t, h, guess, frame[4])
                if trial is not None:
                    trial_rate = self._error_rate(trial)
                    if seg is not None and trial_rate > 0.75 * rate:
                        threshold = max(threshold, 1.25 * rate)     # a floor: keep the longer step
                        break
                    seg, rate = trial, trial_rate
                    if rate <= threshold:
                        break
                elif seg is not None:
                    break
                halvings += 1
                if halvings > MAX_HALVINGS or h / 2 < h_min:
                    break
                h /= 2
                guess = None if guess is None else (0.5 * guess[0], 0.5 * guess[1])
            if seg is None:
                out.status = "failed"
                out.why = (f"step {k} at t = {t:.6g}: no remainder satisfies the Picard validation down to "
                           f"h = {h:.3g} s (error carried at the node: {_radius_text(out)})")
                return out
            out.segments.append(seg)
            try:
                frame = self.reframe(seg.end)
            except ArithmeticError as exc:
                out.status, out.why = "failed", f"step {k} at t = {t:.6g}: {exc}"
                return out
            out.error_radius.append(self._frame_radius(frame))
            t += seg.h
            k += 1
            grow = 2.0 if rate <= 0 else min(2.0, max(0.5, (threshold / rate) ** (1.0 / n1)))
            h = seg.h * grow
            guess = (seg.lo * grow, seg.hi * grow)
            if stop is not None and stop(seg):
                out.status = "stopped"
                return out
        return out

    def _error_rate(self, seg: Segment) -> float:
        """The largest new error of the step per unit time, over ``tol``."""
        size = np.array([max(abs(x.lo), abs(x.hi)) for x in seg.end]) / seg.h
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = np.where(size > 0, size / self.tol, 0.0)
        return float(np.max(rate))

    def _frame_radius(self, frame) -> np.ndarray:
        """Bound of ``|A r|`` per state (the error carried by the frame)."""
        _, A, rmid, rrad, _ = frame
        out = np.zeros(self.n)
        out[self.errors] = np.abs(A @ rmid) + np.abs(A) @ rrad
        return out


def _radius_text(pipe: Flowpipe) -> str:
    if not pipe.error_radius:
        return "0"
    return np.array2string(pipe.error_radius[-1], precision=3)


# ------------------------------------------------------------------ closest approach
@dataclass
class MinimumProof:
    """Outcome of :func:`prove_minimum_at_most` on one subdomain.

    ``proved``: the sub-boxes of ``[-1, 1]^m`` (``(center, radius)`` in ``xi``) every run of which is
    proved to reach ``q <= threshold``, each with the time of its witness step; ``pending``: the
    sub-boxes left; ``fraction``: the proved share of the subdomain's volume."""

    proved: list
    pending: list
    fraction: float
    pipe: Flowpipe
    seconds: float
    status: str            # "proved", "failed", "horizon" or "budget"
    why: str = ""


def restrict(poly: DA, center, radius, m: int) -> DA:
    """``poly`` on the sub-box ``xi = center + radius * eta`` of its first ``m`` variables (in
    ``eta``, the other variables unchanged): an exact change of variables (no truncation, since
    the substitution is affine)."""
    alg = poly.alg
    args = [DA.var(alg, i, float(center[i]), float(radius[i])) for i in range(m)]
    args += [DA.var(alg, j) for j in range(m, alg.nvars)]
    return poly.compose(args)


def prove_minimum_at_most(flow: TMFlow, q, threshold: float, horizon: float, h0: float, max_depth: int = 3,
                          budget: float | None = None) -> MinimumProof:
    """Prove that every run of the subdomain reaches ``q(x) <= threshold`` before ``horizon``.

    ``q`` is compiled for Taylor models (:func:`.flow.compile_expressions`, one output). After each
    validated step, the model ``q(E + J_end)`` at the step's end (in ``(xi, eps)``) is bounded on
    each pending sub-box of ``xi`` (the polynomial restricted to the sub-box, :func:`restrict`,
    bounded over ``eps`` as well by eq. (27), plus its remainder and a rounding allowance of
    ``ROUNDING`` times the coefficients' size): if its upper end is at most
    ``threshold``, then for every run ``xi`` of the sub-box, ``q(x(t_{k+1}; xi)) <= threshold``
    (the run's ``eps(xi)`` is one value of ``eps``), and the sub-box is proved. A sub-box whose
    enclosure straddles the threshold is split into ``2^m`` halves (down to ``max_depth``
    levels) to tighten the bound. The sweep stops when every sub-box is proved, the flowpipe fails
    (its reason), the horizon is reached, or after ``budget`` seconds."""
    started = time.perf_counter()
    m = flow.m
    pending = [(np.zeros(m), np.ones(m), 0)]
    proved = []

    def check(seg: Segment) -> bool:
        nonlocal pending
        value = q(seg.end)
        lo, hi = value.bound()
        t_end = seg.t0 + seg.h
        if lo <= threshold:
            left = []
            todo = list(pending)
            while todo:
                center, radius, depth = todo.pop()
                part = restrict(value.poly, center, radius, m)
                blo, bhi = polynomial_range(part)
                allowance = ROUNDING * float(np.abs(part.c).sum())
                if bhi + value.hi + allowance <= threshold:
                    proved.append((center, radius, t_end))
                elif blo + value.lo <= threshold and depth < max_depth:
                    for corner in np.ndindex(*(2,) * m):
                        offset = (np.array(corner) - 0.5) * radius
                        todo.append((center + offset, 0.5 * radius, depth + 1))
                else:
                    left.append((center, radius, depth))
            pending = left
        if not pending:
            return True
        return budget is not None and time.perf_counter() - started > budget

    pipe = flow.run(horizon, h0, stop=check)
    fraction = float(sum(np.prod(r) for _, r, _ in proved))
    seconds = time.perf_counter() - started
    if not pending:
        status, why = "proved", ""
    elif pipe.status == "failed":
        status, why = "failed", pipe.why
    elif pipe.status == "stopped":
        status, why = "budget", f"time budget of {budget:g} s spent at t = {pipe.t_end:.6g}"
    else:
        status, why = "horizon", f"some runs not shown to reach q <= {threshold:g} by t = {pipe.t_end:.6g}"
    return MinimumProof(proved, pending, fraction, pipe, seconds, status, why)


# ------------------------------------------------------------------ as a rigorous sweep's stretch
class FlowpipeStretch:
    """A flowpipe read as :class:`.verified.Enclosure` is by the rigorous sweep
    (:meth:`.problem.EventProblem.sweep`): ``steps[k]`` (``t0``, ``h``), the Taylor models of the
    state on step ``k`` and at its end, and ``error_box`` (per step, the remainder's size ``|J|``).
    Its models have the variables ``eps`` between ``xi`` and ``sigma`` (still the last variable, so
    :func:`.verified.at_sigma` and every bound over all variables stay valid); the crossing models
    of :func:`.verified.crossing` are not built from it (``crossing_models``: the sweep uses the
    hull of the steps that meet a guard)."""

    crossing_models = False

    def __init__(self, pipe: Flowpipe):
        self.steps = pipe.segments
        self.error_box = np.array([np.maximum(np.abs(s.lo), np.abs(s.hi)) for s in pipe.segments])

    def tm(self, k: int) -> list[TM]:
        return self.steps[k].tm()

    def tm_at_end(self, k: int) -> list[TM]:
        return self.steps[k].end


def stretch_from_box(f, low, high, order: int, exact, tol, duration: float, h0: float, inside,
                     budget: float) -> FlowpipeStretch:
    """The flowpipe of a mode's stretch from the box ``[low, high]`` for ``duration`` (or until
    ``inside(end models)`` says every run is inside an urgent guard), as a :class:`FlowpipeStretch`.
    Raises ArithmeticError with the reason when a step cannot be validated or ``budget`` seconds
    pass first."""
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    flow = TMFlow(f, 0.5 * (low + high), 0.5 * (high - low), order, exact, tol)
    started, spent = time.perf_counter(), []

    def stop(seg: Segment) -> bool:
        if inside(seg.end):
            return True
        if time.perf_counter() - started > budget:
            spent.append(seg.t0 + seg.h)
            return True
        return False

    pipe = flow.run(duration, h0, stop)
    if pipe.status == "failed":
        raise ArithmeticError(f"Taylor-model flowpipe: {pipe.why}")
    if spent:
        raise ArithmeticError(f"Taylor-model flowpipe: time budget of {budget:g} s spent at t = {spent[0]:.6g}")
    return FlowpipeStretch(pipe)
