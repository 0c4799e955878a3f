"""The truncation-remainder estimates of the Taylor back-end against the true truncation error
of functions whose series are known in closed form, from below as well as from above.

Over the scaled deviation ``xi in [-1, 1]`` of ``x = c + w xi``:

* ``1/(1 - x)`` has coefficients ``S_k = w^k / (1 - c)^(k + 1)``, a geometric sequence of ratio
  ``r = w / (1 - c)``. The fit of eq. (20) is then exact, so eq. (28) gives the first neglected
  term ``S_(n+1)``; the true error is the whole tail, largest at ``xi = 1``:
  ``sum_(k > n) S_k = S_(n+1) / (1 - r)``. The estimate is exactly ``1 - r`` times the truth,
  and the next-order remainder ``S_(n+1) (1 + r / (1 - r))`` equals it.
* ``1/(1 - x - y)`` in two variables: the order-``k`` size is ``(w_x + w_y)^k / (1 - c)^(k+1)``
  (the multinomial coefficients of ``(x + y)^k`` summed), geometric again.
* ``exp`` and ``log(1 + x)``: no closed form for the estimate, but the decay is regular, and the
  estimate must lie within a factor of four of the true error, sampled on a fine grid from the
  closed-form coefficients ``e^c w^k / k!`` and ``(-1)^(k+1) w^k / (k (1 + c)^k)``.

A remainder that is too small by a constant factor (or too large) fails the lower (upper) side.
"""

from math import factorial

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.taylor import BACKEND
from reach.backends.taylor.ads import truncation_estimate
from reach.backends.taylor.bound import (enclose, estimated_remainder, next_order_remainder, polynomial_range,
                                         truncate)
from reach.backends.taylor.da import DA, algebra, stack
from reach.model import load_model
from reach.spec import bind, load_properties

XI = np.linspace(-1.0, 1.0, 4001)


def true_error(f, coefficients, c, w):
    """``max |f(c + w xi) - sum_k a_k xi^k|`` over the grid ``XI`` (no DA involved)."""
    poly = np.polyval(np.asarray(coefficients)[::-1], XI)
    return float(np.max(np.abs(f(c + w * XI) - poly)))


@given(c=st.floats(-0.5, 0.5), ratio=st.floats(0.05, 0.8), order=st.integers(2, 8))
@settings(max_examples=40)
def test_geometric_series_estimate_is_the_first_neglected_term(c, ratio, order):
    w = ratio * (1.0 - c)
    p = 1.0 / (1.0 - DA.var(algebra(order, 1), 0, c, w))
    first_neglected = w ** (order + 1) / (1.0 - c) ** (order + 2)
    tail = first_neglected / (1.0 - ratio)
    assert float(estimated_remainder(p)) == pytest.approx(first_neglected, rel=1e-6, abs=0)
    assert truncation_estimate(p)[0] == pytest.approx(first_neglected, rel=1e-6, abs=0)
    high = 1.0 / (1.0 - DA.var(algebra(order + 1, 1), 0, c, w))
    assert float(next_order_remainder(high)) == pytest.approx(tail, rel=1e-6, abs=0)
    # the tail is the true error (at xi = 1), computed without the DA (to rounding in 1/(1 - x))
    coefficients = [w ** k / (1.0 - c) ** (k + 1) for k in range(order + 1)]
    assert true_error(lambda x: 1.0 / (1.0 - x), coefficients, c, w) == pytest.approx(tail, rel=1e-6, abs=1e-13)


def test_two_variable_geometric_series():
    c, wx, wy, order = 0.1, 0.2, 0.25, 5
    x, y = DA.variables(algebra(order, 2), [c, 0.0], [wx, wy])
    p = 1.0 / (1.0 - x - y)
    r = (wx + wy) / (1.0 - c)
    first_neglected = (wx + wy) ** (order + 1) / (1.0 - c) ** (order + 2)
    assert float(estimated_remainder(p)) == pytest.approx(first_neglected, rel=1e-6, abs=0)
    # true error at the corner xi = (1, 1), from the one-variable series of 1/(1 - c - s)
    corner = 1.0 / (1.0 - c - wx - wy) - float(p(np.array([[1.0, 1.0]]))[0])
    assert corner == pytest.approx(first_neglected / (1.0 - r), rel=1e-9, abs=0)


CASES = {
    "exp": (np.exp, lambda c, w, k: np.exp(c) * w ** k / factorial(k), lambda v: v.exp()),
    "log1p": (np.log1p, lambda c, w, k: np.log1p(c) if k == 0 else (-1) ** (k + 1) * w ** k / (k * (1 + c) ** k),
              lambda v: (1.0 + v).log()),
}


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("c, w", [(0.0, 0.2), (0.1, 0.4), (-0.2, 0.5)])
@pytest.mark.parametrize("order", [3, 4, 5, 6])
def test_estimate_is_within_a_factor_of_four_of_the_true_error(name, c, w, order):
    f, coefficient, of_da = CASES[name]
    p = of_da(DA.var(algebra(order, 1), 0, c, w))
    truth = true_error(f, [coefficient(c, w, k) for k in range(order + 1)], c, w)
    estimate = float(estimated_remainder(p))
    assert truth / 4 <= estimate <= 4 * truth


def test_enclosure_with_the_estimate_is_tight_and_contains_the_function():
    """``I_P +- R`` of eq. (28) for ``1/(1 - x)`` on ``[0.1, 0.5]``: it contains the function's
    range (closed form, monotone) and is no wider than the range plus twice the true error."""
    c, w, order = 0.3, 0.2, 4
    p = truncate(1.0 / (1.0 - DA.var(algebra(order + 1, 1), 0, c, w)), order)
    lo, hi = enclose(p, next_order_remainder(1.0 / (1.0 - DA.var(algebra(order + 1, 1), 0, c, w))))
    f_lo, f_hi = 1.0 / (1.0 - (c - w)), 1.0 / (1.0 - (c + w))
    assert lo <= f_lo and f_hi <= hi
    tail = w ** (order + 1) / (1.0 - c) ** (order + 2) / (1.0 - w / (1.0 - c))
    # eq. 27 bounds each monomial separately, so the polynomial part may exceed the range a little
    assert (hi - lo) <= 1.5 * (f_hi - f_lo) + 2 * tail


# ---------------------------------------------------------------- exact small cases (eqs. 20, 27, 28)

def da(order, coefficients):
    """A one-variable DA ``sum_k a_k xi^k`` from its coefficients."""
    alg = algebra(order, 1)
    c = np.zeros(alg.size)
    for k, a in enumerate(coefficients):
        c[alg.index[(k,)]] = a
    return DA(alg, c)


def test_polynomial_range_is_eq_27_with_the_sharper_even_terms():
    """``1 + 0.5 xi - xi^2`` on [-1, 1]: eq. 27 gives [1 - 0.5 - 1, 1 + 0.5 + 0] = [-0.5, 1.5]
    (the true range is [-0.5, 1.0625]); the enclosure adds the remainder on both sides."""
    p = da(3, [1.0, 0.5, -1.0])
    lo, hi = polynomial_range(p)
    assert (float(lo), float(hi)) == (-0.5, 1.5)
    assert tuple(map(float, enclose(p, np.float64(0.25)))) == (-0.75, 1.75)
    lo, hi = polynomial_range(da(4, [0.0, 0.0, 0.0, 0.0, 2.0]))       # 2 xi^4: [0, 2]
    assert (float(lo), float(hi)) == (0.0, 2.0)


def test_single_orders_and_constants():
    """Fewer than two non-zero orders: a constant or an exact low-order polynomial has no
    remainder; a lone top order is carried over as its own size."""
    assert float(estimated_remainder(da(4, [3.0]))) == 0.0
    assert float(estimated_remainder(da(4, [1.0, 0.5]))) == 0.0
    assert float(estimated_remainder(da(4, [1.0, 0.5, 0.0, 0.0, 1e-20]))) == 0.0     # negligible top
    assert float(estimated_remainder(da(4, [1.0, 0.0, 0.0, 0.0, 0.3]))) == pytest.approx(0.3)
    assert float(next_order_remainder(da(5, [1.0, 0.5]))) == 0.0                     # top order empty
    assert float(next_order_remainder(da(3, [1.0, 0.0, 0.0, 0.3]))) == np.inf        # one order only


def test_next_order_tail_from_two_orders_and_growing_sizes():
    """Sizes 0.5, 0.1: ratio 0.2, tail ``0.1 (1 + 0.2 / 0.8) = 0.125``; sizes growing by 1.5
    have no geometric tail (infinite)."""
    assert float(next_order_remainder(da(2, [1.0, 0.5, 0.1]))) == pytest.approx(0.125, rel=1e-12)
    assert float(next_order_remainder(da(3, [1.0, 0.1, 0.15, 0.225]))) == np.inf


@pytest.mark.parametrize("scale", [1e-13, 1.0, 1e8])
def test_the_estimates_scale_with_the_function(scale):
    """Eq. 20 fits log sizes, so scaling the map scales the estimate (the negligible-size rule is
    relative to the largest size, whatever the units)."""
    alg = algebra(6, 1)
    p = (DA.var(alg, 0, 0.1, 0.4)).exp()
    assert float(estimated_remainder(scale * p)) == pytest.approx(scale * float(estimated_remainder(p)), rel=1e-9, abs=0)
    high = (DA.var(algebra(7, 1), 0, 0.1, 0.4)).exp()
    assert float(next_order_remainder(scale * high)) == pytest.approx(scale * float(next_order_remainder(high)),
                                                                       rel=1e-9, abs=0)


@pytest.mark.parametrize("scale", [1e-13, 1.0, 1e8])
def test_an_order_negligible_against_the_largest_is_left_out_of_the_fit(scale):
    """A geometric series ``r^k`` whose order 3 is 1e-17 of the rest: the fit over the other
    orders is exact, so the estimate is ``r^(n+1)`` (times the scale)."""
    r, n = 0.5, 6
    sizes = [r ** k for k in range(n + 1)]
    sizes[3] = 1e-17
    assert float(estimated_remainder(da(n, [scale * s for s in sizes]))) == pytest.approx(scale * r ** (n + 1),
                                                                                         rel=1e-9, abs=0)
    high = [scale * r ** k for k in range(n + 2)]
    high[3] = scale * 1e-17
    assert float(next_order_remainder(da(n + 1, high))) == pytest.approx(scale * r ** (n + 1) / (1 - r), rel=1e-9, abs=0)


def test_vectors_are_estimated_component_by_component():
    """A stacked DA (a state) gets each component's own estimate; components that are exact
    polynomials or a lone top order do not stop the others, and negative even terms of one
    (cos) do not move another's range."""
    c, w, order = 0.1, 0.3, 5
    alg, high_alg = algebra(order, 1), algebra(order + 1, 1)
    parts = [lambda v: 1.0 + 0.5 * (v - c), lambda v: 1.0 + 0.2 * ((v - c) / w) ** v.alg.order,
             lambda v: 1.0 / (1.0 - v), lambda v: (2.0 * v).cos(), lambda v: v.exp()]
    low = [f(DA.var(alg, 0, c, w)) for f in parts]
    high = [f(DA.var(high_alg, 0, c, w)) for f in parts]
    np.testing.assert_allclose(estimated_remainder(stack(low)), [float(estimated_remainder(p)) for p in low])
    np.testing.assert_allclose(next_order_remainder(stack(high)), [float(next_order_remainder(p)) for p in high])
    lo, hi = polynomial_range(stack(low))
    np.testing.assert_allclose(lo, [float(polynomial_range(p)[0]) for p in low])
    np.testing.assert_allclose(hi, [float(polynomial_range(p)[1]) for p in low])
    assert truncation_estimate(stack(low))[0] == max(truncation_estimate(p)[0] for p in low)


def test_the_split_variable_is_the_one_carrying_the_truncation_error():
    alg = algebra(5, 2)
    x, y = DA.variables(alg, [0.0, 0.0], [0.5, 0.5])
    assert truncation_estimate(1.0 / (1.0 - x) + 0.1 * y)[1] == 0
    assert truncation_estimate(0.1 * x + 1.0 / (1.0 - y))[1] == 1
    assert truncation_estimate((0.2 * x).exp() * (1.0 / (1.0 - y)))[1] == 1


def test_an_extremum_found_off_the_run_is_no_candidate(tmp_path):
    """x' = -0.1 x, y' = -0.1 y over 2 s from the unit square: x + y only falls, its maximum 2
    is at the start. Newton on d(x + y)/dt = 0 went to t = 166.7 and the estimate's bound
    reached 1940; a root off the run is no turn of it, and the bound ends at 2."""
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(
        {"name": "decay", "state": ["x", "y", "t"], "horizon": 2,
         "modes": {"go": {"flow": {"x": "-0.1*x", "y": "-0.1*y", "t": 1}}},
         "initial": {"mode": "go", "box": {"x": [0, 1], "y": [0, 1], "t": 0}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "s", "kind": "event", "modes": ["go"], "maximize": "x + y", "require": "<= 2.5"}]}))
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    lo, hi = BACKEND.check(model, prop, {}).bound
    assert 2.0 - 1e-6 <= hi <= 2.0 + 1e-6
