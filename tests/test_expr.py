"""The expression parser: whitelist only, units, constraint normalisation."""

import math

import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.errors import InputError, Where
from reach.model.constraints import affine_coefficients, from_comparisons
from reach.model.expr import parse_comparison, parse_expr
from reach.model.units import UnitSystem

x, y = sympy.symbols("x y", real=True)
NAMES = {"x": x, "y": y, "k": sympy.Float(2.0)}
W = Where("m.yaml", "modes.a.flow.x", 3)


def test_arithmetic_and_functions():
    e = parse_expr("3*k**2*x + sqrt(y) - abs(x)/2 + atan2(y, x)", NAMES, W)
    expected = 12 * x + sympy.sqrt(y) - sympy.Abs(x) / 2 + sympy.atan2(y, x)
    assert sympy.simplify(e - expected) == 0


def test_units_convert_to_model_base_units():
    minutes = UnitSystem(length="m", time="min", mass="kg")
    assert float(parse_expr("10[N]", {}, W, minutes)) == pytest.approx(36000.0)
    assert float(parse_expr("0.055[m/s]", {}, W, minutes)) == pytest.approx(3.3)
    assert float(parse_expr("42164[km]", {}, W)) == pytest.approx(42164e3)
    assert float(parse_expr("3.986e14[m**3/s**2]", {}, W, minutes)) == pytest.approx(3.986e14 * 3600)


def test_a_long_linear_form_is_no_deep_nesting():
    """A sum of 300 terms (an output row of a large model) is a chain, not nesting; each
    coefficient lands where it belongs. Parentheses nested beyond the limit are still refused."""
    names = {f"x{i}": sympy.Symbol(f"x{i}", real=True) for i in range(300)}
    text = " ".join(f"{'-' if i % 3 else '+'} {i + 0.5}*x{i}" for i in range(300))
    e = parse_expr(text, names, W)
    for i in (0, 1, 2, 299):
        assert float(e.coeff(names[f"x{i}"])) == (-1 if i % 3 else 1) * (i + 0.5)
    with pytest.raises(InputError, match="nested too deeply"):
        parse_expr("(" * 80 + "x" + ")*2" * 80, NAMES, W)


def test_a_long_expression_is_quoted_short_in_its_message():
    """A bad input is one short line: an unparsable 200-term form (an imported alias) or a
    chain past Python's parser shows its start and length, not its thousands of characters."""
    names = {f"x{k}": sympy.Symbol(f"x{k}") for k in range(200)}
    bad = " + ".join(f"0.123456789*x{k}" for k in range(200)) + " +"
    with pytest.raises(InputError) as info:
        parse_expr(bad, names, Where("m.yaml", "flow.x0", 4))
    message = str(info.value)
    assert message.startswith("m.yaml:4: flow.x0: cannot parse '0.123456789*x0 + 0.123456789*x1")
    assert f"... ({len(bad)} characters)" in message and len(message) < 250
    chain = "+".join(["x1"] * 20000)
    with pytest.raises(InputError, match=r"too many operations in one chain .*\(59999 characters\)|"
                                         r"\(59999 characters\).*too many operations"):
        parse_expr(chain, names, Where("m.yaml", "flow.x0", 4))


@pytest.mark.parametrize("caret, power", [
    ("x^2", "x**2"), ("-x^2 + y", "-x**2 + y"), ("k*x^3/y^2", "k*x**3/y**2"), ("2^-1*x", "2**-1*x")])
def test_caret_is_the_power(caret, power):
    """``^`` reads as ``**`` with the power's precedence (``-x^2`` is ``-(x^2)``)."""
    assert sympy.simplify(parse_expr(caret, NAMES, W) - parse_expr(power, NAMES, W)) == 0


def test_caret_in_a_unit_is_the_power_of_the_last_name():
    """``[m/s^2]`` is metres per second squared, not ``(m/s)^2``."""
    minutes = UnitSystem(length="m", time="min", mass="kg")
    assert float(parse_expr("1[m/s^2]", {}, W, minutes)) == pytest.approx(3600.0)
    assert float(parse_expr("2[kg*m/s^2]", {}, W, minutes)) == pytest.approx(7200.0)


@pytest.mark.parametrize("text, message", [
    ("__import__('os').system('true')", "only plain function calls"),
    ("eval('1')", "unknown function 'eval'"),
    ("x.__class__", "unsupported syntax 'Attribute'"),
    ("[x for x in y]", "unsupported syntax"),
    ("lambda: 1", "unsupported syntax 'Lambda'"),
    ("vyy + 1", "unknown name 'vyy'"),
    ("9**9**9", "too large"),
    ("'abc'", "unexpected constant"),
    ("x +", "cannot parse"),
    ("10[furlong]", "unknown unit 'furlong'"),
    ("sin(x, y)", "takes 1 argument"),
    ("x / 0", "division by zero"),
])
def test_rejections_name_the_place(text, message):
    with pytest.raises(InputError) as err:
        parse_expr(text, NAMES, W)
    assert message in str(err.value)
    assert str(err.value).startswith("m.yaml:3: modes.a.flow.x: ")


def test_abs_comparison_splits_in_two_halfspaces():
    cons = from_comparisons(parse_comparison("abs(x - y) <= 3", NAMES, W), "abs(x - y) <= 3", W)
    rows = sorted(tuple(affine_coefficients(c.g, [x, y])[0]) + (affine_coefficients(c.g, [x, y])[1],)
                  for c in cons)
    assert rows == [(-1.0, 1.0, -3.0), (1.0, -1.0, -3.0)]


def test_chained_comparison():
    cons = from_comparisons(parse_comparison("-1 <= x < 2", NAMES, W), "", W)
    assert [c.strict for c in cons] == [False, True]
    assert [sympy.simplify(c.g) for c in cons] == [-x - 1, x - 2]


def test_negation_is_the_complement():
    (con,) = from_comparisons(parse_comparison("x <= 1", NAMES, W), "x <= 1", W)
    neg = con.negated()
    assert neg.strict and sympy.simplify(neg.g - (1 - x)) == 0


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet="xyk0123456789+-*/().,[]<=> _abcdefgimnoqrstuvw'\"", max_size=40))
def test_random_text_parses_to_an_expression_in_the_known_names_or_is_one_located_line(text):
    """Any text either parses to a sympy expression over the known names only, or raises an
    InputError of the form ``file:line: field: message`` on a single line; nothing else escapes."""
    try:
        e = parse_expr(text, NAMES, W)
    except InputError as err:
        message = str(err)
        assert message.startswith("m.yaml:3: modes.a.flow.x: ") and "\n" not in message
        assert len(message) > len("m.yaml:3: modes.a.flow.x: ")
        return
    assert isinstance(e, sympy.Basic) and e.free_symbols <= {x, y}


FUNCTIONS_1 = {"sin": math.sin, "cos": math.cos, "exp": math.exp, "atan": math.atan, "abs": abs,
               "tanh": math.tanh}
POINT = {"x": 1.3, "y": -0.7, "k": 2.0}


def _compound(sub):
    return st.one_of(
        st.tuples(sub, st.sampled_from(["+", "-", "*", "/"]), sub).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(st.sampled_from(sorted(FUNCTIONS_1)), sub).map(lambda t: f"{t[0]}({t[1]})"),
        st.tuples(sub, st.sampled_from(["2", "3"])).map(lambda t: f"({t[0]})**{t[1]}"),
        st.tuples(st.sampled_from(["min", "max", "atan2"]), sub, sub).map(lambda t: f"{t[0]}({t[1]}, {t[2]})"),
        sub.map(lambda t: f"-{t}"))


# no ``pi`` among the leaves: ``sin(pi)`` is exactly 0 to sympy but 1.2e-16 to Python
EXPRESSIONS = st.recursive(st.sampled_from(["x", "y", "k", "2", "0.5", "3"]), _compound, max_leaves=8)


@settings(max_examples=200, deadline=None)
@given(EXPRESSIONS)
def test_random_expressions_evaluate_like_python(text):
    """Reference: Python's own evaluation of the same text with the math module."""
    namespace = {"__builtins__": {}, "pi": math.pi, "min": min, "max": max, "atan2": math.atan2,
                 **FUNCTIONS_1, **POINT}
    try:
        expected = eval(text, namespace)           # the text comes from the grammar above only
    except (ZeroDivisionError, OverflowError, ValueError):
        return
    try:
        parsed = parse_expr(text, NAMES, W)
    except InputError as error:         # atan2(x - x, ...) folds to atan2(0, 0), undefined: refused
        assert "atan2" in text and "floating-point range" in str(error)
        return
    value = complex(parsed.subs({x: POINT["x"], y: POINT["y"]}).evalf(30))
    if value != value:                  # atan2(0, 0): undefined to sympy, 0 to Python
        assert "atan2" in text
        return
    assert value.imag == pytest.approx(0.0, abs=1e-9 * (1 + abs(expected)))
    assert value.real == pytest.approx(expected, rel=1e-9, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e6, 1e6, allow_nan=False), st.floats(-1e6, 1e6, allow_nan=False))
def test_parsed_affine_expression_evaluates_like_python(a, b):
    e = parse_expr(f"({a!r})*x + ({b!r})*y - 7", NAMES, W)
    value = float(e.subs({x: 1.5, y: -2.0}))
    assert math.isclose(value, a * 1.5 - b * 2.0 - 7, rel_tol=1e-12, abs_tol=1e-6)


@pytest.mark.parametrize("text", ["sqrt(-1)*x", "log(0)*x", "x + asin(2)", "exp(exp(exp(10)))*x",
                                  "x*(-8)**(1/3)", "acos(1.5) <= x"])
def test_a_constant_part_that_is_no_finite_real_number_is_bad_input(text):
    """``sqrt(-1)`` folds to the imaginary unit, ``log(0)`` to complex infinity; ``asin(2)`` is
    complex and ``exp(exp(exp(10)))`` beyond a float: a model holding one has no real runs (star
    once proved such a flow SAFE), so the expression is refused where it is written."""
    with pytest.raises(InputError, match="not a finite real number|out of the floating-point range"):
        if "<=" in text:
            parse_comparison(text, NAMES, W)
        else:
            parse_expr(text, NAMES, W)


@settings(max_examples=60, deadline=None)
@given(a=st.floats(-50, 50), b=st.floats(0.01, 50))
def test_real_constant_parts_are_kept(a, b):
    """Constant parts that are finite reals (``sqrt(b)``, ``exp(a)``, ``atan(a)``, ``pi``) pass
    and keep their value."""
    e = parse_expr(f"sqrt({b!r})*x + exp({a!r}) + atan({a!r})*pi", NAMES, W)
    value = float(e.subs(x, 2.0))
    assert value == pytest.approx(math.sqrt(b) * 2 + math.exp(a) + math.atan(a) * math.pi, rel=1e-12)
