"""The Lagrange remainder of a linearised flow, enclosed over a box in outward-rounded interval
arithmetic (``mpmath.iv``).

For a twice continuously differentiable ``f`` on a box ``X``, a point ``z`` of ``X`` and any
matrix ``A`` and vector ``b`` (the floating-point linearisation),

    f(x) = A x + b + L(x),
    L(x) = [f(z) - A z - b] + [Df(z) - A] (x - z) + 1/2 (x - z)^T D^2 f_i(xi_i) (x - z),

with ``xi_i`` on the segment from ``z`` to ``x`` (Taylor's theorem with the Lagrange remainder,
component ``i``), hence in ``X``. Evaluating the right-hand side with ``x - z`` replaced by the
interval vector ``X - z`` and ``D^2 f_i(xi)`` by the interval extension of the Hessian over ``X``
gives an interval vector ``[l_lo, l_hi]`` that contains ``L(x)`` for every ``x`` in ``X``: the
first two brackets hold the rounding of ``f(z)`` and ``Df(z)``, so ``A`` and ``b`` need not be
exact. Diagonal terms use ``(x_j - z_j)^2 in [0, r_j^2]``, off-diagonal ones ``H_ijk d_j d_k``
counted twice (``j < k``). ``mpmath.iv`` rounds every endpoint outward at 53 bits, so the
endpoints are doubles and the enclosure survives rounding.
"""

from __future__ import annotations

from dataclasses import dataclass

import mpmath
import numpy as np
import sympy
from mpmath import iv

#: the functions a flow may use besides powers (smooth where finite, with interval versions)
SMOOTH = (sympy.exp, sympy.log, sympy.sin, sympy.cos, sympy.tan)

#: interval versions of them (``lambdify`` prints constants as ``mpf``, ``sqrt`` for ``**(1/2)``)
_NAMESPACE = {"mpf": lambda v: iv.mpf(mpmath.mpf(v)), "sqrt": iv.sqrt, "exp": iv.exp, "log": iv.log,
              "sin": iv.sin, "cos": iv.cos, "tan": iv.tan, "pi": iv.pi}


def unsupported(flow, symbols) -> str | None:
    """Why the remainder of ``flow`` cannot be enclosed here, or None: every function must be
    one of :data:`SMOOTH` (twice continuously differentiable where finite, so the Lagrange form
    holds; a pole or a root of zero inside a box shows up as an unbounded interval)."""
    for i, f in enumerate(flow):
        kinks = f.atoms(sympy.Min, sympy.Max, sympy.Piecewise, sympy.Heaviside)
        if kinks:
            return (f"the flow of {symbols[i]} uses {type(next(iter(kinks))).__name__} (not differentiable: "
                    f"no interval Hessian for it)")
        bad = [a.func.__name__ for a in f.atoms(sympy.Function) if a.func not in SMOOTH]
        if bad:
            return f"the flow of {symbols[i]} uses {bad[0]} (no interval Hessian for it)"
    return None


@dataclass
class Remainder:
    """``L(x) in [low, high]`` for every ``x`` in the box, for ``f(x) = A x + b + L(x)``."""

    A: np.ndarray
    b: np.ndarray
    point: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @property
    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.low)) and np.all(np.isfinite(self.high)))

    def as_input(self):
        """``(b', active, radius)``: ``f(x) = A x + b' + e_active u`` with ``|u| <= radius``
        (componentwise) on the box. ``b' = b + (low + high) / 2`` in floating point; the
        radius is rounded outward around what ``b'`` really holds, so no enclosure is lost."""
        centre = (self.low + self.high) / 2
        shifted = self.b + centre
        active = np.flatnonzero((self.low != 0) | (self.high != 0))
        radius = np.empty(active.size)
        for k, i in enumerate(active):
            moved = iv.mpf(float(shifted[i])) - iv.mpf(float(self.b[i]))
            lo, hi = _endpoints(iv.mpf(float(self.low[i])) - moved), _endpoints(iv.mpf(float(self.high[i])) - moved)
            radius[k] = max(-lo[0], hi[1])
        return shifted, active, radius


class Linearisation:
    """A flow ``f`` (sympy expressions over ``symbols``), its Jacobian and Hessians, compiled for
    interval evaluation; :meth:`over` linearises it at the centre of a box and encloses the
    remainder over the box (module doc)."""

    def __init__(self, flow, symbols):
        self.n = len(symbols)
        jac = [[sympy.diff(f, s) for s in symbols] for f in flow]
        hess = [[[sympy.diff(d, s) for s in symbols] for d in row] for row in jac]
        compile_ = lambda exprs: sympy.lambdify(symbols, exprs, modules=[_NAMESPACE, "mpmath"], cse=True)
        self._f, self._jac, self._hess = compile_(list(flow)), compile_(jac), compile_(hess)
        self.curved = [i for i, row in enumerate(hess) if any(e != 0 for r in row for e in r)]

    def over(self, low, high) -> Remainder:
        """Linearisation at the centre ``z`` of the box ``[low, high]`` and its remainder."""
        low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        z = (low + high) / 2
        point = [iv.mpf(float(v)) for v in z]
        F = [_interval(v) for v in self._f(*point)]
        J = [[_interval(v) for v in row] for row in self._jac(*point)]
        A = np.array([[_mid(v) for v in row] for row in J])
        b = np.array([_mid(v) for v in F]) - A @ z
        box = [iv.mpf([float(a), float(c)]) for a, c in zip(low, high)]
        d = [x - p for x, p in zip(box, point)]
        H = self._hess(*box)
        lo, hi = np.empty(self.n), np.empty(self.n)
        for i in range(self.n):
            value = F[i] - iv.mpf(float(b[i]))
            for j in range(self.n):
                value -= iv.mpf(float(A[i, j])) * point[j]
                value += (J[i][j] - iv.mpf(float(A[i, j]))) * d[j]
            if i in self.curved:
                for j in range(self.n):
                    value += _interval(H[i][j][j]) * d[j] ** 2 / 2   # d**2 >= 0, unlike d*d
                    for k in range(j + 1, self.n):
                        value += _interval(H[i][j][k]) * d[j] * d[k]
            lo[i], hi[i] = _endpoints(value)
        return Remainder(A, b, z, lo, hi)


def _interval(v):
    """A value of a compiled expression as an interval (constants come back as numbers)."""
    if isinstance(v, iv.mpf):
        return v
    return iv.mpf(mpmath.mpf(v) if isinstance(v, mpmath.mpf) else v)


def _mid(v) -> float:
    a, b = float(v.a), float(v.b)
    return (a + b) / 2 if np.isfinite(a) and np.isfinite(b) else np.nan


def _endpoints(v):
    """The interval's endpoints as doubles (exact: ``iv`` works at 53 bits); NaN becomes
    the whole line."""
    a, b = float(v.a), float(v.b)
    return (a if a == a else -np.inf), (b if b == b else np.inf)
