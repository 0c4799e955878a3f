"""The DA engine against sympy series, and the ADS splitting and polynomial bounds on functions
with a known radius of convergence."""

import math

import numpy as np
import pytest
import sympy
from hypothesis import given, settings, strategies as st

from reach.backends.taylor.ads import split_domain
from reach.backends.taylor.bound import contenders, estimated_remainder, next_order_remainder, polynomial_range, truncate
from reach.backends.taylor.da import DA, Layer, algebra, invert

X, Y = sympy.symbols("X Y")


def series_coefficients(expr, order, alg):
    """Taylor coefficients ``D^beta expr(0) / beta!`` of ``expr(X, Y)`` up to ``order``, in ``alg``."""
    out = np.zeros(alg.size)
    along_x = expr
    for a in range(order + 1):
        term = along_x
        for b in range(order + 1 - a):
            value = term.subs({X: 0, Y: 0})
            out[alg.index[(a, b)]] = float(value) / (sympy.factorial(a) * sympy.factorial(b))
            term = sympy.diff(term, Y)
        along_x = sympy.diff(along_x, X)
    return out


def test_arithmetic_and_elementary_functions_match_sympy_series():
    order = 5
    alg = algebra(order, 2)
    x, y = DA.variables(alg, [0.3, -0.2], [1.0, 1.0])
    da = (x * y + x.sin() * y.exp()) / (1 + x ** 2) + (x + 2).sqrt() * y.cos() - (x + y + 1).log() \
        + (2.5 - y) ** -1.5 - 3 * x ** 3
    xs, ys = X + 0.3, Y - 0.2
    expr = (xs * ys + sympy.sin(xs) * sympy.exp(ys)) / (1 + xs ** 2) + sympy.sqrt(xs + 2) * sympy.cos(ys) \
        - sympy.log(xs + ys + 1) + (2.5 - ys) ** -1.5 - 3 * xs ** 3
    np.testing.assert_allclose(da.c, series_coefficients(expr, order, alg), atol=1e-13)


def test_scaled_variables_and_point_evaluation():
    alg = algebra(6, 2)
    x, y = DA.variables(alg, [1.0, 2.0], [0.5, 0.25])
    f = (x * y).exp() / (1 + x * x)
    xi = np.array([[0.2, -0.4], [-1.0, 1.0], [0.0, 0.0]])
    pts = np.array([1.0, 2.0]) + xi * np.array([0.5, 0.25])
    exact = np.exp(pts[:, 0] * pts[:, 1]) / (1 + pts[:, 0] ** 2)
    np.testing.assert_allclose(f(xi), exact, rtol=2e-3)
    assert f(xi)[2] == pytest.approx(exact[2], rel=1e-15)


def test_composition_matches_sympy():
    order = 4
    alg = algebra(order, 2)
    x, y = DA.variables(alg, [0.0, 0.0], [1.0, 1.0])
    outer = (x - y * y).sin() + x * y
    g = [x + 0.5 * y * y, (x + y).exp() - 1]
    composed = outer.compose(g)
    # g has no constant term, so only its terms up to the order matter
    gx = X + Y ** 2 / 2
    gy = sum((X + Y) ** k / sympy.factorial(k) for k in range(1, order + 1))
    expr = sympy.sin(gx - gy ** 2) + gx * gy
    np.testing.assert_allclose(composed.c, series_coefficients(expr, order, alg), atol=1e-13)


def test_inverse_of_a_map_and_of_a_scalar_series():
    alg = algebra(6, 2)
    x, y = DA.variables(alg, [0.0, 0.0], [1.0, 1.0])
    F = [x + 0.5 * y * y + 0.1 * (x * y), y - x ** 3 + 0.2 * x * x + 2.0]
    G = invert(F)
    shifted = [F[0], F[1] - 2.0]
    back = [g.compose(shifted) for g in G]
    np.testing.assert_allclose(back[0].c, x.c, atol=1e-13)
    np.testing.assert_allclose(back[1].c, y.c, atol=1e-13)
    # scalar: the inverse of u = t + t^2 is t = (sqrt(1 + 4u) - 1)/2
    one = algebra(7, 1)
    t = DA.var(one, 0)
    inverse = invert([t + t * t])[0]
    U = sympy.Symbol("U")
    ser = sympy.series((sympy.sqrt(1 + 4 * U) - 1) / 2, U, 0, 8).removeO()
    expected = [float(ser.coeff(U, k)) for k in range(8)]
    np.testing.assert_allclose(inverse.c, expected, atol=1e-10)


def test_a_batch_of_maps_inverts_and_composes_as_each_map_alone():
    """Components of shape (B,) hold B maps: each is inverted, and composed with its own
    arguments, as it is on its own (event maps of an ADS level, :class:`.event.EventSolve`)."""
    alg = algebra(4, 3)
    rng = np.random.default_rng(3)
    B = 5
    F = []
    for i in range(3):
        c = 0.1 * rng.standard_normal((B, alg.size))
        c[:, 1 + i] += 1.0                 # an invertible linear part
        F.append(DA(alg, c))
    identity = [DA.var(alg, 0), DA.var(alg, 1)]
    G = invert(identity + [F[2]])
    target = algebra(4, 2)
    xi = [DA.var(target, j) for j in range(2)]
    dt = G[2].compose(xi + [DA.const(target, -F[2].cons)])
    states = DA(alg, np.stack([f.c for f in F])).compose(xi + [dt])
    assert G[2].shape == (B,) and states.shape == (3, B)
    for b in range(B):
        G_b = invert(identity + [F[2][b]])
        dt_b = G_b[2].compose(xi + [DA.const(target, -F[2][b].cons)])
        np.testing.assert_allclose(G[2].c[b], G_b[2].c, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(dt.c[b], dt_b.c, rtol=1e-13, atol=1e-15)
        alone = DA(alg, np.stack([f.c[b] for f in F])).compose(xi + [dt_b])
        np.testing.assert_allclose(states.c[:, b], alone.c, rtol=1e-13, atol=1e-15)


def test_integrate_and_derivative():
    alg = algebra(4, 2)
    x, y = DA.variables(alg, [0.0, 0.0], [1.0, 1.0])
    f = (x + 2 * y).exp()
    np.testing.assert_allclose(f.integrate(1).derivative(1).c[alg.degree < 4],
                               f.c[alg.degree < 4], atol=1e-15)
    np.testing.assert_allclose(f.derivative(0).c[alg.degree < 4], f.c[alg.degree < 4], atol=1e-15)


def _runge(alg):
    return lambda c, w: 1 / (1 + 25 * DA.var(alg, 0, c[0], w[0]) ** 2)


def test_ads_splits_where_the_radius_of_convergence_is_small(caplog):
    """1/(1 + 25 x^2) has poles at +-0.2i: the radius at c is sqrt(c^2 + 0.04)."""
    alg = algebra(4, 1)
    with caplog.at_level("INFO", logger="reach"):
        subs = split_domain(_runge(alg), [-1.0], [1.0], 1e-4, 15)
    assert len(subs) > 4 and all(s.converged for s in subs)
    levels = [r.getMessage() for r in caplog.records if r.getMessage().startswith("ADS level")]
    assert levels[0].startswith("ADS level 0: 1 boxes") and levels[-1].endswith(f"{len(subs)} subdomains so far")
    for s in subs:
        radius = np.hypot(s.center[0], 0.2)
        assert s.half_width[0] < radius
    widths = {round(float(s.center[0]), 6): float(s.half_width[0]) for s in subs}
    near = min(w for c, w in widths.items() if abs(c) < 0.1)
    far = max(w for c, w in widths.items() if abs(c) > 0.6)
    assert near < far / 2
    # the estimate is of the size of the true truncation error
    for s in subs:
        xi = np.linspace(-1, 1, 201)[:, None]
        x = s.center[0] + s.half_width[0] * xi[:, 0]
        err = np.max(np.abs(s.poly(xi) - 1 / (1 + 25 * x ** 2)))
        assert err < 20 * 1e-4


def test_ads_refines_towards_a_real_pole():
    """1/(1 - x) on [-1, 0.9]: the radius 1 - c shrinks towards x = 1."""
    alg = algebra(4, 1)
    subs = sorted(split_domain(lambda c, w: 1 / (1.0 - DA.var(alg, 0, c[0], w[0])), [-1.0], [0.9],
                               1e-4, 15), key=lambda s: s.center[0])
    widths = [s.half_width[0] for s in subs]
    assert widths[-1] < widths[0] / 8
    assert all(s.half_width[0] < 1.0 - s.center[0] for s in subs)
    assert len(split_domain(lambda c, w: 1 / (1.0 - DA.var(alg, 0, c[0], w[0])), [-0.01], [0.01],
                            1e-4, 15)) == 1


def test_polynomial_bounds_enclose_the_polynomial_and_the_function():
    alg = algebra(6, 2)
    x, y = DA.variables(alg, [0.2, -0.1], [0.3, 0.3])
    f = (x * x + y).exp() * (x - y).cos()
    lo, hi = polynomial_range(truncate(f, 4))
    rng = np.random.default_rng(1)
    xi = rng.uniform(-1, 1, (5000, 2))
    values = truncate(f, 4)(xi)
    assert lo <= values.min() and values.max() <= hi
    p = np.array([0.2, -0.1]) + 0.3 * xi
    exact = np.exp(p[:, 0] ** 2 + p[:, 1]) * np.cos(p[:, 0] - p[:, 1])
    r_est = estimated_remainder(truncate(f, 4))
    r_next = next_order_remainder(truncate(f, 5))
    assert np.max(np.abs(exact - values)) <= r_next
    assert lo - r_est <= exact.min() and exact.max() <= hi + r_est


def test_contenders_drop_only_candidates_that_cannot_hold_the_extremum():
    """For a minimum, a candidate whose enclosure starts above another's upper end is dominated;
    the candidates kept give the same bound as all of them."""
    alg = algebra(3, 1)
    x = DA.var(alg, 0, 0.0, 1.0)
    candidates = {"low": 1.0 + 0.5 * x, "overlapping": 1.2 + 0.5 * x * x, "far": 10.0 + x.sin(),
                  "touching": 1.5 + 0.0 * x}
    kept = contenders(candidates, "min")
    assert set(kept) == {"low", "overlapping", "touching"}
    assert set(contenders(candidates, "max")) == {"far"}
    ends = lambda cands: (min(polynomial_range(p)[0] for p in cands.values()),
                          min(polynomial_range(p)[1] for p in cands.values()))
    assert ends(kept) == ends(candidates)


def _reference_product(alg, a, b):
    """Truncated product by the exponents: every pair of monomials, added at ``alpha + beta``."""
    out = np.zeros(alg.size)
    for i, ea in enumerate(alg.exps):
        for j, eb in enumerate(alg.exps):
            key = tuple(ea + eb)
            if key in alg.index:
                out[alg.index[key]] += a[i] * b[j]
    return out


@settings(max_examples=20, deadline=None)
@given(st.sampled_from([(4, 2), (2, 5), (4, 3), (3, 4)]), st.integers(0, 2 ** 31))
def test_product_and_sine_in_small_and_large_algebras(shape, seed):
    """Products summed by the 0/1 matrix (up to 32 monomials) or by segments (more) equal the
    product by exponents; the sine's series (graded powers) equals sin a0 cos da + cos a0 sin da
    expanded with those products."""
    alg = algebra(*shape)
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(3, alg.size)), rng.normal(size=(3, alg.size))
    got = DA(alg, a) * DA(alg, b)
    for k in range(3):
        np.testing.assert_allclose(got.c[k], _reference_product(alg, a[k], b[k]), rtol=1e-12, atol=1e-12)
    d = a[0].copy()
    d[0] = 0.0
    powers = [np.eye(1, alg.size)[0], d]
    for _ in range(2, alg.order + 1):
        powers.append(_reference_product(alg, powers[-1], d))
    s, c = np.sin(a[0, 0]), np.cos(a[0, 0])
    derivatives = [s, c, -s, -c]
    expected = sum(derivatives[k % 4] / math.factorial(k) * p for k, p in enumerate(powers))
    np.testing.assert_allclose(DA(alg, a[0]).sin().c, expected, rtol=1e-12, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from([(4, 2), (3, 4)]), st.sampled_from([(), (1,), (5,)]), st.integers(0, 2 ** 31))
def test_layer_layout_equals_scalar_series(shape, batch, seed):
    """A network layer in the coefficient-major :class:`Layer` (stack, affine, sine, unstack)
    equals each neuron of each run computed alone: its weighted sum of the inputs, then its sine."""
    alg = algebra(*shape)
    rng = np.random.default_rng(seed)
    inputs = [DA(alg, rng.normal(size=batch + (alg.size,))) for _ in range(3)]
    W, b = rng.normal(size=(4, 3)), rng.normal(size=4)
    out = DA.stack(inputs).affine(W, b).sin().unstack()
    assert isinstance(DA.stack(inputs), Layer) and len(out) == 4
    for i in range(4):
        assert out[i].shape == batch
        for run in np.ndindex(*batch):
            alone = (DA.weighted_sum(W[i], [x[run] for x in inputs]) + b[i]).sin()
            np.testing.assert_allclose(out[i].c[run], alone.c, rtol=1e-12, atol=1e-12)
