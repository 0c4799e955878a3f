"""Urgent guards a run meets between two grid points (reach.model.crossing): a slab of two
opposite rows crossed (an equality ``h x == c``, linear or not), a row dipped into by an
oscillation, a grid point that lies in the guard; the simulator takes the jump there, and star
keeps the side a run enters a slab on (reach.backends.star.explorer._urgent_keeps).

References: solve_ivp with the plane as a terminal event (the crossing instant), closed forms,
and the automaton's semantics (a run that reaches an urgent guard leaves at once, so it is never
on the far side of the plane in the source mode)."""

import textwrap

import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.checking import check_files
from reach.model import load_model
from reach.model.simulate import Simulator
from reach.result import Status

LINEAR = """
name: plane
state: [x, y, t]
modes:
  a: {{flow: {{x: "{a11}*x + {a12}*y + {b1}", y: "{a21}*x + {a22}*y + {b2}", t: 1}}}}
  b: {{flow: {{x: 0, y: 0, t: 0}}}}
transitions:
  - {{from: a, to: b, guard: ["{h1}*x + {h2}*y >= {c}", "{h1}*x + {h2}*y <= {c}"{extra}], urgent: true}}
initial: {{mode: a, box: {{x: 0, y: 0, t: 0}}}}
horizon: {horizon}
"""

coefficient = st.floats(-1.0, 1.0).map(lambda v: round(v, 2))


def _model(folder, text: str):
    (folder / "m.yaml").write_text(textwrap.dedent(text))
    return load_model(folder / "m.yaml")


def _crossing(A, b, h, c, x0, horizon):
    """The first instant ``h . x = c`` on the flow ``x' = A x + b`` from ``x0`` (solve_ivp's
    terminal event), or None."""
    event = lambda t, z: h @ z - c
    event.terminal = True
    run = solve_ivp(lambda t, z: A @ z + b, (0.0, horizon), x0, events=event, rtol=1e-12, atol=1e-13)
    return float(run.t_events[0][0]) if run.t_events[0].size else None


@given(a=st.lists(coefficient, min_size=4, max_size=4), b=st.lists(st.floats(0.5, 2.0), min_size=2, max_size=2),
       h=st.lists(coefficient, min_size=2, max_size=2), level=st.floats(0.05, 0.9),
       dt=st.sampled_from([0.0137, 0.05, 0.1, 0.23]))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_the_run_jumps_where_it_crosses_the_plane(tmp_path_factory, a, b, h, level, dt):
    """``x`` from 0 under a random affine flow; the urgent guard ``h . x == c`` with ``c`` a
    fraction of what ``h . x`` first reaches: the simulator's run freezes (mode ``b``) at the
    instant solve_ivp finds the crossing, whatever the grid step, never later."""
    A, b, h = np.array(a).reshape(2, 2), np.array(b), np.array(h)
    if np.abs(h).sum() < 0.1:
        return
    ts = np.linspace(0.0, 2.0, 401)
    run = solve_ivp(lambda t, z: A @ z + b, (0.0, 2.0), [0.0, 0.0], t_eval=ts, rtol=1e-12, atol=1e-13)
    reach_h = h @ run.y
    if np.max(np.abs(reach_h)) < 0.05:
        return
    c = level * reach_h[np.argmax(np.abs(reach_h))]
    expected = _crossing(A, b, h, c, np.zeros(2), 2.0)
    folder = tmp_path_factory.mktemp("plane")
    model = _model(folder, LINEAR.format(a11=a[0], a12=a[1], a21=a[2], a22=a[3], b1=b[0], b2=b[1], h1=h[0],
                                                h2=h[1], c=c, extra="", horizon=2.0))
    traj = Simulator(model, dt=dt).run(np.zeros((1, 3)))
    assert list(model.modes)[traj.final_mode[0]] == "b"
    assert traj.final_state[0, 2] == pytest.approx(expected, abs=1e-9)


def test_a_crossing_where_another_row_fails_is_no_jump(tmp_path):
    """``x == 1 and y >= 1`` with ``x = t``, ``y = t / 2``: ``y`` is 0.5 where ``x`` crosses 1, so
    the guard never holds and the run stays in ``a`` to the horizon; with ``y >= 0.4`` it jumps
    at t = 1."""
    text = LINEAR.format(a11=0, a12=0, a21=0, a22=0, b1=1, b2=0.5, h1=1, h2=0, c=1, extra=', "y >= {low}"',
                         horizon=1.7)
    for low, mode, t in ((1.0, "a", 1.7), (0.4, "b", 1.0)):
        model = _model(tmp_path, text.replace("{low}", str(low)))
        traj = Simulator(model, dt=0.3).run(np.zeros((1, 3)))
        assert list(model.modes)[traj.final_mode[0]] == mode
        assert traj.final_state[0, 2] == pytest.approx(t, abs=1e-9)


def test_a_crossing_after_the_last_grid_point_is_taken(tmp_path):
    """``x' = 1``, plane ``x == 0.995``, grid step 0.01 and horizon 0.997: the last grid point
    (0.99) is before the plane and the horizon after it; the run jumps at 0.995."""
    model = _model(tmp_path, LINEAR.format(a11=0, a12=0, a21=0, a22=0, b1=1, b2=0, h1=1, h2=0, c=0.995,
                                                  extra="", horizon=0.997))
    traj = Simulator(model, dt=0.01).run(np.zeros((1, 3)))
    assert list(model.modes)[traj.final_mode[0]] == "b"
    assert traj.final_state[0, 2] == pytest.approx(0.995, abs=1e-9)


def test_a_nonlinear_flow_jumps_at_the_crossing(tmp_path):
    """``x' = 1 + x^2`` from 0 crosses ``x == 0.7`` at ``atan(0.7)`` (closed form)."""
    model = _model(tmp_path, """
        name: tangent
        state: [x, t]
        modes:
          a: {flow: {x: "1 + x**2", t: 1}}
          b: {flow: {x: 0, t: 0}}
        transitions:
          - {from: a, to: b, guard: ["x >= 0.7", "x <= 0.7"], urgent: true}
        initial: {mode: a, box: {x: 0, t: 0}}
        horizon: 1
        """)
    traj = Simulator(model, dt=0.07).run(np.zeros((1, 2)))
    assert list(model.modes)[traj.final_mode[0]] == "b"
    assert traj.final_state[0, 1] == pytest.approx(np.arctan(0.7), abs=1e-7)


EQUALITY = """
name: gate
state: [x, y]
modes:
  a: {flow: {x: 1, y: 0}}
  b: {flow: {x: 1, y: 0}}
transitions:
  - {from: a, to: b, guard: GUARD, urgent: true}
initial: {mode: a, box: {x: [0, 0.2], y: 1000000}}
horizon: 3
"""
PROPS = """properties:
  - {id: in_a, kind: safety, modes: [a], require: ["x <= 1.001"]}
  - {id: in_b, kind: safety, modes: [b], require: ["x <= 2.5"]}
"""


@pytest.mark.parametrize("guard", ['["x >= 1", "x <= 1"]', '["x == 1"]', '["2*x - 2 == 0"]'])
def test_an_equality_ends_the_flow_of_its_mode(tmp_path, guard):
    """``x' = 1`` from [0, 0.2] and the urgent ``x == 1`` (two rows, or written as an equality:
    the same two opposite rows): in ``a``, x never exceeds 1 (star: SAFE; Monte Carlo: no
    violation); in ``b`` it reaches 1 + (3 - t_1) = 3.2 > 2.5 (both: UNSAFE, a counterexample
    that jumped at x = 1 and carries that path)."""
    (tmp_path / "m.yaml").write_text(EQUALITY.replace("GUARD", guard))
    (guard_rows,) = [tr.guard for tr in load_model(tmp_path / "m.yaml").transitions]
    assert len(guard_rows) == 2 and sympy.expand(guard_rows[0].g + guard_rows[1].g) == 0
    (tmp_path / "p.yaml").write_text(PROPS)
    in_a, in_b = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "star")
    assert in_a.status is Status.SAFE and in_b.status is Status.UNSAFE
    in_a, in_b = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo")
    assert in_a.status is Status.UNKNOWN and in_b.status is Status.UNSAFE
    for result in check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "star")[1], in_b:
        cex = result.counterexample
        modes, x = np.array(cex.trajectory["mode"]), np.array(cex.trajectory["x"])[:, 0]
        assert len(cex.transitions) == 1 and cex.violation_state[0] > 2.5
        assert np.all(x[modes == "a"] <= 1.0 + 1e-9) and np.any(modes == "b")


@pytest.mark.parametrize("guard", [
    '["x >= 1.000000000001", "x <= 1"]',              # an empty slab: never holds
    '["x + 0.00000001*y <= 1", "x >= 1"]',             # a wedge that is empty where the run is
])
def test_a_guard_that_never_holds_on_the_way_does_not_cut_the_flow(tmp_path, guard):
    """Two nearly opposite rows that bound no slab where the run passes: x' = 1 runs on past
    1.001 in mode a (star and Monte Carlo: UNSAFE, never SAFE)."""
    (tmp_path / "m.yaml").write_text(EQUALITY.replace("GUARD", guard))
    (tmp_path / "p.yaml").write_text(PROPS)
    for backend in ("star", "montecarlo"):
        in_a, _ = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", backend)
        assert in_a.status is Status.UNSAFE, backend


@given(amplitude=st.floats(1.0, 1.5), level=st.floats(0.9, 0.999999), omega=st.floats(1.0, 12.0),
       dt=st.sampled_from([0.05, 0.1, 0.3]))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_peak_that_grazes_the_guard_between_grid_points_jumps(tmp_path_factory, amplitude, level, omega, dt):
    """``x = A sin(w t)`` and the urgent one-row guard ``x >= c A`` (``c`` up to 1 - 1e-6): the run
    jumps at ``asin(c) / w`` (closed form), however short its stay above the level and however
    coarse the grid (the first peak lies between grid points for most ``w``)."""
    c = level * amplitude
    model = _model(tmp_path_factory.mktemp("peak"), f"""
        name: peak
        state: [x, y, t]
        modes:
          a: {{flow: {{x: "{omega}*y", y: "-{omega}*x", t: 1}}}}
          b: {{flow: {{x: 0, y: 0, t: 0}}}}
        transitions:
          - {{from: a, to: b, guard: ["x >= {c!r}"], urgent: true}}
        initial: {{mode: a, box: {{x: 0, y: {amplitude!r}, t: 0}}}}
        horizon: 3
        """)
    traj = Simulator(model, dt=dt).run(np.array([[0.0, amplitude, 0.0]]))
    assert list(model.modes)[traj.final_mode[0]] == "b"
    assert traj.final_state[0, 2] == pytest.approx(np.arcsin(level) / omega, abs=1e-9)


def test_a_dip_that_stays_above_the_guard_is_no_jump(tmp_path):
    """The same oscillation with the guard 1e-6 above its peak: no jump, however the grid falls
    (the tangents meet below the level near a peak, the located minimum does not reach it)."""
    for dt in (0.05, 0.1, 0.3):
        model = _model(tmp_path, """
            name: peak
            state: [x, y, t]
            modes:
              a: {flow: {x: "3*y", y: "-3*x", t: 1}}
              b: {flow: {x: 0, y: 0, t: 0}}
            transitions:
              - {from: a, to: b, guard: ["x >= 1.000001"], urgent: true}
            initial: {mode: a, box: {x: 0, y: 1, t: 0}}
            horizon: 3
            """)
        traj = Simulator(model, dt=dt).run(np.array([[0.0, 1.0, 0.0]]))
        assert list(model.modes)[traj.final_mode[0]] == "a" and traj.final_state[0, 2] == pytest.approx(3.0)


def test_a_clock_equality_on_a_grid_point_is_taken_in_every_run(tmp_path):
    """``t == 2`` with ``t`` on the grid at 2 and segments cut at random piece starts (switch
    decisions for the may-transition of a timeless mode): no run stays in ``b`` past 2 (some
    did: the block product's rounding put t = 2 just outside ``t <= 2`` or ``t >= 2``)."""
    model = _model(tmp_path, """
        name: timer
        state: [x, t]
        modes:
          b: {flow: {x: 0.5, t: 1}}
          c: {flow: false}
          d: {flow: {x: 0, t: 1}}
        transitions:
          - {from: b, to: c, guard: ["t >= 2", "t <= 2"], urgent: true}
          - {from: c, to: d}
        initial: {mode: b, box: {x: [0, 0.5], t: 0}}
        horizon: 4
        """)
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(0, 0.5, 2000), np.zeros(2000)])
    switch = rng.uniform(size=(2000, 21)) < 0.5
    traj = Simulator(model).run(X, signal=(0.2, np.zeros((2000, 21, 0)), switch))
    assert np.all(np.array(list(model.modes))[traj.final_mode] == "d")
    np.testing.assert_allclose(traj.final_state[:, 0], X[:, 0] + 1.0, rtol=0, atol=1e-9)


def test_a_nonlinear_equality_is_met_where_the_run_crosses_it(tmp_path):
    """``x^2 == 1`` (written as two rows whose sum is a number) on ``x' = 1`` from [0, 0.5]: every
    run jumps at ``x = 1`` (Monte Carlo: x <= 1.01 in ``a`` never violated, x <= 0.5 in ``b``
    violated at the jump); taylor, which detects crossings into a guard's interior, refuses it."""
    (tmp_path / "m.yaml").write_text(textwrap.dedent("""
        name: square
        state: [x]
        modes:
          a: {flow: {x: 1}}
          b: {flow: {x: 0}}
        transitions:
          - {from: a, to: b, guard: ["x^2 >= 1", "x^2 <= 1"], urgent: true}
        initial: {mode: a, box: {x: [0, 0.5]}}
        horizon: 3
        """))
    (tmp_path / "p.yaml").write_text("properties:\n"
                                     "  - {id: in_a, kind: safety, modes: [a], require: [\"x <= 1.01\"]}\n"
                                     "  - {id: in_b, kind: safety, modes: [b], require: [\"x <= 0.5\"]}\n")
    in_a, in_b = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "montecarlo")
    assert in_a.status is Status.UNKNOWN and in_b.status is Status.UNSAFE
    assert in_b.counterexample.violation_state[0] == pytest.approx(1.0, abs=1e-9)
    in_a, in_b = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "taylor")
    assert in_a.status is Status.UNSUPPORTED and "equality" in in_a.details["reason"]


def test_a_dip_that_misses_does_not_hide_a_later_crossing(tmp_path):
    """A slowly growing spiral ``x = R e^(a t) cos(120 t + phi)`` (closed form): its first low
    point (-1.005) misses the urgent ``x == -1.01`` (a dip candidate that fails), its second
    crosses it within the same block of grid steps; the run jumps there, at the closed form's
    crossing instant."""
    a, w = 0.19003732088177977, 120.0
    x0, y0 = -0.9934789077058183, -0.1501496513524357
    model = _model(tmp_path, f"""
        name: spiral
        state: [x, y, t]
        modes:
          A: {{flow: {{x: "{a!r}*x + {w}*y", y: "-{w}*x + {a!r}*y", t: 1}}}}
          B: {{flow: {{x: 0, y: 0, t: 0}}}}
        transitions:
          - {{from: A, to: B, guard: ["x <= -1.01", "x >= -1.01"], urgent: true}}
        initial: {{mode: A, box: {{x: {x0!r}, y: {y0!r}, t: 0}}}}
        horizon: 0.1
        """)
    expected = _crossing(np.array([[a, w], [-w, a]]), np.zeros(2), np.array([1.0, 0.0]), -1.01,
                         np.array([x0, y0]), 0.1)
    traj = Simulator(model, dt=0.1 / 24).run(np.array([[x0, y0, 0.0]]))
    assert list(model.modes)[traj.final_mode[0]] == "B"
    assert traj.final_state[0, 2] == pytest.approx(expected, abs=1e-9)


def test_a_dip_into_a_scaled_equality_jumps(tmp_path):
    """``x = cos(120 t)`` and the urgent ``100000 x == -99900`` (rows scaled by 1e5): the run
    dips through x = -0.999 between grid points and jumps at ``acos(-0.999) / 120``."""
    model = _model(tmp_path, """
        name: scaled
        state: [x, y, t]
        modes:
          A: {flow: {x: "120*y", y: "-120*x", t: 1}}
          B: {flow: {x: 0, y: 0, t: 0}}
        transitions:
          - {from: A, to: B, guard: ["100000*x <= -99900", "100000*x >= -99900"], urgent: true}
        initial: {mode: A, box: {x: 1, y: 0, t: 0}}
        horizon: 0.1
        """)
    traj = Simulator(model, dt=0.1 / 24).run(np.array([[1.0, 0.0, 0.0]]))
    assert list(model.modes)[traj.final_mode[0]] == "B"
    assert traj.final_state[0, 2] == pytest.approx(np.arccos(-0.999) / 120, abs=1e-9)
