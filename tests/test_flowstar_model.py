"""The Flow* model written by benchmarks/flowstar_srna01.py is the automaton reach loads.

The printed flows are parsed back (Flow*'s ``^`` read as a power) and evaluated against the
model's own vectorised flow; numbers must match Flow*'s lexer; the dump splice keeps the
flowpipes and replaces only the unsafe block.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import numpy as np
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.model import load_model
from reach.spec import bind, load_properties

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("flowstar_srna01", ROOT / "benchmarks" / "flowstar_srna01.py")
fs = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = fs
_spec.loader.exec_module(fs)

# Flow* 2.1.0 modelLexer.l: the number token, an optional "-" and one of these forms
DIGIT = "[0-9]"
NUMBER_FORMS = [rf"{DIGIT}+", rf"{DIGIT}*\.{DIGIT}*", rf"{DIGIT}+e({DIGIT}+|-{DIGIT}+)",
                rf"{DIGIT}*\.{DIGIT}*e({DIGIT}+|-{DIGIT}+)", rf"{DIGIT}*\.{DIGIT}*e(\+{DIGIT}+|-{DIGIT}+)"]
NUMBERS = [re.compile(f"-?({form})") for form in NUMBER_FORMS]
FLOWSTAR_NUMBER = re.compile("|".join(f"(-?({form}))" for form in NUMBER_FORMS))
IDENT = re.compile(r"[a-zA-Z_][a-zA-Z_0-9.]*")


def tokens(text: str) -> list[tuple[str, str]]:
    """Flow*'s lexer on ``text`` (longest match, as flex): ``(kind, lexeme)``."""
    out, pos = [], 0
    while pos < len(text):
        if text[pos].isspace():
            pos += 1
            continue
        candidates = [(m.end(), kind) for kind, rx in [("num", r) for r in NUMBERS] + [("ident", IDENT)]
                      if (m := rx.match(text, pos)) and m.end() > pos]
        end, kind = max(candidates, default=(pos + 1, "op"))
        out.append((kind, text[pos:end]))
        pos = end
    return out


def assert_parses_as_written(text: str) -> None:
    """No number token swallows a minus sign after an operand (``x -3`` is IDENT NUM for Flow*)."""
    toks = tokens(text)
    for (k0, l0), (k1, l1) in zip(toks, toks[1:]):
        assert not (k1 == "num" and l1.startswith("-") and (k0 in ("num", "ident") or l0 == ")")), text


def read_back(text: str, names) -> sympy.Expr:
    """Flow* expression text as sympy (test-side reader of our own output)."""
    local = {n: sympy.Symbol(n) for n in names}
    local["sqrt"] = sympy.sqrt
    return sympy.sympify(text.replace("^", "**"), locals=local)


def test_srna01_flows_printed_for_flowstar_equal_the_model_flows():
    model = load_model(ROOT / "models" / "SRNA01.yaml")
    rng = np.random.default_rng(3)
    X = np.column_stack([rng.uniform(-1000, 100, 200), rng.uniform(-450, 100, 200),
                         rng.uniform(-5, 5, 200), rng.uniform(-5, 5, 200), rng.uniform(0, 240, 200)])
    for mode in model.modes.values():
        texts = [fs.flowstar_text(sympy.N(fs.scale_powers(f, mode.symbols), 17)) for f in mode.flow]
        for text in texts:
            assert_parses_as_written(text)
        printed = [read_back(text, model.state) for text in texts]
        fn = sympy.lambdify([sympy.symbols(model.state)], printed, modules="numpy")
        got = np.column_stack([np.broadcast_to(np.asarray(c, float), X.shape[:1]) for c in fn(X.T)])
        np.testing.assert_allclose(got, mode.rhs(X), rtol=1e-11, atol=1e-9)


def test_scaled_gravity_has_bases_of_order_one():
    """The rewrite ``b**e = c**e (b/c)**e`` leaves no fractional power of a base near 1.8e15."""
    model = load_model(ROOT / "models" / "SRNA01.yaml")
    f = fs.scale_powers(model.modes["approach"].flow[2], model.modes["approach"].symbols)
    bases = [p.base for p in f.atoms(sympy.Pow) if not p.exp.is_integer]
    assert bases
    for b in bases:
        assert abs(float(b.subs({s: 0 for s in model.modes["approach"].symbols})) - 1.0) < 1e-15


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=0, max_value=1e300, allow_nan=False, allow_infinity=False))
def test_numbers_are_flowstar_tokens_with_the_same_value(v):
    text = fs.number(v)
    assert FLOWSTAR_NUMBER.fullmatch(text), text
    assert float(text) == v


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.floats(-1e6, 1e6, allow_nan=False), st.integers(0, 3), st.integers(0, 3)),
                min_size=1, max_size=5),
       st.floats(0.5, 1e8), st.sampled_from([-3, -1, 1, 3]))
def test_printed_expressions_read_back_to_the_same_function(terms, shift, half_power):
    """Polynomials with signed coefficients, divided by a half-integer power of a positive base.

    The tolerance is relative to the size of the summands (``sum |c| |x|^i |y|^j`` times the power),
    not of the sum: terms that cancel (``x^2 y^2 (a + b x)`` at ``x = -a/b``) leave a value near 0
    whose rounding is that of the summands."""
    x, y = sympy.symbols("x y")
    poly = sum(sympy.Float(c) * x**i * y**j for c, i, j in terms)
    base = x**2 + y**2 + sympy.Float(shift)
    expr = poly * base**sympy.Rational(half_power, 2)
    text = fs.flowstar_text(sympy.N(fs.scale_powers(expr, [x, y]), 17))
    assert_parses_as_written(text)
    back = read_back(text, ["x", "y"])
    for px, py in [(0.3, -1.7), (-2.0, 0.5), (10.0, 4.0)]:
        want = float(expr.subs({x: px, y: py}))
        got = float(back.subs({x: px, y: py}))
        size = sum(abs(c) * abs(px)**i * abs(py)**j for c, i, j in terms) \
            * float(base.subs({x: px, y: py}))**(half_power / 2)
        assert abs(got - want) <= 1e-9 * max(1.0, size)


def test_dump_splice_replaces_only_the_unsafe_block():
    model = load_model(ROOT / "models" / "SRNA01.yaml")
    props = [bind(p, model) for p in load_properties(ROOT / "properties" / "rendezvous.yaml")]
    piece = fs.unsafe_pieces(model, props)["velocity"][0][1]
    dump = ("state var x,y\n\ncomputation paths\n{\n}\n\ngnuplot octagon x , y\n\noutput srna01\n\n"
            "unsafe\n{\nrendezvous\n{\n(1.000000) * y <= 0.000000\n}\n}\n\nhybrid flowpipes\n{\nTMS\n}\n")
    out = fs.check_on_dump(dump, {"rendezvous": piece})
    assert "output srna01" not in out and "\nno output\n" in out
    assert "(1.000000) * y" not in out
    assert out.count("unsafe\n{") == 1 and fs.constraint_text(piece[0]) in out
    assert out.endswith("\nhybrid flowpipes\n{\nTMS\n}\n")


def test_only_the_open_piece_outside_the_invariant_is_left_to_the_lp():
    """``x < -100`` cannot hold in the rendezvous mode (invariant ``x >= -100``); every other
    piece of the two property files goes to Flow*."""
    model = load_model(ROOT / "models" / "SRNA01.yaml")
    props = [bind(p, model) for f in fs.PROPERTY_FILES for p in load_properties(f)]
    outside = [(pid, k) for pid, plist in fs.unsafe_pieces(model, props).items()
               for k, (mode, piece) in enumerate(plist) if fs.outside_invariant(model.modes[mode], piece)]
    assert outside == [("los", 0)]
