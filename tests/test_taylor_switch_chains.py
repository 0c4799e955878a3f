"""taylor on switch chains and degenerate flows: unsupported switches are refused with a reason,
unsafe pieces that differ between modes, runs that cycle through the listed modes, a nilpotent
Jacobian in the rigorous sweep, and estimated bounds that cover only part of the run (checked
against closed forms and solve_ivp)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reach.backends.taylor import BACKEND
from reach.backends.taylor.verified import _metric_factors, lyapunov_metric
from reach.checking import check_spaceex
from reach.result import Status
from reach.spec.properties import BoundSafety
from model_files import load_files

RIGOROUS = {"remainder": "rigorous"}


# ------------------------------------------------------------------ switches taylor cannot follow
def test_a_spacex_network_with_a_timeless_location_is_unsupported_not_a_crash():
    """net.xml: a 'flow false' location left by an asap transition without a guard, equality
    guards; the cfg's forbidden terms name different locations (pieces differ by mode)."""
    results, *_ = check_spaceex("tests/data/taylor_timeless_net.xml", "tests/data/taylor_timeless_net.cfg", "taylor")
    assert [r.status for r in results] == [Status.UNSUPPORTED]
    assert "flow false" in results[0].details["reason"]


SWITCHED = """
name: sw
state: [x, t]
modes:
  a:
    flow: {{x: 1, t: 1}}
    invariant: ["x <= 1"]
  b:
    flow: {{x: -1, t: 1}}
transitions:
  - {{from: a, to: b, guard: {guard}, urgent: true}}
initial: {{mode: a, box: {{x: [0, 0.2], t: 0}}}}
horizon: 2.5
"""

PROPS = """
properties:
  - {id: p, kind: safety, modes: [a, b], avoid: ["x >= 5"]}
"""


@pytest.mark.parametrize("guard, why", [
    ('["x <= 1", "x >= 1"]', "is an equality (x <= 1 and x >= 1)"),
    ("[]", "left at once by 't0', an urgent transition without guard"),
])
def test_guards_entered_without_crossing_are_refused_with_a_reason(tmp_path, guard, why):
    model, props = load_files(tmp_path, SWITCHED.format(guard=guard), PROPS)
    assert why in BACKEND.supports(model, props["p"])


def test_a_guard_crossed_through_a_face_is_supported(tmp_path):
    model, props = load_files(tmp_path, SWITCHED.format(guard='["x >= 1"]'), PROPS)
    assert BACKEND.supports(model, props["p"]) is None


def test_unsafe_pieces_that_differ_between_modes_are_separate_margins(tmp_path):
    """x = x0 + t in a until x = 1, then x = 1 - (t - 1 + x0) in b, T = 2.5: 'x >= 2' (in a)
    has margin 2 - 1 = 1, 'x <= -1' (in a and b) has min(x(T)) + 1 = 0.5 - 0.2 = 0.3."""
    model, props = load_files(tmp_path, SWITCHED.format(guard='["x >= 1"]'), """
        properties:
          - {id: high, kind: safety, modes: [a], avoid: ["x >= 2"]}
          - {id: low, kind: safety, modes: [a, b], avoid: ["x <= -1"]}
    """)
    high, low = props["high"], props["low"]
    # as reach merges a SpaceEx cfg's forbidden terms: mode a has two pieces, mode b one
    merged = BoundSafety("forbidden", ["a", "b"], {"a": high.pieces["a"] + low.pieces["a"], "b": low.pieces["b"]},
                         model.symbols)
    assert BACKEND.supports(model, merged) is None
    result = BACKEND.check(model, merged, RIGOROUS)
    assert result.status is Status.SAFE
    rows = {r["constraint"]: r for r in result.details["constraints"]}
    assert rows["x >= 2"]["modes"] == ["a"] and rows["x <= -1"]["modes"] == ["a", "b"]
    lo, hi = rows["x >= 2"]["margin_bound"]
    assert 0 < lo <= 1 + 1e-9 and hi >= 1 - 1e-9
    lo, hi = rows["x <= -1"]["margin_bound"]
    assert 0 < lo <= 0.3 + 1e-9 and hi >= 0.3 - 1e-9


# ------------------------------------------------------------------ runs that cycle through the modes
# three linear modes cycling every second, an affine reset on leaving B
TRI = """
name: tri
state: [x, y, tau]
modes:
  A:
    flow: {{x: "-0.2*x + y", y: "-x - 0.2*y", tau: 1}}
    invariant: ["tau <= 1"]
  B:
    flow: {{x: "0.1*x + 0.5", y: "-0.3*y + 0.2*x", tau: 1}}
    invariant: ["tau <= 1"]
  C:
    flow: {{x: "-0.5*x", y: "x - y + 1", tau: 1}}
    invariant: ["tau <= 1"]
transitions:
  - {{from: A, to: B, guard: ["tau >= 1"], reset: {{tau: 0}}, urgent: true}}
  - {{from: B, to: C, guard: ["tau >= 1"], reset: {{tau: 0, x: "0.8*x + 0.3", y: "0.9*y - 0.2"}}, urgent: true}}
  - {{from: C, to: A, guard: ["tau >= 1"], reset: {{tau: 0}}, urgent: true}}
initial: {{mode: A, box: {{x: [1, 1.2], y: [0, 0.2], tau: 0}}}}
horizon: {horizon}
"""

TRI_PROPS = """
properties:
  - {id: xmax, kind: event, modes: [A, B, C], maximize: "x", require: "<= 3"}
"""

TRI_FLOWS = {"A": lambda t, z: [-0.2 * z[0] + z[1], -z[0] - 0.2 * z[1]],
             "B": lambda t, z: [0.1 * z[0] + 0.5, -0.3 * z[1] + 0.2 * z[0]],
             "C": lambda t, z: [-0.5 * z[0], z[0] - z[1] + 1]}


def _tri_max_x(horizon: float) -> float:
    """The largest x over runs from a 5 x 5 grid of the initial box (solve_ivp, mode by mode)."""
    best = -np.inf
    for x0 in np.linspace(1.0, 1.2, 5):
        for y0 in np.linspace(0.0, 0.2, 5):
            z, t, k = np.array([x0, y0]), 0.0, 0
            while t < horizon:
                mode = "ABC"[k % 3]
                sol = solve_ivp(TRI_FLOWS[mode], (0, min(1.0, horizon - t)), z, rtol=1e-11, atol=1e-12,
                                dense_output=True)
                best = max(best, sol.sol(np.linspace(0, sol.t[-1], 1001))[0].max())
                z = sol.y[:, -1]
                if mode == "B":
                    z = np.array([0.8 * z[0] + 0.3, 0.9 * z[1] - 0.2])
                t, k = t + 1.0, k + 1
    return best


def test_estimated_candidates_follow_a_cycle_back_into_listed_modes(tmp_path):
    """Five switches in 5.5 s: the maximum (1.72, after t = 3) is on a later visit of a mode."""
    model, props = load_files(tmp_path, TRI.format(horizon=5.5), TRI_PROPS)
    result = BACKEND.check(model, props["xmax"], {})
    truth = _tri_max_x(5.5)
    assert truth > 1.7
    lo, hi = result.bound
    assert np.isfinite(hi) and lo - 1e-6 <= truth <= hi + 1e-6
    assert "note" not in result.details


def test_estimated_bound_past_the_switch_limit_is_open_and_says_why(tmp_path):
    """Twelve switches in 12.5 s: the candidates stop after eight; the maximum (2.32 at t = 11)
    may lie beyond them, so the upper end is open and the reason given."""
    model, props = load_files(tmp_path, TRI.format(horizon=12.5), TRI_PROPS)
    result = BACKEND.check(model, props["xmax"], {})
    lo, hi = result.bound
    assert hi == np.inf and lo <= _tri_max_x(12.5)
    assert "mode switches" in result.details["note"]
    assert result.status is Status.UNKNOWN


# ------------------------------------------------------------------ a double integrator, constant input
DI = """
name: di
state: [x, v]
bounded_inputs:
  u: {range: [-1, 1], varying: false}
modes:
  go: {flow: {x: v, v: u}}
initial: {mode: go, box: {x: 0, v: 0}}
horizon: 2
"""

# x - v = u (t^2 / 2 - t): largest 0.5 at u = -1, t = 1, so the margin of x - v <= 0.45 is -0.05
DI_PROPS = """
properties:
  - {id: xv, kind: safety, modes: [go], require: ["x - v <= 0.45"]}
"""


def test_lyapunov_metric_of_a_nilpotent_jacobian_is_positive_definite_or_refused():
    J = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    for shift in (1e-3, 1e-2, 1e-1, 1.0):
        S = lyapunov_metric(J, shift)
        if S is not None:
            assert np.linalg.eigvalsh(S)[0] > 0
            assert all(np.all(np.isfinite(part)) for part in _metric_factors(S))


def test_rigorous_margin_of_a_double_integrator_holds_the_closed_form(tmp_path):
    model, props = load_files(tmp_path, DI, DI_PROPS)
    result = BACKEND.check(model, props["xv"], RIGOROUS)
    lo, hi = result.details["margin_bound"]
    assert lo <= -0.05 + 1e-9 and hi >= -0.05 - 1e-9
    assert result.status is Status.UNSAFE
    assert np.max(np.abs(result.counterexample.initial_state[:2])) == 0


def test_estimated_margin_is_open_where_the_nominal_run_is_stationary(tmp_path):
    """At u = 0 the margin is constant (0.45) along the run, and the extremum of the other runs
    (t = 1) continues no nominal one: the estimate must not claim [0.45, 0.45]."""
    model, props = load_files(tmp_path, DI, DI_PROPS)
    result = BACKEND.check(model, props["xv"], {})
    row = result.details["constraints"][0]
    assert row["margin_bound"][0] <= -0.05
    assert result.status is not Status.SAFE


def test_a_quantity_constant_on_every_run_keeps_its_bound(tmp_path):
    """q = c with c' = 0: every run is stationary, its start is its extremum, c0 in [0, 1]."""
    model, props = load_files(tmp_path, """
        name: still
        state: [x, c]
        modes:
          m: {flow: {x: -x, c: 0}}
        initial: {mode: m, box: {x: [1, 2], c: [0, 1]}}
        horizon: 1
    """, """
        properties:
          - {id: cmax, kind: event, modes: [m], maximize: "c", require: "<= 2"}
    """)
    result = BACKEND.check(model, props["cmax"], {})
    assert result.bound == pytest.approx((0.0, 1.0), abs=1e-9)
    assert "note" not in result.details
