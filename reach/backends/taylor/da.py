"""Differential algebra: truncated multivariate power series of order ``n`` in ``d`` variables.

A DA number is ``a(xi) = sum_{|beta| <= n} a_beta xi^beta`` (eq. 18 of the Taylor-ADS paper),
stored densely as the coefficient array ``c[..., k]`` over the monomials ``beta_k`` of an
:class:`Algebra`, graded by total degree (``k = 0`` is the constant). Leading axes of ``c``
are batch axes, so a vector of DA numbers (a network layer, a state) is one array.

Products are truncated at order ``n``: ``(ab)_gamma = sum_{alpha + beta = gamma} a_alpha b_beta``.
The pairs ``(alpha, beta)`` with ``|alpha + beta| <= n`` are tabulated once per algebra, sorted
by ``gamma``, so a product is one gather, one multiply and one sum by target (:meth:`Algebra._pairs`).

An analytic ``f`` of a DA ``a = a0 + da`` (``da`` nilpotent: ``da^(n+1) = 0``) is the finite sum
``f(a) = sum_{k <= n} f^(k)(a0)/k! da^k``; sin, cos, exp, log, sqrt, powers and the reciprocal
are built that way. :meth:`DA.compose` evaluates a DA at DA arguments and :func:`invert` inverts
an origin-preserving map by the fixed point ``G = L^-1 (Id - N o G)``, one order per pass.
"""

from __future__ import annotations

from functools import lru_cache
import math
from itertools import combinations_with_replacement
from math import factorial

import numpy as np


MAX_PRODUCT_PAIRS = 3_000_000
DENSE_SUM_SIZE = 32     # algebras with at most this many monomials sum products by a matrix product


class Algebra:
    """Monomial tables of the truncated power series of order ``order`` in ``nvars`` variables."""

    def __init__(self, order: int, nvars: int):
        # products of monomials of total degree <= order: C(order + 2 nvars, 2 nvars) pairs
        pairs = math.comb(order + 2 * nvars, 2 * nvars)
        if pairs > MAX_PRODUCT_PAIRS:
            from reach.errors import InputError
            raise InputError(f"order {order} in {nvars} variables needs {pairs:.3g} monomial products per "
                             f"multiplication; at most {MAX_PRODUCT_PAIRS:.0e} (lower the order)",
                             field="options.taylor.order")
        self.order, self.nvars = order, nvars
        exps = [np.zeros(nvars, dtype=int)]
        for deg in range(1, order + 1):
            for combo in combinations_with_replacement(range(nvars), deg):
                e = np.zeros(nvars, dtype=int)
                np.add.at(e, list(combo), 1)
                exps.append(e)
        self.exps = np.array(exps, dtype=int).reshape(len(exps), nvars)     # (a point: one monomial, 1)
        self.size = len(self.exps)
        self.degree = self.exps.sum(axis=1)
        # first[k]: index of the first monomial of total degree k (monomials are graded; k <= order + 1)
        self.first = [int(np.searchsorted(self.degree, k)) for k in range(order + 2)]
        self.index = {tuple(e): k for k, e in enumerate(self.exps)}
        pairs = [(i, j, self.index[tuple(self.exps[i] + self.exps[j])])
                 for i in range(self.size) for j in range(self.size)
                 if self.degree[i] + self.degree[j] <= order]
        pairs.sort(key=lambda p: p[2])
        P = np.array(pairs, dtype=int)
        self.left, self.right, self.target = P[:, 0], P[:, 1], P[:, 2]
        self._graded: dict = {}
        self._leading_totals: dict = {}
        self._row_products: dict = {}
        # every monomial beta != 0 is parent[k] * xi_{step[k]} (for evaluation and composition)
        self.parent = np.zeros(self.size, dtype=int)
        self.step = np.zeros(self.size, dtype=int)
        for k in range(1, self.size):
            v = int(np.flatnonzero(self.exps[k])[0])
            e = self.exps[k].copy()
            e[v] -= 1
            self.parent[k], self.step[k] = self.index[tuple(e)], v

    def multiply_graded(self, a: np.ndarray, b: np.ndarray, low_a: int, low_b: int) -> np.ndarray:
        """``a b`` when ``a`` has no terms of degree below ``low_a`` and ``b`` none below ``low_b``
        (powers of a deviation): only the pairs that can be non-zero are formed."""
        left, right, total = self._pairs(low_a, low_b, False)
        return total(a.take(left, axis=-1) * b.take(right, axis=-1))

    def square_graded(self, a: np.ndarray, low: int) -> np.ndarray:
        """``a a`` when ``a`` has no terms of degree below ``low``: each pair ``{alpha, beta}`` is
        formed once and counted twice when ``alpha != beta``."""
        left, right, total = self._pairs(low, low, True)
        return total(a.take(left, axis=-1) * a.take(right, axis=-1))

    def multiply(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return self.multiply_graded(a, b, 0, 0)

    def multiply_leading(self, a: np.ndarray, b: np.ndarray, low_a: int, low_b: int) -> np.ndarray:
        """:meth:`multiply_graded` of coefficient-major arrays ``(size, ...)``: the monomial
        pairs are then gathered as contiguous rows (about six times faster than gathering along
        the last axis for 1,024 series), and a square (``a is b``) forms each pair once."""
        square = a is b
        left, right, _ = self._pairs(low_a, low_b, square)
        products = a.take(left, axis=0) * b.take(right, axis=0)
        return self._leading_totals[(low_a, low_b, square)](products)

    def product_rows(self, a: np.ndarray, b: np.ndarray, low_a: int, low_b: int, scale: float) -> np.ndarray:
        """``scale a b`` of coefficient-major series given by their rows from degree ``low_a``
        (``a``) and ``low_b`` (``b``) on (the rows below are zero), as its rows from degree
        ``low_a + low_b`` on; ``a is b`` is a square (each unordered pair formed once). The scale
        is folded into the sum by target."""
        key = (low_a, low_b, a is b, scale)
        if key not in self._row_products:
            self._row_products[key] = self._tabulate_rows(low_a, low_b, a is b, scale)
        left, right, total = self._row_products[key]
        return total(a.take(left, axis=0) * b.take(right, axis=0))

    def _tabulate_rows(self, low_a: int, low_b: int, square: bool, scale: float):
        """``(left, right, total)`` of :meth:`product_rows`: the pairs' rows in ``a`` and ``b``
        and the weighted sum of their products ``(pairs, ...)`` into the target rows (a matrix
        product in a small algebra, else a segmented sum, as :meth:`_pairs`)."""
        keep = (self.degree[self.left] >= low_a) & (self.degree[self.right] >= low_b)
        if square:
            keep &= self.left <= self.right
        left, right, target = self.left[keep], self.right[keep], self.target[keep]
        weight = scale * (np.where(left < right, 2.0, 1.0) if square else np.ones(len(left)))
        low = self.first[low_a + low_b]
        rows = self.size - low
        left, right, target = left - self.first[low_a], right - self.first[low_b], target - low
        if self.size <= DENSE_SUM_SIZE:
            S = np.zeros((rows, len(target)))
            S[target, np.arange(len(target))] = weight

            def total(products):
                return (S @ products.reshape(len(target), -1)).reshape((rows,) + products.shape[1:])

            return left, right, total
        starts = np.flatnonzero(np.r_[True, target[1:] != target[:-1]]) if len(target) else target

        def total(products):
            out = np.zeros((rows,) + products.shape[1:])
            if len(starts):
                weighted = products * weight.reshape((-1,) + (1,) * (products.ndim - 1))
                out[target[starts]] = np.add.reduceat(weighted, starts, axis=0)
            return out

        return left, right, total

    def _pairs(self, low_a: int, low_b: int, square: bool):
        """``(left, right, total)``: the monomial pairs of a graded product (unordered pairs of a
        square) and the function that sums their products ``(..., pairs)`` into the coefficients
        ``(..., size)``, each with its weight (2 for the two orders of an unordered pair). In a
        small algebra the sum is one matrix product with the matrix ``S[p, target_p] = weight_p``,
        otherwise a segmented sum (``np.add.reduceat``, over the pairs sorted by target): per pair
        and run, the matrix product costs about ``size`` multiply-adds in BLAS, and ``reduceat``
        about as much as 30 of them (order 4 in 2 variables, 15 monomials: the matrix product
        takes half the time)."""
        key = (low_a, low_b, square)
        if key not in self._graded:
            self._graded[key], self._leading_totals[key] = self._tabulate(low_a, low_b, square)
        return self._graded[key]

    def _tabulate(self, low_a: int, low_b: int, square: bool):
        """The pairs of :meth:`_pairs`, and the sums by target for both layouts: ``total`` for
        products ``(..., pairs)`` (coefficients last), ``leading`` for ``(pairs, ...)``
        (coefficients first, :meth:`multiply_leading`)."""
        keep = (self.degree[self.left] >= low_a) & (self.degree[self.right] >= low_b)
        if square:
            keep &= self.left <= self.right
        left, right, target = self.left[keep], self.right[keep], self.target[keep]
        weight = np.where(left < right, 2.0, 1.0) if square else np.ones(len(left))
        if self.size <= DENSE_SUM_SIZE:
            S = np.zeros((len(target), self.size))
            S[np.arange(len(target)), target] = weight
            # coefficient-major: only the rows from the lowest target on (the lower ones are zero;
            # a power da^k has no terms of degree below k)
            low = int(target.min()) if len(target) else self.size
            ST = np.ascontiguousarray(S.T[low:])

            def total(products):
                rows = products.reshape(math.prod(products.shape[:-1]), len(target))
                return (rows @ S).reshape(products.shape[:-1] + (self.size,))

            def leading(products):
                out = np.empty((self.size,) + products.shape[1:])
                out[:low] = 0.0
                np.matmul(ST, products.reshape(len(target), -1), out=out[low:].reshape(self.size - low, -1))
                return out

            return (left, right, total), leading
        starts = np.flatnonzero(np.r_[True, target[1:] != target[:-1]]) if len(target) else target

        def total(products):
            out = np.zeros(products.shape[:-1] + (self.size,))
            if len(starts):     # else every product has degree above the order
                out[..., target[starts]] = np.add.reduceat(products * weight if square else products,
                                                           starts, axis=-1)
            return out

        def leading(products):
            out = np.zeros((self.size,) + products.shape[1:])
            if len(starts):
                if square:
                    products = products * weight.reshape((-1,) + (1,) * (products.ndim - 1))
                out[target[starts]] = np.add.reduceat(products, starts, axis=0)
            return out

        return (left, right, total), leading


@lru_cache(maxsize=None)
def algebra(order: int, nvars: int) -> Algebra:
    return Algebra(order, nvars)


class DA:
    """A (batch of) truncated power series; arithmetic mixes freely with floats and arrays."""

    __slots__ = ("alg", "c")
    __array_priority__ = 100

    def __init__(self, alg: Algebra, c: np.ndarray):
        self.alg, self.c = alg, np.asarray(c, dtype=float)

    # ------------------------------------------------------------ construction
    @classmethod
    def const(cls, alg: Algebra, value) -> "DA":
        value = np.asarray(value, dtype=float)
        c = np.zeros(value.shape + (alg.size,))
        c[..., 0] = value
        return cls(alg, c)

    def __reduce__(self):
        """Pickled as order, variables and coefficients (the tables are rebuilt once per process)."""
        return _rebuild, (self.alg.order, self.alg.nvars, self.c)

    def const_like(self, value) -> "DA":
        return DA.const(self.alg, value)

    @classmethod
    def var(cls, alg: Algebra, i: int, center: float = 0.0, scale: float = 1.0) -> "DA":
        """``center + scale * xi_i`` (eq. 3: the initial value plus its deviation)."""
        c = np.zeros(alg.size)
        c[0] = center
        if alg.order >= 1:
            c[1 + i] = scale
        return cls(alg, c)

    @classmethod
    def variables(cls, alg: Algebra, centers, scales) -> list["DA"]:
        return [cls.var(alg, i, c, s) for i, (c, s) in enumerate(zip(centers, scales))]

    # ------------------------------------------------------------ access
    @property
    def cons(self):
        return self.c[..., 0]

    def __getitem__(self, item) -> "DA":
        return DA(self.alg, self.c[item])

    @property
    def shape(self):
        return self.c.shape[:-1]

    def embed(self, target: Algebra) -> "DA":
        """The same series in an algebra with more variables (the new ones last), same order."""
        index = _embedding(self.alg.order, self.alg.nvars, target.order, target.nvars)
        c = np.zeros(self.shape + (target.size,))
        c[..., index] = self.c
        return DA(target, c)

    # ------------------------------------------------------------ vectors (network layers)
    @staticmethod
    def stack(items: list["DA"]) -> "Layer":
        """A vector of scalar DAs as one :class:`Layer` (a network's inputs)."""
        return Layer.stack(items)

    def affine(self, W: np.ndarray, b: np.ndarray | None = None) -> "DA":
        """``W a + b`` for a vector DA ``a`` of shape ``(m, *batch)`` (a layer's inputs, for each of
        a batch of subdomains): one matrix product on the coefficients, shape ``(k, *batch)``."""
        W = np.asarray(W, dtype=float)
        c = (W @ self.c.reshape(W.shape[1], -1)).reshape((W.shape[0],) + self.c.shape[1:])
        if b is not None:
            b = np.asarray(b, dtype=float)
            c[..., 0] += b.reshape(b.shape + (1,) * (c.ndim - 2))
        return DA(self.alg, c)

    @staticmethod
    def weighted_sum(weights: np.ndarray, items: list) -> "DA":
        """``sum_k w_k a_k`` for scalar DAs and floats (one product on the stacked coefficients)."""
        alg = next(v.alg for v in items if isinstance(v, DA))
        shape = np.broadcast_shapes(*[v.c.shape if isinstance(v, DA) else np.shape(v) + (alg.size,) for v in items])
        rows = np.zeros((len(items),) + shape)
        for row, v in zip(rows, items):
            if isinstance(v, DA):
                row[...] = v.c
            else:
                row[..., 0] = v
        return DA(alg, (weights @ rows.reshape(len(rows), -1)).reshape(rows.shape[1:]))

    def unstack(self) -> list["DA"]:
        """The scalar DAs of a vector DA."""
        return [DA(self.alg, row) for row in self.c]

    # ------------------------------------------------------------ arithmetic
    def __add__(self, other):
        if isinstance(other, DA):
            return DA(self.alg, self.c + other.c)
        c = self.c.copy() if np.ndim(other) == 0 else np.broadcast_to(self.c, np.shape(other) + (self.alg.size,)).copy()
        c[..., 0] = c[..., 0] + other
        return DA(self.alg, c)

    __radd__ = __add__

    def __neg__(self):
        return DA(self.alg, -self.c)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if other is self:
            return DA(self.alg, self.alg.square_graded(self.c, 0))
        if isinstance(other, DA):
            return DA(self.alg, self.alg.multiply(self.c, other.c))
        return DA(self.alg, self.c * np.asarray(other, dtype=float)[..., None])

    __rmul__ = __mul__

    def __truediv__(self, other):
        if isinstance(other, DA):
            return self * other.reciprocal()
        return DA(self.alg, self.c / np.asarray(other, dtype=float)[..., None])

    def __rtruediv__(self, other):
        return self.reciprocal() * other

    def __pow__(self, p):
        if isinstance(p, (int, np.integer)) or (np.ndim(p) == 0 and float(p).is_integer() and p >= 0):
            if int(p) >= 0:
                return integer_power(self, int(p))
        p = float(p)
        return self._series(lambda a0, k: _binomial(p, k) * a0 ** (p - k))

    def reciprocal(self):
        return self ** -1.0

    # ------------------------------------------------------------ elementary functions
    def _series(self, coefficient):
        """``sum_k coefficient(a0, k) da^k`` with ``da = a - a0`` and ``coefficient(a0, k) =
        f^(k)(a0)/k!`` (:func:`series_leading`, on the coefficients moved to the front)."""
        leading = np.ascontiguousarray(np.moveaxis(self.c, -1, 0))
        return DA(self.alg, np.moveaxis(series_leading(self.alg, leading, coefficient), 0, -1))

    def exp(self):
        return self._series(lambda a0, k: np.exp(a0) / factorial(k))

    def log(self):
        return self._series(lambda a0, k: np.log(a0) if k == 0 else (-1.0) ** (k + 1) / (k * a0 ** k))

    def sin(self):
        derivatives = _sin_derivatives(self.cons)
        return self._series(lambda a0, k: derivatives[k % 4] / factorial(k))

    def cos(self):
        derivatives = _sin_derivatives(self.cons)
        return self._series(lambda a0, k: derivatives[(k + 1) % 4] / factorial(k))

    def sqrt(self):
        return self ** 0.5

    # ------------------------------------------------------------ calculus
    def integrate(self, i: int, scale: float = 1.0) -> "DA":
        """Antiderivative in ``xi_i`` vanishing at ``xi_i = 0`` (times ``scale``), truncated."""
        source, target, factor = _integration_table(self.alg.order, self.alg.nvars, i)
        c = np.zeros_like(self.c)
        c[..., target] = self.c[..., source] * (factor * scale)
        return DA(self.alg, c)

    def derivative(self, i: int) -> "DA":
        """Partial derivative in ``xi_i``."""
        source, target, factor = _derivative_table(self.alg.order, self.alg.nvars, i)
        c = np.zeros_like(self.c)
        c[..., target] = self.c[..., source] * factor
        return DA(self.alg, c)

    # ------------------------------------------------------------ evaluation
    def monomials(self, args):
        """Values of every monomial at ``args`` (floats/arrays or DAs), by the parent table."""
        alg = self.alg
        one = DA.const(args[0].alg, 1.0) if isinstance(args[0], DA) else np.ones_like(np.asarray(args[0], dtype=float))
        values = [one]
        for k in range(1, alg.size):
            values.append(values[alg.parent[k]] * args[alg.step[k]])
        return values

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Evaluate at points ``(N, d)`` in the scaled variables: ``(*shape, N)``."""
        P = np.atleast_2d(np.asarray(points, dtype=float))
        values = np.stack(self.monomials(list(P.T)), axis=0)          # (M, N)
        return np.tensordot(self.c, values, axes=([-1], [0]))

    def compose(self, args: list["DA"]) -> "DA":
        """``self(args)``: substitute a DA (of any algebra) for each variable. Arguments of a batch
        shape ``S`` are substituted into the batch of the same shape at the end of ``self``'s
        (``self`` of shape ``(..., *S)``: each run's series into that run's)."""
        values = self.monomials(args)
        target = args[0].alg
        V = np.stack(np.broadcast_arrays(*[v.c for v in values]))     # (size, *args shape, target size)
        if V.ndim == 2:             # scalar arguments: one matrix product
            return DA(target, self.c @ V)
        c = np.zeros(np.broadcast_shapes(self.c.shape[:-1] + (1,), V.shape[1:]))
        for k in range(len(V)):
            c += self.c[..., k, None] * V[k]
        return DA(target, c)

    # ------------------------------------------------------------ sizes
    def order_norms(self) -> np.ndarray:
        """``S_i = sum_{|beta| = i} |a_beta|`` for ``i = 0..n`` (eq. 19)."""
        S = np.zeros(self.shape + (self.alg.order + 1,))
        for i in range(self.alg.order + 1):
            S[..., i] = np.abs(self.c[..., self.alg.degree == i]).sum(axis=-1)
        return S

    def variable_norms(self, j: int) -> np.ndarray:
        """Coefficient sizes by the power of ``xi_j`` alone: ``sum_{beta_j = i} |a_beta|``."""
        S = np.zeros(self.shape + (self.alg.order + 1,))
        for i in range(self.alg.order + 1):
            S[..., i] = np.abs(self.c[..., self.alg.exps[:, j] == i]).sum(axis=-1)
        return S

    def __repr__(self):
        return f"DA(order={self.alg.order}, nvars={self.alg.nvars}, shape={self.shape}, cons={self.cons})"


def series_leading(alg: Algebra, c: np.ndarray, coefficient) -> np.ndarray:
    """The series ``f(a) = sum_k coefficient(a0, k) da^k`` (``coefficient(a0, k) = f^(k)(a0)/k!``,
    ``da = a - a0``) of coefficient-major ``c`` ``(size, ...)``. ``da^k`` has no terms of degree
    below ``k``, so each power is a graded product (:meth:`Algebra.multiply_leading`)."""
    a0 = c[0]
    d = c.copy()
    d[0] = 0.0
    out = coefficient(a0, 1) * d
    out[0] += coefficient(a0, 0)
    if alg.size == 1:                   # no variables (a point): da is 0, so are its powers
        return out
    power = d
    for k in range(2, alg.order + 1):
        power = alg.multiply_leading(d, d, 1, 1) if k == 2 else alg.multiply_leading(power, d, k - 1, 1)
        out += coefficient(a0, k) * power
    return out


def sine_leading(alg: Algebra, c: np.ndarray) -> np.ndarray:
    """``sin(a)`` of coefficient-major ``c`` ``(size, ...)``. With ``a = a0 + da``,

        sin(a) = sin(a0) C(da) + cos(a0) S(da),
        C(da) = sum_{k even} w_k da^k,   S(da) = sum_{k odd} w_k da^k,   w_k = (-1)^floor(k/2) / k!,

    so the powers of ``da`` are summed with scalar weights and the two arrays that depend on
    ``a0`` scale only ``C - 1`` and ``S`` at the end (:func:`series_leading` scales every power by
    an array ``f^(k)(a0)/k!``). The weighted powers ``w_k da^k = (w_k / w_(k-1)) (w_(k-1) da^(k-1)) da``
    are graded products with the ratio folded into their sums, each held as its rows from degree
    ``k`` on (:meth:`Algebra.product_rows`), so no operation touches rows that are zero."""
    sin0, cos0 = np.sin(c[0]), np.cos(c[0])
    out = np.empty_like(c)
    out[0] = sin0
    d = c[1:]                       # da, from degree 1
    odd = d.copy()                  # S(da), from degree 1
    even = None                     # C(da) - 1, from degree 2
    power, weight = d, 1.0          # w_k da^k, from degree k
    first = alg.first
    for k in range(2, alg.order + 1):
        w = (-1.0) ** (k // 2) / factorial(k)
        power = alg.product_rows(power, d, k - 1, 1, w / weight)
        weight = w
        if k % 2:
            odd[first[k] - 1:] += power
        elif even is None:
            even = power            # w_2 da^2 is last read as a factor of w_3 da^3, before even grows
        else:
            even[first[k] - first[2]:] += power
    out[1:] = cos0 * odd
    if even is not None:
        out[first[2]:] += sin0 * even
    return out


class Layer:
    """A vector of DA numbers stored coefficient-major: ``c[k, i, ...]`` is monomial ``k`` of
    component ``i`` (further axes: a batch of runs). The hidden layers of a network
    (:mod:`reach.model.network`) stay in this layout from :meth:`stack` to :meth:`unstack`, so
    the sine series gathers its monomial pairs as contiguous rows and no layer moves axes."""

    __slots__ = ("alg", "c")

    def __init__(self, alg: Algebra, c: np.ndarray):
        self.alg, self.c = alg, c

    @classmethod
    def stack(cls, items: list[DA]) -> "Layer":
        return cls(items[0].alg, np.ascontiguousarray(np.moveaxis(stack(items).c, -1, 0)))

    def affine(self, W: np.ndarray, b: np.ndarray | None = None) -> "Layer":
        """``W a + b`` for every monomial (and run): one stacked matrix product."""
        W = np.asarray(W, dtype=float)
        size, m = self.c.shape[:2]
        c = np.matmul(W, self.c.reshape(size, m, -1)).reshape((size, W.shape[0]) + self.c.shape[2:])
        if b is not None:
            c[0] += np.reshape(b, (-1,) + (1,) * (c.ndim - 2))
        return Layer(self.alg, c)

    def sin(self) -> "Layer":
        return Layer(self.alg, sine_leading(self.alg, self.c))

    def unstack(self) -> list[DA]:
        """The scalar DAs (coefficients last again)."""
        return [DA(self.alg, row) for row in np.ascontiguousarray(np.moveaxis(self.c, 0, -1))]


def _rebuild(order: int, nvars: int, c: np.ndarray) -> DA:
    return DA(algebra(order, nvars), c)


def integer_power(x, k: int):
    """``x**k`` for ``k >= 0`` by repeated squaring (any series type with ``*`` and ``const_like``)."""
    if k == 0:
        return x.const_like(np.ones(x.shape))
    out, base = None, x
    while k:
        if k & 1:
            out = base if out is None else out * base
        k >>= 1
        if k:
            base = base * base
    return out


def _binomial(p: float, k: int) -> float:
    out = 1.0
    for j in range(k):
        out *= (p - j) / (j + 1)
    return out


def _sin_derivatives(a0):
    """``sin^(k)(a0)`` for ``k = 0, 1, 2, 3`` (the cycle of the sine's derivatives)."""
    s, c = np.sin(a0), np.cos(a0)
    return s, c, -s, -c


@lru_cache(maxsize=None)
def _embedding(order: int, nvars: int, target_order: int, target_nvars: int) -> np.ndarray:
    small, big = algebra(order, nvars), algebra(target_order, target_nvars)
    pad = np.zeros((small.size, target_nvars - nvars), dtype=int)
    return np.array([big.index[tuple(e)] for e in np.hstack([small.exps, pad])], dtype=int)


@lru_cache(maxsize=None)
def _integration_table(order: int, nvars: int, i: int):
    """Monomials ``beta`` of degree ``< n``, the index of ``beta + e_i`` and ``1/(beta_i + 1)``."""
    alg = algebra(order, nvars)
    source = np.flatnonzero(alg.degree < order)
    raised = alg.exps[source].copy()
    raised[:, i] += 1
    target = np.array([alg.index[tuple(e)] for e in raised], dtype=int)
    return source, target, 1.0 / raised[:, i]


@lru_cache(maxsize=None)
def _derivative_table(order: int, nvars: int, i: int):
    """Monomials ``beta`` with ``beta_i > 0``, the index of ``beta - e_i`` and ``beta_i``."""
    alg = algebra(order, nvars)
    source = np.flatnonzero(alg.exps[:, i] > 0)
    lowered = alg.exps[source].copy()
    lowered[:, i] -= 1
    target = np.array([alg.index[tuple(e)] for e in lowered], dtype=int)
    return source, target, alg.exps[source, i].astype(float)


def stack(items: list[DA]) -> DA:
    return DA(items[0].alg, np.stack([x.c for x in items], axis=0))


def invert(F: list[DA]) -> list[DA]:
    """Inverse of the map ``xi -> F(xi) - F(0)`` (``m`` components in ``m`` variables).

    With ``F - F(0) = L + N`` (linear part ``L``, invertible, and nonlinear part ``N``) the
    inverse ``G`` solves ``G = L^-1 (Id - N o G)``; each pass fixes one more order, so ``n``
    passes give the order-``n`` inverse. The returned ``G`` takes ``F - F(0)`` to ``xi``.
    Components of a batch shape hold a batch of maps, each inverted on its own.
    """
    alg = F[0].alg
    m = alg.nvars
    shape = np.broadcast_shapes(*[f.shape for f in F])        # a batch of maps: one inverse each
    C = np.stack([np.broadcast_to(f.c, shape + (alg.size,)) for f in F], axis=0)   # (m, *shape, size)
    C[..., 0] = 0.0
    lin = alg.degree == 1
    Linv = np.linalg.inv(np.moveaxis(C[..., lin], 0, -2))     # (*shape, m, m)
    N = C.copy()
    N[..., lin] = 0.0
    nonlinear = DA(alg, N)
    identity = np.zeros((m, alg.size))
    identity[:, lin] = np.eye(m)
    G = DA(alg, np.moveaxis(Linv @ identity, -2, 0))
    for _ in range(alg.order):
        NG = nonlinear.compose([G[i] for i in range(m)])
        G = DA(alg, np.moveaxis(Linv @ (identity - np.moveaxis(NG.c, 0, -2)), -2, 0))
    return [G[i] for i in range(m)]
