"""The simulator's runs are runs of the automaton (reach.model.simulate), and what Monte Carlo,
star and ``reach replay`` conclude from them.

* Invariants. A heater ``x' = -0.1 x + 3`` (rising towards 30) with invariant ``x <= 22`` and
  either no way out, an urgent switch off at ``x >= 22`` or a may-transition there: no run of
  the automaton goes past 22, so ``x <= 22``, ``x <= 22.000001`` and ``avoid x >= 22.000001``
  hold, and no back-end may report a violation; ``x <= 21.9`` is violated (from ``x0 = 21``
  after 0.11 time units), found and replayed.
* Branches. From ``x = 0`` (``x' = 1``) two urgent transitions ``a -> b`` and ``a -> c`` hold
  together at ``x = 1``; in ``b`` ``x`` stays 1, in ``c`` it grows to the invariant ``x <= 5``:
  ``x <= 4`` is violated only through ``c``, at ``t = 4``. The same with may-transitions taken
  where ``a``'s invariant ``x <= 1`` ends.
* Timeless modes. ``move`` (``x' = 1`` to ``x = 2``), then ``wait`` (SpaceEx ``flow false``), then
  ``back`` (``x' = -1``): no time passes in ``wait``, so ``x = 0.2`` is reached at ``t = 3.8``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.montecarlo.initial_sampling import branch_plan
from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.star import BACKEND as STAR
from reach.cli import main
from reach.model import load_model
from reach.model.simulate import INVARIANT_TOLERANCE, Branches, Simulator
from reach.model.spaceex import load_spaceex
from reach.report import line
from reach.result import Status
from reach.spec import bind, load_properties

HEATER = """name: heater_{kind}
state: [x]
modes:
  heat:
    flow: {{x: "-0.1*x + 0.1*({level} + 8)"}}
    invariant: ["x <= {level}"]
  cool:
    flow: {{x: "-0.1*x"}}
transitions: {exit}
initial: {{mode: heat, box: {{x: [{low}, {start}]}}}}
horizon: 20
"""
EXITS = {"blocked": "[]",
         "urgent": '[{{from: heat, to: cool, guard: ["x >= {level}"], urgent: true}}]',
         "may": '[{{from: heat, to: cool, guard: ["x >= {level}"]}}]'}

HEATER_PROPERTIES = """properties:
  - {id: above, kind: safety, modes: [heat], require: ["x <= 22"]}
  - {id: above_eps, kind: safety, modes: [heat], require: ["x <= 22.000001"]}
  - {id: avoid_eps, kind: safety, modes: [heat], avoid: {box: {x: [22.000001, 1000]}}}
  - {id: below_21p9, kind: safety, modes: [heat], require: ["x <= 21.9"]}
"""

BRANCH = """name: branch
state: [x]
modes:
  a: {{flow: {{x: 1}}{a_invariant}}}
  b: {{flow: {{x: 0}}}}
  c: {{flow: {{x: 1}}, invariant: ["x <= 5"]}}
transitions:
  - {{from: a, to: b, guard: ["x >= 1"]{urgent}}}
  - {{from: a, to: c, guard: ["x >= 1"]{urgent}}}
initial: {{mode: a, box: {{x: 0}}}}
horizon: 6
"""
BRANCH_PROPERTIES = """properties:
  - {id: le4, kind: safety, modes: [a, b, c], require: ["x <= 4"]}
"""

TIMELESS_XML = """<?xml version="1.0"?>
<sspaceex xmlns="http://www-verimag.imag.fr/xml-namespaces/sspaceex" version="0.2">
  <component id="system">
    <param name="x" type="real" local="false" d1="1" d2="1" dynamics="any" />
    <param name="t" type="real" local="false" d1="1" d2="1" dynamics="any" />
    <location id="1" name="move">
      <invariant>x &lt;= 2</invariant>
      <flow>x' == 1 &amp; t' == 1</flow>
    </location>
    <location id="2" name="wait"><flow>false</flow></location>
    <location id="3" name="back"><flow>x' == -1 &amp; t' == 1</flow></location>
    <transition source="1" target="2" asap="true"><guard>x &gt;= 2</guard></transition>
    <transition source="2" target="3"><guard>GUARD</guard></transition>
  </component>
</sspaceex>
"""
TIMELESS_CFG = """system = "system"
initially = "x == 0 & t == 0 & loc() == move"
time-horizon = 4
forbidden = "x <= 0.2 & loc() == back"
"""


def _load(folder, model_text, props_text, name="m"):
    (folder / f"{name}.yaml").write_text(model_text)
    (folder / f"{name}_props.yaml").write_text(props_text)
    model = load_model(folder / f"{name}.yaml")
    return model, {p.id: bind(p, model) for p in load_properties(folder / f"{name}_props.yaml")}


def heater(folder, kind, level=22.0, start=21.0, low=20.0, props=HEATER_PROPERTIES):
    exit_ = EXITS[kind].format(level=level)
    return _load(folder, HEATER.format(kind=kind, level=level, start=start, low=low, exit=exit_), props,
                 f"heater_{kind}")


class Watched:
    """Every state the observers are shown, with its mode."""

    def __init__(self):
        self.X, self.mode = [], []

    def __call__(self, t, X, mode, rows):
        self.X.append(np.array(X, dtype=float))
        self.mode.append(np.broadcast_to(mode, (len(rows),)).copy())


def assert_watched_inside(model, runs):
    """Every watched state lies in its mode's invariant (to the simulator's tolerance)."""
    X, mode = np.concatenate(runs.X), np.concatenate(runs.mode)
    names = list(model.modes)
    for m in np.unique(mode):
        Y = X[mode == m]
        margins = model.modes[names[m]].invariant_margins(Y)
        if margins.shape[1]:
            assert np.all(margins.max(axis=1) <= INVARIANT_TOLERANCE * (1 + np.abs(Y).max(axis=1))), names[m]


# ------------------------------------------------------------------ invariants

@pytest.mark.parametrize("kind", sorted(EXITS))
def test_no_violation_is_reported_beyond_an_invariant(tmp_path, kind):
    model, props = heater(tmp_path, kind)
    results = MONTECARLO.check_many(model, [props[k] for k in ("above", "above_eps", "avoid_eps")])
    assert [r.status for r in results] == [Status.UNKNOWN] * 3, [r.counterexample for r in results]
    assert STAR.check(model, props["avoid_eps"]).status is not Status.UNSAFE


@pytest.mark.parametrize("kind", sorted(EXITS))
def test_a_violation_inside_the_invariant_is_found_and_replays(tmp_path, capsys, kind):
    model, props = heater(tmp_path, kind)
    result = MONTECARLO.check(model, props["below_21p9"])
    assert result.status is Status.UNSAFE
    cex = result.counterexample
    assert 21.9 < cex.violation_state[0] <= 22.0
    cex.save(tmp_path / "cex.json")
    assert main(["replay", str(tmp_path / "cex.json")]) == 1
    assert capsys.readouterr().out.startswith("replayed:")


@pytest.mark.parametrize("general", [False, True])
@pytest.mark.parametrize("kind", sorted(EXITS))
def test_every_watched_state_is_inside_the_invariant(tmp_path, kind, general):
    """On the block path and on the general per-segment path, from initial states partly
    outside the invariant (which are no initial states of the automaton)."""
    model, _ = heater(tmp_path, kind, low=20.0, start=23.0)
    sim = Simulator(model)
    if general:
        sim.tables = dict.fromkeys(model.modes)
    watched = Watched()
    x0 = np.linspace(20.0, 23.0, 301)[:, None]
    traj = sim.run(x0, observers=[watched])
    assert_watched_inside(model, watched)
    assert np.all(traj.blocked_at[x0[:, 0] > 22.0 + 1e-9] == 0.0)
    if kind == "blocked":        # every run stops where it reaches 22, no later than the closed form
        reach_22 = 10 * np.log((30 - x0[x0[:, 0] <= 22, 0]) / 8)
        assert np.all(traj.blocked_at[x0[:, 0] <= 22] <= reach_22 + 1e-9)
        assert np.all(traj.final_state[x0[:, 0] <= 22, 0] <= 22.0 + INVARIANT_TOLERANCE * 23)


@settings(max_examples=12, deadline=None)
@given(level=st.floats(1.0, 1000.0), kind=st.sampled_from(sorted(EXITS)), above=st.floats(0.0, 1e-6))
def test_montecarlo_never_violates_past_an_invariant_at_any_level(tmp_path_factory, level, kind, above):
    """Invariant ``x <= c`` at a random level ``c``; the requirement ``x <= c (1 + d)`` for a
    random ``d`` in ``[0, 1e-6]`` holds on every run of the automaton."""
    folder = tmp_path_factory.mktemp("level")
    bound = level * (1 + above)
    props = f"properties:\n  - {{id: p, kind: safety, modes: [heat], require: ['x <= {bound!r}']}}\n"
    model, prop = heater(folder, kind, level=level, start=level * 0.999, low=level * 0.99, props=props)
    result = MONTECARLO.check(model, prop["p"], {"samples": 200, "generations": 5, "polish": 20})
    assert result.status is Status.UNKNOWN, result.counterexample


# ------------------------------------------------------------------ branches

@pytest.fixture(params=["urgent", "may"])
def branch(request, tmp_path):
    urgent = request.param == "urgent"
    text = BRANCH.format(urgent=", urgent: true" if urgent else "",
                         a_invariant="" if urgent else ', invariant: ["x <= 1"]')
    model, props = _load(tmp_path, text, BRANCH_PROPERTIES, "branch")
    return model, props["le4"], tmp_path


def test_the_structured_runs_take_every_branch(branch):
    model, _, _ = branch
    sim = Simulator(model)
    assert sim.max_options == 2
    X, _, _, choice, count = branch_plan(2, 1, np.zeros((1, 1)), None, None, np.random.default_rng(0))
    traj = sim.run(X, record=True, branches=Branches(values=choice))
    assert count == 2 and traj.transitions == {0: ["t0"], 1: ["t1"]}
    np.testing.assert_allclose(traj.final_state[:, 0], [1.0, 5.0], atol=1e-9)


def test_montecarlo_finds_the_violation_through_the_second_branch(branch, capsys):
    model, prop, folder = branch
    result = MONTECARLO.check(model, prop)
    assert result.status is Status.UNSAFE
    cex = result.counterexample
    assert cex.transitions == ["t1"] and cex.violation_mode == "c"
    assert cex.violation_time == pytest.approx(4.0, abs=0.01)
    cex.save(folder / "cex.json")
    assert main(["replay", str(folder / "cex.json")]) == 1
    # an older file without the transitions replays with the first enabled one: through b
    data = json.loads((folder / "cex.json").read_text())
    del data["transitions"]
    (folder / "old.json").write_text(json.dumps(data))
    assert main(["replay", str(folder / "old.json")]) == 3
    assert "NOT replayed" in capsys.readouterr().out


def test_star_replays_its_witness_along_its_branch(branch, capsys):
    model, prop, folder = branch
    result = STAR.check(model, prop)
    assert result.status is Status.UNSAFE
    assert result.counterexample.transitions == ["t1"]
    result.counterexample.save(folder / "star.json")
    assert main(["replay", str(folder / "star.json")]) == 1


def test_a_prescribed_branch_that_is_not_enabled_falls_back_to_the_first(branch):
    model, _, _ = branch
    traj = Simulator(model).run(np.zeros((2, 1)), record=True,
                                branches=Branches(prescribed=[["nope", "t1"], ["t1"]]))
    assert traj.transitions == {0: ["t0"], 1: ["t1"]}


# ------------------------------------------------------------------ timeless modes

def _timeless(folder, guard="true"):
    (folder / "tl.xml").write_text(TIMELESS_XML.replace("GUARD", guard))
    (folder / "tl.cfg").write_text(TIMELESS_CFG)
    model, props, _ = load_spaceex(folder / "tl.xml", folder / "tl.cfg")
    return model, props[0]


def test_no_time_passes_in_a_timeless_mode(tmp_path):
    model, _ = _timeless(tmp_path)
    assert model.modes["wait"].timeless
    traj = Simulator(model).run(np.zeros((1, 2)), record=True)
    t, mode, X = traj.path[0]
    names = np.array(list(model.modes))[mode]
    assert np.all(t[names == "wait"] == t[names == "wait"][0])
    assert t[names == "back"][0] == pytest.approx(2.0, abs=1e-9)
    assert traj.final_state[0, 0] == pytest.approx(0.0, abs=1e-9)          # back to 0 at t = 4
    assert traj.transitions[0] == ["move_to_wait", "wait_to_back"]


def test_montecarlo_leaves_a_timeless_mode_at_once(tmp_path):
    model, prop = _timeless(tmp_path)
    result = MONTECARLO.check(model, bind(prop, model))
    assert result.status is Status.UNSAFE
    assert result.counterexample.violation_time == pytest.approx(3.8, abs=0.01)


def test_a_timeless_mode_with_nothing_enabled_blocks_the_run(tmp_path):
    model, _ = _timeless(tmp_path, guard="x &gt;= 3")
    traj = Simulator(model).run(np.zeros((1, 2)), record=True)
    assert traj.blocked_at[0] == pytest.approx(2.0, abs=1e-9)
    assert list(model.modes)[traj.final_mode[0]] == "wait"


# ------------------------------------------------------------------ the report line

def test_an_unsafe_line_states_the_counterexample_not_a_probability_bound(branch):
    model, prop, _ = branch
    result = MONTECARLO.check(model, prop)
    text = line(result, prop, model)
    assert text.startswith("violated at t=4")
    assert "margin" in text and "at the violation" in text
    assert "P(violation)" not in text
    k = result.details["violating_runs"]
    assert f"violating runs: {k} of {result.details['random_runs']}" in text and 0 < k < 1000
    assert "violation_probability_upper_95" in result.details          # --json keeps it
