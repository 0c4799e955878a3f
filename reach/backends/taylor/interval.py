"""Interval arithmetic with first derivatives: an enclosure of a vector field's Jacobian on a box.

A :class:`Jet` holds an interval ``[lo, hi]`` for a value and intervals for its gradient with
respect to ``n`` inputs. Evaluating a flow on jets seeded with the box ``Z`` (value ``Z_i``,
gradient ``e_i``) gives, by the chain rule carried out in interval arithmetic, intervals that
contain ``f(z)`` and ``Df(z)`` for every ``z`` in ``Z`` — what the verified integration needs for
its logarithmic-norm bound. Ranges of ``sin`` and ``cos`` use their Lipschitz constant 1 around the
midpoint; powers with non-integer exponents need a positive base and are unbounded otherwise.
"""

from __future__ import annotations

import numpy as np

from reach.backends.taylor.tm import _imul, _ipow

INF = np.inf


def _ipow_real(lo, hi, p: float):
    """``[lo, hi]^p`` for a real exponent (integers of either sign, or a positive base)."""
    if float(p).is_integer() and p >= 1:
        return _ipow(lo, hi, int(p))
    if p == 0:
        return np.ones_like(lo), np.ones_like(hi)
    if float(p).is_integer():
        crosses = (lo <= 0) & (hi >= 0)
        a, b = _ipow(lo, hi, int(-p))
        with np.errstate(divide="ignore"):
            inv = np.stack([1.0 / a, 1.0 / b])
        return (np.where(crosses, -INF, inv.min(axis=0)), np.where(crosses, INF, inv.max(axis=0)))
    positive = lo > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        a, b = np.abs(lo) ** p, np.abs(hi) ** p
    return (np.where(positive, np.minimum(a, b), -INF), np.where(positive, np.maximum(a, b), INF))


class PowerQuotients:
    """Quotients and square roots of a jet type through its ``*`` and ``**`` (whose ``__pow__``
    carries the chain rule): ``a / b = a * b**-1``, ``sqrt(a) = a**0.5``."""

    __slots__ = ()

    def __truediv__(self, other):
        if isinstance(other, PowerQuotients):
            return self * other ** -1.0
        return self * (1.0 / np.asarray(other, dtype=float))

    def __rtruediv__(self, other):
        return (self ** -1.0) * other

    def sqrt(self):
        return self ** 0.5


class Jet(PowerQuotients):
    """Interval value ``[lo, hi]`` (shape ``S``) and interval gradient ``[glo, ghi]`` (``S + (n,)``)."""

    __slots__ = ("lo", "hi", "glo", "ghi")
    __array_priority__ = 200

    def __init__(self, lo, hi, glo, ghi):
        self.lo, self.hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        self.glo, self.ghi = np.asarray(glo, dtype=float), np.asarray(ghi, dtype=float)

    @classmethod
    def seed(cls, lo: np.ndarray, hi: np.ndarray) -> list["Jet"]:
        """The inputs ``z_i in [lo_i, hi_i]`` with gradients ``e_i``."""
        n = len(lo)
        eye = np.eye(n)
        return [cls(lo[i], hi[i], eye[i], eye[i]) for i in range(n)]

    def const_like(self, value) -> "Jet":
        value = np.asarray(value, dtype=float)
        zero = np.zeros(value.shape + self.glo.shape[-1:])
        return Jet(value, value, zero, zero)

    # ------------------------------------------------------------ arithmetic
    def __add__(self, other):
        if isinstance(other, Jet):
            return Jet(self.lo + other.lo, self.hi + other.hi, self.glo + other.glo, self.ghi + other.ghi)
        return Jet(self.lo + other, self.hi + other, self.glo, self.ghi)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.hi, -self.lo, -self.ghi, -self.glo)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if not isinstance(other, Jet):
            c = np.asarray(other, dtype=float)
            lo, hi = _imul(self.lo, self.hi, c, c)
            glo, ghi = _imul(self.glo, self.ghi, c[..., None], c[..., None])
            return Jet(lo, hi, glo, ghi)
        lo, hi = _imul(self.lo, self.hi, other.lo, other.hi)
        a = _imul(self.lo[..., None], self.hi[..., None], other.glo, other.ghi)
        b = _imul(other.lo[..., None], other.hi[..., None], self.glo, self.ghi)
        return Jet(lo, hi, a[0] + b[0], a[1] + b[1])

    __rmul__ = __mul__

    def _chain(self, lo, hi, dlo, dhi) -> "Jet":
        """A function with value range ``[lo, hi]`` and derivative range ``[dlo, dhi]`` on self."""
        glo, ghi = _imul(dlo[..., None], dhi[..., None], self.glo, self.ghi)
        return Jet(lo, hi, glo, ghi)

    def __pow__(self, p):
        p = float(p)
        if p == 0:
            return self.const_like(np.ones_like(self.lo))
        lo, hi = _ipow_real(self.lo, self.hi, p)
        dlo, dhi = _ipow_real(self.lo, self.hi, p - 1)
        dlo, dhi = _imul(dlo, dhi, p, p)
        return self._chain(lo, hi, dlo, dhi)

    def _lipschitz_one(self, fn):
        mid, rad = 0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo)
        v = fn(mid)
        return np.maximum(v - rad, -1.0), np.minimum(v + rad, 1.0)

    def sin(self):
        lo, hi = self._lipschitz_one(np.sin)
        dlo, dhi = self._lipschitz_one(np.cos)
        return self._chain(lo, hi, dlo, dhi)

    def cos(self):
        lo, hi = self._lipschitz_one(np.cos)
        slo, shi = self._lipschitz_one(np.sin)
        return self._chain(lo, hi, -shi, -slo)

    def exp(self):
        lo, hi = np.exp(self.lo), np.exp(self.hi)
        return self._chain(lo, hi, lo, hi)

    def log(self):
        positive = self.lo > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            lo = np.where(positive, np.log(np.abs(self.lo)), -INF)
            hi = np.where(positive, np.log(np.abs(self.hi)), INF)
        dlo, dhi = _ipow_real(self.lo, self.hi, -1.0)
        return self._chain(lo, hi, dlo, dhi)

    # ------------------------------------------------------------ vectors (network layers)
    @staticmethod
    def stack(items: list["Jet"]) -> "Jet":
        return Jet(*(np.stack([getattr(j, k) for j in items]) for k in ("lo", "hi", "glo", "ghi")))

    def affine(self, W, b=None) -> "Jet":
        W = np.asarray(W, dtype=float)
        b = 0.0 if b is None else np.asarray(b, dtype=float)
        mid, rad = 0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo)
        gmid, grad = 0.5 * (self.glo + self.ghi), 0.5 * (self.ghi - self.glo)
        m, r = W @ mid + b, np.abs(W) @ rad
        gm, gr = W @ gmid, np.abs(W) @ grad
        return Jet(m - r, m + r, gm - gr, gm + gr)

    def unstack(self) -> list["Jet"]:
        return [Jet(self.lo[i], self.hi[i], self.glo[i], self.ghi[i]) for i in range(len(self.lo))]
