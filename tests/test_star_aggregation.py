"""The interval hull of successor stars contains each of them (every direction's support, by
LP) and is the smallest box that does; a member whose box bounds lie inside the hull of the
others costs no LP."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.star.aggregation import interval_hull
from reach.sets import Box, Star
from reach.sets.hpolytope import HPolytope


@st.composite
def stars(draw, dim=3):
    """A random star: centre, basis (some rows zero: a state a reset fixes), coefficient box
    and a few predicate rows through a point of the box (so it is never empty)."""
    seed = draw(st.integers(0, 2 ** 31 - 1))
    rng = np.random.default_rng(seed)
    m = draw(st.integers(1, 4))
    rows = draw(st.integers(0, 3))
    fixed = draw(st.lists(st.booleans(), min_size=dim, max_size=dim))
    box = Box(-rng.uniform(0.1, 2.0, m), rng.uniform(0.1, 2.0, m))
    inside = rng.uniform(box.low, box.high)
    A = rng.normal(size=(rows, m))
    predicate = HPolytope(A, A @ inside + rng.uniform(0, 1, rows)) if rows else None
    basis = rng.normal(size=(dim, m))
    basis[np.array(fixed)] = 0.0
    return Star(rng.normal(size=dim), basis, predicate, box)


@settings(max_examples=40, deadline=None)
@given(st.lists(stars(), min_size=1, max_size=4), st.integers(0, 2 ** 31 - 1))
def test_the_hull_contains_its_members(members, seed):
    counted = []
    invariant = (np.zeros((0, 3)), np.zeros(0))
    hull, kept = interval_hull([(s, None) for s in members], invariant, counted.append)
    assert hull is not None and len(kept) == len(members)
    for w in np.random.default_rng(seed).normal(size=(12, 3)):
        for star in members:
            assert star.support(w) <= hull.support(w) + 1e-7 * (1 + abs(hull.support(w)))
    low, high = hull.box_bound().low, hull.box_bound().high      # the tightest box (up to padding)
    tight = np.max([[s.support(e) for e in np.eye(3)] for s in members], axis=0)
    assert np.allclose(high, tight, rtol=1e-6, atol=1e-6)
    assert np.allclose(low, np.min([[-s.support(-e) for e in np.eye(3)] for s in members], axis=0),
                       rtol=1e-6, atol=1e-6)


def test_a_member_inside_the_others_costs_no_lp():
    """The cube ``[-1, 1]^3`` cut by ``x + y + z <= 1`` and, inside it, a smaller such cube:
    the small one's box bounds are below the big one's supports, so only the big one's six
    supports are solved, and the hull is the big one's (``x <= 1``: the corner (1, 0, 0))."""
    def cut_cube(radius):
        return Star(np.zeros(3), radius * np.eye(3), HPolytope(np.ones((1, 3)), np.array([1.0 / radius])),
                    Box(-np.ones(3), np.ones(3)))
    counted = []
    hull, kept = interval_hull([(cut_cube(0.2), "small"), (cut_cube(1.0), "big")],
                               (np.zeros((0, 3)), np.zeros(0)), counted.append)
    assert sum(counted) == 6 and [path for _, path in kept] == ["small", "big"]
    assert np.allclose(hull.box_bound().high, 1.0) and np.allclose(hull.box_bound().low, -1.0)


def test_an_empty_member_is_dropped():
    empty = Star(np.zeros(3), np.eye(3), HPolytope(np.array([[1.0, 0, 0]]), np.array([-2.0])),
                 Box(-np.ones(3), np.ones(3)))
    full = Star.from_box(Box(np.zeros(3), np.ones(3)))
    hull, kept = interval_hull([(empty, "empty"), (full, "full")], (np.zeros((0, 3)), np.zeros(0)),
                               lambda count: None)
    assert [path for _, path in kept] == ["full"]
    assert np.allclose(hull.box_bound().low, 0.0) and np.allclose(hull.box_bound().high, 1.0)
