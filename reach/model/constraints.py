"""Constraints ``g(x) <= 0`` over a model's state, linear ones as half-spaces ``a.x <= b``.

Requirements, invariants and guards are conjunctions of constraints. The negation of a
conjunction is a union of single negated constraints, which is how a safety requirement
becomes a union of convex unsafe pieces.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
import sympy

from reach.errors import Where
from reach.model.expr import Comparison
from reach.model.units import DisplayUnit

NUMERICAL_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Constraint:
    """``g <= 0`` (``g < 0`` when strict), ``text`` being what the user wrote; ``dimension``
    of ``g`` and the ``unit`` the requirement was written in, when known."""

    g: sympy.Expr
    strict: bool
    text: str
    where: Where
    dimension: tuple | None = None
    unit: DisplayUnit | None = None

    def negated(self) -> "Constraint":
        """The complement: ``-g < 0`` (or ``-g <= 0`` for a strict constraint)."""
        return replace(self, g=-self.g, strict=not self.strict, text=f"not ({self.text})")

    def substitute(self, mapping) -> "Constraint":
        return replace(self, g=sympy.sympify(self.g).subs(mapping))


def from_comparisons(comparisons: Sequence[Comparison], text: str, where: Where) -> list[Constraint]:
    """Normalise ``lhs op rhs`` to ``g <= 0`` form; ``abs(e) <= c`` becomes ``e <= c, -e <= c``
    and ``a == b`` the two opposite rows ``a - b <= 0, b - a <= 0`` (a slab of width 0)."""
    out = []
    for cmp in comparisons:
        if cmp.op == "==":
            g = sympy.expand(cmp.lhs - cmp.rhs)
            out += [Constraint(g, False, text, where, cmp.dimension, cmp.unit),
                    Constraint(sympy.expand(-g), False, text, where, cmp.dimension, cmp.unit)]
            continue
        small, big = (cmp.lhs, cmp.rhs) if cmp.op in ("<=", "<") else (cmp.rhs, cmp.lhs)
        strict = cmp.op in ("<", ">")
        tags = (cmp.dimension, cmp.unit)
        if isinstance(small, sympy.Abs):
            inner = small.args[0]
            out.append(Constraint(sympy.expand(inner - big), strict, text, where, *tags))
            out.append(Constraint(sympy.expand(-inner - big), strict, text, where, *tags))
        else:
            out.append(Constraint(sympy.expand(small - big), strict, text, where, *tags))
    return out


def affine_coefficients(expr: sympy.Expr, symbols: Sequence[sympy.Symbol]):
    """``(a, c)`` with ``expr == a . symbols + c`` if expr is affine in symbols, else None."""
    expr = sympy.sympify(expr)
    unknown = expr.free_symbols - set(symbols)
    if unknown:
        return None
    fast = _affine_terms(expr, symbols)
    if fast is not None:
        return fast
    a = np.zeros(len(symbols))
    present = expr.free_symbols
    for i, s in enumerate(symbols):
        if s not in present:            # the coefficient of an absent symbol is 0
            continue
        d = sympy.diff(expr, s)
        if d.free_symbols:
            return None
        try:
            a[i] = float(d)
        except (TypeError, ValueError):
            return None
    try:
        c = float(expr.subs({s: 0 for s in symbols if s in present}))
    except (TypeError, ValueError):
        return None
    if not (np.all(np.isfinite(a)) and np.isfinite(c)):
        return None
    return a, c


def _affine_terms(expr: sympy.Expr, symbols: Sequence[sympy.Symbol]):
    """:func:`affine_coefficients` read off the terms of ``expr`` (a sum of numbers times single
    symbols, and a number), or None when a term is anything else (the general path decides)."""
    index = {s: i for i, s in enumerate(symbols)}
    a, c = np.zeros(len(symbols)), 0.0
    for term, coefficient in expr.as_coefficients_dict().items():
        if not coefficient.is_Number:
            return None
        if term is sympy.S.One:
            c += float(coefficient)
        elif term in index:
            a[index[term]] += float(coefficient)
        else:
            return None
    if not (np.all(np.isfinite(a)) and np.isfinite(c)):
        return None
    return a, c


def halfspaces(constraints: Sequence[Constraint], symbols: Sequence[sympy.Symbol]):
    """``(A, b)`` with the conjunction equal to ``A x <= b``, or None if any is nonlinear.

    Strict and non-strict inequalities give the same closed half-space here; the
    closure is the sound choice for an unsafe set (it can only grow).
    """
    rows, rhs = [], []
    for con in constraints:
        coeffs = affine_coefficients(con.g, symbols)
        if coeffs is None:
            return None
        rows.append(coeffs[0])
        rhs.append(-coeffs[1])
    n = len(symbols)
    return np.array(rows, dtype=float).reshape(-1, n), np.array(rhs, dtype=float)


def lambdify_margins(constraints: Sequence[Constraint], symbols: Sequence[sympy.Symbol]):
    """A vectorised ``g(X)`` for all constraints: ``X (N, n) -> (N, m)``.

    Affine constraints are evaluated as one matrix product ``X A^T - b``.
    """
    if not constraints:
        return lambda X: np.zeros((X.shape[0], 0))
    linear = halfspaces(constraints, symbols)
    if linear is not None:
        A, b = linear
        At = np.ascontiguousarray(A.T)          # a contiguous operand: a much faster product
        return lambda X: X @ At - b
    fn = sympy.lambdify([list(symbols)], [c.g for c in constraints], modules="numpy")

    def margins(X: np.ndarray) -> np.ndarray:
        cols = fn(X.T)
        return np.stack([np.broadcast_to(np.asarray(c, dtype=float), X.shape[:1]) for c in cols],
                        axis=1)

    return margins


def opposite_pairs(constraints: Sequence[Constraint]) -> list[tuple[int, int, float, bool]]:
    """``(i, j, total, strict)`` for each pair ``i < j`` of constraints ``p - c_hi <= 0`` and
    ``c_lo - p <= 0`` whose sum ``total = c_lo - c_hi`` is a number (a slab of ``p``, any
    expression: ``x^2 == 1`` too; an equality when ``total`` is 0), ``strict`` if either is."""
    pairs = []
    for i, a in enumerate(constraints):
        for j in range(i + 1, len(constraints)):
            b = constraints[j]
            total = sympy.expand(a.g + b.g)
            if total.is_number:
                pairs.append((i, j, float(total), a.strict or b.strict))
    return pairs


def equality_rows(constraints: Sequence[Constraint]) -> list[int]:
    """Indices of the constraints that pair up into equalities: two non-strict constraints
    ``g <= 0`` and ``-g <= 0`` (``t == 20`` written as ``t <= 20`` and ``t >= 20``)."""
    return sorted({k for i, j, total, strict in opposite_pairs(constraints) if not strict and total == 0
                   for k in (i, j)})


def violation_test(constraints: Sequence[Constraint], symbols: Sequence[sympy.Symbol]):
    """Vectorised robust membership in the conjunction: ``X -> (inside, depth)``.

    ``depth = max_j g_j(X)`` is non-positive on the closure and its size is a margin.
    ``inside`` asks for ``depth < -1e-9 (1 + |x|_inf)``: a point counts as inside only if
    rounding errors of that relative size cannot have put it there, so a violation found
    this way is a violation of the strict and the non-strict reading alike.

    Equalities (:func:`equality_rows`, e.g. the instant ``t == 20``) cannot hold with a
    margin: a point meets one when ``|g| <= 1e-9 (1 + |x|_inf)`` (it is on the equality up
    to rounding), and is inside when it meets every equality and lies beyond rounding in
    every other constraint; its depth is then the largest of the other margins."""
    margins = lambdify_margins(constraints, symbols)
    equal = np.zeros(len(constraints), dtype=bool)
    equal[equality_rows(constraints)] = True

    def test(X: np.ndarray):
        g = margins(X)
        depth = g.max(axis=1) if g.shape[1] else np.full(X.shape[0], -np.inf)
        tolerance = NUMERICAL_TOLERANCE * (1.0 + np.abs(X).max(axis=1))
        if not equal.any():
            return depth < -tolerance, depth
        on = np.all(np.abs(g[:, equal]) <= tolerance[:, None], axis=1)
        rest = g[:, ~equal].max(axis=1) if (~equal).any() else np.full(X.shape[0], -np.inf)
        depth = np.where(on, rest, depth)
        return on & (rest < -tolerance), depth

    return test
