"""Sequential conditioning in the fsr back-end (``method: markov``) on the cases the
random-walk tests do not reach, against closed forms and quadrature.

* one kept row: the value is the normal mass ``Phi(u) - Phi(l)`` itself, reported with the
  documented rounding interval ``[max(0, v - 1e-12), min(1, v + 1e-12)]``;
* a row with no conditional variance left: ``x = (w_0 + w_1, 1/2)`` (kicks on the first
  state only), at step 1 the rows ``x_1 <= 1`` and ``x_1 + x_2 <= 0.9``; once ``x_1`` is drawn the
  second row is certain or impossible (its conditional variance is exactly 0), so it enters as
  an indicator, and the Kalman update must leave the covariance alone; with the target
  ``x_1 <= 0`` at step 2 the probability is
  ``P(w_0 <= 0.4, w_0 + w_1 <= 0) = int_{-inf}^{0.4} phi(a) Phi(-a) da`` (quad).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import ndtr
from scipy.stats import norm

from reach.backends.fsr import GaussianProblem, reach_avoid
from reach.model.ltv import KickedLinearSystem

NONE = (np.zeros((0, 1)), np.zeros(0))


def walk(steps: int, dim: int = 1, x0=None) -> GaussianProblem:
    """``x[k+1] = x[k] + w[k] e_1``, ``w ~ N(0, 1)``, ``x[0] = x0`` (no flow between kicks)."""
    G = np.zeros((dim, 1))
    G[0, 0] = 1.0
    system = KickedLinearSystem.from_continuous(np.zeros((dim, dim)), None, G, 1.0, float(steps))
    start = np.zeros(dim) if x0 is None else np.asarray(x0, float)
    return GaussianProblem(system, start, np.zeros((dim, dim)), np.zeros(1), np.eye(1))


@pytest.mark.parametrize("low,high", [(-0.3, 1.1), (-np.inf, 0.7), (-7.2, 7.2), (7.2, np.inf), (0.2, 0.2)])
def test_one_kept_row_is_the_normal_mass_with_a_rounding_interval(low, high):
    """``P(low <= S_1 <= high)`` for ``S_1 ~ N(0, 1)``, the target of a one-step walk (the
    deterministic start is checked, not integrated); masses within ``1e-12`` of 1 or of 0
    (``Phi(7.2) ~ 1 - 3e-13``) keep the interval in ``[0, 1]``."""
    H = np.array([[1.0], [-1.0]])
    target = (H, np.array([high, -low]))
    p, info = reach_avoid(walk(1), target, NONE, method="markov", drop_budget=0.0)
    exact = float(ndtr(high) - ndtr(low))
    assert info["kept"] == 1
    assert p.value == pytest.approx(exact, abs=1e-15)
    assert p.low == max(0.0, p.value - 1e-12) and p.high == min(1.0, p.value + 1e-12)
    assert 0.0 <= p.low <= exact <= p.high <= 1.0


def test_a_row_without_conditional_variance_enters_as_an_indicator():
    problem = walk(2, dim=2, x0=[0.0, 0.5])
    safe = (np.array([[1.0, 0.0], [1.0, 1.0]]), np.array([1.0, 0.9]))
    target = (np.array([[1.0, 0.0]]), np.array([0.0]))
    exact = quad(lambda a: norm.pdf(a) * ndtr(-a), -np.inf, 0.4)[0]
    p, info = reach_avoid(problem, target, safe, method="markov", abs_error=2e-4, drop_budget=0.0)
    assert info["kept"] == 3
    assert p.low <= exact <= p.high and p.high - p.low < 1e-3
    genz, _ = reach_avoid(problem, target, safe, method="genz", abs_error=2e-4, drop_budget=0.0)
    assert genz.low <= exact <= genz.high
