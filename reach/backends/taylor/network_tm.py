"""Taylor-model enclosures of a closed-loop field and of its Jacobian on a box, through a network.

The verified integration (:mod:`.verified`) needs the range of ``Df`` over a box ``Z`` of states.
Interval jets (:mod:`.interval`) give it by interval arithmetic, which wraps at every layer of a
network controller: each sine layer of a SIREN turns the width of its input interval into the
width of its output, with no memory of which input caused it, so on the CW SIREN transfer the
interval gradient over a 1 mm box is several times wider than the gradient itself.

A :class:`TMJet` carries instead a Taylor model (:mod:`.tm`) of the value and Taylor models of the
``n`` partial derivatives, all in the box's scaled variables ``xi in [-1, 1]^n``
(``z_i = c_i + r_i xi_i``). Forward-mode differentiation in Taylor-model arithmetic:

* sums, products and affine maps (a network layer ``W h + b``) act on the value and by the
  product rule on the derivatives, ``(u v)' = u' v + u v'``;
* an analytic ``phi`` (each sine layer, the square root of the thrust normalisation) gives
  ``phi(u)`` and ``phi'(u) u'``, both Taylor models with their Lagrange remainders (:meth:`.tm.TM._analytic`).

Every Taylor model asserts ``g(xi) - P(xi) in I`` on the whole box, so the interval bounds of the
derivative models contain ``Df(z)`` for every ``z`` in ``Z`` (the same statement as the interval jet),
while the dependence on ``xi`` is kept through the layers up to the model's order. On a 1 mm box of
the transfer the Jacobian enclosure of the thrust rows is 2.3e-5 wide (order 3) against 5.6e5 for
the interval jet (the gradient's size: 1.4e-3).

The verified integration does not use it yet: with it, the Jacobian is no longer what stops the
proof on CW SIREN; the logarithmic-norm Gronwall radius is (results/cw_siren.md).
"""

from __future__ import annotations

import numpy as np

from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.interval import PowerQuotients
from reach.backends.taylor.tm import TM, scaled_sum


def _trailing(t: TM) -> TM:
    """``t`` with a trailing axis of length 1 (to multiply a gradient, shape ``S + (n,)``)."""
    lo, hi = np.asarray(t.lo, dtype=float), np.asarray(t.hi, dtype=float)
    return TM(DA(t.alg, t.poly.c[..., None, :]), lo[..., None], hi[..., None])


class TMJet(PowerQuotients):
    """A Taylor model ``v`` of a value (batch shape ``S``) and ``g`` of its gradient (``S + (n,)``)."""

    __array_priority__ = 300

    def __init__(self, v: TM, g: TM):
        self.v, self.g = v, g

    @classmethod
    def seed(cls, low: np.ndarray, high: np.ndarray, order: int) -> list["TMJet"]:
        """The states ``z_i = c_i + r_i xi_i`` on the box ``[low, high]``, gradients ``e_i``."""
        low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        n = len(low)
        alg = algebra(order, n)
        center, radius = 0.5 * (low + high), 0.5 * (high - low)
        eye = np.eye(n)
        return [cls(TM(DA.var(alg, i, center[i], radius[i])), TM(DA.const(alg, eye[i]))) for i in range(n)]

    @property
    def nvars(self) -> int:
        return self.g.shape[-1]

    def const_like(self, value) -> "TMJet":
        value = np.asarray(value, dtype=float)
        return TMJet(TM(DA.const(self.v.alg, value)), TM(DA.const(self.v.alg, np.zeros(value.shape + (self.nvars,)))))

    # ------------------------------------------------------------ arithmetic
    def __add__(self, other):
        if isinstance(other, TMJet):
            return TMJet(self.v + other.v, self.g + other.g)
        return TMJet(self.v + other, self.g)

    __radd__ = __add__

    def __neg__(self):
        return TMJet(-self.v, -self.g)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if not isinstance(other, TMJet):
            c = np.asarray(other, dtype=float)
            return TMJet(self.v * c, self.g * (c[..., None] if c.ndim else c))
        return TMJet(self.v * other.v, _trailing(self.v) * other.g + _trailing(other.v) * self.g)

    __rmul__ = __mul__

    def _chain(self, value: TM, derivative: TM) -> "TMJet":
        """``phi(self)`` from the models of ``phi(v)`` and ``phi'(v)``."""
        return TMJet(value, _trailing(derivative) * self.g)

    def __pow__(self, p):
        p = float(p)
        if p == 0:
            return self.const_like(np.ones(self.v.shape))
        if p == 1:
            return self
        return self._chain(self.v ** p, self.v ** (p - 1) * p)

    def sin(self):
        return self._chain(self.v.sin(), self.v.cos())

    def cos(self):
        return self._chain(self.v.cos(), -self.v.sin())

    def exp(self):
        e = self.v.exp()
        return self._chain(e, e)

    def log(self):
        return self._chain(self.v.log(), self.v ** -1.0)

    weighted_sum = staticmethod(scaled_sum)

    # ------------------------------------------------------------ vectors (network layers)
    @staticmethod
    def stack(items: list["TMJet"]) -> "TMJet":
        return TMJet(TM.stack([j.v for j in items]), TM.stack([j.g for j in items]))

    def affine(self, W, b=None) -> "TMJet":
        return TMJet(self.v.affine(W, b), self.g.affine(W))

    def unstack(self) -> list["TMJet"]:
        return [TMJet(v, g) for v, g in zip(self.v.unstack(), self.g.unstack())]

    def bounds(self):
        """Interval hulls ``(lo, hi)`` of the value and ``(glo, ghi)`` of the gradient on the box."""
        lo, hi = self.v.bound()
        glo, ghi = self.g.bound()
        return lo, hi, glo, ghi


def field_enclosure(f, low: np.ndarray, high: np.ndarray, order: int = 3):
    """Enclosures of ``f`` and ``Df`` on the box ``[low, high]`` by Taylor models of ``order``:
    ``(flo, fhi, Jlo, Jhi)`` with ``f(z)`` in ``[flo, fhi]`` and ``Df(z)`` in ``[Jlo, Jhi]`` for every
    ``z`` in the box (``f``: a compiled field, :func:`.flow.compile_expressions`)."""
    out = f(TMJet.seed(low, high, order))
    ends = [o.bounds() for o in out]
    flo, fhi = np.array([e[0] for e in ends], dtype=float), np.array([e[1] for e in ends], dtype=float)
    Jlo, Jhi = np.array([e[2] for e in ends], dtype=float), np.array([e[3] for e in ends], dtype=float)
    return flo, fhi, Jlo, Jhi


def jacobian_box(f, low: np.ndarray, high: np.ndarray, order: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``[Jc - Jr, Jc + Jr]`` containing ``Df`` on the box (the interface of
    :func:`.verified.jacobian_box`)."""
    _, _, Jlo, Jhi = field_enclosure(f, low, high, order)
    return 0.5 * (Jlo + Jhi), 0.5 * (Jhi - Jlo)
