"""The LP layer (reach.lp, highspy's bare solver) against scipy's ``linprog`` on random LPs:
the same verdict (optimal, infeasible, unbounded), the same optimum, and a feasible optimiser;
``maximize_many`` gives the supports one LP each would."""

from __future__ import annotations

import time

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


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.booleans())
def test_large_lps_are_presolved_and_agree_with_linprog(seed, empty):
    """Beyond ``PRESOLVE_ENTRIES`` the model is presolved (set small here, the same code path):
    the supports agree with scipy's, and an empty polyhedron is still reported empty (presolve's
    infeasible verdict confirmed without it)."""
    rng = np.random.default_rng(seed)
    n, m = 6, 40
    A = rng.normal(size=(m, n))
    b = rng.uniform(0.1, 1.0, m) if not empty else -rng.uniform(0.1, 1.0, m)
    if empty:                                    # x and -x both below -0.1 in one coordinate
        A[0], A[1], b[0], b[1] = np.eye(n)[0], -np.eye(n)[0], -0.1, -0.1
    box = (-np.ones(n), np.ones(n))
    C = rng.normal(size=(4, n))
    saved, lp.PRESOLVE_ENTRIES = lp.PRESOLVE_ENTRIES, 50
    try:
        many = lp.maximize_many(C, A, b, box)
    finally:
        lp.PRESOLVE_ENTRIES = saved
    for c, value in zip(C, many):
        ref = linprog(-c, A_ub=A, b_ub=b, bounds=list(zip(*box)), method="highs")
        if ref.status == 2:
            assert value == -np.inf
        else:
            assert ref.status == 0 and value == pytest.approx(-ref.fun, abs=1e-6)


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


@st.composite
def boxed_problems(draw):
    """``(c, A, b, lo, hi)``: 1-6 bounded variables and 0-8 random rows, feasible (the rows
    hold at a random point of the box)."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31 - 1)))
    n, rows = draw(st.integers(1, 6)), draw(st.integers(0, 8))
    lo, hi = -rng.uniform(0, 2, n), rng.uniform(0, 2, n)
    A = rng.normal(size=(rows, n))
    point = rng.uniform(lo, hi)
    b = A @ point + rng.uniform(0, 1, rows)
    return rng.normal(size=n), A, b, lo, hi


@settings(max_examples=100, deadline=None)
@given(boxed_problems(), st.integers(0, 2 ** 31 - 1))
def test_the_dual_bound_holds_for_any_multipliers_and_is_tight_at_the_solvers(problem, seed):
    """Weak duality: for any multipliers (random here, of either sign) the bound is at least
    the maximum (scipy's linprog); with the solver's own duals it is the maximum, which
    ``maximize_many`` returns (a box makes every star support one of these)."""
    c, A, b, lo, hi = problem
    status, value = reference(-c, A, b, np.zeros((0, c.size)), np.zeros(0), lo, hi)
    assert status == lp.OPTIMAL
    top = -value
    y = np.random.default_rng(seed).normal(size=A.shape[0]) * 3
    assert lp.DualBound(A, b, lo, hi)(c, y) >= top - 1e-9 * (1 + abs(top))
    assert lp.maximize_many(c[None], A, b, (lo, hi))[0] == pytest.approx(top, rel=1e-6, abs=1e-6)
    assert lp.maximize_many(c[None], A, b, (lo, hi))[0] >= top - 1e-12 * (1 + abs(top))


def test_the_dual_bound_covers_a_solver_value_short_of_the_maximum():
    """A solver may stop within its tolerances below the maximum; the bound does not rest
    on it: multipliers off by 1e-4 still give an upper bound (looser, not lower)."""
    A, b = np.array([[1.0, 1.0], [1.0, -1.0]]), np.array([1.0, 0.0])
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    c = np.array([1.0, 0.0])                            # max x0 = 1/2 at (1/2, 1/2)
    exact = np.array([0.5, 0.5])                        # the optimal multipliers
    assert lp.DualBound(A, b, lo, hi)(c, exact) == pytest.approx(0.5, abs=1e-12)
    for shift in ([1e-4, 0.0], [0.0, -1e-4], [-1e-4, 1e-4]):
        assert lp.DualBound(A, b, lo, hi)(c, exact + np.array(shift)) >= 0.5


@settings(max_examples=100, deadline=None)
@given(boxed_problems(), st.integers(0, 2 ** 31 - 1), st.booleans())
def test_the_variable_bound_holds_for_any_multipliers_and_is_tight_at_the_solvers(problem, seed, capped):
    """``x_j`` unbounded below (and above unless ``capped``), the others boxed: the bound
    from any multipliers is at least the maximum of ``x_j`` (scipy's linprog), and the
    solver's own duals give the maximum."""
    _, A, b, lo, hi = problem
    j = 0
    lo, hi = lo.copy(), hi.copy()
    lo[j], hi[j] = -np.inf, (hi[j] if capped else np.inf)
    c = np.eye(lo.size)[j]
    status, value = reference(-c, A, b, np.zeros((0, c.size)), np.zeros(0), lo, hi)
    if status != lp.OPTIMAL:
        return
    top = -value
    y = np.random.default_rng(seed).normal(size=A.shape[0]) * 3
    assert lp.variable_bound(j, A, b, lo, hi, y) >= top - 1e-9 * (1 + abs(top))
    res = lp.maximize(c, A, b, bounds=(lo, hi))
    assert lp.variable_bound(j, A, b, lo, hi, res.duals) == pytest.approx(top, rel=1e-6, abs=1e-6)


def test_maximize_many_over_no_variables_is_the_point_or_empty():
    """A star with no coefficients (a single point) asks for supports over R^0: 0 when every
    row holds at the origin, -inf (empty) otherwise."""
    C = np.zeros((2, 0))
    assert list(lp.maximize_many(C, np.zeros((1, 0)), [0.5], (np.zeros(0), np.zeros(0)))) == [0.0, 0.0]
    assert list(lp.maximize_many(C, np.zeros((1, 0)), [-0.5], (np.zeros(0), np.zeros(0)))) == [-np.inf] * 2


def test_an_lp_past_the_deadline_decides_nothing():
    """Under :func:`reach.lp.deadline` HiGHS stops at the instant given: an LP that takes far
    longer (a dense 800 x 300 polytope, a tenth of a second or more of simplex) started after it gives ``nan``
    from ``maximize_many`` (the caller falls back to a bound it can argue without the LP) and
    an LPError from ``minimize``, never a value. Without the deadline the same LP is solved."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(800, 300))
    b = 1.0 + rng.uniform(size=800)                    # 0 is inside: feasible and bounded
    box = (np.full(300, -10.0), np.full(300, 10.0))
    c = rng.normal(size=(1, 300))
    with lp.deadline(time.perf_counter() - 1.0):
        assert np.isnan(lp.maximize_many(c, A, b, box)).all()
        with pytest.raises(lp.LPError):
            lp.minimize(c[0], A, b, bounds=box)
    assert np.isfinite(lp.maximize_many(c, A, b, box)).all()
