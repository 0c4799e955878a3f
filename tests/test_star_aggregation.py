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
from model_files import load_files


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


PERIODIC = """
name: periodic
state: [x, y, tau]
modes:
  A: {flow: {x: "-0.2*x + y", y: "-x - 0.2*y", tau: 1}, invariant: ["tau <= 1"]}
  B: {flow: {x: "0.1*x + 0.5", y: "-0.3*y + 0.2*x", tau: 1}, invariant: ["tau <= 1"]}
  C: {flow: {x: "-0.5*x", y: "x - y + 1", tau: 1}, invariant: ["tau <= 1"]}
transitions:
  - {from: A, to: B, guard: ["tau >= 1"], reset: {tau: 0}, urgent: true}
  - {from: B, to: C, guard: ["tau >= 1"], reset: {tau: 0, x: "0.8*x + 0.3", y: "0.9*y - 0.2"}, urgent: true}
  - {from: C, to: A, guard: ["tau >= 1"], reset: {tau: 0}, urgent: true}
initial: {mode: A, box: {x: [1, 1.2], y: [0, 0.2], tau: 0}}
horizon: 12.5
"""

_FLOWS = {"A": ([[-0.2, 1], [-1, -0.2]], [0, 0]), "B": ([[0.1, 0], [0.2, -0.3]], [0.5, 0]),
          "C": ([[-0.5, 0], [1, -1]], [0, 1])}


def _least_y(x0, y0, samples=200) -> float:
    """The least y of the run from (x0, y0): exact affine flows (expm of the augmented matrix)
    on 1 s stretches A, B, C, A, ..., the reset into C applied, sampled densely."""
    import scipy.linalg

    z, least, mode, t = np.array([x0, y0, 1.0]), y0, "A", 0.0
    order = {"A": "B", "B": "C", "C": "A"}
    while t < 12.5:
        A, b = _FLOWS[mode]
        M = np.zeros((3, 3))
        M[:2, :2], M[:2, 2] = A, b
        length = min(1.0, 12.5 - t)
        for s in np.linspace(0, length, samples):
            least = min(least, (scipy.linalg.expm(M * s) @ z)[1])
        z = scipy.linalg.expm(M * length) @ z
        if mode == "B":
            z = np.array([0.8 * z[0] + 0.3, 0.9 * z[1] - 0.2, 1.0])
        mode, t = order[mode], t + length
    return least


def test_a_periodic_switch_with_affine_resets_against_exact_flows(tmp_path):
    """Every run switches at t = 1, 2, ... (a clock reset at each jump, no global clock), 12
    times, with an affine reset into C: the least y of the runs (about -0.827, exact flows from a
    grid of the initial box) is proved above -0.835; -0.82 is crossed by a run, so it is never
    SAFE."""
    from reach.backends.star import BACKEND
    from reach.result import Status

    least = min(_least_y(x0, y0) for x0 in np.linspace(1, 1.2, 5) for y0 in np.linspace(0, 0.2, 5))
    assert -0.835 < least < -0.82
    model, props = load_files(tmp_path, PERIODIC, "properties:\n  - {id: low, kind: safety, require: ['y >= -0.835']}\n"
                                                  "  - {id: high, kind: safety, require: ['y >= -0.82']}\n")
    low, high = props["low"], props["high"]
    assert BACKEND.check(model, low).status is Status.SAFE
    assert BACKEND.check(model, high).status is not Status.SAFE
