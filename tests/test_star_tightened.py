"""Coefficient-box tightening of stars (reach.backends.star.flowpipe._tightened) against brute force.

``_tightened(star, rows)`` shrinks the coefficient box ``[lo, hi]`` of a star by bound
propagation over its last ``rows`` predicate rows: each round replaces, for every row
``sum_j A_ij a_j <= b_i`` and every ``k`` with ``A_ik != 0``, the bound of ``a_k`` by
``(b_i - sum_{j != k} min(A_ij a_j)) / A_ik`` relaxed by ``1e-9 (1 + |bound| + size_i / |A_ik|)``,
``size_i = |b_i| + sum_j |A_ij| max(|lo_j|, |hi_j|)`` (the row's magnitudes). The references:

* one row and the box: the range of ``a_k`` over the polytope ``{a in box, A_i a <= b_i}`` is
  attained at a vertex, and every vertex is a box corner or the crossing of the hyperplane with a
  box edge; enumerating those gives the exact range, which one round of the propagation reaches
  (the new bound is that range widened by the documented slack);
* several rows: the box after one round is the intersection of the single-row ranges; after
  any number of rounds it still contains the exact range of every coefficient over the whole
  polytope (``linprog``), and ``None`` (proved empty) only when that polytope is empty;
* a chain ``a_1 <= 1/2``, ``a_(j+1) <= a_j`` on ``[0, 1]^L``: round ``r`` carries the bound
  ``1/2`` to ``a_r`` (Jacobi: every row sees the box of the previous round), so ``rounds``
  rounds tighten exactly the first ``rounds`` links to the linear programme's ``1/2``, each
  widened by the slack of its own and of every earlier link (a few 1e-9 each);
* a thin sliver far from the origin (terms of 1e8 that cancel): the slack relative to the
  row's magnitudes keeps a point whose row is met only up to rounding.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from reach.backends.star.flowpipe import _tightened
from reach.sets import Box, HPolytope, Star


def slack(v, a_k, a, b, lo, hi):
    """The documented relaxation of a bound ``v`` of ``a_k`` from the row ``a . x <= b``."""
    size = abs(b) + np.abs(a) @ np.maximum(np.abs(lo), np.abs(hi))
    return 1e-9 * (1.0 + abs(v) + size / abs(a_k))


def row_range(a, b, lo, hi):
    """Per coefficient, ``(min, max)`` of ``a_k`` over ``{x in [lo, hi], a . x <= b}`` by vertex
    enumeration (box corners on the allowed side, and the hyperplane's crossings of box edges);
    None if the polytope is empty."""
    m = len(a)
    points = [np.array(c) for c in itertools.product(*zip(lo, hi)) if np.dot(a, c) <= b]
    for i in range(m):
        if a[i] == 0:
            continue
        others = [j for j in range(m) if j != i]
        for c in itertools.product(*[(lo[j], hi[j]) for j in others]):
            x = np.empty(m)
            x[others] = c
            x[i] = (b - sum(a[j] * x[j] for j in others)) / a[i]
            if lo[i] - 1e-12 <= x[i] <= hi[i] + 1e-12:
                x[i] = min(max(x[i], lo[i]), hi[i])
                points.append(x)
    if not points:
        return None
    P = np.array(points)
    return P.min(axis=0), P.max(axis=0)


def star_of(A, b, lo, hi, seed=0):
    """A star in R^3 with coefficient box ``[lo, hi]`` and predicate ``A a <= b`` (random centre
    and basis: the tightening must leave them alone)."""
    rng = np.random.default_rng(seed)
    m = len(lo)
    return Star(rng.normal(size=3), rng.normal(size=(3, m)), HPolytope(np.atleast_2d(A), np.atleast_1d(b)),
                Box(np.array(lo, float), np.array(hi, float)))


COEFFS = (st.sampled_from([-3.0, -1.5, -1.0, -0.5, 0.0, 0.0, 0.5, 1.0, 2.0, 3.0])
          | st.floats(0.1, 3.0) | st.floats(-3.0, -0.1))
WIDTH = st.just(0.0) | st.floats(0.0, 3.0)


@st.composite
def boxes(draw, m):
    lo = np.array(draw(st.lists(st.floats(-3, 3), min_size=m, max_size=m)))
    width = np.array(draw(st.lists(WIDTH, min_size=m, max_size=m)))
    return lo, lo + width


@st.composite
def one_row(draw):
    m = draw(st.integers(1, 4))
    lo, hi = draw(boxes(m))
    a = np.array(draw(st.lists(COEFFS, min_size=m, max_size=m)))
    b = draw(st.floats(-6, 6))
    return a, b, lo, hi


def assert_same_set(out: Star, star: Star):
    np.testing.assert_array_equal(out.center, star.center)
    np.testing.assert_array_equal(out.basis, star.basis)
    np.testing.assert_array_equal(out.predicate.A, star.predicate.A)
    np.testing.assert_array_equal(out.predicate.b, star.predicate.b)


@given(one_row(), st.integers(0, 2**32 - 1))
@settings(max_examples=200)
def test_one_row_gives_its_exact_range_widened_by_the_documented_slack(row, seed):
    a, b, lo, hi = row
    exact = row_range(a, b, lo, hi)
    star = star_of(a, b, lo, hi, seed)
    least = np.sum(np.minimum(a * lo, a * hi))
    assume(abs(least - b) > 1e-6)           # not a near-tie between empty and a single face
    out = _tightened(star, 1, rounds=1)     # later rounds take the slack over the smaller box
    if exact is None:
        assert out is None or not np.any(a)        # proved empty whenever a coefficient can show it
        return
    assert out is not None
    assert_same_set(out, star)
    vmin, vmax = exact
    want_hi = [h if a[k] <= 0 else min(h, v + slack(v, a[k], a, b, lo, hi)) for k, (h, v) in enumerate(zip(hi, vmax))]
    want_lo = [lo_k if a[k] >= 0 else max(lo_k, v - slack(v, a[k], a, b, lo, hi))
               for k, (lo_k, v) in enumerate(zip(lo, vmin))]
    np.testing.assert_allclose(out.box.high, want_hi, rtol=0, atol=1e-11)
    np.testing.assert_allclose(out.box.low, want_lo, rtol=0, atol=1e-11)


def test_a_zero_coefficient_with_no_room_left_keeps_its_bounds():
    """``a_1 + 0 a_2 <= 0`` with ``a_1 in [0, 1]``: the room left for ``a_2`` is exactly 0, and
    0 / 0 must not reach the box; ``a_1`` is pinned to 0 (to the slack)."""
    star = star_of([1.0, 0.0], 0.0, [0.0, -1.0], [1.0, 2.0])
    out = _tightened(star, 1, rounds=1)
    np.testing.assert_array_equal(out.box.low, [0.0, -1.0])
    np.testing.assert_allclose(out.box.high, [slack(0.0, 1.0, np.array([1.0, 0.0]), 0.0, [0.0, -1.0], [1.0, 2.0]), 2.0],
                               rtol=0, atol=1e-18)


def test_a_pinned_coefficient_is_not_taken_for_an_empty_box():
    """A coefficient fixed by its box (``lo = hi``) that no row moves: the star is not empty."""
    star = star_of([[1.0, 1.0]], [5.0], [1.0, 0.0], [1.0, 2.0])
    out = _tightened(star, 1)
    assert out is not None
    np.testing.assert_array_equal(out.box.low, [1.0, 0.0])
    np.testing.assert_array_equal(out.box.high, [1.0, 2.0])


@st.composite
def several_rows(draw):
    m = draw(st.integers(1, 4))
    k = draw(st.integers(2, 4))
    lo, hi = draw(boxes(m))
    A = np.array(draw(st.lists(st.lists(COEFFS, min_size=m, max_size=m), min_size=k, max_size=k)))
    b = np.array(draw(st.lists(st.floats(-6, 6), min_size=k, max_size=k)))
    return A, b, lo, hi


@given(several_rows())
@settings(max_examples=150)
def test_one_round_is_the_intersection_of_the_single_row_ranges(rows):
    A, b, lo, hi = rows
    assume(all(abs(np.sum(np.minimum(r * lo, r * hi)) - c) > 1e-6 for r, c in zip(A, b)))
    ranges = [row_range(r, c, lo, hi) for r, c in zip(A, b)]
    out = _tightened(star_of(A, b, lo, hi), len(b), rounds=1)
    if any(rg is None and np.any(r) for rg, r in zip(ranges, A)):
        assert out is None
        return
    want_lo, want_hi = lo.copy(), hi.copy()
    for r, c, rg in zip(A, b, ranges):
        if rg is None:
            continue
        vmin, vmax = rg
        for k in range(len(lo)):
            if r[k] > 0:
                want_hi[k] = min(want_hi[k], vmax[k] + slack(vmax[k], r[k], r, c, lo, hi))
            if r[k] < 0:
                want_lo[k] = max(want_lo[k], vmin[k] - slack(vmin[k], r[k], r, c, lo, hi))
    if np.any(want_lo > want_hi):
        assert out is None
        return
    assert out is not None
    np.testing.assert_allclose(out.box.low, want_lo, rtol=0, atol=1e-11)
    np.testing.assert_allclose(out.box.high, want_hi, rtol=0, atol=1e-11)


@given(several_rows())
@example((np.array([[-3.0, -3.0], [-3.0, 0.5]]), np.zeros(2), np.array([0.0, 2.0 ** -24]),
          np.array([0.0, 2.0 ** -24])))           # empty by 3e-8, feasible to linprog's tolerance
@settings(max_examples=100)
def test_the_box_keeps_every_point_of_the_star(rows):
    """Sound after the default rounds: the new box contains the range of every coefficient over
    ``{a in box, A a <= b}`` (linprog), lies inside the old box, and None means empty."""
    A, b, lo, hi = rows
    out = _tightened(star_of(A, b, lo, hi), len(b))
    bounds = list(zip(lo, hi))
    feasible = linprog(np.zeros(len(lo)), A_ub=A, b_ub=b, bounds=bounds, method="highs")
    if out is None:
        # empty: linprog agrees, or (within its 1e-7 feasibility tolerance it may not) every
        # point of the box violates some row, the least worst violation being positive
        worst = linprog(np.append(np.zeros(len(lo)), 1.0), A_ub=np.hstack([A, -np.ones((len(b), 1))]),
                        b_ub=b, bounds=bounds + [(None, None)], method="highs")
        assert feasible.status == 2 or worst.fun > 0
        return
    assert np.all(out.box.low >= lo) and np.all(out.box.high <= hi)
    if feasible.status == 2:
        return
    for k in range(len(lo)):
        e = np.eye(len(lo))[k]
        low = linprog(e, A_ub=A, b_ub=b, bounds=bounds, method="highs")
        high = linprog(-e, A_ub=A, b_ub=b, bounds=bounds, method="highs")
        assert out.box.low[k] <= low.fun + 1e-7
        assert out.box.high[k] >= -high.fun - 1e-7


def chain_star(links: int):
    """``a_1 <= 1/2`` and ``a_(j+1) - a_j <= 0`` on ``[0, 1]^links``."""
    A = np.zeros((links, links))
    A[0, 0] = 1.0
    for j in range(1, links):
        A[j, j], A[j, j - 1] = 1.0, -1.0
    b = np.zeros(links)
    b[0] = 0.5
    return star_of(A, b, np.zeros(links), np.ones(links))


def assert_chained(high, reached: int):
    """The first ``reached`` links at the programme's 1/2 up to their slacks (a few 1e-9 per
    link down the chain), the others untouched at 1."""
    assert np.all(high[:reached] >= 0.5)
    assert np.all(high[:reached] <= 0.5 + 5e-9 * np.arange(1, reached + 1))
    np.testing.assert_array_equal(high[reached:], 1.0)


@pytest.mark.parametrize("rounds", [1, 2, 3, 5])
def test_each_round_carries_a_bound_one_link_down_a_chain(rounds):
    links = 6
    out = _tightened(chain_star(links), links, rounds=rounds)
    assert_chained(out.box.high, min(rounds, links))
    np.testing.assert_array_equal(out.box.low, 0.0)


def test_the_default_is_three_rounds_and_stops_at_a_fixed_point():
    assert_chained(_tightened(chain_star(5), 5).box.high, 3)
    short = _tightened(chain_star(2), 2, rounds=50)     # a fixed point within a few rounds
    assert_chained(short.box.high, 2)


def test_only_the_last_rows_are_used():
    """Rows before the last ``rows`` are taken as already propagated (docstring): an old row
    that would pin ``a_1`` is not looked at, the new one on ``a_2`` is."""
    star = star_of([[1.0, 0.0], [0.0, 1.0]], [-0.5, 0.25], [-1.0, -1.0], [1.0, 1.0])
    out = _tightened(star, 1)
    np.testing.assert_array_equal(out.box.low, [-1.0, -1.0])
    lo, hi = [-1.0, -1.0], [1.0, 1.0]
    second = slack(0.25, 1.0, np.array([0.0, 1.0]), 0.25, lo, hi)
    np.testing.assert_allclose(out.box.high, [1.0, 0.25 + second], rtol=0, atol=1e-15)
    both = _tightened(star, 2)
    first = slack(-0.5, 1.0, np.array([1.0, 0.0]), -0.5, lo, hi)
    np.testing.assert_allclose(both.box.high, [-0.5 + first, 0.25 + second], rtol=0, atol=1e-15)


def test_no_rows_or_an_unbounded_box_leave_the_star_as_it_is():
    star = star_of([[1.0, 1.0]], [0.0], [-1.0, -1.0], [1.0, 1.0])
    assert _tightened(star, 0) is star
    for lo, hi in (([-np.inf, -1.0], [1.0, 1.0]), ([-1.0, -1.0], [1.0, np.inf])):
        unbounded = star_of([[1.0, 1.0]], [0.0], lo, hi)
        assert _tightened(unbounded, 1) is unbounded


def test_a_sliver_far_from_the_origin_keeps_its_points():
    """``x + y >= 1e8 + 1`` over ``x in [-1e8, 1e8]``, ``y in [0, 1]`` as a star with centre
    ``(0, 0.5)``: only the corner ``x = 1e8, y = 1`` is in the set, and the row computed in
    floating point (normalised, ``b = g - H c``) misses it by about 1e-8. The star is not
    empty, and its box keeps the corner."""
    H = np.array([[-1.0, -1.0]]) / np.sqrt(2.0)
    g = np.array([-(1e8 + 1.0)]) / np.sqrt(2.0)
    c, V = np.array([0.0, 0.5]), np.diag([1e8, 0.5])
    star = Star(c, V, HPolytope(H @ V, g - H @ c), Box(-np.ones(2), np.ones(2)))
    out = _tightened(star, 1)
    assert out is not None
    assert np.all(out.box.high >= 1.0)
