"""Taylor-model jets through the CW SIREN closed loop: they contain the field and its Jacobian
(references: the numpy field, and the exact gradient from an order-1 DA at the point) and are
tighter than the interval jet on the same box."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.flow import compile_expressions, compile_numeric
from reach.backends.taylor.interval import Jet
from reach.backends.taylor.network_tm import TMJet, field_enclosure
from reach.model import load_model


@pytest.fixture(scope="module")
def transfer():
    model = load_model("models/cw_siren.yaml")
    flow = model.modes["transfer"].flow
    return compile_expressions(flow, model.symbols), compile_numeric(flow, model.symbols)


def gradient_at(f, z):
    """``Df(z)`` from the linear coefficients of an order-1 DA evaluation (forward mode)."""
    alg = algebra(1, len(z))
    return np.array([o.c[1:] for o in f([DA.var(alg, i, z[i], 1.0) for i in range(len(z))])])


# states along the transfer (positions in m, velocities in m/s, clock in s) and box half-widths
STATE = st.tuples(st.floats(-600, 600), st.floats(-700, 100), st.floats(-0.12, 0.12), st.floats(-0.12, 0.12),
                  st.floats(0, 14_000))


@settings(max_examples=15, deadline=None)
@given(STATE, st.sampled_from([1e-3, 1e-2, 0.1, 1.0]), st.integers(0, 2 ** 31 - 1))
def test_enclosures_contain_the_field_and_its_jacobian(transfer, z0, size, seed):
    f, f_numeric = transfer
    z0 = np.array(z0)
    radius = np.array([size, size, 1e-2 * size, 1e-2 * size, size])
    low, high = z0 - radius, z0 + radius
    flo, fhi, Jlo, Jhi = field_enclosure(f, low, high)
    if size <= 1e-2 and np.hypot(z0[0], z0[1]) > 50:     # away from the target's singular layer
        assert np.all(np.isfinite(Jlo)) and np.all(np.isfinite(Jhi))
    points = low + (high - low) * np.random.default_rng(seed).random((6, 5))
    for z in np.vstack([points, low, high]):
        value = np.array(f_numeric(list(z)), dtype=float)
        grad = gradient_at(f, z)
        slack = 1e-12 * (1 + np.abs(value))
        assert np.all((flo - slack <= value) & (value <= fhi + slack))
        gslack = 1e-12 * (1 + np.abs(grad))
        assert np.all((Jlo - gslack <= grad) & (grad <= Jhi + gslack))


def test_tighter_than_the_interval_jet_on_a_millimetre_box(transfer):
    """On a 1 mm (1e-5 m/s) box of the transfer the interval jet wraps at every sine layer; the
    Taylor-model jet's Jacobian stays within a few per cent of the gradient's size."""
    f, _ = transfer
    z0 = np.array([300.0, -300.0, 0.05, 0.03, 3000.0])
    r = np.array([1e-3, 1e-3, 1e-5, 1e-5, 1.0])
    _, _, Jlo, Jhi = field_enclosure(f, z0 - r, z0 + r)
    jets = f(Jet.seed(z0 - r, z0 + r))
    jet_width = np.array([o.ghi - o.glo for o in jets])
    tm_width = Jhi - Jlo
    net_rows = slice(2, 4)                      # the thrust rows (vx', vy') carry the network
    size = np.abs(gradient_at(f, z0)[net_rows, :4]).max()
    assert tm_width[net_rows, :4].max() < 0.05 * size < jet_width[net_rows, :4].max()
    assert np.all(tm_width <= jet_width + 1e-15)


def test_affine_layer_maps_value_and_gradient():
    """A layer ``W h + b`` on a seeded jet: value ``W z + b`` and gradient ``W`` exactly."""
    rng = np.random.default_rng(2)
    low = rng.uniform(-1, 0, 3)
    high = low + rng.uniform(0.1, 1, 3)
    W, b = rng.normal(size=(2, 3)), rng.normal(size=2)
    out = TMJet.stack(TMJet.seed(low, high, 2)).affine(W, b)
    lo, hi, glo, ghi = out.bounds()
    z = np.array([0.5 * (low + high)])
    np.testing.assert_allclose(glo, W, atol=1e-14)
    np.testing.assert_allclose(ghi, W, atol=1e-14)
    mid = W @ z[0] + b
    assert np.all((lo <= mid) & (mid <= hi))
