"""Replays of runs driven by piecewise-constant input signals (``Simulator.run(signal=...)``
through :func:`reach.backends.montecarlo.replay`): against scipy's solve_ivp piece by piece,
against the path that stops at every piece start, and the bisections of the linear modes
against a plain bisection on scipy's expm."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
import scipy.linalg
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.backends.montecarlo import replay
from reach.model import load_model
from reach.model.simulate import BISECTION_STEPS, Simulator
from reach.spec import bind, load_properties
from model_files import load_files

# x'' = -x + c + u/2 with c = +1 in ``out`` and -1 in ``home``: a limit cycle switching at
# p = +-0.6, wherever the switching level is met (inside a piece, generically)
SWING = """
name: swing
state: [p, q]
bounded_inputs:
  u: {range: [-1, 1], varying: true}
modes:
  out: {flow: {p: q, q: "-p + 1 + 0.5*u"}}
  home: {flow: {p: q, q: "-p - 1 + 0.5*u"}}
transitions:
  - {from: out, to: home, guard: ["p >= 0.6"], urgent: true}
  - {from: home, to: out, guard: ["p <= -0.6"], urgent: true}
EXTRA
initial: {mode: out, box: {p: 0, q: 0}}
horizon: 8
"""

PROPS = """
properties:
  - {id: loose, kind: safety, require: ["p <= 5"]}
  - {id: tight, kind: safety, require: ["q <= 0.9"]}
"""

STEP = 0.5


def _model(folder, text):
    path = folder / "m.yaml"
    path.write_text(textwrap.dedent(text))
    return load_model(path)


def _load(tmp_path, extra=""):
    model = _model(tmp_path, SWING.replace("EXTRA", extra))
    (tmp_path / "p.yaml").write_text(textwrap.dedent(PROPS))
    props = {p.id: bind(p, model) for p in load_properties(tmp_path / "p.yaml")}
    return model, props


def _signal(values, step=STEP, switch=None):
    out = {"step": step, "inputs": ["u"], "values": [[float(v)] for v in values]}
    if switch is not None:
        out["switch"] = [int(s) for s in switch]
    return out


def _reference(values, horizon=8.0, step=STEP):
    """``(switch instants, final (p, q))`` by solve_ivp, piece by piece (the input constant on
    each), each mode's integration ended at its guard's crossing (a terminal event)."""
    level = {"out": (0.6, 1.0, "home"), "home": (-0.6, -1.0, "out")}
    mode, y, switches = "out", np.zeros(2), []
    for k, u in enumerate(values):
        a, b = k * step, (horizon if k == len(values) - 1 else min((k + 1) * step, horizon))
        while a < b:
            p_switch, c, target = level[mode]

            def crossing(s, z, p_switch=p_switch):
                return z[0] - p_switch

            crossing.terminal, crossing.direction = True, np.sign(p_switch)
            sol = solve_ivp(lambda s, z, c=c, u=u: [z[1], -z[0] + c + 0.5 * u], (a, b), y, events=crossing,
                            method="DOP853", rtol=1e-12, atol=1e-14)
            if sol.status == 1:
                a, y, mode = sol.t_events[0][0], sol.y_events[0][0], target
                switches.append(a)
            else:
                a, y = b, sol.y[:, -1]
    return np.array(switches), y


def _switches(run):
    """The instants at which a replayed run changes mode."""
    modes, t = run.trajectory["mode"], np.array(run.trajectory["t"])
    return np.array([t[i] for i in range(1, len(modes)) if modes[i] != modes[i - 1]])


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.floats(-1.0, 1.0), min_size=16, max_size=16))
def test_signal_replay_equals_solve_ivp_piece_by_piece(tmp_path, values):
    model, props = _load(tmp_path)
    want_switches, want_final = _reference(values)
    # the switching level is crossed inside pieces, not at their starts
    assume(want_switches.size and np.all(np.abs(want_switches / STEP - np.round(want_switches / STEP)) > 1e-3))
    run = replay(model, props["loose"], [0.0, 0.0, values[0]], None, STEP / 5, _signal(values))
    assert not run.violated
    got = _switches(run)
    assert got.shape == want_switches.shape
    np.testing.assert_allclose(got, want_switches, atol=1e-8)
    assert run.trajectory["t"][-1] == pytest.approx(8.0)
    np.testing.assert_allclose(run.trajectory["x"][-1][:2], want_final, atol=1e-8)


def _every_piece_stops(self, step, values, switch):
    """The signal path as it was: every piece start ends a segment."""
    return lambda k, rows: k + 1


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from([-1.0, 0.25, 1.0]), min_size=12, max_size=12).flatmap(
    lambda v: st.tuples(st.just(v), st.lists(st.sampled_from([0, 0, 0, 1]), min_size=12, max_size=12))))
def test_merged_pieces_equal_the_path_stopping_at_every_piece(tmp_path, drawn):
    """Runs of equal pieces (and switching decisions, for a may-transition out -> home where
    q <= 0; the last piece, to the horizon, asks at every piece start if its decision is 1)
    replay as on the path that stops at every piece start: same mode sequence, states,
    violation and violation time."""
    values, switch = drawn
    values = [v for v in values for _ in range(3)]               # runs of equal pieces
    switch = [s for s in switch for _ in range(3)]
    model, props = _load(tmp_path, '  - {from: out, to: home, guard: ["q <= 0"]}')
    args = ([0.0, 0.0, values[0]], None, STEP / 12, _signal(values, STEP / 3, switch))
    fast = {name: replay(model, prop, *args) for name, prop in props.items()}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Simulator, "_signal_stops", _every_piece_stops)
        slow = {name: replay(model, prop, *args) for name, prop in props.items()}
    for name in props:
        a, b = fast[name], slow[name]
        assert a.violated == b.violated
        if a.violated:
            assert a.time == pytest.approx(b.time, rel=1e-9, abs=1e-12)
            np.testing.assert_allclose(a.state, b.state, rtol=1e-9, atol=1e-12)
        assert a.trajectory["mode"] == b.trajectory["mode"]
        np.testing.assert_allclose(a.trajectory["t"], b.trajectory["t"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.trajectory["x"], b.trajectory["x"], rtol=1e-9, atol=1e-12)


def _plain_bisection(M, x, h, before):
    """Bisection of ``[0, h]``, the state at each midpoint from ``x`` by scipy's expm."""
    lo, hi = 0.0, h
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        z = scipy.linalg.expm(M * mid) @ np.append(x, 1.0)
        lo, hi = (lo, mid) if before(z[:-1]) else (mid, hi)
    return lo, hi


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.floats(-0.5, 0.5), st.floats(0.5, 2.0), st.floats(-1.0, 1.0))
def test_linear_bisections_equal_a_plain_bisection(tmp_path, p0, q0, u):
    """The first entry into ``p >= 0.6`` and the last instant inside ``p <= 0.6`` from ``(p0,
    q0)`` in ``out`` over ``(0, h]``, ``h`` the step by which ``p`` has crossed: equal to a plain
    bisection on expm, to its resolution ``h 2^-40``."""
    model = _model(tmp_path, SWING.replace("EXTRA", "").replace(
        "  out: {flow: {p: q, q: \"-p + 1 + 0.5*u\"}}",
        "  out: {flow: {p: q, q: \"-p + 1 + 0.5*u\"}, invariant: [\"p <= 0.6\"]}"))
    sim = Simulator(model, dt=0.05)
    M = sim.generators["out"]
    x = np.array([p0, q0, u])
    hs = np.linspace(0.01, 3.0, 300)
    crossed = [h for h in hs if (scipy.linalg.expm(M * h) @ np.append(x, 1.0))[0] >= 0.6 + 1e-6]
    assume(crossed)
    h = crossed[0]
    (tr, guard), = sim.urgent["out"]
    entry = sim._first_entry("out", x[None, :], np.array([h]), guard)[0]
    want = _plain_bisection(M, x, h, lambda z: z[0] >= 0.6)[1]
    assert entry == pytest.approx(want, abs=2 * h * 2.0 ** -BISECTION_STEPS)
    inside, state = sim._last_inside("out", x[None, :], np.array([h]))
    want = _plain_bisection(M, x, h, lambda z: z[0] > 0.6)[0]
    assert inside[0] == pytest.approx(want, abs=2 * h * 2.0 ** -BISECTION_STEPS)
    assert state[0, 0] <= 0.6                                   # the state the bisection found inside


INTEGRATOR = """
name: integrator
state: [x]
bounded_inputs:
  u: {range: [-1, 1], varying: true}
modes:
  run: {flow: {x: u}}
initial: {mode: run, box: {x: 0}}
horizon: 1
"""


@pytest.mark.parametrize("dt", [None, 0.1, 0.03, 0.07, 0.0333])
def test_a_signal_replays_the_same_at_any_step(tmp_path, dt):
    """x' = u with pieces of 0.1: x is the running sum of the pieces' values times 0.1, largest
    0.2 (first at t = 0.4; x = 0.19 at t = 0.39). A replay at a step the pieces are no multiple
    of refines its grid to them: violated past 0.19, never past 0.21, at whatever ``dt``."""
    model, props = load_files(tmp_path, INTEGRATOR, "properties:\n  - {id: lo, kind: safety, require: ['x <= 0.19']}\n"
                                                    "  - {id: hi, kind: safety, require: ['x <= 0.21']}\n")
    lo, hi = props["lo"], props["hi"]
    signal = {"step": 0.1, "inputs": ["u"], "values": [[v] for v in [1, -1, 1, 1, -1, 1, -1, -1, 1, 1, -1]]}
    hit = replay(model, lo, [0.0, 0.0], None, dt, signal)
    assert hit.violated and 0.39 - 1e-9 <= hit.time <= 0.4 + 1e-9
    assert not replay(model, hi, [0.0, 0.0], None, dt, signal).violated


def test_the_simulator_refuses_pieces_off_its_grid(tmp_path):
    (tmp_path / "m.yaml").write_text(INTEGRATOR)
    sim = Simulator(load_model(tmp_path / "m.yaml"), 0.03)
    with pytest.raises(ValueError, match="not a multiple"):
        sim.run(np.zeros((1, 2)), None, signal=(0.1, np.ones((1, 11, 1)), None))


@pytest.mark.parametrize("dt, step, field", [(1e9, 0.1, "dt"), (1e-12, 0.1, "dt"), (None, 1e-300, "input_signal"),
                                             (0.1, 0.1, None)])
def test_a_step_that_does_not_fit_the_horizon_is_refused_naming_its_field(tmp_path, dt, step, field):
    """A hand-edited counterexample's ``dt`` or signal step beyond the horizon, or cutting it into
    more grid steps than the simulator takes, is bad input naming the field (a step of 1e9 was an
    internal ZeroDivisionError, 1e-15 blamed ``options.dt``)."""
    from reach.backends.montecarlo import check_run
    from reach.errors import InputError

    (tmp_path / "m.yaml").write_text(INTEGRATOR)
    model = load_model(tmp_path / "m.yaml")
    signal = {"step": step, "inputs": ["u"], "values": [[1.0]]}
    if field is None:
        check_run(model, [0.0, 0.0], None, signal, None, dt)
        return
    with pytest.raises(InputError) as caught:
        check_run(model, [0.0, 0.0], None, signal, None, dt)
    assert caught.value.field == field
