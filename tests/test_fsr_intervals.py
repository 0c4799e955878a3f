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


def drifting_walk(steps: int, mean: float, sd: float) -> GaussianProblem:
    system = KickedLinearSystem.from_continuous(np.zeros((1, 1)), None, np.eye(1), 1.0, float(steps))
    return GaussianProblem(system, np.zeros(1), np.zeros((1, 1)), np.array([mean]), np.array([[sd * sd]]))


def test_boole_term_is_the_sum_of_the_smallest_closed_form_tails_of_the_random_rows():
    """Corridor ``|x| <= 3`` around a walk with drift ``0.3`` and kick sd ``0.5``: the tails
    ``P(S_k < -3) = Phi((-3 - 0.3 k) / (0.5 sqrt k))`` and ``P(S_k > 3) = Phi((0.3 k - 3) /
    (0.5 sqrt k))``, ``k = 1..K``, the smallest dropped while their sum stays within the budget;
    the fixed start ``x[0] = 0`` costs nothing (its sides are 0, not normal tails)."""
    steps, budget = 6, 0.01
    H, g = np.array([[1.0], [-1.0]]), np.array([3.0, 3.0])
    p, info = reach_avoid(drifting_walk(steps, 0.3, 0.5), (H, g), (H, g), drop_budget=budget, abs_error=1e-4)
    k = np.arange(1, steps + 1)
    low = ndtr((-3.0 - 0.3 * k) / (0.5 * np.sqrt(k)))
    high = ndtr((0.3 * k - 3.0) / (0.5 * np.sqrt(k)))
    sides = np.concatenate([low, high])
    order = np.argsort(sides)
    dropped = np.zeros(sides.size, bool)
    dropped[order[np.cumsum(sides[order]) <= budget]] = True
    assert 0 < dropped.sum() < sides.size
    assert info["boole"] == pytest.approx(np.sum(sides[dropped]), rel=1e-12)
    assert info["rows"] == steps + 1 and info["method"] == "genz"
    assert info["kept"] == np.count_nonzero(~(dropped[:steps] & dropped[steps:]))
    assert info["dropped"] == info["rows"] - info["kept"]
    assert p.high - p.low <= info["boole"] + 1e-3


def scaled_problem(c: float, relative: float) -> GaussianProblem:
    """Two independent walks, kick variances ``c^2`` and ``relative c^2``, two steps."""
    system = KickedLinearSystem.from_continuous(np.zeros((2, 2)), None, np.eye(2), 1.0, 2.0)
    return GaussianProblem(system, np.zeros(2), np.zeros((2, 2)), np.zeros(2), c * c * np.diag([1.0, relative]))


@pytest.mark.parametrize("method", ["genz", "markov"])
@pytest.mark.parametrize("c", [1e-6, 1.0, 1e6])
def test_what_counts_as_deterministic_does_not_depend_on_units(method, c):
    """The same problem in units scaled by ``c``: a row with relative variance ``1e-20`` is
    random (``P(x_2[1] <= 0) = 1/2`` exactly, whatever its spread), one with ``1e-28`` is
    deterministic (below ``ZERO_VARIANCE = 1e-24`` of the largest variance) and, violated at its
    mean, makes the probability exactly 0. With ``x_1`` the walk of unit kicks (in units of ``c``):
    ``P = 1/2 int_{-inf}^3 phi(a) Phi(10 - a) da``."""
    safe = (np.eye(2), np.array([3.0 * c, 0.0]))
    target = (np.array([[1.0, 0.0]]), np.array([10.0 * c]))
    p, _ = reach_avoid(scaled_problem(c, 1e-20), target, safe, method=method, abs_error=1e-4, drop_budget=0.0)
    exact = 0.5 * quad(lambda a: norm.pdf(a) * ndtr(10.0 - a), -np.inf, 3.0)[0]
    assert p.low <= exact <= p.high and p.high - p.low < 1e-3
    violated = (np.eye(2), np.array([3.0 * c, -1e-3 * c]))
    q, info = reach_avoid(scaled_problem(c, 1e-28), target, violated, method=method)
    assert (q.value, q.low, q.high) == (0.0, 0.0, 0.0)
    assert info["reason"] and info["kept"] == 0 and info["boole"] == 0.0
    assert info["dropped"] == info["rows"] == 5
