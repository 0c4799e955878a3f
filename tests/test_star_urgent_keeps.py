"""An urgent guard cuts the flow of its source mode: a run that enters with ``h x >= c`` leaves
the instant ``h x = c``, so star's chains in that mode keep ``h x >= c`` (reach.backends.star.
explorer._urgent_keeps), but only where the entry star meets it whole -- states entering inside
the guard leave at once, and are still checked there.

References: solve_ivp with a terminal event on the guard, from the corners and random points of
the initial box (a state strictly inside the guard at t = 0 is checked at t = 0 only)."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from reach.checking import check_files
from reach.result import Status

MODEL = """
name: cut
state: [x, y]
modes:
  a: {{flow: {{x: "{a11}*x + {a12}*y + {b1}", y: "{a21}*x + {a22}*y + {b2}"}}}}
  b: {{flow: {{x: 0, y: 0}}}}
transitions:
  - {{from: a, to: b, guard: ["{h1}*x + {h2}*y <= {c}"], urgent: true}}
initial: {{mode: a, box: {{x: [{x0}, {x1}], y: [{y0}, {y1}]}}}}
horizon: 2
"""


def _largest_in_a(p, w) -> float:
    """The largest ``w . (x, y)`` in mode ``a`` over sampled runs (solve_ivp, guard as event)."""
    A = np.array([[p["a11"], p["a12"]], [p["a21"], p["a22"]]])
    b, h = np.array([p["b1"], p["b2"]]), np.array([p["h1"], p["h2"]])
    rng = np.random.default_rng(0)
    corners = [(x, y) for x in (p["x0"], p["x1"]) for y in (p["y0"], p["y1"])]
    starts = np.vstack([corners, rng.uniform([p["x0"], p["y0"]], [p["x1"], p["y1"]], (60, 2))])
    best = -np.inf
    for z0 in starts:
        best = max(best, w @ z0)
        if h @ z0 <= p["c"]:                    # inside the guard: leaves at once
            continue
        event = lambda t, z: h @ z - p["c"]
        event.terminal, event.direction = True, -1
        run = solve_ivp(lambda t, z: A @ z + b, (0.0, 2.0), z0, events=event, max_step=0.01,
                        rtol=1e-10, atol=1e-12)
        best = max(best, float(np.max(w @ run.y)))
    return best


coefficient = st.floats(-1.0, 1.0).map(lambda v: round(v, 2))


@given(a=st.lists(coefficient, min_size=6, max_size=6), h=st.lists(coefficient, min_size=2, max_size=2),
       c=st.floats(-1.0, 1.0).map(lambda v: round(v, 2)), low=st.lists(st.floats(-1, 0.8).map(lambda v: round(v, 2)),
                                                                          min_size=2, max_size=2),
       w=st.lists(coefficient, min_size=2, max_size=2))
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_no_safe_below_what_the_runs_reach_in_the_source_mode(tmp_path_factory, a, h, c, low, w):
    if abs(h[0]) + abs(h[1]) < 0.1 or abs(w[0]) + abs(w[1]) < 0.1:
        return
    p = dict(zip(["a11", "a12", "a21", "a22", "b1", "b2"], a), h1=h[0], h2=h[1], c=c,
             x0=low[0], x1=low[0] + 0.2, y0=low[1], y1=low[1] + 0.2)
    w = np.array(w)
    reached = _largest_in_a(p, w)
    folder = tmp_path_factory.mktemp("cut")
    (folder / "m.yaml").write_text(MODEL.format(**p))
    (folder / "p.yaml").write_text(
        "properties:\n"
        f"  - {{id: below, kind: safety, modes: [a], require: [\"{w[0]}*x + {w[1]}*y <= {reached - 1e-3}\"]}}\n")
    (result,) = check_files(folder / "m.yaml", folder / "p.yaml", "star")
    assert result.status is not Status.SAFE


def test_an_urgent_guard_ends_the_flow_of_its_mode(tmp_path):
    """x' = 1 from 0 with an urgent switch at x >= 1 (no invariant written): x never exceeds 1
    in the source mode, and star proves x <= 1.001 there (it was UNKNOWN: the flow ran on to the
    horizon); from an entry that straddles the guard (x0 in [0.5, 1.5]) the states entering
    inside it are still checked: x <= 1.4 does not hold (x0 = 1.5 is in the mode at t = 0)."""
    (tmp_path / "m.yaml").write_text(
        "name: asap\nstate: [x]\nmodes:\n  a: {flow: {x: 1}}\n  b: {flow: {x: -1}}\n"
        "transitions:\n  - {from: a, to: b, guard: [\"x >= 1\"], urgent: true}\n"
        "initial: {mode: a, box: {x: [LOW, HIGH]}}\nhorizon: 5\n")
    text = (tmp_path / "m.yaml").read_text()
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: tight, kind: safety, modes: [a], require: [\"x <= 1.001\"]}\n"
        "  - {id: inside, kind: safety, modes: [a], require: [\"x <= 1.4\"]}\n")
    (tmp_path / "m.yaml").write_text(text.replace("LOW", "0").replace("HIGH", "0"))
    tight, inside = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "star")
    assert tight.status is Status.SAFE and inside.status is Status.SAFE
    (tmp_path / "m.yaml").write_text(text.replace("LOW", "0.5").replace("HIGH", "1.5"))
    tight, inside = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "star")
    assert tight.status is Status.UNSAFE and inside.status is Status.UNSAFE
