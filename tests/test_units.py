"""Dimensions: declarations, inference through the flows, and mismatches as one-line errors."""

from fractions import Fraction
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.cli import main
from reach.errors import InputError, Where
from reach.model import load_model
from reach.model.expr import DimensionContext, parse_comparison, parse_expr
from reach.model.units import UNITS, DimensionSystem, Form, UnitSystem, dimension
from reach.spec import bind, load_properties

MINUTES = UnitSystem("m", "min", "kg")
W = Where("p.yaml", "require[0]", 4)

# ------------------------------------------------------------------ the solver


def test_system_reduces_and_detects_contradictions():
    system = DimensionSystem()
    velocity = dimension(1, -1)
    assert system.equate(Form.name("x"), Form(const=dimension(1)))
    # x' = vx: d_vx = d_x - time
    assert system.equate(Form.name("vx"), Form.name("x").minus(Form(const=dimension(time=1))))
    assert system.of("vx") == velocity
    # 2 d_n + d_x = d_vx - time: n is a rate
    assert system.equate(Form.name("n").times(Fraction(2)).plus(Form.name("x")),
                         Form.name("vx").minus(Form(const=dimension(time=1))))
    assert system.of("n") == dimension(time=-1)
    # Fx - mc is an acceleration; neither is known until one of them is
    assert system.equate(Form.name("Fx").minus(Form.name("mc")), Form(const=dimension(1, -2)))
    assert system.of("Fx") is None and system.of("mc") is None
    assert system.equate(Form.name("mc"), Form(const=dimension(mass=1)))
    assert system.of("Fx") == dimension(1, -2, 1)
    assert not system.equate(Form.name("vx"), Form.name("x"))
    assert system.of("vx") == velocity            # a refused equation leaves the system as it was


unit_names = st.sampled_from(sorted(UNITS))


@st.composite
def unit_expressions(draw):
    """A bracket unit such as ``kg*m/min**2`` and its exponent vector."""
    text, dim = "", (0, 0, 0, 0)
    for i in range(draw(st.integers(1, 3))):
        name = draw(unit_names)
        power = draw(st.integers(1, 2))
        divide = i > 0 and draw(st.booleans())
        sign = -1 if divide else 1
        part = name if power == 1 else f"{name}**{power}"
        text = part if i == 0 else f"{text}{'/' if divide else '*'}{part}"
        dim = tuple(d + sign * power * u for d, u in zip(dim, UNITS[name][1]))
    return text, dim


def _context(declared: dict) -> DimensionContext:
    system = DimensionSystem()
    for name, dim in declared.items():
        system.equate(Form.name(name), Form(const=tuple(Fraction(d) for d in dim)))
    return DimensionContext(system, MINUTES, frozenset(declared))


@settings(max_examples=150, deadline=None)
@given(unit_expressions(), unit_expressions())
def test_a_bracket_is_compatible_iff_the_exponents_agree(a, b):
    (_, da), (ub, db) = a, b
    dims = _context({"q": da})
    text = f"q <= 2[{ub}]"
    if da == db:
        (cmp,) = parse_comparison(text, {"q": parse_expr("1", {}, W)}, W, MINUTES, dims)
        assert cmp.dimension == tuple(Fraction(d) for d in da)
    else:
        with pytest.raises(InputError) as err:
            parse_comparison(text, {"q": parse_expr("1", {}, W)}, W, MINUTES, dims)
        assert f"2[{ub}] compared with q [" in str(err.value)


def test_every_term_of_a_long_sum_is_checked():
    """A sum is read term by term (no nesting limit): the last of 200 terms still meets the rest."""
    assert float(parse_expr(" + ".join(["1[km]"] * 200), {}, W, MINUTES, _context({}))) == pytest.approx(2e5)
    with pytest.raises(InputError, match="added to"):
        parse_expr(" + ".join(["1[m]"] * 200 + ["1[s]"]), {}, W, MINUTES, _context({}))


@settings(max_examples=150, deadline=None)
@given(unit_expressions(), unit_expressions())
def test_a_sum_of_brackets_needs_one_dimension_and_converts_both(a, b):
    (ua, da), (ub, db) = a, b
    dims = _context({})
    text = f"3[{ua}] + 5[{ub}]"
    if da != db:
        with pytest.raises(InputError, match="added to"):
            parse_expr(text, {}, W, MINUTES, dims)
        return
    value = float(parse_expr(text, {}, W, MINUTES, dims))
    si_a = parse_expr(f"1[{ua}]", {}, W).evalf()
    si_b = parse_expr(f"1[{ub}]", {}, W).evalf()
    expected = float((3 * si_a + 5 * si_b)) / MINUTES.factor(da)   # SI sum, then to model units
    assert value == pytest.approx(expected, rel=1e-12)


def test_plain_numbers_take_the_dimension_they_meet_and_functions_want_pure_numbers():
    dims = _context({"x": (1, 0, 0, 0)})
    names = {"x": parse_expr("1", {}, W)}
    parse_comparison("3*x + 2 <= 5", names, W, MINUTES, dims)
    parse_comparison("x*tan(pi/6) <= 5[km]*cos(30[deg])", names, W, MINUTES, dims)
    with pytest.raises(InputError, match=r"the argument of sin\(\) must be a pure number, got x \[m\]"):
        parse_expr("sin(x)", names, W, MINUTES, dims)
    with pytest.raises(InputError, match=r"30\[deg\] compared with x \[m\]"):
        parse_comparison("x <= 30[deg]", names, W, MINUTES, dims)


def test_unit_names_in_model_units():
    assert MINUTES.name(dimension(1, -2, 1)) == "kg*m/min**2"
    assert MINUTES.name(dimension(0, -1)) == "1/min"
    assert MINUTES.name(dimension(Fraction(3, 2), -1)) == "m**(3/2)/min"
    assert MINUTES.name(dimension(-1, -2, 1)) == "kg/(m*min**2)"
    assert MINUTES.name(dimension()) == "1"


# ------------------------------------------------------------------ models


def _write(tmp_path: Path, name: str, data: dict) -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _model(**changes) -> dict:
    data = {"name": "m", "units": {"length": "m", "time": "min", "mass": "kg"},
            "constants": {"n": 0.001, "mc": "500[kg]"},
            "state": {"x": "m", "vx": "m/min", "t": "min"}, "inputs": ["F"],
            "modes": {"a": {"flow": {"x": "vx", "vx": "n**2*x + F/mc", "t": 1}, "control": {"F": "-mc*n*vx"}}},
            "initial": {"mode": "a", "box": {"x": [-1, 1], "vx": "0.01[m/s]", "t": 0}}, "horizon": "2[h]"}
    data.update(changes)
    return data


def test_inference_through_flows_and_laws(tmp_path):
    model = load_model(_write(tmp_path, "m.yaml", _model()))
    assert model.dimension_of("n") == dimension(time=-1)
    assert model.dimension_of("F") == dimension(1, -2, 1)
    assert model.units.name(model.dimension_of("F")) == "kg*m/min**2"
    assert model.horizon == pytest.approx(120.0)
    assert model.initial.low[1] == pytest.approx(0.6)


@pytest.mark.parametrize("changes, line", [
    ({"modes": {"a": {"flow": {"x": "vx*vx", "vx": "n**2*x + F/mc", "t": 1}, "control": {"F": 0}}}},
     "modes.a.flow.x: vx*vx [m**2/min**2] is not a rate of x: expected [m/min]"),
    ({"modes": {"a": {"flow": {"x": "vx", "vx": "n**2*x + F/mc", "t": 1}, "control": {"F": "-mc*vx"}}}},
     "modes.a.control.F: -mc*vx [kg*m/min] given for F [kg*m/min**2]"),
    ({"horizon": "2[m]"}, "horizon: 2[m] given for the horizon [min]"),
    ({"initial": {"mode": "a", "box": {"x": "1[s]", "vx": 0, "t": 0}}}, "initial.box.x: 1[s] given for x [m]"),
    ({"state": {"x": "m", "vx": "m/s", "t": "min"}}, "state.vx: 'm/s' is not in the model's units"),
])
def test_model_mismatches_name_the_field(tmp_path, changes, line):
    path = _write(tmp_path, "m.yaml", _model(**changes))
    with pytest.raises(InputError) as err:
        load_model(path)
    assert line in str(err.value)
    assert str(err.value).startswith(f"{path}:")


def test_a_model_without_declarations_is_not_checked(tmp_path):
    data = _model(state=["x", "vx", "t"])
    del data["units"]
    data["constants"] = {"n": 0.001, "mc": 500}
    data["initial"] = {"mode": "a", "box": {"x": [-1, 1], "vx": 0, "t": 0}}
    data["horizon"] = 100
    model = load_model(_write(tmp_path, "m.yaml", data))
    assert model.dimensions is None and model.dimension_of("x") is None
    props = _write(tmp_path, "p.yaml", {"properties": [
        {"id": "p", "kind": "safety", "require": ["x <= 5[N]", "vx <= 1"]}]})
    bound = bind(load_properties(props)[0], model)
    assert bound.margin_unit() is None


# ------------------------------------------------------------------ the two probes on SRA02

PROBES = """properties:
  - id: position
    kind: safety
    modes: [rendezvous]
    require: ["x >= -100[N]"]
  - id: speed
    kind: safety
    modes: [rendezvous]
    require: ["abs(vx) <= 0.055[m]"]
"""


def test_the_two_wrong_unit_probes_are_rejected_with_both_sides(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text(PROBES)
    model = load_model("models/SRA02.yaml")
    position, speed = load_properties(path)
    lines = []
    for prop in (position, speed):
        with pytest.raises(InputError) as err:
            bind(prop, model)
        lines.append(str(err.value))
    assert lines == [f"{path}:5: properties[0].require[0]: -100[N] compared with x [m]",
                     f"{path}:9: properties[1].require[0]: 0.055[m] compared with abs(vx) [m/min]"]


def test_the_cli_gives_the_probe_line_and_bad_input(tmp_path, capsys):
    path = tmp_path / "p.yaml"
    path.write_text(PROBES)
    code = main(["check", "models/SRA02.yaml", str(path), "--backend", "star", "--property", "speed"])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{path}:9: properties[1].require[0]: 0.055[m] compared with abs(vx) [m/min]" in err
    assert "Traceback" not in err


# ------------------------------------------------------------------ every shipped file

MODELS = sorted(p for p in Path(__file__).resolve().parent.parent.glob("models/*.yaml"))
def test_a_model_that_declares_no_dimension_is_not_checked():
    """The thermostat writes T' = -0.1 (T - 10) + 3 with no units: its plain rate constant is not
    refused, and no dimension is claimed for T."""
    model = load_model(Path(__file__).resolve().parent.parent / "models" / "thermostat.yaml")
    assert model.dimensions is None and model.dimension_of("T") is None


SUITE = yaml.safe_load((Path(__file__).resolve().parent.parent / "suite.yaml").read_text())


UNDIMENSIONED = {"thermostat.yaml"}      # degrees Celsius: no temperature among the base dimensions


@pytest.mark.parametrize("path", [p for p in MODELS if not p.name.startswith("_") and p.name not in UNDIMENSIONED],
                         ids=lambda p: p.name)
def test_every_shipped_model_loads_with_dimensions(path):
    model = load_model(path)
    assert model.dimensions is not None
    unknown = [v for v in model.state + model.inputs + list(model.constants) if model.dimension_of(v) is None]
    assert unknown == [], f"{path.name}: no dimension for {unknown}"
    for v in model.state:
        if all(m.flow[model.index(v)] == 1 for m in model.modes.values()):
            assert model.dimension_of(v) == dimension(time=1)       # a clock is a time


@pytest.mark.parametrize("path", [p for p in MODELS if p.name.startswith("_")], ids=lambda p: p.name)
def test_every_template_serves_a_model_that_loads(path):
    children = [p for p in MODELS if (yaml.safe_load(p.read_text()) or {}).get("extends") == path.name]
    assert children
    for child in children:
        if not child.name.startswith("_"):
            load_model(child)


@pytest.mark.parametrize("instance", SUITE["instances"], ids=lambda i: i["id"])
def test_every_suite_property_binds_with_its_model(instance):
    model = load_model(instance["model"])
    for prop in load_properties(instance["properties"]):
        bind(prop, model)


def test_every_property_file_binds_wherever_its_names_exist():
    """No shipped property file meets a dimension error on any shipped model it can name."""
    root = Path(__file__).resolve().parent.parent
    models = [load_model(p) for p in MODELS if not p.name.startswith("_")]
    checked = 0
    for path in sorted(root.glob("properties/*.yaml")):
        for prop in load_properties(path):
            for model in models:
                try:
                    bind(prop, model)
                    checked += 1
                except InputError as err:
                    assert "unknown name" in str(err) or "beyond the model horizon" in str(err), str(err)
    assert checked > 100


@pytest.mark.parametrize("prop, line", [
    ({"id": "e", "kind": "event", "modes": ["approach"], "maximize": "Fx", "require": "<= 10[m]"},
     "properties[0].require: 10[m] compared with Fx [kg*m/min**2]"),
    ({"id": "b", "kind": "safety", "modes": ["passive"], "avoid": {"box": {"x": ["-1[s]", "1[m]"]}}},
     "properties[0].avoid.box.x: -1[s] compared with x [m]"),
    ({"id": "s", "kind": "safety", "require": ["x + 1[m/s] <= 0"]},
     "properties[0].require[0]: 1[m/s] added to x [m]"),
    ({"id": "l", "kind": "safety", "require": ["max(x, vx) <= 0"]},
     "properties[0].require[0]: x [m] compared with (in max()) vx [m/min]"),
])
def test_property_mismatches_name_the_field_and_both_sides(tmp_path, prop, line):
    path = _write(tmp_path, "p.yaml", {"properties": [prop]})
    with pytest.raises(InputError) as err:
        bind(load_properties(path)[0], load_model("models/SRA01.yaml"))
    assert str(err.value).endswith(line)


def test_reach_time_and_disturbance_are_checked(tmp_path):
    path = _write(tmp_path, "p.yaml", {"properties": [
        {"id": "r", "kind": "reach", "at": "500[m]", "target": {"box": {"x": ["-1[m]", "1[m]"]}}}]})
    with pytest.raises(InputError, match=r"'at' must be a time \[s\], got 500\[m\]"):
        bind(load_properties(path)[0], load_model("models/fsr_burn.yaml"))
    data = yaml.safe_load(Path("models/fsr_burn.yaml").read_text())
    data["disturbance"]["gaussian"]["cov"] = ["(0.05[m])**2"]
    with pytest.raises(InputError, match=r"disturbance.gaussian.cov: \(0.05\[m\]\)\*\*2 \[km\*\*2\] given for "
                                         r"the variance of vy \[km\*\*2/s\*\*2\]"):
        load_model(_write(tmp_path, "m.yaml", data))


@settings(max_examples=25, deadline=None)
@given(st.tuples(*[st.integers(-2, 2)] * 3), st.integers(1, 4))
def test_inference_down_a_chain_of_derivatives(base, length):
    """x0 compared with a constant of dimension D and x_i' = x_(i+1): x_i has dimension
    D - i*time."""
    import tempfile

    units = UnitSystem("km", "h", "g")
    names = [f"x{i}" for i in range(length + 1)]
    flows = {n: names[i + 1] for i, n in enumerate(names[:-1])}
    flows[names[-1]] = 0
    data = {"name": "chain", "units": {"length": "km", "time": "h", "mass": "g"},
            "constants": {"d0": f"1[{units.name(dimension(*base))}]"}, "state": names,
            "modes": {"a": {"flow": flows, "invariant": [f"{names[0]} <= d0"]}},
            "initial": {"mode": "a", "box": {n: 0 for n in names}}, "horizon": 1}
    with tempfile.TemporaryDirectory() as tmp:
        model = load_model(_write(Path(tmp), "m.yaml", data))
    for i, n in enumerate(names):
        assert model.dimension_of(n) == dimension(base[0], base[1] - i, base[2])


@pytest.mark.parametrize("text", ["x**sqrt(-1)", "x**log(-1)", "x**log(0)"])
def test_a_complex_exponent_is_bad_input(text):
    with pytest.raises(InputError, match="is not a real number"):
        parse_expr(text, {"x": parse_expr("1", {}, W)}, W)


def test_temperature_is_a_fourth_base_dimension():
    """Kelvin converts by scale (1[mK] = 0.001 K), rates read K/min in a minute model, and a
    temperature never meets a length."""
    dims = _context({"T": (0, 0, 0, 1)})
    names = {"T": parse_expr("1", {}, W)}
    assert float(parse_expr("5[mK]", {}, W, MINUTES, dims)) == pytest.approx(0.005, rel=1e-15)
    parse_comparison("T <= 300[K] + 5[mK]", names, W, MINUTES, dims)
    with pytest.raises(InputError, match=r"compared with T \[K\]"):
        parse_comparison("T <= 3[m]", names, W, MINUTES, dims)
    assert MINUTES.name(dimension(temperature=1, time=-1)) == "K/min"
    # 2 W for 60 s is 120 J = 120 kg m^2/s^2 = 120 * 3600 kg m^2/min^2
    assert float(parse_expr("2[W]*60[s]", {}, W, MINUTES, dims)) == pytest.approx(120.0 * 3600.0, rel=1e-12)


def test_a_plain_bound_reads_in_the_unit_its_state_was_declared_in(tmp_path, capsys):
    """``w: rad/s`` reduces to 1/s (an angle is a pure number), but a requirement on ``w`` alone
    shows its margin in rad/s; a bracket in the requirement still wins (deg/s), a sum of two
    states keeps the model's unit, and the margin's number is the same in each."""
    data = {"name": "spin", "units": {"length": "m", "time": "s", "mass": "kg"},
            "state": {"th": "rad", "w": "rad/s"},
            "modes": {"coast": {"flow": {"th": "w", "w": "-0.01[1/s^2]*th - 0.1[1/s]*w"}}},
            "initial": {"mode": "coast", "box": {"th": [0.1, 0.2], "w": [0, 0.01]}}, "horizon": 20}
    model = load_model(_write(tmp_path, "spin.yaml", data))
    props = _write(tmp_path, "p.yaml", {"properties": [
        {"id": "rate", "kind": "safety", "require": ["w <= 0.001"]},
        {"id": "angle", "kind": "safety", "require": ["th <= 0.5"]},
        {"id": "rate_deg", "kind": "safety", "require": ["w <= 0.3[deg/s]"]},
        {"id": "sum", "kind": "safety", "require": ["w + 0.1[1/s]*th <= 1[1/s]"]}]})
    rate, angle, rate_deg, both = (bind(p, model) for p in load_properties(props))
    assert rate.margin_unit().text == "rad/s" and rate.margin_unit().scale == pytest.approx(1.0)
    assert angle.margin_unit().text == "rad"
    assert rate_deg.margin_unit().text == "deg/s"
    assert both.margin_unit().text == "1/s"
    assert main(["check", str(tmp_path / "spin.yaml"), str(props), "-b", "montecarlo", "-p", "rate",
                 "--counterexamples", str(tmp_path / "cx")]) == 1
    assert "margin -0.009 rad/s at the violation" in capsys.readouterr().out
