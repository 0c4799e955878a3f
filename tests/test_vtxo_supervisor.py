"""The VTXO mission supervisor (models/vtxo_supervisor.yaml): star verdicts, an independent
closed-form mission length, mutants with replayed counterexamples, and the zero-dwell lint."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reach.backends.montecarlo import replay
from reach.backends.star import BACKEND as STAR
from reach.cli import main as cli
from reach.model import load_model
from reach.model.lint import zero_dwell_cycles
from reach.model.simulate import Simulator
from reach.result import Status
from reach.spec import bind, load_properties

ROOT = Path(__file__).resolve().parent.parent
MODEL = "models/vtxo_supervisor.yaml"
PROPS = "properties/vtxo_supervisor.yaml"

# Table 6 of the VTXO paper, hours; section 8: orbit 32.5 h, at most 10 h of science per
# orbit, R_fs = 32.5 h - 10 h - 3 min; commissioning 60 days, de-commissioning 5 days.
TABLE6 = [0.2, 1.5, 4.2, 4.9, 5.4, 19.0, 146.0, 452.0]
ORBIT, SCIENCE, T_MAX, T_MIN = 32.5, 10.0, 3 / 60, 9 / 3600
R_FS = ORBIT - SCIENCE - T_MAX


def mission_length(d: float) -> float:
    """End of the mission with every transient lasting ``d`` hours, from Table 6 alone:
    object k takes ceil(T_k / 10 h) orbits; all but its last last R_fs + d + 10 h, the last
    is completed to a full orbit before the next object (or de-commissioning) starts."""
    total = 60 * 24.0
    for T in TABLE6:
        orbits = math.ceil(T / SCIENCE)
        total += (orbits - 1) * (R_FS + d + SCIENCE) + ORBIT
    return total + 5 * 24.0


def bound(model_file, prop_id):
    model = load_model(model_file)
    prop = next(p for p in load_properties(PROPS) if p.id == prop_id)
    return model, bind(prop, model)


def run_once(model):
    """The single run from the model's initial state: (times, mode names, states, blocked_at)."""
    traj = Simulator(model, 20.0).run(model.initial.low[None], None, record=True)
    t, modes, x = traj.path[0]
    names = list(model.modes)
    return t, [names[int(m)] for m in modes], x, traj.blocked_at[0]


@pytest.fixture(scope="module")
def supervisor():
    model = load_model(MODEL)
    return model, [bind(p, model) for p in load_properties(PROPS)]


# ------------------------------------------------------------------ star verdicts

def test_star_proves_all_four_requirements(supervisor):
    model, props = supervisor
    assert [p.id for p in props] == ["transient_first", "positive_dwell", "observation_time", "mission_end"]
    for prop in props:
        result = STAR.check(model, prop)
        assert result.status == Status.SAFE, (prop.id, result.details.get("reason"))
        assert result.details["stars"] > 200          # every orbit explored, none cut off


# ------------------------------------------------------------------ independent reference

@pytest.mark.parametrize("model_file, d", [("models/vtxo_supervisor_tmin.yaml", T_MIN), (MODEL, T_MAX)])
def test_simulated_end_matches_closed_form(model_file, d):
    t, names, x, blocked = run_once(load_model(model_file))
    assert np.isnan(blocked)                                   # the run never blocks
    end = t[names.index("end")]
    assert end == pytest.approx(mission_length(d), abs=1e-6)
    assert mission_length(T_MAX) == pytest.approx(3770.0)      # the H of property mission_end
    assert mission_length(T_MIN) == pytest.approx(3767.15)
    # every transient of the run lasted d: entries to and exits from `transient`
    enter = [t[i] for i in range(1, len(t)) if names[i] == "transient" and names[i - 1] != "transient"]
    leave = [t[i] for i in range(1, len(t)) if names[i - 1] == "transient" and names[i] != "transient"]
    assert len(enter) == len(leave) == sum(math.ceil(T / SCIENCE) for T in TABLE6) == 68
    assert np.allclose(np.subtract(leave, enter), d, atol=1e-6)
    final = dict(zip(load_model(model_file).state, x[-1]))
    for name, T in zip(["sco", "gx5", "grs", "cyg", "crab", "cen", "cas", "eta"], TABLE6):
        assert final[f"obs_{name}"] == pytest.approx(T, abs=1e-6)


# ------------------------------------------------------------------ mutants

def test_mutant_without_transient_is_unsafe_with_replayed_counterexample():
    model, prop = bound("models/vtxo_supervisor_no_transient.yaml", "transient_first")
    result = STAR.check(model, prop)
    assert result.status == Status.UNSAFE
    cex = result.counterexample
    assert cex.violation_mode == "science"
    assert cex.violation_time == pytest.approx(60 * 24 + R_FS, abs=1e-6)   # first science entry
    again = replay(model, prop, cex.initial_state, cex.switch_time, cex.dt)
    assert again.violated and again.mode == "science"


def test_mutant_with_short_rule_is_unsafe_with_replayed_counterexample():
    """Cas observed 141 h instead of Table 6's 146 h: found at de-commissioning. The star
    back-end answers UNSAFE only after its own replay violated (one full-mission simulation,
    recorded in ``details``); the counterexample's trajectory shows the shortfall."""
    model, prop = bound("models/vtxo_supervisor_short_cas.yaml", "observation_time")
    result = STAR.check(model, prop, {"replay_dt": 50.0})
    assert result.status == Status.UNSAFE
    assert result.details["replays"][-1]["violated"] is True
    cex = result.counterexample
    assert cex.violation_mode == "decommissioning"
    state = dict(zip(model.state, cex.violation_state))
    assert state["obs_cas"] == pytest.approx(141.0, abs=1e-6)
    assert state["obs_eta"] == pytest.approx(452.0, abs=1e-6)
    # ceil(141 / 10) = 15 orbits as for 146 h: de-commissioning starts when it would have
    assert cex.violation_time == pytest.approx(mission_length(T_MAX) - 5 * 24, abs=1e-6)


# ------------------------------------------------------------------ lint

def test_lint_finds_the_zeno_cycle_and_cli_reports_it(capsys):
    lints = load_model("models/vtxo_supervisor_zeno.yaml").lints
    assert len(lints) == 1 and lints[0].startswith(
        "models/vtxo_supervisor_zeno.yaml: transitions: possible zero-dwell cycle transient -> science "
        "-> transient (no clock reset on it is bounded below by a positive guard, and its jumps slewed, "
        "lock_lost can all be taken twice round at one instant from t=0, c=0")
    assert cli(["lint", "models/vtxo_supervisor_zeno.yaml"]) == 1
    assert "transient -> science -> transient" in capsys.readouterr().out
    # the supervisor itself: no zero-dwell cycle; the lint cannot exclude a run that spends its
    # object's time (rem = 0) after the orbit's end (co > T_orb), where `next` would not take it,
    # though no run gets there (R_fs + t_max + S_max = T_orb), so it names that face in part
    assert cli(["lint", MODEL]) == 1
    out = capsys.readouterr().out
    assert "zero-dwell" not in out and out.count("\n") == 1
    assert "modes.science.invariant" in out and "'next': co <= T_orb" in out
    assert cli(["lint", "models/thermostat.yaml"]) == 0
    assert "no findings" in capsys.readouterr().out
    assert cli(["lint", "models/no_such_model.yaml"]) == 2
    assert cli(["lint", "properties"]) == 2           # a folder of property files holds no model to lint
    assert "properties holds no model file" in capsys.readouterr().err


def test_shipped_models_lint_clean_except_the_zeno_variant():
    """Every model in models/ but the Zeno variant and the region-switched sliding-mode formation
    (whose boundary-layer guards meet, so the lint names a state where a cycle can be taken at
    one instant) is non-Zeno by the lint's conditions; the hysteresis thermostat is clean because
    its guards T >= 21 and T <= 19 cannot hold together."""
    def zeno(model):
        return [line for line in model.lints if "zero-dwell" in line]

    flagged = set()
    for path in sorted(Path("models").glob("*.yaml")):
        if not path.name.startswith("_") and zeno(load_model(path)):
            flagged.add(path.name)
    assert "vtxo_supervisor_zeno.yaml" in flagged
    assert flagged <= {"vtxo_supervisor_zeno.yaml", "vtxo_formation_smc.yaml"}
    for name in ("SRA01", "SRA02", "SRA08", "SRNA01", "SRU01", "vtxo_supervisor", "thermostat",
                 "vtxo_supervisor_tmin", "vtxo_supervisor_short_cas"):
        assert not zeno(load_model(f"models/{name}.yaml")), name
    # the supervisor's `next` is left through eight guards on id bands that cover co = T_orb
    # together: no finding there; the one finding is science's face rem = 0 where co > T_orb
    # (unreachable, see test_lint_finds_the_zeno_cycle_and_cli_reports_it)
    (finding,) = load_model(MODEL).lints
    assert "modes.science.invariant" in finding and "'next': co <= T_orb" in finding


def test_a_reset_off_its_own_guard_is_no_zero_dwell_cycle(tmp_path):
    """A relaxation oscillator (x' = 2 - x, reset to 0.5 at x >= 1.5) takes its self-loop once
    at an instant but never twice: x needs ln 3 = 1.1 time units to climb back. With the reset
    to 1.5 instead, the loop can be taken again at once, without end."""
    doc = {"name": "relax", "state": ["x"], "horizon": 6,
           "modes": {"charge": {"flow": {"x": "2 - x"}, "invariant": ["x <= 1.5"]}},
           "transitions": [{"from": "charge", "to": "charge", "guard": ["x >= 1.5"], "reset": {"x": 0.5},
                            "urgent": True}],
           "initial": {"mode": "charge", "box": {"x": [0, 0.2]}}}
    (tmp_path / "relax.yaml").write_text(yaml.safe_dump(doc))
    assert load_model(tmp_path / "relax.yaml").lints == []
    doc["transitions"][0]["reset"] = {"x": 1.5}
    (tmp_path / "stuck.yaml").write_text(yaml.safe_dump(doc))
    (finding,) = load_model(tmp_path / "stuck.yaml").lints
    assert "zero-dwell cycle charge -> charge" in finding and "from x=1.5" in finding


def test_check_prints_lints_as_warnings(capsys, tmp_path):
    code = cli(["check", "models/vtxo_supervisor_zeno.yaml", PROPS, "--backend", "star",
                "--property", "transient_first", "--option", "max_jumps=3",
                "--counterexamples", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 1     # with t_min = 0 a transient may last 0 s: science entered at ctr - c = 0 < 9 s,
    #                      a witness whose may-jumps at one instant (slewed, lock_lost) replay
    assert err.startswith("warning: models/vtxo_supervisor_zeno.yaml: transitions: possible zero-dwell cycle")


# ---- property test: the lint against a brute-force search on small random automata

CLOCKS = ("x", "y")


def _zeno_by_brute_force(modes, transitions) -> set[tuple[str, ...]]:
    """Mode cycles that some choice of transitions lets a run traverse forever without time
    passing: from large clock values, go round the cycle twice with zero delay, applying
    guards (``clock >= L``) and resets; every simple mode cycle, every transition choice."""
    found = set()
    for k in range(1, len(modes) + 1):
        for cycle in itertools.permutations(modes, k):
            if cycle[0] != min(cycle):
                continue
            steps = list(zip(cycle, cycle[1:] + cycle[:1]))
            options = [[tr for tr in transitions if (tr["from"], tr["to"]) == s] for s in steps]
            for choice in itertools.product(*options):
                value = {c: 100.0 for c in CLOCKS}
                ok = True
                for tr in list(choice) * 2:
                    if any(value[c] < low for c, low in tr["_bounds"].items()):
                        ok = False
                        break
                    value.update(tr["_resets"])
                if ok:
                    found.add(cycle)
                    break
    return found


@st.composite
def automata(draw, reset_values):
    modes = ["a", "b", "c"][:draw(st.integers(1, 3))]
    transitions = []
    for _ in range(draw(st.integers(1, 6))):
        resets = {c: draw(st.sampled_from(reset_values)) for c in CLOCKS if draw(st.booleans())}
        bounds = {c: draw(st.sampled_from([0, 1, 3])) for c in CLOCKS if draw(st.booleans())}
        transitions.append({"from": draw(st.sampled_from(modes)), "to": draw(st.sampled_from(modes)),
                            "_resets": resets, "_bounds": bounds})
    return modes, transitions


def _load(modes, transitions, tmp_path):
    doc = {"name": "random", "state": list(CLOCKS), "horizon": 10,
           "modes": {m: {"flow": {c: 1 for c in CLOCKS}} for m in modes},
           "transitions": [{"from": t["from"], "to": t["to"],
                            "guard": [f"{c} >= {low}" for c, low in t["_bounds"].items()],
                            "reset": dict(t["_resets"])} for t in transitions],
           "initial": {"mode": modes[0], "box": {c: 0 for c in CLOCKS}}}
    path = tmp_path / "random.yaml"
    path.write_text(yaml.safe_dump(doc))
    return load_model(path)


def _lint_cycles(model) -> set[tuple[str, ...]]:
    cycles, complete = zero_dwell_cycles(model)
    assert complete
    return {tuple(modes[:-1]) for modes, _, _ in cycles}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(automata(reset_values=[0]))
def test_lint_equals_brute_force_with_resets_to_zero(tmp_path, case):
    """With every reset to 0 the structural condition is exact."""
    modes, transitions = case
    assert _lint_cycles(_load(modes, transitions, tmp_path)) == _zeno_by_brute_force(modes, transitions)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(automata(reset_values=[0, 2]))
def test_lint_never_misses_a_zeno_cycle(tmp_path, case):
    """With resets to other constants the lint is conservative: it reports every cycle the
    brute force can traverse without time passing (and maybe more)."""
    modes, transitions = case
    assert _lint_cycles(_load(modes, transitions, tmp_path)) >= _zeno_by_brute_force(modes, transitions)
