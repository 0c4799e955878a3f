"""Zero-dwell returns (reach.backends.star.returns): a saturated controller written as three
modes with closed guards on the shared boundaries, against solve_ivp of the same loop with
``u = sat(-x - 2 v)``; and two automata where a jump back is a real run with time in the other
mode, which must still be taken (each condition of the claim on its own)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.star import BACKEND
from reach.backends.star.flowpipe import AffineFlow
from reach.backends.star.returns import rising, undone
from reach.backends.star.transitions import _Jump
from reach.result import Status
from reach.sets import Box, Star
from model_files import load_files

SATURATED = """
name: saturated
state: [x, v]
modes:
  lin:
    flow: {x: v, v: "-x - 2*v"}
    invariant: ["-x - 2*v <= 1", "-x - 2*v >= -1"]
  satp:
    flow: {x: v, v: 1}
    invariant: ["-x - 2*v >= 1"]
  satn:
    flow: {x: v, v: -1}
    invariant: ["-x - 2*v <= -1"]
transitions:
  - {from: lin, to: satp, guard: ["-x - 2*v >= 1"]}
  - {from: satp, to: lin, guard: ["-x - 2*v <= 1"]}
  - {from: lin, to: satn, guard: ["-x - 2*v <= -1"]}
  - {from: satn, to: lin, guard: ["-x - 2*v >= -1"]}
initial: {mode: satn, box: {x: [4, 4.2], v: 0}}
horizon: 15
"""
SATURATED_MODES = ["lin", "satp", "satn"]


def _least_v(samples=41):
    """Least ``v`` over runs of ``x'' = sat(-x - 2 x')`` from ``x(0)`` in [4, 4.2], ``v(0) = 0``."""
    def f(_, s):
        return [s[1], min(1.0, max(-1.0, -s[0] - 2 * s[1]))]
    low = np.inf
    for x0 in np.linspace(4.0, 4.2, samples):
        sol = solve_ivp(f, (0, 15), [x0, 0.0], rtol=1e-10, atol=1e-12, max_step=0.005, dense_output=True)
        low = min(low, float(sol.sol(np.linspace(0, 15, 30001))[1].min()))
    return low


def _check(text, tmp_path, require, modes, options=None):
    props = f'properties: [{{id: p, kind: safety, modes: [{", ".join(modes)}], require: ["{require}"]}}]'
    model, bound = load_files(tmp_path, text, props)
    return BACKEND.check(model, bound["p"], options or {})


@pytest.fixture(scope="module")
def least_v():
    low = _least_v()
    assert -1.4196 < low < -1.4192          # the saturated loop's undershoot
    return low


def test_a_saturated_loop_with_closed_shared_guards_is_proved(least_v, tmp_path):
    """Both guards hold on each boundary, so a run may switch there back and forth at one
    instant; those returns are not taken, and a bound 0.3 % beyond the least v is SAFE."""
    result = _check(SATURATED, tmp_path, f"v >= {least_v * 1.003:.5f}", SATURATED_MODES)
    assert result.status == Status.SAFE, result.reason
    assert result.details["zero_dwell_returns"] > 0


def test_a_bound_the_saturated_loop_crosses_is_violated(least_v, tmp_path):
    result = _check(SATURATED, tmp_path, f"v >= {least_v * 0.997:.5f}", SATURATED_MODES)
    assert result.status == Status.UNSAFE
    assert result.counterexample is not None


# A jump back that follows time spent in the other mode is a run of its own: z counts the time
# in `m`, and `p` requires z <= 0.05.

FALLING_BACK = """
name: falling-back
state: [x, y, z]
modes:
  p: {flow: {x: 1, y: 0, z: 0}, invariant: ["x <= 1"]}
  m: {flow: {x: y, y: -1, z: 1}, invariant: ["x >= 1"]}
transitions:
  - {from: p, to: m, guard: ["x >= 1"]}
  - {from: m, to: p, guard: ["x <= 1"]}
initial: {mode: p, box: {x: [0, 0.2], y: [0, 0.02], z: 0}}
horizon: 3
"""

ENTERED_INSIDE = """
name: entered-inside
state: [x, z]
modes:
  p: {flow: {x: 1, z: 0}, invariant: ["x <= 1"]}
  m: {flow: {x: 1, z: 1}, invariant: ["x <= 2"]}
transitions:
  - {from: p, to: m, guard: ["x >= 0.9"]}
  - {from: m, to: p, guard: ["x <= 1"]}
initial: {mode: p, box: {x: [0, 0.2], z: 0}}
horizon: 3
"""


@pytest.mark.parametrize("text", [FALLING_BACK, ENTERED_INSIDE], ids=["guard-not-rising", "entered-inside"])
def test_a_return_after_time_in_the_other_mode_is_taken(text, tmp_path):
    """``falling-back``: the runs enter ``m`` on the far side of its guard back (``x >= 1`` is
    its invariant, condition (a) holds), but ``x' = y`` turns negative within the first cell
    (condition (b) fails): from ``y(0) = 0.02`` the run is back at ``x = 1`` after 0.04 s.
    ``entered-inside``: the runs enter ``m`` at x in [0.9, 1], inside the guard back (condition
    (a) fails) and return after up to 0.1 s. Either way a run is back in ``p`` with z > 0.01."""
    result = _check(text, tmp_path, "z <= 0.01", ["p"])
    assert result.status == Status.UNSAFE, result.reason


def _jump(H, g, R=None, r=None):
    n = np.asarray(H).shape[1]
    return _Jump("j", "p", np.atleast_2d(np.asarray(H, float)), np.atleast_1d(np.asarray(g, float)),
                 np.eye(n) if R is None else np.asarray(R, float), np.zeros(n) if r is None else np.asarray(r, float),
                 None)


def test_a_return_undoes_only_the_inverse_reset():
    R1, r1 = np.array([[2.0, 0.0], [0.0, 1.0]]), np.array([0.0, 1.0])
    first = _jump([[1.0, 0.0]], [0.0], R1, r1)
    assert undone(first, _jump([[1.0, 0.0]], [0.0], np.linalg.inv(R1), -np.linalg.inv(R1) @ r1))
    assert not undone(first, _jump([[1.0, 0.0]], [0.0]))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-2, 2), min_size=4, max_size=4), st.lists(st.floats(-1, 1), min_size=2, max_size=2),
       st.lists(st.floats(-1, 1), min_size=2, max_size=2), st.floats(0.0, 0.5), st.floats(-1, 1))
def test_rising_is_a_lower_bound_of_the_guard_rate(a, b, centre, u_radius, shift):
    """Where ``rising`` says the guard row rises over a box, it rises at every sampled state of
    the box and for both extreme inputs: ``h (A x + b + B u) > 0``."""
    A = np.array(a).reshape(2, 2)
    B = np.array([[0.0], [1.0]])
    flow = AffineFlow(A, np.array(b) + shift, B, np.array([u_radius]))
    box = Star(np.array(centre), np.eye(2), None, Box(-0.3 * np.ones(2), 0.3 * np.ones(2)))
    jump = _jump([[0.6, -0.8]], [0.0])
    if not rising(flow, jump, [0], box):
        return
    grid = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 7), np.linspace(-0.3, 0.3, 7)), -1).reshape(-1, 2)
    for x in np.array(centre) + grid:
        for u in (-u_radius, u_radius):
            assert jump.H[0] @ (A @ x + flow.b + B[:, 0] * u) > 0


# Two jumps into `m`: j1 (identity, undone by the urgent j2) and j5 (y := y + 1). The j5 runs
# enter `m` at states inside the hull of the j1 runs; from (1, 2) they are back in `p` at once,
# with y - x = 1 (closed form: x = y = t until t = 1). The j1 aggregate skips its returns, so it
# must not cover the j5 one (the fixpoint check's tag).

TWO_WAYS_IN = """
name: two-ways-in
state: [x, y, s]
modes:
  i0: {flow: {x: 1, y: 1, s: 0}, invariant: ["x <= 0.1"]}
  i1: {flow: {x: 1, y: 1, s: 0}, invariant: ["x <= 0.2"]}
  p:  {flow: {x: 1, y: 1, s: "-s"}, invariant: ["x <= 3"]}
  m:  {flow: {x: 2, y: 0, s: 0}, invariant: ["x >= 1"]}
transitions:
  a:  {from: i0, to: i1, guard: ["x >= 0.1"]}
  b:  {from: i1, to: p, guard: ["x >= 0.2"]}
  j1: {from: p, to: m, guard: ["x >= 1"]}
  j5: {from: p, to: m, guard: ["x >= 1", "x <= 2"], reset: {y: "y + 1"}}
  j2: {from: m, to: p, guard: ["x <= 1"], urgent: true}
initial: {mode: i0, box: {x: 0, y: 0, s: 1}}
horizon: 4
"""


def test_an_aggregate_that_skips_returns_covers_only_runs_that_came_its_way(tmp_path):
    result = _check(TWO_WAYS_IN, tmp_path, "y - x <= 0.5", ["p"], {"finer_retry": False})
    assert result.status != Status.SAFE
