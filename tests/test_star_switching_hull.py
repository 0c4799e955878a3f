"""The bound of a closed switching group around its mean flow (:mod:`reach.backends.star.hull`),
against independent references: a scalar closed form (the comparison principle), random
switching and input signals integrated by scipy's solve_ivp on random small systems, and the
published Platoon PLAA01 over the ARCH reports' horizon 20."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from reach.backends.star import BACKEND, hull
from reach.backends.star.switching import SwitchingModel
from reach.errors import InputError
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

ROOT = Path(__file__).resolve().parent.parent

#: x' = -x + 1 in a, x' = -2x + 0.5 in b, switching at any instant, x(0) = 0. For x >= -1/2 a's
#: rate is the larger, so by the comparison principle every run stays below the run that never
#: leaves a: sup x over [0, 1] is 1 - 1/e, attained.
SCALAR = """
name: scalar_closed
state: [x]
modes:
  a: {flow: {x: "-x + 1"}}
  b: {flow: {x: "-2*x + 0.5"}}
transitions:
  - {from: a, to: b}
  - {from: b, to: a}
initial: {mode: a, box: {x: [0, 0]}}
horizon: 1
"""

TOP = 1 - np.exp(-1.0)


def _model(folder: Path, text: str):
    (folder / "m.yaml").write_text(text)
    return load_model(folder / "m.yaml")


def _extremes(folder: Path, model, states, steps: int, horizon: float | None = None):
    """``(low, high)``: the hull's bounds of each state over the horizon (pieces ``x > 1e6``,
    ``x < -1e6``: their least lower bounds are ``-max x`` and ``min x``)."""
    modes = "[" + ", ".join(model.modes) + "]"
    props = "".join(f"  - {{id: p{k}, kind: safety, modes: {modes}, require: ['{s} <= 1e6']}}\n"
                    f"  - {{id: q{k}, kind: safety, modes: {modes}, require: ['{s} >= -1e6']}}\n"
                    for k, s in enumerate(states))
    (folder / "p.yaml").write_text("properties:\n" + props)
    data = SwitchingModel.of(model)
    group = hull.closed_group(model, data)
    box = hull._initial_box(data, model)
    low, high = [], []
    for k, prop in enumerate(load_properties(folder / "p.yaml")):
        pieces = hull._pieces(data, bind(prop, model), group)
        (entry,) = hull.bound(data, group, box, pieces, horizon or model.horizon, steps)
        if k % 2:
            low.append(entry["least"][0])
        else:
            high.append(-entry["least"][0])
    return np.array(low), np.array(high)


def test_closed_groups_only(tmp_path):
    """The bound applies when no transition leaves the initial mode's group and none resets."""
    way_out = (SCALAR.replace("  - {from: b, to: a}\n",
                              "  - {from: b, to: a}\n  - {from: b, to: c, guard: ['x >= 0.5']}\n")
               .replace('  b: {flow: {x: "-2*x + 0.5"}}\n', '  b: {flow: {x: "-2*x + 0.5"}}\n  c: {flow: {x: "0"}}\n'))
    reset = SCALAR.replace("{from: b, to: a}", "{from: b, to: a, reset: {x: 'x / 2'}}")
    for text, group in ((SCALAR, ("a", "b")), (way_out, None), (reset, None)):
        model = _model(tmp_path, text)
        assert hull.closed_group(model, SwitchingModel.of(model)) == group


def test_scalar_bound_against_the_closed_form(tmp_path):
    """The upper bound contains sup x = 1 - 1/e and exceeds it by less than 1 % with 200 steps
    (the members' difference is one generator whose coefficient the signal chooses: exact
    here); the lower bound lies within 0.01 below 0 (the least x, at t = 0)."""
    model = _model(tmp_path, SCALAR)
    low, high = _extremes(tmp_path, model, ["x"], 200)
    assert TOP <= high[0] <= 1.01 * TOP
    assert -0.01 <= low[0] <= 0.0


def _random_signal(rng, horizon: float, pieces: int, inputs: int):
    """Piece ends, modes (0/1) and input values (extremes of [-1, 1] or inside) of a random
    piecewise-constant switching and input signal."""
    ends = np.sort(rng.uniform(0, horizon, pieces - 1))
    ends = np.append(ends, horizon)
    modes = rng.integers(0, 2, pieces)
    values = np.where(rng.random((pieces, inputs)) < 0.7, rng.choice([-1.0, 1.0], (pieces, inputs)),
                      rng.uniform(-1, 1, (pieces, inputs)))
    return ends, modes, values


def _simulate(flows, x0, ends, modes, values, samples_per_piece: int = 4):
    """States of the switched run (solve_ivp, per piece, tight tolerances) at the pieces' ends
    and samples inside them."""
    x, t, out = np.asarray(x0, float), 0.0, [np.asarray(x0, float)]
    for end, mode, u in zip(ends, modes, values):
        A, b, B = flows[mode]
        if end <= t:
            continue
        sol = solve_ivp(lambda _, y: A @ y + b + B @ u, (t, end), x, rtol=1e-9, atol=1e-12,
                        t_eval=np.linspace(t, end, samples_per_piece + 1)[1:])
        out.extend(sol.y.T)
        x, t = sol.y[:, -1], end
    return np.array(out)


def _text(names, A, b, B):
    rows = {}
    for i, name in enumerate(names):
        terms = [f"({float(A[i, j])!r})*{other}" for j, other in enumerate(names) if A[i, j]]
        terms += [f"({float(B[i, 0])!r})*u"] if B is not None and B[i, 0] else []
        terms.append(repr(float(b[i])))
        rows[name] = " + ".join(terms)
    return "{" + ", ".join(f'{k}: "{v}"' for k, v in rows.items()) + "}"


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), n=st.integers(1, 3), with_input=st.booleans(),
       horizon=st.floats(0.5, 2.0))
def test_random_switched_systems_stay_inside_the_bound(tmp_path_factory, seed, n, with_input, horizon):
    """Random two-mode affine systems (stable parts, different offsets), random switching and
    input signals: every sampled state is within the hull's bounds of each state."""
    rng = np.random.default_rng(seed)
    names = [f"x{i + 1}" for i in range(n)]
    A = [rng.uniform(-1, 1, (n, n)) - 1.5 * np.eye(n) for _ in range(2)]
    b = [rng.uniform(-1, 1, n) for _ in range(2)]
    B = rng.uniform(-1, 1, (n, 1)) if with_input else None
    low0, high0 = rng.uniform(-0.5, 0, n), rng.uniform(0, 0.5, n)
    text = (f"name: random_switched\nstate: [{', '.join(names)}]\n"
            + ("bounded_inputs: {u: {range: [-1, 1], varying: true}}\n" if with_input else "")
            + f"modes:\n  a: {{flow: {_text(names, A[0], b[0], B)}}}\n  b: {{flow: {_text(names, A[1], b[1], B)}}}\n"
            + "transitions:\n  - {from: a, to: b}\n  - {from: b, to: a}\n"
            + "initial: {mode: a, box: {"
            + ", ".join(f"{s}: [{float(lo)!r}, {float(hi)!r}]" for s, lo, hi in zip(names, low0, high0))
            + "}}\n" + f"horizon: {horizon!r}\n")
    folder = tmp_path_factory.mktemp("random")
    model = _model(folder, text)
    low, high = _extremes(folder, model, names, 200)
    flows = [(A[k], b[k], B if B is not None else np.zeros((n, 1))) for k in range(2)]
    for trial in range(6):
        x0 = np.where(rng.random(n) < 0.5, low0, high0) if trial % 2 else rng.uniform(low0, high0)
        ends, modes, values = _random_signal(rng, horizon, int(rng.integers(1, 16)), 1)
        states = _simulate(flows, x0, ends, modes, values if with_input else 0 * values)
        assert np.all(states.min(axis=0) >= low - 1e-9), (states.min(axis=0), low)
        assert np.all(states.max(axis=0) <= high + 1e-9), (states.max(axis=0), high)


PLAA01 = ROOT / "models/spaceex/imported/models/PLAA01-BND50-h20-forbidden.yaml"
PLAA01_PROPS = ROOT / "models/spaceex/imported/properties/PLAA01-BND50-h20-forbidden.yaml"


def _plaa01():
    model = load_model(PLAA01)
    return model, [bind(p, model) for p in load_properties(PLAA01_PROPS)]


def test_plaa01_over_the_reports_horizon_is_safe():
    """PLAA01-BND50 over 20 s: the inclusion alone is undecided, the hull proves e1, e2, e3 >= -50
    (on 500 steps: e1 >= -37.8, e2 >= -43.6, e3 >= -30.3)."""
    model, props = _plaa01()
    for prop in props:
        result = BACKEND.check(model, prop)
        assert result.status is Status.SAFE, result.details
        report = result.details["hull"]
        assert report["proved"] and report["group"] == ["communication", "no_communication"]
        (entry,) = report["bounds"]
        assert -50 < entry["least"][0] < -25
        assert "mean flow" in result.details["semantics"]


def test_plaa01_random_switching_runs_stay_inside_the_bound():
    """Runs of PLAA01 with random switching and lead accelerations (bang-bang, or anywhere in
    [-9, 1]) held over random multiples of 0.05 s, stepped exactly with each mode's matrix
    exponential: every e_i stays above the hull's lower bound for it at every grid point."""
    model, props = _plaa01()
    data = SwitchingModel.of(model)
    group = hull.closed_group(model, data)
    box = hull._initial_box(data, model)
    least = [hull.bound(data, group, box, hull._pieces(data, p, group), 20.0, 500)[0]["least"][0] for p in props]
    n, dt = data.n, 0.05
    maps = []                                     # x -> Phi x + psi + chi u, per mode
    for mode in group:
        f = data.flows[mode]
        aug = np.zeros((n + 2, n + 2))
        aug[:n, :n], aug[:n, n], aug[:n, n + 1] = f.A, f.b, (f.B * f.u_radius)[:, 0]
        E = expm(aug * dt)
        maps.append((E[:n, :n], E[:n, n], E[:n, n + 1]))
    rng = np.random.default_rng(7)
    index = [model.index(s) for s in ("e1", "e2", "e3")]
    lowest = np.zeros(3)
    for _ in range(200):
        x, mode, u, hold = np.zeros(n), 0, -1.0, 0
        for _ in range(400):
            if hold == 0:
                mode, hold = int(rng.integers(0, 2)), int(rng.geometric(rng.choice([0.05, 0.3, 1.0])))
                u = rng.choice([-1.0, 1.0]) if rng.random() < 0.8 else rng.uniform(-1, 1)
            Phi, psi, chi = maps[mode]
            x, hold = Phi @ x + psi + chi * u, hold - 1
            lowest = np.minimum(lowest, x[index])
    assert np.all(lowest >= np.array(least)), (lowest, least)


def test_the_hull_only_answers_safe_or_leaves_unknown(tmp_path):
    """A violated requirement (x reaches 1 - 1/e) is never SAFE; switching_hull=false leaves
    PLAA01 over 20 s undecided (the hull is what decides it)."""
    model = _model(tmp_path, SCALAR)
    (tmp_path / "p.yaml").write_text("properties: [{id: p, kind: safety, modes: [a, b], require: ['x <= 0.6']}]\n")
    result = BACKEND.check(model, bind(load_properties(tmp_path / "p.yaml")[0], model))
    assert result.status is not Status.SAFE, result.details
    plaa01, props = _plaa01()
    off = BACKEND.check(plaa01, props[1], {"switching_hull": False})
    assert off.status is Status.UNKNOWN and "hull" not in off.details


@pytest.mark.parametrize("options", [{"hull_steps": 0}, {"hull_steps": 10 ** 6}, {"switching_hull": "yes"},
                                     {"hull_steps": 2.5}])
def test_bad_hull_options_are_refused(options):
    model, props = _plaa01()
    with pytest.raises(InputError):
        BACKEND.check(model, props[0], options)
