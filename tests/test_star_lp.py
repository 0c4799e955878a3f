"""The LP layer (reach.lp, highspy's bare solver) against scipy's ``linprog`` on random LPs:
the same verdict (optimal, infeasible, unbounded), the same optimum, and a feasible optimiser;
``maximize_many`` gives the supports one LP each would."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from reach import lp


@st.composite
def problems(draw):
    """``(c, A_ub, b_ub, A_eq, b_eq, lo, hi)``: 1-4 variables, some bounds infinite (so some
    problems are unbounded), a few random rows (so some are infeasible)."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31 - 1)))
    n = draw(st.integers(1, 4))
    rows, eqs = draw(st.integers(0, 4)), draw(st.integers(0, 1))
    lo = np.where(rng.random(n) < 0.3, -np.inf, -rng.uniform(0, 2, n))
    hi = np.where(rng.random(n) < 0.3, np.inf, rng.uniform(0, 2, n))
    A = rng.normal(size=(rows, n))
    b = rng.normal(size=rows)
    E = rng.normal(size=(eqs, n))
    f = rng.normal(size=eqs)
    return rng.normal(size=n), A, b, E, f, lo, hi


def reference(c, A, b, E, f, lo, hi):
    bounds = [(None if not np.isfinite(a) else a, None if not np.isfinite(z) else z) for a, z in zip(lo, hi)]
    res = linprog(c, A_ub=A if A.size else None, b_ub=b if A.size else None,
                  A_eq=E if E.size else None, b_eq=f if E.size else None, bounds=bounds, method="highs",
                  options={"presolve": False})
    return {0: lp.OPTIMAL, 2: lp.INFEASIBLE, 3: lp.UNBOUNDED}.get(res.status), res.fun


@settings(max_examples=150, deadline=None)
@given(problems())
def test_minimize_agrees_with_linprog(problem):
    c, A, b, E, f, lo, hi = problem
    status, value = reference(*problem)
    res = lp.minimize(c, A, b, A_eq=E, b_eq=f, bounds=(lo, hi))
    if status is None:                     # the reference itself undecided: nothing to compare
        return
    assert res.status == status
    if res.optimal:
        assert abs(res.value - value) <= 1e-6 * (1 + abs(value))
        x = res.x
        assert np.all(x >= lo - 1e-7) and np.all(x <= hi + 1e-7)
        assert np.all(A @ x <= b + 1e-6) and np.allclose(E @ x, f, atol=1e-6)
        assert abs(c @ x - res.value) <= 1e-6 * (1 + abs(value))


@settings(max_examples=60, deadline=None)
@given(problems())
def test_maximize_many_gives_each_support(problem):
    c, A, b, _, _, lo, hi = problem
    directions = np.vstack([c, -c, np.eye(c.size)])
    many = lp.maximize_many(directions, A, b, (lo, hi))
    for w, value in zip(directions, many):
        one = lp.maximize(w, A, b, bounds=(lo, hi))
        expected = one.support_value()
        if np.isfinite(expected):
            assert abs(value - expected) <= 1e-6 * (1 + abs(expected))
        else:
            assert value == expected


def test_bounds_as_pairs_and_none():
    res = lp.maximize([1.0, 1.0], [[1.0, 2.0]], [4.0], bounds=[(0, None), (0, 1)])
    assert res.optimal and res.value == 4.0
    assert lp.maximize([1.0], bounds=None).unbounded
    assert lp.feasible_point([[1.0], [-1.0]], [1.0, -2.0]) is None


def test_an_lp_with_non_finite_data_is_an_error_not_a_changed_polyhedron():
    """HiGHS drops a NaN coefficient from a kept row (x0 + nan x1 <= 0 became x0 <= 0: max 0
    where nothing bounds x0 below 1) and rejects huge ones (the row vanishes): both raise."""
    from reach import lp

    box = (np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    for A, b in (([[1.0, np.nan]], [0.0]), ([[1.0, np.inf]], [0.0]), ([[1.0, 1e16]], [0.0]),
                 ([[1.0, 0.0]], [np.nan])):
        with pytest.raises(lp.LPError):
            lp.maximize(np.array([1.0, 0.0]), A, b, bounds=box)
    with pytest.raises(lp.LPError):
        lp.maximize_many(np.array([[np.nan, 1.0]]), np.array([[1.0, 1.0]]), np.array([1.0]), box)
    assert lp.maximize(np.array([1.0, 0.0]), [[1.0, 1.0]], [0.0], bounds=box).value == pytest.approx(1.0)


@settings(max_examples=40, deadline=None)
@given(scale=st.floats(1e-14, 1e-7), offset=st.floats(0.1, 0.9))
def test_a_row_of_tiny_coefficients_keeps_its_half_space(scale, offset):
    """``scale (x0 + x1) <= -offset scale`` is ``x0 + x1 <= -offset``: HiGHS drops coefficients
    below 1e-9, which would read the row as ``0 <= -offset scale`` (infeasible); the row is
    scaled up first, so the polyhedron is non-empty and its support is the true one."""
    A = scale * np.array([[1.0, 1.0]])
    b = np.array([-offset * scale])
    res = lp.maximize([1.0, 1.0], A, b, bounds=[(-1, 1), (-1, 1)], tolerance=1e-10)
    assert res.optimal and res.value == pytest.approx(-offset, abs=1e-9)
    assert lp.maximize_many(np.array([[1.0, 0.0]]), A, b, (np.array([-1.0, -1.0]), np.array([1.0, 1.0])))[0] \
        == pytest.approx(1.0 - offset, abs=1e-9)
