"""The interval hull of successor stars contains each of them (every direction's support, by
LP) and is the smallest box that does."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.star.aggregation import interval_hull
from reach.sets import Box, Star
from reach.sets.hpolytope import HPolytope


@st.composite
def stars(draw, dim=3):
    """A random star: centre, basis, coefficient box and a few predicate rows through a
    point of the box (so it is never empty)."""
    seed = draw(st.integers(0, 2 ** 31 - 1))
    rng = np.random.default_rng(seed)
    m = draw(st.integers(1, 4))
    rows = draw(st.integers(0, 3))
    box = Box(-rng.uniform(0.1, 2.0, m), rng.uniform(0.1, 2.0, m))
    inside = rng.uniform(box.low, box.high)
    A = rng.normal(size=(rows, m))
    predicate = HPolytope(A, A @ inside + rng.uniform(0, 1, rows)) if rows else None
    return Star(rng.normal(size=dim), rng.normal(size=(dim, m)), predicate, box)


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
