"""taylor's rigorous sweep through closed guards on a shared boundary: a saturated loop written as
three modes with urgent guards (returns at the entry instant are not taken, entry states stay on
the face they cross), a return after a dwell that must still be taken, and the two set operations
behind it (the face contraction and the time slices of a step) against sampled points."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.integrate import solve_ivp

from reach.backends.taylor import BACKEND
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.problem import _entry_slices, _on_face, _tied
from reach.backends.taylor.tm import TM
from reach.result import Status
from model_files import load_files

RIGOROUS = {"remainder": "rigorous"}

# u = sat(-x - v) at +-1 as three modes: each guard is the boundary of the next mode, closed, so a
# run that has just entered lin at -x - v = -1 is also inside the guard back to satn
SATURATED = """
name: sat
state: [x, v]
modes:
  lin:  {flow: {x: v, v: "-x - v"}}
  satp: {flow: {x: v, v: 1}}
  satn: {flow: {x: v, v: -1}}
transitions:
  lp: {from: lin, to: satp, guard: ["-x - v >= 1"], urgent: true}
  pl: {from: satp, to: lin, guard: ["-x - v <= 1"], urgent: true}
  ln: {from: lin, to: satn, guard: ["-x - v <= -1"], urgent: true}
  nl: {from: satn, to: lin, guard: ["-x - v >= -1"], urgent: true}
initial: {mode: satn, box: {x: [2, 2.5], v: [0, 0.2]}}
horizon: 15
"""


def _saturated_min_x() -> float:
    """The least x over runs from a 9 x 5 grid of the initial box (solve_ivp on the saturated
    feedback, one continuous flow)."""
    def f(t, z):
        return [z[1], float(np.clip(-z[0] - z[1], -1.0, 1.0))]
    return min(solve_ivp(f, (0, 15), [x0, v0], max_step=0.005, rtol=1e-10, atol=1e-12).y[0].min()
               for x0 in np.linspace(2, 2.5, 9) for v0 in np.linspace(0, 0.2, 5))


def test_a_saturated_loop_with_closed_urgent_guards_is_proved(tmp_path):
    """Before: the sweep followed lin -> satn -> lin ... at the entry instant until the switch
    limit, and the bound was open. The true least x is -0.3846; the rigorous bound must hold it
    and prove x >= -0.55."""
    truth = _saturated_min_x()
    assert -0.40 < truth < -0.37
    model, props = load_files(tmp_path, SATURATED, """
        properties:
          - {id: low, kind: safety, modes: [lin, satp, satn], require: ["x >= -0.55"]}
    """)
    result = BACKEND.check(model, props["low"], RIGOROUS)
    assert result.status is Status.SAFE, result.details.get("reason")
    lo, hi = result.details["margin_bound"]
    assert lo <= truth + 0.55 <= hi


# P accelerates into x >= 1, M decelerates and brings every run back to x = 1 after a dwell of
# 2 sqrt(2 (1 - x0)): the return must be taken there, where v = -sqrt(2 (1 - x0)) < -1
BACK = """
name: back
state: [x, v, t]
modes:
  P: {flow: {x: v, v: 1, t: 1}}
  M: {flow: {x: v, v: -1, t: 1}}
transitions:
  - {from: P, to: M, guard: ["x >= 1"], urgent: true}
  - {from: M, to: P, guard: ["x <= 1"], urgent: true}
initial: {mode: P, box: {x: [0, 0.1], v: 0, t: 0}}
horizon: 5
"""


def test_a_return_after_a_dwell_is_still_taken(tmp_path):
    """The exit back to P is skipped only while its face rises (v > 0 in M); once v may be 0 it
    is taken as any exit. Skipping it for good would leave P with v >= 0 only: a false SAFE."""
    model, props = load_files(tmp_path, BACK, """
        properties:
          - {id: vP, kind: safety, modes: [P], require: ["v >= -1"]}
    """)
    result = BACKEND.check(model, props["vP"], RIGOROUS)
    assert result.status is Status.UNSAFE
    assert result.counterexample is not None
    assert result.details["margin_bound"][0] <= 1 - np.sqrt(2 * 0.9) + 1e-9


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3),
       st.lists(st.floats(0.05, 2), min_size=3, max_size=3),
       st.lists(st.one_of(st.just(0.0), st.floats(0.1, 2), st.floats(-2, -0.1)), min_size=3,
                max_size=3).filter(any),
       st.integers(0, 2**31 - 1))
def test_the_face_contraction_keeps_every_state_of_the_box_on_the_face(center, radius, a, seed):
    """Every point of box cap {a . x + b = 0} (sampled: a random point of the box with one
    coordinate solved from the face) lies in the contracted box, and the tied coordinate is the
    face's function of the others."""
    center, radius, a = np.array(center), np.array(radius), np.array(a)
    box = np.stack([center - radius, center + radius], axis=1)
    rng = np.random.default_rng(seed)
    b = -float(a @ rng.uniform(box[:, 0], box[:, 1]))          # a face through the box
    cut, j = _on_face(box, a, b)
    assert np.all(cut[:, 0] >= box[:, 0] - 1e-9) and np.all(cut[:, 1] <= box[:, 1] + 1e-9)
    points = rng.uniform(box[:, 0], box[:, 1], size=(2000, 3))
    for i in np.flatnonzero(a):
        others = np.delete(np.arange(3), i)
        x = points.copy()
        x[:, i] = -(b + x[:, others] @ a[others]) / a[i]
        on = x[(x[:, i] >= box[i, 0]) & (x[:, i] <= box[i, 1])]
        assert np.all(on >= cut[:, 0] - 1e-12) and np.all(on <= cut[:, 1] + 1e-12)
    alg = algebra(2, 4)
    start = [DA.var(alg, k, float(np.mean(cut[k])), float(np.diff(cut[k])[0] / 2)) for k in range(3)]
    poly, error = _tied(start, cut, j, a, b)
    xi = rng.uniform(-1, 1, size=4)
    values = [s.compose([DA.const(alg, v) for v in xi]).cons for s in start]
    tied = poly.compose([DA.const(alg, v) for v in xi]).cons
    others = [k for k in range(3) if k != j]
    exact = -(b + sum(a[k] * values[k] for k in others)) / a[j]
    assert abs(tied - exact) <= error + 1e-12 * (1 + abs(exact))


def test_the_time_slices_of_a_step_hold_every_state_entering_the_guard():
    """A step x(xi, sigma) = 1 + 0.3 xi + sigma + 0.4 sigma^2 (+-1e-3), y = 2 xi - sigma: the states
    with x >= 1.9 (the guard) at sampled (xi, sigma) lie in the sliced hull, which is narrower in y
    than the step's box."""
    alg = algebra(3, 2)
    xi, sigma = DA.var(alg, 0), DA.var(alg, 1)
    X = [TM(1.0 + 0.3 * xi + sigma + 0.4 * sigma * sigma, -1e-3, 1e-3), TM(2.0 * xi - sigma, 0.0, 0.0)]
    code = SimpleNamespace(may_enter=lambda ex, part: all(face(part).bound()[0] <= 0 for face in ex.faces))
    exit_ = SimpleNamespace(faces=[lambda part: 1.9 - part[0]])
    box = _entry_slices(code, exit_, X)
    rng = np.random.default_rng(3)
    s, u = rng.uniform(-1, 1, 20000), rng.uniform(-1, 1, 20000)
    x = 1.0 + 0.3 * u + s + 0.4 * s * s + rng.uniform(-1e-3, 1e-3, s.size)
    y = 2.0 * u - s
    inside = x >= 1.9
    assert inside.any()
    assert np.all(x[inside] >= box[0, 0]) and np.all(x[inside] <= box[0, 1])
    assert np.all(y[inside] >= box[1, 0]) and np.all(y[inside] <= box[1, 1])
    whole = np.array([part.bound() for part in X])
    assert box[0, 0] > whole[0, 0] + 0.5          # the slices that cannot meet the guard are gone
    assert _entry_slices(code, SimpleNamespace(faces=[lambda part: 5.0 - part[0]]), X) is None


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 6), st.integers(1, 4), st.floats(-1, 1), st.floats(0.01, 1), st.integers(0, 2**31 - 1))
def test_a_slice_of_the_step_time_is_the_composition_with_its_affine_map(order, nvars, centre, radius, seed):
    """``sigma_in(p, c, r)`` is ``p(xi, c + r sigma)`` (DA composition)."""
    from reach.backends.taylor.verified import sigma_in

    alg = algebra(order, nvars)
    p = DA(alg, np.random.default_rng(seed).normal(size=alg.size))
    args = [DA.var(alg, j) for j in range(nvars - 1)] + [DA.var(alg, nvars - 1, centre, radius)]
    assert np.allclose(sigma_in(p, centre, radius).c, p.compose(args).c, rtol=1e-12, atol=1e-12)
