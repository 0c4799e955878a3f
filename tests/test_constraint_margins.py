"""Constraint normal form and its vectorised margins against direct numpy evaluation.

``g <= 0`` rows from comparisons keep their text, place and strictness; margins of nonlinear
and constant constraints equal the formulas evaluated by numpy; the robust membership test
counts a point inside only beyond the relative rounding allowance ``1e-9 (1 + |x|_inf)``.
"""

import numpy as np
import pytest
import sympy

from reach.errors import Where
from reach.model.constraints import (affine_coefficients, from_comparisons, halfspaces, lambdify_margins,
                                     violation_test)
from reach.model.expr import parse_comparison

x, y = sympy.symbols("x y", real=True)
NAMES = {"x": x, "y": y}
W = Where("m.yaml", "modes.a.invariant[0]", 7)
POINTS = np.array([[0.3, -0.4], [2.0, 1.0], [-1.5, 0.0], [0.0, 0.0]])


def constraints(text):
    return from_comparisons(parse_comparison(text, NAMES, W), text, W)


def test_comparisons_keep_text_place_and_strictness():
    for text, strict in (("abs(x) <= 2", False), ("abs(x) < 2", True), ("y > x", True), ("y >= x", False)):
        rows = constraints(text)
        assert all(r.text == text and r.where is W and r.strict is strict for r in rows)
    negated = constraints("y >= x")[0].negated()
    assert negated.text == "not (y >= x)" and negated.where is W and negated.strict


def test_nonlinear_and_constant_margins_are_the_formulas():
    rows = constraints("x**2 + y**2 <= 1") + constraints("x <= 0.5") + constraints("sin(y) >= -1")
    rows += from_comparisons(parse_comparison("1 <= 2", {}, W), "1 <= 2", W)          # constant: -1 <= 0
    assert halfspaces(rows, [x, y]) is None
    margins = lambdify_margins(rows, [x, y])(POINTS)
    X, Y = POINTS.T
    expected = np.column_stack([X ** 2 + Y ** 2 - 1, X - 0.5, -np.sin(Y) - 1, np.full(len(X), -1.0)])
    np.testing.assert_allclose(margins, expected, atol=1e-12)
    assert margins.shape == (len(POINTS), 4) and margins.dtype == float


def test_linear_margins_and_no_constraints():
    rows = constraints("abs(x + y) <= 1")
    H, g = halfspaces(rows, [x, y])
    np.testing.assert_array_equal(H, [[1.0, 1.0], [-1.0, -1.0]])
    np.testing.assert_array_equal(g, [1.0, 1.0])
    np.testing.assert_allclose(lambdify_margins(rows, [x, y])(POINTS), POINTS @ H.T - g)
    empty = lambdify_margins([], [x, y])(POINTS)
    assert empty.shape == (len(POINTS), 0)
    inside, depth = violation_test([], [x, y])(POINTS)
    assert inside.all() and np.all(depth == -np.inf)


@pytest.mark.parametrize("c", [0.0, 1.0, 1e6])
def test_inside_only_beyond_the_relative_rounding_allowance(c):
    """``x <= c`` at points ``c - f * 1e-9 (1 + |x|)``: inside for f = 2 and 1.2, not for f = 0.5
    or 0; each point's allowance is its own (a far point in the same call changes nothing)."""
    rows = from_comparisons(parse_comparison(f"x <= {c!r}", NAMES, W), "x <= c", W)
    test = violation_test(rows, [x, y])
    allowance = 1e-9 * (1.0 + c)
    pts = np.array([[c - f * allowance, 0.0] for f in (2.0, 1.2, 0.5, 0.0, -1.0)])
    inside, depth = test(pts)
    assert list(inside) == [True, True, False, False, False]
    np.testing.assert_allclose(depth, pts[:, 0] - c, rtol=1e-6, atol=0)
    inside, _ = test(np.vstack([pts, [[c - 10.0, 1e9]]]))            # its own allowance: about 1
    assert list(inside) == [True, True, False, False, False, True]


def test_affine_coefficients_refuse_unknown_names_and_non_finite_values():
    assert affine_coefficients(2 * x - 3 * y + 1, [x, y])[0].tolist() == [2.0, -3.0]
    assert affine_coefficients(2 * x + sympy.Symbol("z"), [x, y]) is None
    assert affine_coefficients(x + sympy.oo, [x, y]) is None
    assert affine_coefficients(x * y, [x, y]) is None
