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


def row_magnitudes(constraints: Sequence[Constraint], symbols: Sequence[sympy.Symbol],
                   sources: np.ndarray | None = None):
    """The scale of each constraint's rounding at a state: ``X (N, n) -> (N, m)``, for ``g <= 0``
    the largest magnitude that ``g`` combines there, not the state's largest coordinate: for an
    affine row ``a.x + c``, the largest of ``|c|`` and ``|a_i| s_i`` over the states it reads;
    for another, the largest of its terms' ``|.|`` and of ``s_i`` over the states it reads.
    ``s_i = |x_i|``, or with ``sources`` ((n, n) booleans, ``[i, j]`` where state ``i`` is
    computed from state ``j``, ``[i, i]`` true: :func:`reach.model.simulate.value_sources`) the
    largest ``|x_j|`` over those ``j``, the scale of the rounding a simulated ``x_i`` carries.
    An angle of 1e-4 rad beside a range of 7e6 m keeps its own scale; a position keeps that of
    the velocity it is integrated from."""
    index = {s: i for i, s in enumerate(symbols)}
    rows = []
    for con in constraints:
        coeffs = affine_coefficients(con.g, symbols)
        if coeffs is not None:
            rows.append((np.abs(coeffs[0]), abs(coeffs[1]), None))
            continue
        expr = sympy.expand(con.g)
        weights = np.zeros(len(symbols))
        weights[[index[v] for v in expr.free_symbols if v in index]] = 1.0
        terms = sympy.lambdify([list(symbols)], list(sympy.Add.make_args(expr)), modules="numpy")
        rows.append((weights, 0.0, terms))
    return _magnitudes(rows, len(symbols), sources)


def affine_magnitudes(H: np.ndarray, g: np.ndarray, sources: np.ndarray | None = None):
    """:func:`row_magnitudes` of the rows ``H x <= g`` (margins ``H x - g``)."""
    return _magnitudes([(np.abs(h), abs(float(c)), None) for h, c in zip(H, g)], H.shape[1], sources)


def _magnitudes(rows: list, n: int, sources: np.ndarray | None):
    """``X (N, n) -> (N, m)`` from ``rows`` of ``(weights, constant, terms)``: the largest of the
    constant, of ``weights_i s_i`` (:func:`row_magnitudes`) and, where ``terms`` is not None (a
    function of the states giving the row's additive terms), of the terms' magnitudes. An
    infinite magnitude (an overflow, ``exp(exp(t))``) is read as 0: the margin it comes with is
    no rounding of a finite number, and ``-inf`` must count as beyond the bound, not within a
    tolerance of ``1e-9 * inf``."""
    columns = [np.flatnonzero(w) for w, _, _ in rows]
    read = np.zeros(n, dtype=bool)
    for cols in columns:
        read[cols] = True
    sources = np.eye(n, dtype=bool) if sources is None else np.asarray(sources, dtype=bool)
    # s_i for the states the rows read, by groups of states computed from the same ones
    groups, which = np.unique(sources[read], axis=0, return_inverse=True)
    members = [np.flatnonzero(read)[which.reshape(-1) == k] for k in range(groups.shape[0])]
    groups = [np.flatnonzero(g) for g in groups]

    def magnitudes(X: np.ndarray) -> np.ndarray:
        size = np.abs(X)
        S = np.zeros_like(size)
        for cols, states in zip(groups, members):
            S[:, states] = size[:, cols].max(axis=1, initial=0.0)[:, None]
        out = np.empty((X.shape[0], len(rows)))
        for r, ((weights, constant, terms), cols) in enumerate(zip(rows, columns)):
            out[:, r] = (S[:, cols] * weights[cols]).max(axis=1, initial=constant)
            if terms is not None:
                for term in terms(X.T):
                    np.maximum(out[:, r], np.abs(np.broadcast_to(np.asarray(term, dtype=float), X.shape[:1])),
                               out=out[:, r])
        out[np.isinf(out)] = 0.0            # an infinite value is no rounding: -inf is beyond any bound
        return out

    return magnitudes


def violation_test(constraints: Sequence[Constraint], symbols: Sequence[sympy.Symbol],
                   sources: np.ndarray | None = None):
    """Vectorised robust membership in the conjunction: ``X -> (inside, depth)``.

    ``depth = max_j g_j(X)`` is non-positive on the closure and its size is a margin.
    ``inside`` asks for ``g_j < -1e-9 (1 + m_j(x))`` for every ``j``, ``m_j`` the magnitude
    that row combines (:func:`row_magnitudes`, with ``sources``): a point counts as inside
    only if rounding errors of that relative size cannot have put it there, so a violation
    found this way is a violation of the strict and the non-strict reading alike. The scale
    is each row's own, so a large coordinate the row does not read (a range in metres beside
    an angle) does not hide a violation of it.

    Equalities (:func:`equality_rows`, e.g. the instant ``t == 20``) cannot hold with a
    margin: a point meets one when ``|g| <= 1e-9 (1 + m)`` (it is on the equality up
    to rounding), and is inside when it meets every equality and lies beyond rounding in
    every other constraint; its depth is then the largest of the other margins."""
    margins = lambdify_margins(constraints, symbols)
    magnitudes = row_magnitudes(constraints, symbols, sources)
    equal = np.zeros(len(constraints), dtype=bool)
    equal[equality_rows(constraints)] = True

    def test(X: np.ndarray):
        g = margins(X)
        depth = g.max(axis=1) if g.shape[1] else np.full(X.shape[0], -np.inf)
        rest = g[:, ~equal].max(axis=1, initial=-np.inf)
        # every tolerance is at least NUMERICAL_TOLERANCE: the rows' magnitudes are needed only
        # below it, or to tell which states are on the equalities
        rows = np.arange(X.shape[0]) if equal.any() else np.flatnonzero(rest < -NUMERICAL_TOLERANCE)
        tolerance = NUMERICAL_TOLERANCE * (1.0 + magnitudes(X[rows]))
        on = np.ones(X.shape[0], dtype=bool)
        on[rows] = np.all(np.abs(g[rows][:, equal]) <= tolerance[:, equal], axis=1)
        inside = np.zeros(X.shape[0], dtype=bool)
        inside[rows] = on[rows] & np.all(g[rows][:, ~equal] < -tolerance[:, ~equal], axis=1)
        return inside, np.where(on, rest, depth)

    return test
