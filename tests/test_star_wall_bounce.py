"""A harmonic oscillator against a wall (``x' = v``, ``v' = -x``, invariant ``x <= 1``, urgent
self-loop ``x >= 1 & v >= 0`` with ``v := -0.5 v``), from ``x`` in [0, 0.5], ``v`` in [1.05,
1.2] (every run hits the wall; none grazes it at ``v = 0``, where the bounce changes nothing and
could be taken again and again at one instant).

A chain's grid star at ``t_j`` applied the invariant rows of the earlier grid points to the state
at ``t_j`` instead of at their own instants, so a run that crossed the wall between two grid
points and came back inside stayed in the chain (the unbounced run from ``(0.5, 1.2)`` reaches
``v = -1.3``): every extreme ended UNKNOWN.

References: scipy's ``solve_ivp`` with the wall as an event (rtol 1e-12) over a grid of
initial states, refined by a bounded local search; and closed forms where they exist."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

from reach.backends.star import BACKEND
from reach.result import Status
from tests.model_files import load_files

MODEL = """
name: wall
state: [x, v]
modes:
  osc: {{flow: {{x: v, v: "-x"}}, invariant: ["x <= 1"]}}
transitions: {transitions}
initial: {{mode: osc, box: {{x: [0, 0.5], v: [{vlow}, 1.2]}}}}
horizon: 10
"""
BOUNCE = '[{from: osc, to: osc, guard: ["x >= 1", "v >= 0"], reset: {v: "-0.5*v"}, urgent: true}]'
LOW, HIGH = np.array([0.0, 1.05]), np.array([0.5, 1.2])


def _run(x0: float, v0: float, horizon: float = 10.0) -> np.ndarray:
    """Samples ``(x, v)`` of the bouncing run (the wall an event, the reset applied there)."""
    def wall(t, y):
        return y[0] - 1.0
    wall.terminal, wall.direction = True, 1.0
    t, y, out = 0.0, np.array([x0, v0]), []
    while t < horizon - 1e-12:
        sol = solve_ivp(lambda _, s: [s[1], -s[0]], (t, horizon), y, events=wall, rtol=1e-12, atol=1e-12,
                        dense_output=True)
        end = sol.t[-1]
        out.append(sol.sol(np.linspace(t, end, 1000)).T)
        if sol.status != 1 or end - t < 1e-9:            # horizon, or a graze at (1, 0)
            if sol.status == 1:                        # a graze: the reset changes nothing; move on
                y = sol.y[:, -1]
                sol = solve_ivp(lambda _, s: [s[1], -s[0]], (end, horizon), y, rtol=1e-12, atol=1e-12,
                                dense_output=True)
                out.append(sol.sol(np.linspace(end, horizon, 2000)).T)
            break
        t, y = end, np.array([1.0, -0.5 * sol.y[1, -1]])
    return np.vstack(out)


QUANTITY = {"minv": lambda s: s[:, 1].min(), "maxxmv": lambda s: -(s[:, 0] - s[:, 1]).max()}


@functools.lru_cache(maxsize=None)
def _true(key: str) -> float:
    """The least value of ``QUANTITY[key]`` (min v, or minus max x - v) over the initial box."""
    f = QUANTITY[key]
    grid = [(x, v) for x in np.linspace(0, 0.5, 6) for v in np.linspace(1.05, 1.2, 5)]
    start = min(grid, key=lambda p: f(_run(*p)))
    res = minimize(lambda p: f(_run(*np.clip(p, LOW, HIGH))), start, method="Nelder-Mead",
                   options={"xatol": 1e-9, "fatol": 1e-12, "maxiter": 300})
    return float(min(f(_run(*start)), res.fun))


def _check(tmp_path, require: str, transitions: str = BOUNCE, vlow: float = 1.05):
    props = f"""
    properties:
      - id: p
        kind: safety
        modes: [osc]
        require: ["{require}"]
    """
    model, bound = load_files(tmp_path, MODEL.format(transitions=transitions, vlow=vlow), props)
    return BACKEND.check(model, bound["p"])


def test_the_smallest_speed_has_its_closed_form():
    """After the first bounce the run circles with ``r'^2 = 1 + (v_wall / 2)^2``, ``v_wall^2 =
    r^2 - 1``: from the corner ``(0.5, 1.2)``, min v = -sqrt(1 + 0.69 / 4)."""
    assert _true("minv") == pytest.approx(-math.sqrt(1 + 0.69 / 4), abs=1e-6)


@pytest.mark.parametrize("key", ["minv", "maxxmv"])
def test_safe_one_percent_beyond_the_true_extremes(tmp_path, key):
    extreme = _true(key)
    require = f"v >= {float(1.01 * extreme)!r}" if key == "minv" else f"x - v <= {float(-1.01 * extreme)!r}"
    result = _check(tmp_path, require)
    assert result.status is Status.SAFE, result.details.get("reason")


def test_unsafe_one_percent_inside_the_smallest_speed_with_a_replayed_run(tmp_path):
    extreme = _true("minv")
    result = _check(tmp_path, f"v >= {float(0.99 * extreme)!r}")
    assert result.status is Status.UNSAFE, result.details.get("reason")
    x0 = np.asarray(result.counterexample.initial_state, dtype=float)[:2]
    assert np.all(x0 >= LOW - 1e-12) and np.all(x0 <= HIGH + 1e-12)
    assert QUANTITY["minv"](_run(*x0)) < 0.99 * extreme


def test_without_the_wall_only_the_grazing_run_lives_past_it(tmp_path):
    """No transition: a run that reaches ``x = 1`` with ``v > 0`` cannot go on (the invariant),
    so only the run from ``(0, 1)``, which touches ``x = 1`` at ``v = 0``, lives past a quarter
    turn, and ``v >= -1`` over all runs. Grid stars that forgot the earlier grid points' rows
    kept the run from ``(0.5, 1.2)``, down to ``v = -1.3``."""
    result = _check(tmp_path, "v >= -1.01", transitions="[]", vlow=1.0)
    assert result.status is Status.SAFE, result.details.get("reason")
