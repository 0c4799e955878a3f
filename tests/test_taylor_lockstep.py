"""Batched (lockstep) expansion of ADS boxes: the same maps as one box at a time.

References: each run stepped on its own (the scalar path), scipy's solve_ivp for the flow, and the
plain truncated product for the sparse power products.
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.integrate import solve_ivp

from reach.backends.taylor import BACKEND
from reach.backends.taylor.bound import enclose, estimated_remainder
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.event import Picard, initial_state
from reach.backends.taylor.flow import rk8
from reach.backends.taylor.lockstep import Propagation, propagate_batch
from reach.backends.taylor.units import expand_box, problem
from reach.model import load_model
from reach.spec import bind, load_properties


@pytest.fixture(scope="module")
def siren():
    model = load_model("models/cw_siren.yaml")
    return model, bind(load_properties("properties/cw_siren.yaml")[0], model)


def _box(model, fx, fy, sx, sy):
    """A sub-box of the initial box: centre at fractions ``fx, fy`` of the width, half-widths
    shrunk by ``sx, sy``."""
    low, high = model.initial.low, model.initial.high
    center, half = 0.5 * (low + high), 0.5 * (high - low)
    half[:2] = half[:2] / np.array([sx, sy])
    center[:2] = low[:2] + half[:2] + (high[:2] - low[:2] - 2 * half[:2]) * np.array([fx, fy])
    return center, half


def test_batched_network_steps_equal_each_run_alone_and_solve_ivp(siren):
    """Three runs with different step sizes (one of them padded with zero steps) through the
    network flow: each equals its own run stepped alone, and the constant parts follow solve_ivp."""
    model, prop = siren
    code = problem(model, prop).code("transfer")
    alg = algebra(2, 2)
    starts = [_box(model, f, 1 - f, 4, 8) for f in (0.1, 0.5, 0.9)]
    requests = [Propagation(code.f, initial_state(alg, c, h, [0, 1]), list(steps))
                for (c, h), steps in zip(starts, ([25.0] * 20, [20.0] * 22, [30.0] * 15 + [10.0]))]
    batch = propagate_batch(requests)
    for req, got in zip(requests, batch):
        alone = req.x
        for h in req.steps:
            alone = rk8(req.f, alone, h, 1)
        for a, b in zip(alone, got):
            np.testing.assert_allclose(b.c, a.c, rtol=1e-13, atol=1e-13 * np.max(np.abs(a.c)))
        ref = solve_ivp(lambda t, x: np.array(code.f_numeric(list(x)), dtype=float), (0, sum(req.steps)),
                        np.array([x.cons for x in req.x]), method="DOP853", rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose([x.cons for x in got], ref.y[:, -1], rtol=1e-9, atol=1e-9)


@settings(max_examples=10, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 1), st.floats(0, 1)), min_size=1, max_size=5))
def test_picard_requests_in_a_batch_equal_each_alone(siren, fractions):
    """The Picard expansions and events of a batch (time refinement, eq. 6, through the network)
    equal each request answered alone, and their first-order term in the time deviation is the
    rate of the numeric flow at the state."""
    model, prop = siren
    code = problem(model, prop).code("transfer")
    alg = algebra(4, 1)
    states = [_box(model, fx, fy, 1, 1)[0] for fx, fy in fractions]
    requests = [Picard(code.f, code.qdot, [DA.const(alg, v) for v in x], 0, 4) for x in states]
    for req, x0, (x, E) in zip(requests, states, Picard.answer(requests)):
        x_alone, E_alone = Picard.answer([req])[0]
        for a, b in zip(x_alone + [E_alone], x + [E]):
            np.testing.assert_allclose(b.c, a.c, rtol=1e-12, atol=1e-12 * np.max(np.abs(a.c)))
        np.testing.assert_allclose([xi.c[1] for xi in x], code.f_numeric(list(x0)), rtol=1e-12, atol=1e-15)


def test_zero_steps_leave_a_run_exactly(siren):
    model, prop = siren
    code = problem(model, prop).code("transfer")
    x = initial_state(algebra(2, 2), *_box(model, 0.3, 0.6, 2, 2), [0, 1])
    moved, still = propagate_batch([Propagation(code.f, x, [100.0, 100.0]), Propagation(code.f, x, [])])
    assert all(np.array_equal(a.c, b.c) for a, b in zip(x, still))
    assert not np.allclose(moved[0].c, x[0].c)


def test_level_of_boxes_in_lockstep_gives_the_one_box_maps(siren):
    """Candidate maps of boxes of different sizes (different nominal runs and step counts),
    expanded as one batch, equal those expanded one at a time."""
    model, prop = siren
    boxes = [_box(model, 0.2, 0.7, 8, 4), _box(model, 0.9, 0.1, 2, 16)]
    batch = problem(model, prop).candidates_batch(boxes, 2, 1e-9)
    for (c, h), maps in zip(boxes, batch):
        alone, _ = expand_box(model, prop, 2, 2, 1e-9, c, h)
        assert set(maps) == set(alone) and any("exit" in name for name in maps)
        for name, p in alone.items():
            np.testing.assert_allclose(maps[name].c, p.c, rtol=0, atol=1e-11 * np.max(np.abs(p.c)))


def test_ads_bounds_are_the_one_box_bounds(siren):
    """Every subdomain's estimated bound from the batched ADS equals the bound from its box
    expanded on its own (eq. 27 plus the eq. 28 remainder, minimum over the candidates)."""
    model, prop = siren
    result = BACKEND.check(model, prop, {"order": 2, "e_tol": 1e-2, "max_splits": 1})
    rows = result.details["subdomains"]
    assert len(rows) >= 2
    u = [0, 1]
    for row in rows:
        center, half = 0.5 * (model.initial.low + model.initial.high), np.zeros(model.n)
        center[u], half[u] = 0.5 * (row["low"] + row["high"]), 0.5 * (row["high"] - row["low"])
        maps, _ = expand_box(model, prop, 2, 2, 1e-9, center, half)
        ends = [enclose(p, estimated_remainder(p)) for p in maps.values()]
        expected = (min(float(lo) for lo, _ in ends), min(float(hi) for _, hi in ends))
        assert row["bound"] == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_affine_on_a_batch_adds_the_bias_per_output():
    """``W a + b`` on a ``(m, B)`` DA, with ``B`` equal to the output count (where a bias added
    along the wrong axis would still broadcast)."""
    rng = np.random.default_rng(4)
    alg = algebra(2, 2)
    a = DA(alg, rng.normal(size=(2, 3, alg.size)))
    W, b = rng.normal(size=(3, 2)), rng.normal(size=3)
    out = a.affine(W, b)
    assert out.shape == (3, 3)
    for k in range(3):                       # run k of the batch on its own
        alone = DA(alg, a.c[:, k]).affine(W, b)
        np.testing.assert_allclose(out.c[:, k], alone.c, rtol=1e-14, atol=1e-14)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 5), st.integers(1, 3), st.integers(1, 3), st.integers(0, 2 ** 31 - 1))
def test_graded_product_is_the_full_product(order, nvars, low_a, seed):
    """The product restricted to the pairs of degrees ``>= low_a`` and ``>= 1`` equals the full
    truncated product when the factors have no lower terms."""
    alg = algebra(order, nvars)
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(4, alg.size)), rng.normal(size=(4, alg.size))
    a[:, alg.degree < low_a] = 0.0
    b[:, alg.degree < 1] = 0.0
    np.testing.assert_allclose(alg.multiply_graded(a, b, low_a, 1), alg.multiply(a, b), rtol=1e-13, atol=1e-13)
