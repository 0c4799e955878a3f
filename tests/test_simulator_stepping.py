"""On the general path of segments (a mode the block path does not take: an urgent guard that
is not linear, a may-transition with a general guard), a few runs of a large linear model step
grid point by grid point (``Simulator._stepped``) where many runs take powers of the one-step
matrix: both against the closed form
``x(t) = e^{A t} x0 + int_0^t e^{A s} b ds`` (one exponential of the augmented matrix)."""

import numpy as np
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.model import load_model
from reach.model.simulate import Simulator, batched_expm

BUILDING = "models/spaceex/imported/models/BLDC01-BDS01.yaml"      # 48 states, one mode


def _closed_form(model, x0, t):
    mode = next(iter(model.modes.values()))
    A, b = mode.linear
    n = model.n
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    E = scipy.linalg.expm(M * t)
    return x0 @ E[:n, :n].T + E[:n, n]


def test_one_run_steps_and_many_take_powers_both_as_the_closed_form():
    model = load_model(BUILDING)
    rng = np.random.default_rng(3)
    low, high = model.initial.low, model.initial.high
    X = low + (high - low) * rng.random((model.n + 4, model.n))
    sim = Simulator(model)
    sim.tables = {name: None for name in model.modes}      # the general path
    called = []
    stepped = sim._stepped
    sim._stepped = lambda *a: called.append(a[1].shape[0]) or stepped(*a)
    one = sim.run(X[:1], record=True)
    many = sim.run(X, record=True)
    assert called[0] == 1                           # the single run stepped
    expected = _closed_form(model, X, model.horizon)
    scale = 1.0 + np.abs(expected).max()
    np.testing.assert_allclose(one.final_state[0], expected[0], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(many.final_state, expected, rtol=0, atol=1e-9 * scale)
    t, _, x = one.path[0]                          # every visited state, not only the last
    inside = t < model.horizon
    np.testing.assert_allclose(x[inside], np.array([_closed_form(model, X[:1], s)[0] for s in t[inside]]),
                               rtol=0, atol=1e-9 * scale)


def test_a_long_grid_is_not_refused_for_powers_it_never_holds():
    """400,000 steps of the 48-state Building: the one-step matrix's powers were planned at one
    per step (7.2 GiB) and the run refused; a mode holds at most ``POWERS_HELD`` of them. The
    run ends where the closed form does, and the table stayed that small."""
    from reach.model.simulate import POWERS_HELD

    model = load_model(BUILDING)
    x0 = 0.5 * (model.initial.low + model.initial.high)[None]
    sim = Simulator(model, dt=model.horizon / 400_000)
    sim.tables = {name: None for name in model.modes}      # the general path, where powers are taken
    final = sim.run(x0).final_state
    expected = _closed_form(model, x0, model.horizon)
    np.testing.assert_allclose(final, expected, rtol=0, atol=1e-8 * (1.0 + np.abs(expected).max()))
    assert all(p.table.shape[0] <= POWERS_HELD for p in sim.powers.values())


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), n=st.integers(1, 6),
       exponents=st.lists(st.floats(-12, 1), min_size=1, max_size=12))
def test_one_batched_exponential_of_many_durations_is_each_ones_exponential(seed, n, exponents):
    """``batched_expm(M, h)`` for durations from 1e-12 to 10 in one call (each scaled and
    squared for its own length) against ``scipy.linalg.expm(M h_k)`` one at a time."""
    M = np.random.default_rng(seed).normal(size=(n, n))
    h = 10.0 ** np.array(exponents)
    E = batched_expm(M, h)
    for k, hk in enumerate(h):
        reference = scipy.linalg.expm(M * hk)
        np.testing.assert_allclose(E[k], reference, rtol=1e-11, atol=1e-13 * np.abs(reference).max())
