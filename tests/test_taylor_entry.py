"""taylor's rigorous sweep through an urgent switch with the entry kept as a Taylor model: an
enclosure started from a polynomial plus an error box contains the runs from every point of that
set, a clock keeps its start error, and a switch into a stiff mode is bounded against the closed
form (samples and corners)."""

import textwrap

import numpy as np
import pytest
import sympy
from scipy.integrate import solve_ivp

from reach.backends.taylor import BACKEND
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.flow import compile_expressions, compile_numeric
from reach.backends.taylor.verified import enclose_stretch
from reach.model.loader import load_model
from reach.result import Status
from reach.spec.properties import bind, load_properties

# coast at v0 in [1, 2] from x0 in [0, 0.5] until x = 1, then brake hard (v' = -20 v):
# x = 1 + v0 (1 - exp(-20 s)) / 20, v = v0 exp(-20 s), s the time since the switch, so
# q = x + 0.04 v = 1 + 0.05 v0 - 0.01 v0 exp(-20 s) rises from 1 + 0.04 v0 to 1 + 0.05 v0.
STIFF_DOCK = """
name: stiff_dock
state: [x, v, t]
modes:
  coast:
    flow: {x: v, v: 0, t: 1}
    invariant: ["x <= 1"]
  brake:
    flow: {x: v, v: -20*v, t: 1}
transitions:
  dock: {from: coast, to: brake, urgent: true, guard: ["x >= 1"]}
initial: {mode: coast, box: {x: [0, 0.5], v: [1, 2], t: 0}}
horizon: 2
"""


def _closed_form_max(x0, v0, T=2.0):
    s = T - (1.0 - x0) / v0                       # time spent braking before the horizon
    return 1.0 + 0.05 * v0 - 0.01 * v0 * np.exp(-20.0 * s)


def test_enclosure_from_a_taylor_model_start_contains_the_runs_of_the_whole_set():
    """Damped oscillator with a clock from ``x0(xi) + [-e0, e0]``: solve_ivp runs from sampled
    points and from the corners of the error box lie in the enclosure at every step end, and the
    clock (a rate independent of the state) keeps exactly its start error."""
    x, v, t = sympy.symbols("x v t")
    flow = [v, -4 * x - 3 * v, sympy.Integer(1)]
    f, fn = compile_expressions(flow, [x, v, t]), compile_numeric(flow, [x, v, t])
    alg = algebra(4, 2)
    xi0 = DA.var(alg, 0)
    x0 = [1.0 + 0.2 * xi0 + 0.05 * xi0 * xi0, 0.1 * xi0, DA.const(alg, 0.0)]
    e0 = np.array([0.01, 0.02, 0.003])
    T = 3.0
    enc = enclose_stretch(f, x0, np.array([0.0, 0.05, T]), rel_tol=1e-4, e0=e0)
    assert enc is not None and enc.steps[-1].t0 + enc.steps[-1].h == pytest.approx(T)
    # the clock keeps its start error (plus the rounding allowance); the others grow past it
    assert np.all(enc.error_box[:, 2] <= e0[2] + 1e-9) and np.all(enc.error_box[:, 0] > e0[2])
    ends = np.array([s.t0 + s.h for s in enc.steps])
    rhs = lambda _, y: np.array(fn(list(y)), dtype=float)
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    for point in np.r_[np.linspace(-1, 1, 5), 0.37]:
        base = np.array([float(p(np.array([[point, -1.0]]))[0]) for p in x0])
        for corner in corners:
            ref = solve_ivp(rhs, (0, T), base + e0 * corner, method="DOP853", rtol=1e-12, atol=1e-12,
                            t_eval=ends).y.T
            for k in range(len(enc.steps)):
                for i, tm in enumerate(enc.tm_at_end(k)):
                    value = float(tm.poly(np.array([[point, 1.0]]))[0])
                    assert tm.lo - 1e-9 <= ref[k, i] - value <= tm.hi + 1e-9


def test_switch_into_a_stiff_mode_is_bounded_against_the_closed_form(tmp_path):
    """The largest q over the braking stretch: the rigorous bound holds the closed form at
    samples and corners (its supremum 1.1 at v0 = 2) and, with the entry a Taylor model of the
    coasting step, proves a requirement a little above it."""
    path = tmp_path / "dock.yaml"
    path.write_text(textwrap.dedent(STIFF_DOCK))
    props = tmp_path / "p.yaml"
    props.write_text("properties:\n  - {id: q, kind: event, modes: [brake], maximize: \"x + 0.04*v\", "
                     "require: \"<= 4\"}\n")
    model = load_model(str(path))
    prop = bind(load_properties(str(props))[0], model)
    result = BACKEND.check(model, prop, {"remainder": "rigorous", "max_splits": 0})
    assert result.status is Status.SAFE
    lo, hi = result.bound
    rng = np.random.default_rng(3)
    starts = np.r_[rng.uniform([0, 1], [0.5, 2], (200, 2)), [[0, 1], [0, 2], [0.5, 1], [0.5, 2]]]
    values = _closed_form_max(starts[:, 0], starts[:, 1])
    assert lo <= values.min() and values.max() <= hi
    # the same against an independent integration of the hybrid run from a corner
    x0, v0 = 0.5, 2.0
    coast = (1.0 - x0) / v0
    brake = solve_ivp(lambda _, y: [y[1], -20 * y[1]], (0, 2.0 - coast), [1.0, v0], method="DOP853",
                      rtol=1e-12, atol=1e-12, dense_output=True)
    s = np.linspace(0, 2.0 - coast, 2001)
    xs, vs = brake.sol(s)
    assert np.max(xs + 0.04 * vs) == pytest.approx(_closed_form_max(x0, v0), abs=1e-9)
    assert np.max(xs + 0.04 * vs) <= hi
