"""Modes that switch to one another at any instant, explored by star as one differential
inclusion (:mod:`reach.backends.star.switching`). Checked against closed forms (the comparison
principle for a scalar switched system), random switching signals solved exactly, and the
published Platoon PLAA01 files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

from model_files import load_files
from reach.backends.star import BACKEND
from reach.backends.star.switching import SwitchingModel, switching_groups
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

ROOT = Path(__file__).resolve().parent.parent

#: x' = -x + 1 in a, x' = -2x + 0.5 in b, switching at any instant, x(0) = 0. For x >= -1/2 the
#: larger rate is a's and the smaller b's, so by the comparison principle every run lies between
#: the runs that never switch: 0.25 (1 - e^{-2t}) <= x(t) <= 1 - e^{-t}, both attained.
SCALAR = """
name: scalar_switching
state: [x]
modes:
  a: {flow: {x: "-x + 1"}}
  b: {flow: {x: "-2*x + 0.5"}}
  c: {flow: {x: "0"}}
transitions:
  - {from: a, to: b}
  - {from: b, to: a}
  - {from: b, to: c, guard: ["x >= 0.5"]}
initial: {mode: a, box: {x: [0, 0]}}
horizon: 1
"""

TOP = 1 - np.exp(-1.0)          # the largest x up to t = 1 (in a, never switching)


def _check(folder, model_text, modes, require, **options):
    (folder / "m.yaml").write_text(model_text)
    (folder / "p.yaml").write_text(f"properties: [{{id: p, kind: safety, modes: {modes}, require: {require}}}]\n")
    model = load_model(folder / "m.yaml")
    return BACKEND.check(model, bind(load_properties(folder / "p.yaml")[0], model), options)


def test_groups_are_the_modes_joined_both_ways_without_guards(tmp_path):
    (tmp_path / "m.yaml").write_text(SCALAR)
    model = load_model(tmp_path / "m.yaml")
    assert switching_groups(model) == [("a", "b")]
    data = SwitchingModel.of(model)
    assert [j.target for j in data.fired["a"]] == ["c"]      # b's way out fires from a's chain
    guarded = SCALAR.replace("{from: a, to: b}", "{from: a, to: b, guard: ['x >= 0.1']}")
    (tmp_path / "m.yaml").write_text(guarded)
    assert switching_groups(load_model(tmp_path / "m.yaml")) == []


def test_scalar_switching_bounds_against_the_closed_form(tmp_path):
    upper = _check(tmp_path, SCALAR, "[a, b]", f"['x <= {TOP * 1.02}', 'x >= -0.02']")
    assert upper.status is Status.SAFE, upper.details
    assert upper.details["switching"]["groups"] == [["a", "b"]]
    assert "differential inclusion" in upper.details["semantics"]
    below_top = _check(tmp_path, SCALAR, "[a, b]", f"['x <= {TOP * 0.98}']")
    assert below_top.status is not Status.SAFE, below_top.details


def test_a_way_out_of_the_group_from_another_member_is_explored(tmp_path):
    """c is entered only from b, with x in [0.5, 1 - 1/e]: the group's chain (started in a)
    must fire b's transition, else c would look unreachable and anything would be SAFE there."""
    inside = _check(tmp_path, SCALAR, "[c]", f"['x <= {TOP * 1.02}', 'x >= 0.49']")
    assert inside.status is Status.SAFE, inside.details
    violated = _check(tmp_path, SCALAR, "[c]", "['x <= 0.55']")
    assert violated.status is not Status.SAFE, violated.details


PAIR = """
name: switched_pair
state: [x, y]
modes:
  p: {flow: {x: "-x + y", y: "-y + 1"}}
  q: {flow: {x: "-x + 1.25*y", y: "-1.25*y + 1"}}
transitions:
  - {from: p, to: q}
  - {from: q, to: p}
initial: {mode: p, box: {x: [0, 0.1], y: [0, 0.1]}}
horizon: 3
"""


def _sampled_peak(rng, runs=400, pieces=12, horizon=3.0, dt=0.005) -> float:
    """Largest x over random switching signals (``pieces`` dwells at uniform random instants,
    from the initial box's corners), solved exactly step by step with matrix exponentials."""
    flows = {0: (np.array([[-1.0, 1.0], [0.0, -1.0]]), np.array([0.0, 1.0])),
             1: (np.array([[-1.0, 1.25], [0.0, -1.25]]), np.array([0.0, 1.0]))}
    steps = {}
    for k, (A, b) in flows.items():
        aug = np.zeros((3, 3))
        aug[:2, :2], aug[:2, 2] = A, b
        E = expm(aug * dt)
        steps[k] = (E[:2, :2], E[:2, 2])
    peak = -np.inf
    for _ in range(runs):
        z = np.array([rng.choice([0.0, 0.1]), rng.choice([0.0, 0.1])])
        cuts = np.sort(rng.uniform(0, horizon, pieces - 1))
        mode, t = int(rng.integers(2)), 0.0
        for end in list(cuts) + [horizon]:
            while t < end:
                P, p = steps[mode]
                z, t = P @ z + p, t + dt
                peak = max(peak, z[0])
            mode = 1 - mode
    return peak


def test_switched_pair_bound_contains_sampled_runs(tmp_path):
    """The proved bound on x lies above every sampled switching run and within a quarter of
    the sampled peak (0.887); a bound just below the sampled peak is never SAFE."""
    peak = _sampled_peak(np.random.default_rng(1))
    safe = _check(tmp_path, PAIR, "[p, q]", f"['x <= {1.25 * peak}']")
    assert safe.status is Status.SAFE, safe.details
    assert _check(tmp_path, PAIR, "[p, q]", f"['x <= {0.98 * peak}']").status is not Status.SAFE


def test_switching_can_be_turned_off(tmp_path):
    """Mode by mode, every cell of every chain may switch: the budget runs out."""
    result = _check(tmp_path, SCALAR, "[a, b]", f"['x <= {TOP * 1.02}']", switching=False,
                    max_stars=30, max_lps=500)
    assert "switching" not in result.details
    assert result.status is Status.UNKNOWN


@pytest.mark.parametrize("cfg", ["PLAA01-BND50-forbidden.cfg"])
def test_platoon_with_arbitrary_communication_loss(cfg):
    """ARCH-COMP AFF PLAA01-BND50 on its published files (horizon 5 of the cfg): safe."""
    from reach.model.spaceex import load_spaceex
    from reach.spec.properties import BoundSafety

    folder = ROOT / "models/spaceex/Platoon"
    model, props, docs = load_spaceex(folder / "PLAA01-BND.xml", folder / cfg)
    bound = [bind(p, model) for p in props]
    modes = [m for m in model.modes if any(m in b.modes for b in bound)]
    pieces = {m: [piece for b in bound for piece in b.pieces.get(m, [])] for m in modes}
    prop = BoundSafety(docs.property_id, modes, pieces, model.symbols, cfg, "forbidden set")
    result = BACKEND.check(model, prop, {})
    assert result.status is Status.SAFE, result.details


def test_a_reset_within_the_group_is_still_fired(tmp_path):
    """Besides the free transitions, a ↦ b may also jump with x := 10 (once x >= 0.5): the
    inclusion covers switching, not resets, so that jump must fire and b sees x = 10."""
    model = """
name: reset_in_group
state: [x]
modes:
  a: {flow: {x: "1"}}
  b: {flow: {x: "1"}}
transitions:
  - {from: a, to: b}
  - {from: b, to: a}
  - {from: a, to: b, guard: ["x >= 0.5"], reset: {x: "10"}}
initial: {mode: a, box: {x: [0, 0]}}
horizon: 2
"""
    assert _check(tmp_path, model, "[b]", "['x <= 5']").status is not Status.SAFE
    loop = model.replace("{from: a, to: b, guard", "{from: a, to: a, guard")
    assert _check(tmp_path, loop, "[a]", "['x <= 5']").status is not Status.SAFE


def test_a_strict_and_a_closed_piece_are_both_kept():
    """``x > 5`` in one member and ``x >= 5`` in the other have the same rows; a run touching
    x = 5 in the second violates, so the merged pieces keep both."""
    from reach.backends.star.switching import group_pieces
    from reach.backends.star.transitions import _Piece

    H, g = np.array([[-1.0]]), np.array([-5.0])
    strict, closed = _Piece(H, g, True, "x > 5"), _Piece(H, g, False, "x >= 5")
    merged = group_pieces({"a": [strict], "b": [closed]}, [("a", "b")])
    assert {p.strict for p in merged["a"]} == {True, False} == {p.strict for p in merged["b"]}


def test_a_point_start_grows_its_region(tmp_path):
    """x' = t in a, -t in b, from x = t = 0 (a single point, t the model's clock): every run
    has |x| <= t^2 / 2 = 2 by t = 2, and staying in a reaches it."""
    model = """
name: clock_pair
state: [x, t]
modes:
  a: {flow: {x: "t", t: "1"}}
  b: {flow: {x: "-t", t: "1"}}
transitions:
  - {from: a, to: b}
  - {from: b, to: a}
initial: {mode: b, box: {x: [0, 0], t: [0, 0]}}
horizon: 2
"""
    assert _check(tmp_path, model, "[a, b]", "['x <= 2.1', 'x >= -2.1']").status is Status.SAFE
    assert _check(tmp_path, model, "[a, b]", "['x <= 1.9']").status is not Status.SAFE


#: an axis whose rate damping may drop out and return at any instant: nom x'' = -x - 0.5 x',
#: fail x'' = -x + 0.1 x' (undamped, slightly unstable)
DROPOUT = """
name: dropout
state: [x, v]
modes:
  nom: {flow: {x: v, v: "-x - 0.5*v"}}
  fail: {flow: {x: v, v: "-x + 0.1*v"}}
transitions:
  - {from: nom, to: fail}
  - {from: fail, to: nom}
initial: {mode: nom, box: {x: [0.9, 1.0], v: [-0.1, 0.1]}}
horizon: 10
"""


def test_an_undecided_inclusion_is_explored_mode_by_mode_and_its_witness_switches(tmp_path):
    """Dropping to `fail` at t = 0 and staying there drives x below -0.9 from every initial
    state (closed form: e^{A_fail t} x0 on a fine grid); the inclusion's witnesses replay runs
    that never switch and are undecided, so star explores the group mode by mode: UNSAFE with
    a replayed run through `fail`. A bound no run reaches stays SAFE."""
    A_fail = np.array([[0.0, 1.0], [-1.0, 0.1]])
    ts = np.linspace(0, 10, 4001)
    corners = [np.array([x, v]) for x in (0.9, 1.0) for v in (-0.1, 0.1)]
    lowest = max(min((expm(A_fail * t) @ x0)[0] for t in ts) for x0 in corners)
    assert lowest < -0.95                   # every corner (and so every state) goes below -0.95
    model, props = load_files(tmp_path, DROPOUT, """
        properties:
          - {id: low, kind: safety, modes: [nom, fail], require: ["x >= -0.9"]}
          - {id: wide, kind: safety, modes: [nom, fail], require: ["x >= -10"]}
    """)
    low = BACKEND.check(model, props["low"], {})
    assert low.status is Status.UNSAFE
    assert "explored mode by mode" in low.details["semantics"]
    cex = low.counterexample
    assert cex.transitions and cex.violation_state[0] < -0.9     # a run that switched, below -0.9
    assert BACKEND.check(model, props["wide"], {}).status is Status.SAFE
