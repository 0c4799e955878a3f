"""Reported figures in the requirement's units, checked against hand conversions.

The ARCH models are in kg, m, min: 1 N = 1 kg m/s^2 = 3600 kg m/min^2, so 10 N = 36000 model
units; 1 m/s = 60 m/min.
"""

import json
import re
from pathlib import Path

import pytest

from reach.cli import main
from reach.model import load_model
from reach.report import figures, json_row, line, quantity
from reach.result import Counterexample, Result, Status
from reach.spec import bind, load_properties


@pytest.fixture(scope="module")
def sra01():
    return load_model("models/SRA01.yaml")


def _prop(model, path, pid):
    return bind(next(p for p in load_properties(path) if p.id == pid), model)


def test_ten_newtons_is_36000_model_units(sra01):
    event = _prop(load_model("models/SRNA01.yaml"), "properties/rendezvous_events.yaml", "thrust_x_max")
    assert event.value == pytest.approx(36000.0)
    assert event.unit.text == "N" and event.unit.scale == pytest.approx(3600.0)
    result = Result("taylor", "SRNA01", event.id, Status.UNKNOWN, bound=(25180.0, 26630.0))
    f = figures(result, event, sra01)
    assert f["bound"] == pytest.approx([25180 / 3600, 26630 / 3600])
    assert f["margin"] == pytest.approx((36000 - 26630) / 3600)
    assert f["required"] == {"op": "<=", "value": pytest.approx(10.0)}
    assert line(result, event, sra01) == "max Fx in [6.994, 7.397] N <= 10 N, margin 2.603 N"
    assert quantity(event, 26630.0, 6) == "7.39722 N"            # as reach replay shows an extremum


def test_safety_margin_in_newtons_next_to_the_requirement(sra01):
    thrust = _prop(sra01, "properties/rendezvous.yaml", "thrust")
    result = Result("montecarlo", "SRA01", "thrust", Status.UNKNOWN, details={"closest_depth": 9371.0})
    assert figures(result, thrust, sra01)["closest_margin"] == pytest.approx(9371 / 3600)
    assert line(result, thrust, sra01).startswith("abs(Fx) <= 10[N], abs(Fy) <= 10[N] (in approach, rendezvous): closest margin 2.603 N")


def test_a_proved_margin_bound_in_newtons(sra01):
    """taylor's safety answer carries the margin bound in model units (kg m/min^2); the line
    shows it in the requirement's N: 9371.15 / 3600 = 2.603, 10817.6 / 3600 = 3.005."""
    thrust = _prop(sra01, "properties/rendezvous.yaml", "thrust")
    result = Result("taylor", "SRA01", "thrust", Status.SAFE, details={"margin_bound": [9371.15, 10817.6]})
    assert figures(result, thrust, sra01)["margin_bound"] == pytest.approx([9371.15 / 3600, 10817.6 / 3600])
    assert line(result, thrust, sra01).startswith(
        "abs(Fx) <= 10[N], abs(Fy) <= 10[N] (in approach, rendezvous): smallest margin in [2.603, 3.005] N")


def test_velocity_margin_in_metres_per_second(sra01):
    velocity = _prop(sra01, "properties/rendezvous.yaml", "velocity")
    result = Result("montecarlo", "SRA01", "velocity", Status.UNKNOWN, details={"closest_depth": 0.07698})
    assert velocity.margin_unit().text == "m/s"
    assert figures(result, velocity, sra01)["closest_margin"] == pytest.approx(0.07698 / 60)


def test_squared_speed_in_the_square_of_the_written_unit():
    model = load_model("models/SRNA01.yaml")
    speed = _prop(model, "properties/rendezvous_events.yaml", "speed")
    assert speed.value == pytest.approx((0.055 * 60) ** 2)             # (m/min)^2
    assert speed.unit.text == "(m/s)**2" and speed.unit.scale == pytest.approx(3600.0)
    result = Result("taylor", model.name, "speed", Status.UNKNOWN, bound=(9.0, 9.9))
    assert figures(result, speed, model)["margin"] == pytest.approx((10.89 - 9.9) / 3600)


def test_a_touching_margin_says_why(sra01):
    los = _prop(sra01, "properties/rendezvous.yaml", "los")
    result = Result("montecarlo", "SRA01", "los", Status.UNKNOWN, details={"closest_depth": -2.8e-14})
    text = line(result, los, sra01)
    assert "closest margin -2.8e-14 m" in text and "touching" in text
    safe_margin = Result("montecarlo", "SRA01", "los", Status.UNKNOWN, details={"closest_depth": 3.0})
    assert "touching" not in line(safe_margin, los, sra01)


def test_metres_in_a_kilometre_model():
    model = load_model("models/fsr_lqr1_reach.yaml")
    dock = _prop(model, "properties/fsr_lqr1_reach.yaml", "dock")
    x_low = dock.target[0]
    assert x_low.unit.text == "m" and x_low.unit.scale == pytest.approx(1e-3)
    corridor = _prop(model, "properties/fsr_lqr1_reach.yaml", "dock_corridor")
    assert corridor.safe[0].unit.text == "km" and corridor.safe[0].unit.scale == 1.0
    result = Result("fsr", model.name, "dock", Status.SAFE, probability=(0.71, 0.72))
    assert line(result, dock, model).startswith("P in [0.71, 0.72], required >= 0.6")


def test_mixed_dimensions_stay_in_model_units(tmp_path, sra01):
    path = tmp_path / "p.yaml"
    path.write_text("properties:\n  - id: mixed\n    kind: safety\n    modes: [passive]\n"
                    "    avoid: {box: {x: ['-1[m]', '1[m]'], vx: ['-1[m/s]', '1[m/s]']}}\n")
    mixed = bind(load_properties(path)[0], sra01)
    assert mixed.margin_unit() is None
    result = Result("montecarlo", "SRA01", "mixed", Status.UNKNOWN, details={"closest_depth": 12.0})
    assert "closest margin 12 (model units)" in line(result, mixed, sra01)


def test_json_keeps_old_keys_and_leaves_the_trajectory_in_its_file(sra01):
    thrust = _prop(sra01, "properties/thrust_7N.yaml", "thrust_7N")
    cex = Counterexample("SRA01", "thrust_7N", "models/SRA01.yaml", "properties/thrust_7N.yaml",
                         [0.0] * 5, 120.0, 0.0, "approach", [0.0] * 5, 0.1,
                         trajectory={"t": [0.0, 0.1], "mode": ["approach"] * 2, "x": [[0.0] * 5] * 2})
    result = Result("star", "SRA01", "thrust_7N", Status.UNSAFE, counterexample=cex)
    row = json_row(result, thrust, sra01, "out/cex.json")
    for key in ("property", "status", "seconds", "backend", "model", "bound", "probability", "details"):
        assert key in row
    assert "trajectory" not in row["counterexample"]
    assert row["counterexample"]["trajectory_file"] == "out/cex.json"
    assert row["report"]["unit"] == "N" and row["report"]["time_unit"] == "min"
    assert json_row(result, thrust, sra01)["counterexample"]["trajectory"]["t"] == [0.0, 0.1]
    assert "violated at t=0 min in approach, switch at t=120 min" in line(result, thrust, sra01)


def test_cli_text_and_json_agree_on_the_margin(capsys, tmp_path):
    args = ["check", "models/SRA01.yaml", "properties/rendezvous.yaml", "--backend", "montecarlo",
            "--property", "thrust", "--option", "samples=40", "--option", "search_rounds=0",
            "--counterexamples", str(tmp_path)]
    main(args + ["--json"])
    row = json.loads(capsys.readouterr().out)[0]
    depth = row["details"]["closest_depth"]                              # kg m/min^2
    assert row["report"]["closest_margin"] == pytest.approx(depth / 3600)
    main(args)
    text = capsys.readouterr().out
    assert f"closest margin {depth / 3600:.4g} N" in text


def test_a_star_counterexample_is_measured_against_the_requirement(sra01):
    """At the corner (-925, -375) at rest the ARCH gain K1 asks Fx = K1[0] . x (kg m/min^2)."""
    thrust = _prop(sra01, "properties/thrust_7N.yaml", "thrust_7N")
    corner = [-925.0, -375.0, 0.0, 0.0, 0.0]
    fx = (-28.82867767694 * -925.0 + 0.1004799482599 * -375.0) / 3600     # N, from the model file
    cex = Counterexample("SRA01", "thrust_7N", "models/SRA01.yaml", "properties/thrust_7N.yaml",
                         corner, 120.0, 0.0, "approach", corner, 0.1)
    result = Result("star", "SRA01", "thrust_7N", Status.UNSAFE, counterexample=cex)
    f = figures(result, thrust, sra01)
    assert fx == pytest.approx(7.3969, abs=1e-4)
    assert f["violation_margin"] == pytest.approx(7.0 - fx, rel=1e-9)
    assert f"margin {7.0 - fx:.4g} N at the violation" in line(result, thrust, sra01)


def test_an_avoided_set_reads_as_avoid(tmp_path, sra01):
    path = tmp_path / "p.yaml"
    path.write_text("properties:\n  - id: wall\n    kind: safety\n    modes: [passive]\n"
                    "    avoid: ['x >= 5[m]']\n")
    wall = bind(load_properties(path)[0], sra01)
    result = Result("montecarlo", "SRA01", "wall", Status.UNKNOWN, details={"closest_depth": 60.0})
    assert line(result, wall, sra01).startswith("avoid x >= 5[m] (in passive): closest margin 60 m")


def test_a_model_without_units_shows_no_unit_of_time():
    """The thermostat declares no units: its times carry none (not the SI default "s"), while
    a model in minutes says so, in the report line and on a plot's time axis."""
    from reach.plotting.axes import make_axis

    root = Path(__file__).resolve().parents[1]
    thermostat, sra01 = load_model(root / "models" / "thermostat.yaml"), load_model(root / "models" / "SRA01.yaml")
    assert thermostat.time_unit == "" and make_axis(thermostat, "time").label == "time"
    assert sra01.time_unit == "min" and make_axis(sra01, "time").label == "time [min]"
    prop = next(p for p in load_properties(root / "properties" / "thermostat.yaml") if p.id == "below_20p5")
    cex = Counterexample(model="thermostat", property=prop.id, model_file="m.yaml", property_file="p.yaml",
                         initial_state=[19.5], switch_time=None, violation_time=1.25, violation_mode="heating",
                         violation_state=[20.6], dt=0.01)
    text = line(Result("montecarlo", "thermostat", prop.id, Status.UNSAFE, counterexample=cex),
                bind(prop, thermostat), thermostat)
    assert "violated at t=1.25 in heating" in text


def test_an_avoided_union_reads_as_a_union(tmp_path):
    """A forbidden set of several pieces is their union, ``avoid A or B``, with the modes named
    where a piece does not apply in all (the Gearbox cfg forbids ``move_free & t >= 0.2`` or
    ``I >= 20``); one piece of several constraints reads as their conjunction."""
    from reach.checking import check_spaceex
    from reach.report import requirement
    gearbox = "models/spaceex/Gearbox/GRBX01-MES01"
    _, _, _, merged = check_spaceex(gearbox + ".xml", gearbox + ".cfg", "montecarlo", {"samples": 10})
    assert requirement(merged["GRBX01-MES01"]) == "avoid I >= 20 or t >= 0.2 (in loc01__move_free)"
    model = load_model("models/thermostat.yaml")
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: band, kind: safety, modes: [heating], avoid: ['T >= 30', 'T <= 31']}\n")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    assert requirement(prop) == "avoid T >= 30 and T <= 31"


@pytest.mark.parametrize("written", ["(2*T) >= 70.0", "(T - 1) >= 30 and T <= 31", "T >= (30)"])
def test_an_avoided_set_reads_as_written(tmp_path, written):
    """A constraint that opens or closes with a parenthesis is shown whole: the text of one piece is
    never trimmed, only pieces joined by ``or`` are parenthesised."""
    from reach.report import requirement
    model = load_model("models/thermostat.yaml")
    constraints = written.split(" and ")
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: p, kind: safety, modes: [heating], avoid: [%s]}\n"
        % ", ".join(f"'{c}'" for c in constraints))
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    assert requirement(prop) == "avoid " + written


def test_a_counterexample_replays_from_any_working_folder(tmp_path, monkeypatch, capsys):
    """The saved counterexample names its model and property files relative to itself, so the
    replay finds them from another folder (and after the folder is moved with its files)."""
    import shutil
    work = tmp_path / "project"
    (work / "models").mkdir(parents=True)
    (work / "properties").mkdir()
    shutil.copy("models/thermostat.yaml", work / "models")
    shutil.copy("properties/thermostat.yaml", work / "properties")
    monkeypatch.chdir(work)
    assert main(["check", "models/thermostat.yaml", "properties/thermostat.yaml", "-b", "star",
                 "--counterexamples", "out"]) == 1
    saved = json.loads((work / "out" / "thermostat_below_20p5_star.json").read_text())
    assert saved["model_file"] == str(Path("..") / "models" / "thermostat.yaml")
    moved = tmp_path / "moved"
    shutil.move(str(work), str(moved))
    monkeypatch.chdir(tmp_path)
    capsys.readouterr()
    assert main(["replay", str(moved / "out" / "thermostat_below_20p5_star.json")]) == 1
    out = capsys.readouterr().out
    assert "replayed: thermostat violates 'below_20p5'" in out
    # the margin at the violating state is that state's distance past the bound T <= 20.5
    T = float(re.search(r"state T=([-\d.e]+)", out).group(1))
    there = float(re.search(r"margin ([-\d.e]+) \(model units\) there", out).group(1))
    assert there == pytest.approx(20.5 - T, abs=1e-5) and there < 0


def test_a_note_that_explains_a_negative_margin_is_said_once(sra01):
    """A bound reaching past the requirement (margin -0.5 N) with the back-end's note on why it is
    open: the note explains the margin and is not repeated after it."""
    event = _prop(load_model("models/SRNA01.yaml"), "properties/rendezvous_events.yaml", "thrust_x_max")
    note = "the bound is open on 25% of the box; -o refine=2 halves the subdomains that hold it open"
    result = Result("taylor", "SRNA01", event.id, Status.UNKNOWN, bound=(25180.0, 37800.0), details={"note": note})
    text = line(result, event, sra01)
    assert "margin -0.5 N" in text and text.count(note) == 1


@pytest.mark.parametrize("description", ["", "y3 stays within 1.7e-4 (ISU02)"])
def test_a_requirement_written_out_over_many_states_is_shown_short(tmp_path, description):
    """An imported output (an alias of 270 states, as ISS's y3) writes a requirement of
    thousands of characters: the line shows the property's description instead, or the text cut
    at MAX_REQUIREMENT_CHARS."""
    from reach.report import MAX_REQUIREMENT_CHARS
    names = [f"x{i}" for i in range(200)]
    (tmp_path / "m.yaml").write_text(
        f"name: wide\nstate: [{', '.join(names)}]\nmodes:\n  m: {{flow: {{{', '.join(n + ': 0' for n in names)}}}}}\n"
        f"initial: {{mode: m, box: {{{', '.join(n + ': 0' for n in names)}}}}}\nhorizon: 1\n")
    long = " + ".join(f"0.001*{n}" for n in names) + " <= 1"
    extra = f", description: \"{description}\"" if description else ""
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: out, kind: safety{extra}, require: [\"{long}\"]}}\n")
    model = load_model(tmp_path / "m.yaml")
    prop = bind(load_properties(tmp_path / "p.yaml")[0], model)
    result = Result("star", model.name, "out", Status.SAFE, details={})
    shown = line(result, prop, model)
    assert len(shown) < MAX_REQUIREMENT_CHARS + 80
    assert (description in shown) if description else "0.001*x0 + 0.001*x1" in shown and "..." in shown
