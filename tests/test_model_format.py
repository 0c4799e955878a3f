"""Model format: polytopic initial sets, bounded inputs, models without a global clock, and
their sampling by Monte Carlo (vertices and faces first, hit-and-run, input signals, replay)."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reach import lp
from reach.backends.montecarlo.initial_sampling import PolytopeSampler
from reach.checking import check_files
from reach.cli import main
from reach.errors import InputError
from reach.model import load_model
from reach.model.automaton import LinearSet
from reach.model.simulate import Simulator


def model_file(tmp_path, text: str, name="m.yaml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


TRIANGLE = """
name: tri
state: [x, y]
modes:
  still: {flow: {x: 0, y: 0}}
initial: {mode: still, constraints: ["x >= 0", "y >= 0", "x + y <= 1"]}
horizon: 1
"""

INPUT = """
name: drive
state: [x]
bounded_inputs:
  u: {range: [-1, 1], varying: VARYING}
modes:
  go: {flow: {x: u}}
initial: {mode: go, box: {x: 0}}
horizon: 2
"""


def test_polytopic_initial_set_and_its_bounding_box(tmp_path):
    model = load_model(model_file(tmp_path, TRIANGLE))
    assert not model.initial.is_box
    assert np.allclose(model.initial.low, [0, 0]) and np.allclose(model.initial.high, [1, 1])
    P = model.initial.polytope
    assert np.all(P.A @ np.array([0.2, 0.3]) <= P.b) and not np.all(P.A @ np.array([0.8, 0.8]) <= P.b)


def test_equalities_give_a_segment(tmp_path):
    text = TRIANGLE.replace('constraints: ["x >= 0", "y >= 0", "x + y <= 1"]',
                            'box: {x: [0, 2]}, constraints: ["y == 2*x + 1"]')
    model = load_model(model_file(tmp_path, text))
    assert np.allclose(model.initial.low, [0, 1]) and np.allclose(model.initial.high, [2, 5])
    assert model.initial.polytope.E.shape == (1, 2)


def test_an_axis_aligned_polytope_is_a_box(tmp_path):
    text = TRIANGLE.replace('"x + y <= 1"', '"x <= 1", "y <= 3"')
    model = load_model(model_file(tmp_path, text))
    assert model.initial.is_box and np.allclose(model.initial.high, [1, 3])


@pytest.mark.parametrize("constraints,needle", [
    ('["x >= 0", "y >= 0", "x + y <= -1"]', "empty"),
    ('["x >= 0", "y >= 0"]', "unbounded in 'x'"),
    ('["x*y <= 1", "x >= 0", "y >= 0", "x <= 1", "y <= 1"]', "not linear"),
    ('["x == y == 1"]', "only <=, <, >=, >"),
])
def test_bad_polytopes_are_bad_input(tmp_path, constraints, needle):
    text = TRIANGLE.replace('["x >= 0", "y >= 0", "x + y <= 1"]', constraints)
    with pytest.raises(InputError, match=needle) as info:
        load_model(model_file(tmp_path, text))
    assert info.value.line is not None and "initial" in (info.value.field or "")


def test_bounded_inputs_are_trailing_zero_flow_states(tmp_path):
    model = load_model(model_file(tmp_path, INPUT.replace("VARYING", "true")))
    (u,) = model.bounded_inputs
    assert (model.state, u.index, u.low, u.high, u.varying) == (["x", "u"], 1, -1.0, 1.0, True)
    A, b = model.modes["go"].linear
    assert np.array_equal(A, [[0, 1], [0, 0]]) and np.array_equal(b, [0, 0])
    assert np.array_equal(model.initial.low, [0, -1]) and np.array_equal(model.initial.high, [0, 1])
    assert model.global_clock is None


@pytest.mark.parametrize("edit,needle", [
    (("modes:\n  go: {flow: {x: u}}", "modes:\n  go: {flow: {x: u}, invariant: [\"u <= 0.5\"]}"), "invariant"),
    (("initial: {mode: go, box: {x: 0}}", "transitions:\n  - {from: go, to: go, guard: [\"u >= 0\"]}\n"
      "initial: {mode: go, box: {x: 0}}"), "guard"),
    (("initial: {mode: go, box: {x: 0}}", "transitions:\n  - {from: go, to: go, guard: [\"x >= 1\"], "
      "reset: {u: 0}}\ninitial: {mode: go, box: {x: 0}}"), "cannot be reset"),
    (("box: {x: 0}", "box: {x: 0, u: 1}"), "starts anywhere in its range"),
    (("go: {flow: {x: u}}", "go: {flow: {x: u, u: 1}}"), "it has no flow"),
    (("range: [-1, 1]", "range: [1, -1]"), "empty interval"),
])
def test_misused_inputs_are_bad_input(tmp_path, edit, needle):
    text = INPUT.replace("VARYING", "true").replace(*edit)
    with pytest.raises(InputError, match=needle):
        load_model(model_file(tmp_path, text))


@pytest.mark.parametrize("states, inputs, ok", [(999, 0, True), (1000, 0, True), (1000, 1, False),
                                                 (5000, 0, False)])
def test_more_variables_than_a_model_may_have_are_bad_input_at_the_state_line(tmp_path, capsys, states,
                                                                                inputs, ok):
    """At most MAX_VARIABLES states and bounded inputs (20 000 states took 22 GB to load):
    beyond, exit 2 naming the file's ``state`` line, before the flows are built."""
    from cli_input import bad_input
    from reach.model.automaton import MAX_VARIABLES

    names = [f"q{i}" for i in range(states)]
    bounded = "bounded_inputs: {u: {range: [0, 1]}}\n" if inputs else ""
    flow = ", ".join(f"{q}: 1" for q in names)
    box = ", ".join(f"{q}: 0" for q in names)
    text = (f"name: big\nstate: [{', '.join(names)}]\n{bounded}modes:\n  go: {{flow: {{{flow}}}}}\n"
            f"initial: {{mode: go, box: {{{box}}}}}\nhorizon: 1\n")
    path = tmp_path / "big.yaml"
    path.write_text(text)
    assert states + inputs <= MAX_VARIABLES if ok else states + inputs > MAX_VARIABLES
    if ok:
        assert load_model(path).n == states + inputs
        return
    err = bad_input(["lint", str(path)], capsys)
    assert f"big.yaml:2: state: {states + inputs} states and inputs" in err


def test_flow_false_and_the_added_clock(tmp_path):
    text = TRIANGLE.replace("still: {flow: {x: 0, y: 0}}", "still: {flow: {x: 1, y: 0}}\n  stop: {flow: false}")
    text = text.replace("horizon: 1", "transitions:\n  - {from: still, to: stop, guard: [\"x >= 2\"], urgent: true}\n"
                        "horizon: 1")
    model = load_model(model_file(tmp_path, text))
    assert model.modes["stop"].timeless and all(f == 0 for f in model.modes["stop"].flow)
    assert model.clocks == [] and model.global_clock is None
    timed, i = model.with_global_clock()
    assert (timed.state[i], i, timed.n) == ("_time", 2, 3) and timed.global_clock == 2
    assert all(m.flow[i] == 1 for m in timed.modes.values())
    P = timed.initial.polytope
    assert np.allclose(P.E, [[0, 0, 1]]) and np.allclose(P.f, [0])
    assert timed.with_global_clock() == (timed, 2)
    assert model.n == 2                                   # the original is unchanged


# ---------------------------------------------------------------- polytope sampling
def brute_vertices(A, b):
    """Vertices of a 2-D polygon: every pair of lines, kept when feasible (reference)."""
    out = []
    for i in range(len(b)):
        for j in range(i + 1, len(b)):
            M = A[[i, j]]
            if abs(np.linalg.det(M)) > 1e-12:
                v = np.linalg.solve(M, b[[i, j]])
                if np.all(A @ v <= b + 1e-9):
                    out.append(v)
    return np.unique(np.round(out, 9), axis=0)


def test_triangle_vertices_faces_and_uniform_interior():
    A = np.array([[-1.0, 0], [0, -1], [1, 1]])
    b = np.array([0.0, 0, 1])
    S = PolytopeSampler(LinearSet(A, b, np.zeros((0, 2)), np.zeros(0)), np.zeros(2), np.ones(2))
    assert np.allclose(np.unique(np.round(S.to_x(S.vertices), 9), axis=0), brute_vertices(A, b))
    pts = S.structured()
    assert np.allclose(pts[:3][np.lexsort(pts[:3].T[::-1])], [[0, 0], [0, 1], [1, 0]])
    assert any(np.allclose(p, [0.5, 0.5]) for p in pts)        # the centre of the face x + y = 1
    X = S.uniform(4000, np.random.default_rng(1))
    assert S.contains(X).all()
    # uniform on the triangle: mean (1/3, 1/3), P(x > 1/2) = 1/4 (standard errors ~0.004, ~0.007)
    assert np.allclose(X.mean(axis=0), [1 / 3, 1 / 3], atol=0.02)
    assert abs(np.mean(X[:, 0] > 0.5) - 0.25) < 0.03


def test_a_box_cut_by_loose_rows_is_sampled_exactly_by_rejection():
    """A 150-state box cut by two loose slabs on weighted sums (as the ISS's initial box by its
    outputs' ranges) with a pinned clock ``t == 0``: points by rejection from the box (hit-and-run
    would take 30 d steps of (d x k) products per point), uniform: each coordinate's mean 0 and
    P(x_i > 1/2) = 1/4 on [-1, 1], the slab respected. A thin triangle (2 % of its box) is left
    to hit-and-run."""
    n = 151
    rng = np.random.default_rng(3)
    c = np.append(rng.uniform(0, 0.02, n - 1), 0.0)
    A = np.vstack([np.eye(n), -np.eye(n), c, -c])
    b = np.concatenate([np.ones(n), np.ones(n), [0.25, 0.25]])
    E, f = np.eye(n)[-1:], np.zeros(1)
    low, high = np.append(-np.ones(n - 1), 0.0), np.append(np.ones(n - 1), 0.0)
    S = PolytopeSampler(LinearSet(A, b, E, f), low, high)
    X = S._rejection(4000, np.random.default_rng(4))
    assert X is not None and X.shape == (4000, n) and S.contains(X).all()
    assert np.all(X[:, -1] == 0.0) and np.abs(X @ c).max() <= 0.25
    assert np.abs(X[:, :-1].mean(axis=0)).max() < 0.07            # standard error 0.009 each
    assert abs(np.mean(X[:, :-1] > 0.5) - 0.25) < 0.01
    thin = PolytopeSampler(LinearSet(np.array([[-1.0, 0], [0, -1], [1, 1]]), np.array([0.0, 0, 0.2]),
                                     np.zeros((0, 2)), np.zeros(0)), np.zeros(2), np.ones(2))
    assert thin._rejection(100, np.random.default_rng(5)) is None
    assert thin.contains(thin.uniform(100, np.random.default_rng(5))).all()


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_random_polytopes_extreme_points_attain_the_support(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5))
    k = int(rng.integers(1, 6))
    A = np.vstack([np.eye(n), -np.eye(n), rng.normal(size=(k, n))])
    b = np.concatenate([np.ones(2 * n), np.abs(rng.normal(size=k)) + 0.1])     # contains 0
    E, f = (rng.normal(size=(1, n)), np.zeros(1)) if seed % 3 == 0 else (np.zeros((0, n)), np.zeros(0))
    S = PolytopeSampler(LinearSet(A, b, E, f), -np.ones(n), np.ones(n))
    V = S.to_x(S.vertices)
    assert S.contains(V).all() and S.contains(S.uniform(50, rng)).all()
    for c in rng.normal(size=(5, n)):
        res = lp.maximize(c, A, b, A_eq=E if E.shape[0] else None, b_eq=f if E.shape[0] else None)
        assert np.max(V @ c) == pytest.approx(res.value, abs=1e-7)
    pulled = S.pull_inside(rng.normal(size=(20, n)) * 3)
    assert S.contains(pulled).all()


def test_a_polytope_of_one_point_is_sampled_and_pulled_onto_that_point():
    """Equalities that fix every coordinate (a SpaceEx ``initially`` of ``x == a`` terms, with
    an inequality the point meets): every sample, vertex and pulled point is that point."""
    E, f = np.eye(2), np.array([0.25, 0.4])
    S = PolytopeSampler(LinearSet(np.array([[1.0, 1.0]]), np.array([1.0]), E, f), np.zeros(2), np.ones(2))
    rng = np.random.default_rng(0)
    for X in (S.to_x(S.vertices), S.structured(), S.uniform(5, rng), S.pull_inside(rng.normal(size=(5, 2)))):
        assert np.allclose(X, f) and S.contains(X).all()


def test_montecarlo_samples_the_polytope_not_its_box(tmp_path):
    path = model_file(tmp_path, TRIANGLE)
    props = model_file(tmp_path, """
        properties:
          - {id: corner, kind: safety, avoid: ["x >= 0.8", "y >= 0.8"]}
          - {id: vertex, kind: safety, require: ["x <= 0.999"]}
        """, "p.yaml")
    corner, vertex = check_files(path, props, "montecarlo", {"samples": 300})
    assert corner.status.value == "UNKNOWN"       # in the bounding box, not in the triangle
    assert vertex.status.value == "UNSAFE"         # only near the vertex (1, 0)
    assert vertex.counterexample.initial_state == pytest.approx([1.0, 0.0])


# ---------------------------------------------------------------- input signals
def test_piecewise_constant_signal_matches_the_integral(tmp_path):
    model = load_model(model_file(tmp_path, INPUT.replace("VARYING", "true")))
    sim = Simulator(model, dt=0.01)
    values = np.array([[[1.0], [-0.5], [0.25], [1.0]]])
    traj = sim.run(np.zeros((1, 2)), signal=(0.5, values), record=True)
    t, _, X = traj.path[0]
    expected = np.interp(t, [0, 0.5, 1.0, 1.5, 2.0], [0, 0.5, 0.25, 0.375, 0.875])
    assert np.allclose(X[:, 0], expected, atol=1e-12)


def test_counterexample_carries_its_signal_and_replays(tmp_path):
    path = model_file(tmp_path, INPUT.replace("VARYING", "true"))
    props = model_file(tmp_path, """
        properties:
          - {id: reach_far, kind: safety, require: ["x <= 1.5"]}
        """, "p.yaml")
    (result,) = check_files(path, props, "montecarlo", {"samples": 50, "input_step": 0.5})
    assert result.status.value == "UNSAFE"
    cex = result.counterexample
    signal = np.array(cex.input_signal["values"])[:, 0]
    assert cex.input_signal["inputs"] == ["u"] and np.all(np.abs(signal) <= 1)
    # independent: x(t) is the integral of the signal; the violation needs x > 1.5 by t = 2
    k = int(np.floor(cex.violation_time / 0.5 + 1e-12))
    x_then = 0.5 * signal[:k].sum() + (cex.violation_time - 0.5 * k) * signal[min(k, len(signal) - 1)]
    assert x_then == pytest.approx(cex.violation_state[0], abs=1e-9) and x_then > 1.5
    file = tmp_path / "cex.json"
    cex.save(file)
    assert main(["replay", str(file)]) == 1                # it violates the property
    data = json.loads(file.read_text())
    data["input_signal"]["values"] = [[-v[0]] for v in data["input_signal"]["values"]]
    file.write_text(json.dumps(data))
    assert main(["replay", str(file)]) == 3                # the mirrored signal stays below 1.5
    del data["input_signal"]
    file.write_text(json.dumps(data))
    assert main(["replay", str(file)]) == 2


def test_constant_input_is_a_state_and_other_backends_refuse_varying_ones(tmp_path):
    props = model_file(tmp_path, """
        properties:
          - {id: bound, kind: safety, require: ["x <= 2.5"]}
        """, "p.yaml")
    constant = model_file(tmp_path, INPUT.replace("VARYING", "false"), "c.yaml")
    (r,) = check_files(constant, props, "taylor")
    assert r.status.value != "UNSUPPORTED" or "varying" not in r.details.get("reason", "")
    varying = model_file(tmp_path, INPUT.replace("VARYING", "true"), "v.yaml")
    for backend in ("taylor", "fsr"):
        (r,) = check_files(varying, props, backend)
        assert r.status.value == "UNSUPPORTED" and "time-varying" in r.details["reason"]


def test_the_readme_example_loads(tmp_path):
    from pathlib import Path
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = text.split("## Model format: polytopes, bounded inputs, no clock")[1].split("```yaml")[1].split("```")[0]
    model = load_model(model_file(tmp_path, "name: readme\nhorizon: 1\n" + block))
    assert model.state == ["x1", "x2", "x4", "u", "p"] and model.modes["stop"].timeless
    # x1 = 0.00056 x4 - 0.06 on x4 in [27, 33]
    assert model.initial.low[0] == pytest.approx(0.00056 * 27 - 0.06)
    assert model.initial.high[0] == pytest.approx(0.00056 * 33 - 0.06)


def test_a_start_outside_the_polytope_does_not_replay(tmp_path):
    from reach.backends.montecarlo import replay
    from reach.spec import bind, load_properties
    model = load_model(model_file(tmp_path, TRIANGLE))
    props = model_file(tmp_path, """
        properties:
          - {id: corner, kind: safety, avoid: ["x >= 0.8", "y >= 0.8"]}
        """, "p.yaml")
    prop = bind(load_properties(props)[0], model)
    assert not replay(model, prop, [0.9, 0.9], None).violated          # in the box, not the set


SWITCHED = """
name: updown
state: [x]
modes:
  up: {flow: {x: 1}}
  down: {flow: {x: -1}}
transitions:
  - {from: up, to: down}
  - {from: down, to: up}
initial: {mode: up, box: {x: 0}}
horizon: 4
"""


def test_a_switch_asked_for_at_time_zero_is_taken_from_the_initial_state(tmp_path):
    """``x`` is ``-t`` after a switch at 0 (the closed form), ``t`` without it."""
    model = load_model(model_file(tmp_path, SWITCHED))
    sim = Simulator(model, 0.01)
    for first, sign in ((True, -1.0), (False, 1.0)):
        signal = (1.0, np.zeros((1, 2, 0)), np.array([[first, False]]))
        runs = sim.run(np.zeros((1, 1)), signal=signal)
        assert runs.final_state[0, 0] == pytest.approx(sign * 4.0)


def test_arbitrary_switching_is_sampled_and_replayed(tmp_path):
    """Guard-free may-transitions and no invariant: only a run that switches early goes below 0."""
    path = model_file(tmp_path, SWITCHED)
    props = model_file(tmp_path, """
        properties:
          - {id: stays_up, kind: safety, require: ["x >= -0.5"]}
        """, "p.yaml")
    (result,) = check_files(path, props, "montecarlo", {"samples": 200})
    assert result.status.value == "UNSAFE"
    cex = result.counterexample
    switch = np.array(cex.input_signal["switch"])
    step = cex.input_signal["step"]
    # independent: x is the integral of +1 in 'up' and -1 in 'down', the mode flipping at the
    # piece starts k * step (k >= 0) where switch[k] is 1
    t = np.linspace(0, cex.violation_time, 4001)
    flips = np.array([k * step for k in range(len(switch)) if switch[k]])
    rate = np.where(np.searchsorted(flips, t, side="right") % 2 == 0, 1.0, -1.0)
    x = np.concatenate([[0], np.cumsum(rate[1:] * np.diff(t))])
    assert x[-1] == pytest.approx(cex.violation_state[0], abs=2e-3) and x[-1] < -0.5
    file = tmp_path / "cex.json"
    cex.save(file)
    assert main(["replay", str(file)]) == 1
    data = json.loads(file.read_text())
    data["input_signal"]["switch"] = [0] * len(switch)
    file.write_text(json.dumps(data))
    assert main(["replay", str(file)]) == 3                # never switching, x only grows


def test_a_property_file_given_as_the_model_says_so(tmp_path, capsys):
    """``reach check PROPERTIES MODEL``, the two files the wrong way round: one line saying the
    first is a property file, not "unknown field 'properties'"."""
    from cli_input import bad_input
    (tmp_path / "p.yaml").write_text("properties:\n  - {id: hot, kind: safety, require: ['T <= 22']}\n")
    (tmp_path / "m.yaml").write_text("name: m\nstate: [T]\nmodes:\n  on: {flow: {T: '1'}}\n"
                                     "initial: {mode: on, box: {T: [0, 1]}}\nhorizon: 1\n")
    err = bad_input(["check", str(tmp_path / "p.yaml"), str(tmp_path / "m.yaml"), "-b", "star"], capsys)
    assert err == f"reach: {tmp_path / 'p.yaml'}:1: properties: this is a property file, not a model " \
                  "(give the model first, then the property file)", err


@pytest.mark.parametrize("constraints, empty", [
    (["x > 1", "x < 1", "y == 0"], True),            # closure {1}: no point of the written set
    (["x > 1", "x <= 1", "y == 0"], True),
    (["x + y > 2", "x + y < 2", "x >= 0", "y >= 0", "x <= 5", "y <= 5"], True),
    (["x > 1", "x < 1.5", "x + y == 2", "y >= 0"], False),     # points: read as the closure
    (["x >= 1", "x <= 1", "y > 0", "y < 1"], False),
])
def test_strict_initial_constraints_that_leave_no_point_are_bad_input(tmp_path, constraints, empty):
    """Strict bounds are read closed once the set has points (the closure's bounds); where they
    leave none, every run would start outside the written set: bad input at the constraints."""
    path = tmp_path / "m.yaml"
    path.write_text("name: s\nstate: [x, y]\nmodes: {a: {flow: {x: 1, y: 0}}}\n"
                    f"initial: {{mode: a, constraints: {json.dumps(constraints)}}}\nhorizon: 1\n")
    if empty:
        with pytest.raises(InputError, match="initial set is empty: its strict constraints"):
            load_model(path)
    else:
        model = load_model(path)
        assert np.all(model.initial.low <= model.initial.high)


@pytest.mark.parametrize("invariant, box, outcome", [
    (["th >= 0", "th <= -1"], "[0, 1]", "refused"),           # an empty invariant: no run starts
    (["th >= 0"], "[-2, -1]", "refused"),                     # the box on the wrong side
    (["th >= 0"], "[-1, 1.2]", "lint"),                       # partly outside: those states start no run
    (["th >= 0"], "[0, 1.2]", "clean"),
    (["th <= 1.5"], "[1e200, 1e201]", "refused"),              # the LP failed on 1e200 (exit 3 later)
])
def test_an_initial_set_outside_its_modes_invariant(tmp_path, invariant, box, outcome):
    """No initial state in the initial mode's invariant is bad input (every property would hold
    for want of runs); a set partly outside is a lint that names the broken row."""
    from reach.model.lint import initial_outside
    path = tmp_path / "m.yaml"
    path.write_text("name: s\nstate: [th]\n"
                    f"modes: {{swing: {{flow: {{th: -1}}, invariant: {json.dumps(invariant)}}}}}\n"
                    f"initial: {{mode: swing, box: {{th: {box}}}}}\nhorizon: 1\n")
    if outcome == "refused":
        with pytest.raises(InputError, match="no state of the initial set lies in the invariant of its mode 'swing'"):
            load_model(path)
        return
    finding = initial_outside(load_model(path))
    if outcome == "lint":
        assert finding is not None and "(th >= 0 fails there)" in finding
    else:
        assert finding is None


def test_the_readme_tank_example_checks_as_it_says(tmp_path):
    """The README's first model and properties, as written: star proves ``level`` (the
    invariants keep 2 <= h <= 8; the reset adds 0.5 at h <= 3) and ``early_full`` (filling from
    h <= 3, ``h = 10 - (10 - h0) e^{-t/10}`` reaches 8 at ``t >= 10 ln 3.5 = 12.53 > 12``)."""
    from pathlib import Path

    from reach.backends.star import BACKEND as STAR
    from reach.result import Status
    from reach.spec import bind, load_properties
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = text.split("## Model and property files in brief")[1]
    model_text, props_text = (part.split("```")[0] for part in section.split("```yaml")[1:3])
    (tmp_path / "tank.yaml").write_text(model_text)
    (tmp_path / "tank_props.yaml").write_text(props_text)
    model = load_model(tmp_path / "tank.yaml")
    props = {p.id: bind(p, model) for p in load_properties(tmp_path / "tank_props.yaml")}
    assert 10 * np.log(3.5) > 12
    for pid in ("level", "early_full"):
        assert STAR.check(model, props[pid], {}).status is Status.SAFE
