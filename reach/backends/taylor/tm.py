"""Taylor models: a DA polynomial plus an interval that encloses everything it leaves out.

A Taylor model ``(P, I)`` of a function ``g`` on the scaled box ``xi in [-1, 1]^d`` asserts
``g(xi) - P(xi) in I`` for every ``xi`` in the box (Makino & Berz). Operations keep that
assertion true:

* sums add polynomials and intervals;
* a product ``(Pa + Ia)(Pb + Ib)`` keeps the order-``n`` part of ``Pa Pb`` and encloses the rest:
  the dropped terms of order ``> n`` by ``sum_{p + q > n} S_p(Pa) S_q(Pb)`` (``S_p``: L1 size of
  the order-``p`` terms, each monomial being at most 1 in size on the box), and the interval
  cross terms by ``B(Pa) Ib + Ia B(Pb) + Ia Ib`` with ``B`` the eq. (27) range bound;
* an analytic ``f`` of ``a = a0 + d`` is ``sum_{k <= n} f^(k)(a0)/k! d^k`` evaluated in Taylor-model
  arithmetic plus the Lagrange remainder ``f^(n+1)(a0 + theta d)/(n+1)! d^(n+1)``, bounded with
  an interval bound of ``f^(n+1)`` over ``a0 + B(d)``.

Floating-point rounding of the coefficients is not directed; the verified integration that
uses these models adds a relative allowance for it and says so.
"""

from __future__ import annotations

from math import factorial

import numpy as np

from reach.backends.taylor.bound import polynomial_range
from reach.backends.taylor.da import DA, integer_power, stack

INF = np.inf


def _imul(alo, ahi, blo, bhi):
    """Interval product ``[alo, ahi] * [blo, bhi]`` (elementwise; 0 * inf counts as 0)."""
    if np.ndim(alo) == 0 and np.ndim(blo) == 0 and np.ndim(ahi) == 0 and np.ndim(bhi) == 0:
        p = [float(x) * float(y) for x in (alo, ahi) for y in (blo, bhi)]
        p = [0.0 if v != v else v for v in p]
        return np.float64(min(p)), np.float64(max(p))
    with np.errstate(invalid="ignore", over="ignore"):
        p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
        lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
        hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
    if np.isnan(lo).any() or np.isnan(hi).any():
        p = np.nan_to_num(np.stack(np.broadcast_arrays(p1, p2, p3, p4)), nan=0.0, posinf=np.inf, neginf=-np.inf)
        return p.min(axis=0), p.max(axis=0)
    return lo, hi


def _ipow(lo, hi, k: int):
    """``[lo, hi]^k`` for an integer ``k >= 1``."""
    a, b = lo ** k, hi ** k
    if k % 2:
        return a, b
    low = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(a, b))
    return low, np.maximum(a, b)


class TM:
    """A (batch of) Taylor model(s): ``poly`` (a DA) and the remainder interval ``[lo, hi]``."""

    __slots__ = ("poly", "lo", "hi")
    __array_priority__ = 200

    def __init__(self, poly: DA, lo=0.0, hi=0.0):
        self.poly = poly
        if poly.c.ndim == 1:            # a scalar model: plain floats are much faster
            self.lo, self.hi = float(lo), float(hi)
        else:
            self.lo = np.broadcast_to(np.asarray(lo, dtype=float), poly.shape).copy()
            self.hi = np.broadcast_to(np.asarray(hi, dtype=float), poly.shape).copy()

    # ------------------------------------------------------------ construction and access
    @classmethod
    def const(cls, alg, value) -> "TM":
        return cls(DA.const(alg, value))

    def const_like(self, value) -> "TM":
        return TM(DA.const(self.poly.alg, value))

    @property
    def alg(self):
        return self.poly.alg

    @property
    def shape(self):
        return self.poly.shape

    @property
    def cons(self):
        return self.poly.cons

    def bound(self) -> tuple[np.ndarray, np.ndarray]:
        """An interval that contains the modelled function's values on the whole box. A NaN
        (``inf - inf`` in a remainder or a coefficient: an enclosure that has blown up) bounds
        nothing, so that component's interval is the whole line; left as NaN, comparisons such as
        ``max(bound, nan)`` would silently drop it."""
        plo, phi = polynomial_range(self.poly)
        lo, hi = plo + self.lo, phi + self.hi
        lost = np.isnan(lo) | np.isnan(hi)
        if np.any(lost):
            lo, hi = np.where(lost, -np.inf, lo), np.where(lost, np.inf, hi)
        return lo, hi

    def widen(self, lo, hi) -> "TM":
        return TM(self.poly, self.lo + lo, self.hi + hi)

    # ------------------------------------------------------------ arithmetic
    def __add__(self, other):
        if isinstance(other, TM):
            return TM(self.poly + other.poly, self.lo + other.lo, self.hi + other.hi)
        return TM(self.poly + other, self.lo, self.hi)

    __radd__ = __add__

    def __neg__(self):
        return TM(-self.poly, -self.hi, -self.lo)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if not isinstance(other, TM):
            c = np.asarray(other, dtype=float)
            lo, hi = _imul(self.lo, self.hi, c, c)
            return TM(self.poly * c, lo, hi)
        a, b = self.poly, other.poly
        dropped = _dropped_product_size(a, b)
        alo, ahi = polynomial_range(a)
        blo, bhi = polynomial_range(b)
        r1 = _imul(alo, ahi, other.lo, other.hi)
        r2 = _imul(self.lo, self.hi, blo, bhi)
        r3 = _imul(self.lo, self.hi, other.lo, other.hi)
        lo = r1[0] + r2[0] + r3[0] - dropped
        hi = r1[1] + r2[1] + r3[1] + dropped
        return TM(a * b, lo, hi)

    __rmul__ = __mul__

    def __truediv__(self, other):
        if isinstance(other, TM):
            return self * other.reciprocal()
        return self * (1.0 / np.asarray(other, dtype=float))

    def __rtruediv__(self, other):
        return self.reciprocal() * other

    def __pow__(self, p):
        if np.ndim(p) == 0 and float(p).is_integer() and p >= 0:
            return integer_power(self, int(p))
        p = float(p)

        def derivative_range(k, lo, hi):
            falling = np.prod([p - j for j in range(k)]) if k else 1.0
            if np.any(lo <= 0):
                return np.full_like(lo, -INF), np.full_like(lo, INF)
            a, b = lo ** (p - k), hi ** (p - k)
            return _imul(np.minimum(a, b), np.maximum(a, b), falling, falling)

        return self._analytic(lambda a0, k: np.prod([p - j for j in range(k)]) * a0 ** (p - k) / factorial(k),
                              derivative_range)

    def reciprocal(self):
        return self ** -1.0

    def sqrt(self):
        return self ** 0.5

    # ------------------------------------------------------------ elementary functions
    def _analytic(self, coefficient, derivative_range) -> "TM":
        """``f(self)``: ``coefficient(a0, k) = f^(k)(a0)/k!``; ``derivative_range(k, lo, hi)``
        an interval containing ``f^(k)`` on ``[lo, hi]``."""
        n = self.alg.order
        a0 = self.cons
        d = self - a0
        dlo, dhi = d.bound()
        out = self.const_like(coefficient(a0, 0))
        power = self.const_like(np.ones(self.shape))
        for k in range(1, n + 1):
            power = power * d
            out = out + power * coefficient(a0, k)
        flo, fhi = derivative_range(n + 1, a0 + dlo, a0 + dhi)
        plo, phi = _ipow(dlo, dhi, n + 1)
        rlo, rhi = _imul(flo, fhi, plo, phi)
        return out.widen(rlo / factorial(n + 1), rhi / factorial(n + 1))

    def sin(self):
        return self._analytic(lambda a0, k: _sin_derivative(a0, k) / factorial(k), _unit_range)

    def cos(self):
        return self._analytic(lambda a0, k: _sin_derivative(a0, k + 1) / factorial(k), _unit_range)

    def exp(self):
        return self._analytic(lambda a0, k: np.exp(a0) / factorial(k), lambda k, lo, hi: (np.exp(lo), np.exp(hi)))

    def log(self):
        def derivative_range(k, lo, hi):
            if np.any(lo <= 0):
                return np.full_like(lo, -INF), np.full_like(lo, INF)
            scale = (-1.0) ** (k + 1) * factorial(k - 1)
            a, b = scale / lo ** k, scale / hi ** k
            return np.minimum(a, b), np.maximum(a, b)

        return self._analytic(lambda a0, k: np.log(a0) if k == 0 else (-1.0) ** (k + 1) / (k * a0 ** k),
                              derivative_range)

    @staticmethod
    def weighted_sum(weights: np.ndarray, items: list) -> "TM":
        """``sum_k w_k a_k`` for scalar Taylor models and floats."""
        alg = next(v.alg for v in items if isinstance(v, TM))
        models = [v if isinstance(v, TM) else TM.const(alg, v) for v in items]
        w = np.asarray(weights, dtype=float)
        poly = DA.weighted_sum(w, [m.poly for m in models])
        lo = np.array([m.lo for m in models])
        hi = np.array([m.hi for m in models])
        pos, neg = np.maximum(w, 0.0), np.minimum(w, 0.0)
        return TM(poly, pos @ lo + neg @ hi, pos @ hi + neg @ lo)

    # ------------------------------------------------------------ vectors (network layers)
    @staticmethod
    def stack(items: list["TM"]) -> "TM":
        return TM(stack([t.poly for t in items]), np.stack([t.lo for t in items]),
                  np.stack([t.hi for t in items]))

    def affine(self, W, b=None) -> "TM":
        """``W a + b``: the remainder interval maps by midpoint and radius, ``|W| rad``."""
        W = np.asarray(W, dtype=float)
        mid, rad = 0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo)
        m, r = W @ mid, np.abs(W) @ rad
        return TM(self.poly.affine(W, b), m - r, m + r)

    def unstack(self) -> list["TM"]:
        return [TM(DA(self.alg, c), lo, hi) for c, lo, hi in zip(self.poly.c, self.lo, self.hi)]

    def __repr__(self):
        return f"TM({self.poly!r}, [{self.lo}, {self.hi}])"


def scaled_sum(weights, items: list):
    """``sum_k w_k a_k`` by the items' own ``*`` and ``+`` (types that carry derivatives or
    remainder symbols besides a Taylor model: :class:`.network_tm.TMJet`,
    :class:`.tm_flowpipe.LinearTM`)."""
    out = None
    for w, item in zip(np.asarray(weights, dtype=float), items):
        term = item * float(w)
        out = term if out is None else out + term
    return out


def _dropped_product_size(a: DA, b: DA) -> np.ndarray:
    """``sum_{p + q > n} S_p(a) S_q(b)``: a bound of the terms a truncated product drops."""
    n = a.alg.order
    Sa, Sb = a.order_norms(), b.order_norms()
    total = np.zeros(np.broadcast_shapes(a.shape, b.shape))
    for p in range(1, n + 1):
        for q in range(n + 1 - p, n + 1):
            total = total + Sa[..., p] * Sb[..., q]
    return total


def _sin_derivative(a0, k: int):
    return (np.sin(a0), np.cos(a0), -np.sin(a0), -np.cos(a0))[k % 4]


def _unit_range(k, lo, hi):
    return -np.ones_like(lo), np.ones_like(hi)
