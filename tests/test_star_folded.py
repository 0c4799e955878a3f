"""Folding a star's small coefficients into a box (:func:`reach.backends.star.flowpipe.folded`):
the folded star contains the original (every support at least as large, by LP), keeps the first
coefficients as they are, and has fewer coefficients."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.star.flowpipe import folded
from reach.sets import Box, Star
from reach.sets.hpolytope import HPolytope


@st.composite
def stars_with_small_columns(draw):
    """A star of ``big`` ordinary columns and more than ``n`` tiny ones (1e-8), cut by random
    predicate rows over all its coefficients that keep the box centre inside."""
    n = draw(st.integers(1, 4))
    big = draw(st.integers(1, 3))
    small = draw(st.integers(n + 1, n + 6))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 31 - 1)))
    m = big + small
    signs = rng.choice([-1.0, 1.0], size=(n, big))
    V = np.hstack([signs * rng.uniform(0.5, 2.0, size=(n, big)), 1e-8 * rng.normal(size=(n, small))])
    box = Box(-rng.uniform(0.5, 2, m), rng.uniform(0.5, 2, m))
    rows = rng.normal(size=(draw(st.integers(0, 3)), m))
    b = rows @ box.center + rng.uniform(0.1, 1.0, rows.shape[0])
    return Star(rng.normal(size=n), V, HPolytope(rows, b), box), big


def coefficients_inside(star, rng, tries: int):
    """Coefficient vectors of ``star``'s predicate, drawn uniformly in its box (those outside
    its rows dropped)."""
    lo, hi = star.box.low, star.box.high
    for _ in range(tries):
        a = lo + (hi - lo) * rng.uniform(size=star.nvars)
        if np.all(star.predicate.A @ a <= star.predicate.b):
            yield a


@settings(max_examples=60, deadline=None)
@given(stars_with_small_columns(), st.integers(0, 2 ** 31 - 1))
def test_the_folded_star_contains_the_star(case, seed):
    """Every point ``c + V a`` of the star (``a`` sampled in its predicate) is a point of the
    folded star, with the coefficients the containment argument names: ``a_K`` kept, and
    ``e_i = (V_F (a_F - a_F0))_i / r_i`` in ``[-1, 1]`` on the box columns, meeting the
    folded predicate (checked directly: LP optima are not exact at the folded columns' scale)."""
    star, big = case
    out = folded(star, big)
    assert out.nvars < star.nvars
    assert np.array_equal(out.basis[:, :big], star.basis[:, :big])
    small = np.ones(star.nvars, dtype=bool)
    small[:big] = False
    small &= np.abs(star.basis).sum(axis=0) * star.box.radius <= 1e-6 * (np.abs(star.basis).sum(axis=0)
                                                                        * star.box.radius).max()
    kept = ~small
    samples = 0
    for a in coefficients_inside(star, np.random.default_rng(seed), 400):
        samples += 1
        x = star.center + star.basis @ a
        radius = out.basis[:, kept.sum():]
        rows = np.flatnonzero(np.abs(radius).sum(axis=1) > 0)
        e = np.zeros(radius.shape[1])
        moved = star.basis[:, small] @ (a[small] - star.box.center[small])
        e[:] = moved[rows] / radius[rows, np.arange(rows.size)]
        assert np.all(np.abs(e) <= 1.0)
        b = np.concatenate([a[kept], e])
        assert np.all(out.predicate.A @ b <= out.predicate.b)
        assert np.allclose(out.center + out.basis @ b, x, rtol=0, atol=1e-13 * (1 + np.abs(x).max()))
    assert samples > 0


def test_nothing_is_folded_where_it_would_not_reduce_the_count():
    star = Star(np.zeros(2), np.array([[1.0, 1e-9], [0.0, 1e-9]]), box=Box(-np.ones(2), np.ones(2)))
    assert folded(star, 1) is star            # one small column for two new ones
    assert folded(star, 2) is star            # nothing past the kept ones


@settings(max_examples=40, deadline=None)
@given(stars_with_small_columns(), st.integers(0, 2 ** 31 - 1))
def test_the_shared_shape_hull_contains_each_member(case, seed):
    """Two members of one shape (the same first columns, centres 1e-9 apart, other tiny columns):
    every sampled point ``c_i + V_i a`` of either is ``c_0 + V_0 a_K + E e`` with ``a_K`` in the
    hull's coefficient box and its shared rows, and ``|e| <= 1`` (the containment argument,
    checked directly)."""
    from reach.backends.star.aggregation import shared_shape_hull

    star, big = case
    rng = np.random.default_rng(seed)
    other = Star(star.center + 1e-9 * rng.normal(size=star.dim),
                 np.hstack([star.basis[:, :big], 1e-8 * rng.normal(size=(star.dim, star.nvars - big))]),
                 star.predicate, star.box)
    hull = shared_shape_hull([(star, "a"), (other, "b")], big, lambda count: None)
    assert hull is not None and np.array_equal(hull.basis[:, :big], star.basis[:, :big])
    E = hull.basis[:, big:]
    rows = np.flatnonzero(np.abs(E).sum(axis=1) > 0)
    samples = 0
    for member in (star, other):
        for a in coefficients_inside(member, rng, 200):
            samples += 1
            x = member.center + member.basis @ a
            rest = x - hull.center - hull.basis[:, :big] @ a[:big]
            assert np.all(np.abs(rest[np.abs(E).sum(axis=1) == 0]) <= 1e-15)
            e = rest[rows] / E[rows, np.arange(rows.size)]
            assert np.all(np.abs(e) <= 1.0)
            b = np.concatenate([a[:big], e])
            assert np.all(hull.box.low <= b) and np.all(b <= hull.box.high)
            assert np.all(hull.predicate.A @ b <= hull.predicate.b)
    assert samples > 0
