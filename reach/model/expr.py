"""Safe expression parsing: Python ``ast`` -> sympy through a whitelist, with dimensions.

Model and property files hold expressions as strings (``"3*n**2*x + 2*n*vy + Fx/mc"``,
``"abs(Fx) <= 10[N]"``). They are parsed with :mod:`ast` and only numbers, known names,
``+ - * / **`` (``^`` is read as ``**``), calls of the functions in :data:`FUNCTIONS`,
comparisons, and unit brackets are accepted; everything else is an :class:`~reach.errors.InputError`. Nothing is ever
passed to ``eval`` or ``exec``, so a model file from a stranger cannot run code.

With a :class:`DimensionContext` the parser also computes each subexpression's dimension
as an affine form in the unknown dimensions of the names (:mod:`reach.model.units`) and
equates the two sides of every sum and comparison; a contradiction is an InputError that
names both sides: ``0.055[m] compared with abs(vx) [m/min]``. Plain numbers are free:
they take the dimension of what they meet (they are written in model units).
"""

from __future__ import annotations

import ast
import math
import warnings
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Mapping

import sympy

from reach.errors import Where
from reach.model.units import (DIMENSIONLESS, SI, UNITS, DimensionSystem, DisplayUnit, Form, UnitSystem,
                               bracket_display, known_units, model_display)

MAX_LENGTH = 200_000
MAX_DEPTH = 60
MAX_EXPONENT = 64


def _sat(arg):
    return sympy.Max(-1, sympy.Min(1, arg))


FUNCTIONS = {
    "sqrt": sympy.sqrt, "sin": sympy.sin, "cos": sympy.cos, "tan": sympy.tan,
    "asin": sympy.asin, "acos": sympy.acos, "atan": sympy.atan, "atan2": sympy.atan2,
    "sinh": sympy.sinh, "cosh": sympy.cosh, "tanh": sympy.tanh,
    "exp": sympy.exp, "log": sympy.log, "abs": sympy.Abs, "sign": sympy.sign,
    "min": sympy.Min, "max": sympy.Max, "sat": _sat,
}
ARITY = {"atan2": (2, 2), "min": (2, 16), "max": (2, 16)}
CONSTANTS = {"pi": sympy.pi}
# dimension rules: the result has the argument's dimension (abs), half of it (sqrt), all
# arguments share one (min, max, atan2), or the argument must be a pure number (the rest)
_SAME = {"abs"}
_SHARED = {"min", "max", "atan2"}
_ANY_ARGUMENT = {"sign"}

_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_COMPARE = {ast.LtE: "<=", ast.Lt: "<", ast.GtE: ">=", ast.Gt: ">"}


@dataclass(frozen=True)
class Comparison:
    """``lhs op rhs`` with op one of ``<= < >= >``; ``dimension`` of both sides if known, and
    the ``unit`` the requirement was written in (its bracketed unit, else the model's)."""

    lhs: sympy.Expr
    op: str
    rhs: sympy.Expr
    dimension: tuple | None = None
    unit: DisplayUnit | None = None


@dataclass
class DimensionContext:
    """What dimension checking needs: the equations so far, the model's units and the names
    whose dimensions are unknowns of the system (states, inputs, constants)."""

    system: DimensionSystem
    units: UnitSystem
    names: frozenset
    brackets: list = field(default_factory=list)      # (text, SI value, dimension) seen

    def show(self, form: Form) -> str:
        """``[m/min]`` for a known dimension, ``[dimension unknown]`` otherwise."""
        value = self.system.value(form)
        return f"[{self.units.name(value)}]" if value is not None else "[dimension unknown]"

    def require(self, a: Form | None, b: Form | None, where: Where, message) -> None:
        """Equate ``a`` and ``b`` (None: a plain number, equal to anything); on a contradiction
        raise ``message(show(a), show(b))`` at ``where``."""
        if a is None or b is None:
            return
        shown = self.show(a), self.show(b)
        if not self.system.equate(a, b):
            raise where.error(message(*shown))

    def display(self, form: Form | None, brackets: list) -> tuple[tuple | None, DisplayUnit | None]:
        """Dimension of ``form`` and the unit to show it in: the first bracketed unit it is a
        power of, else the unit a single state or input was declared in (``w: rad/s``), else the
        model's unit."""
        if form is None:
            return None, None
        value = self.system.value(form)
        if value is None:
            return None, None
        (name, k), = form.coeffs.items() if len(form.coeffs) == 1 else ((None, 0),)
        declared = [self.system.written[name]] if k == 1 and name in self.system.written else []
        for text, si, dim in list(brackets) + declared:
            shown = bracket_display(self.units, value, text, si, dim)
            if shown is not None:
                return value, shown
        return value, model_display(self.units, value)


def _fraction(value: sympy.Expr) -> Fraction | None:
    """A numeric exponent as an exact fraction (floats from constants snapped to 1/1000ths)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(number):
        return None
    exact = Fraction(number).limit_denominator(1000)
    return exact if abs(float(exact) - number) <= 1e-12 * max(1.0, abs(number)) else None


def _is_literal(node: ast.AST) -> bool:
    """``100[N]`` or ``-0.055[m/s]``: a number with its unit, shown without a dimension."""
    while isinstance(node, ast.UnaryOp):
        node = node.operand
    return isinstance(node, ast.Subscript) and isinstance(node.value, ast.Constant)


def _has_bracket(node: ast.AST) -> bool:
    return any(isinstance(n, ast.Subscript) for n in ast.walk(node))


class _Parser:
    def __init__(self, names: Mapping[str, sympy.Expr], where: Where, units: UnitSystem,
                 dims: DimensionContext | None = None, source: str = ""):
        self.names = names
        self.where = where
        self.units = units
        self.dims = dims
        self.source = source

    def fail(self, message: str):
        raise self.where.error(message)

    def text(self, node: ast.AST) -> str:
        return _quoted((ast.get_source_segment(self.source, node) if self.source else None) or ast.unparse(node))

    def side(self, node: ast.AST, shown: str) -> str:
        return self.text(node) if _is_literal(node) else f"{self.text(node)} {shown}"

    def meet(self, a_node, a: Form | None, b_node, b: Form | None, verb: str) -> Form | None:
        """``a`` and ``b`` must have one dimension (a sum, a comparison, min/max arguments)."""
        if self.dims is None or a is None or b is None:
            return a if b is None else b
        first, second = (b_node, a_node) if _has_bracket(b_node) and not _has_bracket(a_node) else (a_node, b_node)

        def message(shown_a, shown_b):
            shown = {id(a_node): shown_a, id(b_node): shown_b}
            return f"{self.side(first, shown[id(first)])} {verb} {self.side(second, shown[id(second)])}"

        self.dims.require(a, b, self.where, message)
        return a

    def pure(self, node, form: Form | None, what: str) -> Form | None:
        """``form`` must be dimensionless (function arguments, exponents)."""
        if self.dims is None or form is None:
            return None
        self.dims.require(form, Form(), self.where,
                          lambda shown, _: f"{what} must be a pure number, got {self.side(node, shown)}")
        return Form()

    def expr(self, node: ast.AST, depth: int = 0) -> tuple[sympy.Expr, Form | None]:
        """The sympy expression and its dimension (None: a plain number)."""
        if depth > MAX_DEPTH:
            self.fail("expression nested too deeply")
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                self.fail(f"unexpected constant {node.value!r}")
            if not math.isfinite(node.value):
                self.fail("number is not finite")
            value = sympy.Integer(node.value) if isinstance(node.value, int) else sympy.Float(node.value)
            return value, None
        if isinstance(node, ast.Name):
            if node.id in self.names:
                form = Form.name(node.id) if self.dims is not None and node.id in self.dims.names else None
                return self.names[node.id], form
            if node.id in CONSTANTS:
                return CONSTANTS[node.id], None
            if node.id in FUNCTIONS:
                self.fail(f"'{node.id}' is a function; call it as {node.id}(...)")
            self.fail(f"unknown name '{node.id}'")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            operand, form = self.expr(node.operand, depth + 1)
            return (-operand if isinstance(node.op, ast.USub) else operand), form
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return self.binary(node, depth)
        if isinstance(node, ast.Call):
            return self.call(node, depth)
        if isinstance(node, ast.Subscript):
            value, form = self.expr(node.value, depth + 1)
            si, dim = self._unit(node.slice)
            if self.dims is not None:
                self.dims.brackets.append((self.text(node.slice), si, dim))
            unit = Form(const=dim)
            return value * sympy.Float(self.units.convert(si, dim)), unit if form is None else form.plus(unit)
        if isinstance(node, ast.Compare):
            self.fail("a comparison is not allowed here")
        self.fail(f"unsupported syntax '{type(node).__name__}'")

    def binary(self, node: ast.BinOp, depth: int):
        op = _BINARY[type(node.op)]
        if op in ("+", "-"):
            return self.sum(node, depth)
        (left, lf), (right, rf) = self.expr(node.left, depth + 1), self.expr(node.right, depth + 1)
        if op == "*":
            return left * right, (rf if lf is None else lf if rf is None else lf.plus(rf))
        if op == "/":
            if right == 0:
                self.fail("division by zero")
            return left / right, (lf if rf is None else rf.times(Fraction(-1)) if lf is None else lf.minus(rf))
        if right.is_number and not right.is_real:
            self.fail(f"exponent '{self.text(node.right)}' is not a real number")
        if right.is_number and abs(float(right)) > MAX_EXPONENT:
            self.fail(f"exponent {float(right):g} is too large (at most {MAX_EXPONENT})")
        if left == 0 and right.is_number and float(right) < 0:
            self.fail("division by zero")
        self.pure(node.right, rf, "an exponent")
        form = None
        if lf is not None:
            k = _fraction(right) if right.is_number else None
            form = lf.times(k) if k is not None else self.pure(node.left, lf, "the base of a power with a non-rational exponent")
        return left ** right, form

    def sum(self, node: ast.BinOp, depth: int):
        """A chain ``a + b - c + ...`` (nested to the left in the syntax tree) read term by term:
        its length is no nesting (a linear form of 270 terms, as in the ISS model)."""
        chain = []
        while isinstance(node, ast.BinOp) and _BINARY.get(type(node.op)) in ("+", "-"):
            chain.append(node)
            node = node.left
        first, form = self.expr(node, depth + 1)
        terms = [first]
        for link in reversed(chain):
            term, tf = self.expr(link.right, depth + 1)
            plus = _BINARY[type(link.op)] == "+"
            form = self.meet(link.left, form, link.right, tf, "added to" if plus else "subtracted from")
            terms.append(term if plus else -term)
        return sympy.Add(*terms), form

    def call(self, node: ast.Call, depth: int):
        if not isinstance(node.func, ast.Name):
            self.fail("only plain function calls such as sqrt(x) are allowed")
        name = node.func.id
        if name not in FUNCTIONS:
            self.fail(f"unknown function '{name}'")
        if node.keywords:
            self.fail(f"{name}() takes no keyword arguments")
        low, high = ARITY.get(name, (1, 1))
        if not low <= len(node.args) <= high:
            self.fail(f"{name}() takes {low if low == high else f'{low} to {high}'}"
                      f" argument{'s' if high > 1 else ''}, got {len(node.args)}")
        parsed = [self.expr(a, depth + 1) for a in node.args]
        value = FUNCTIONS[name](*[p[0] for p in parsed])
        forms = [p[1] for p in parsed]
        if name in _SHARED:
            form = forms[0]
            for arg, f in zip(node.args[1:], forms[1:]):
                form = self.meet(node.args[0], form, arg, f, f"compared with (in {name}())")
            if name == "atan2":
                form = None if form is None else Form()
        elif name in _SAME:
            form = forms[0]
        elif name == "sqrt":
            form = None if forms[0] is None else forms[0].times(Fraction(1, 2))
        elif name in _ANY_ARGUMENT:
            form = None if forms[0] is None else Form()
        else:
            form = self.pure(node.args[0], forms[0], f"the argument of {name}()")
        return value, form

    def _unit(self, node: ast.AST):
        """SI value and dimension of a bracketed unit expression."""
        if isinstance(node, ast.Name):
            if node.id not in UNITS:
                self.fail(f"unknown unit '{node.id}' (known: {known_units()})")
            si, dim = UNITS[node.id]
            return si, tuple(Fraction(d) for d in dim)
        if isinstance(node, ast.Constant) and type(node.value) is int and node.value == 1:
            return 1.0, DIMENSIONLESS
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Mult, ast.Div)):
            (a, da), (b, db) = self._unit(node.left), self._unit(node.right)
            sign = 1 if isinstance(node.op, ast.Mult) else -1
            return (a * b if sign == 1 else a / b,
                    tuple(x + sign * y for x, y in zip(da, db)))
        if (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow)
                and isinstance(node.right, ast.Constant) and type(node.right.value) is int
                and abs(node.right.value) <= 4):
            a, da = self._unit(node.left)
            k = node.right.value
            return a ** k, tuple(x * k for x in da)
        self.fail("a unit must be a product or quotient of unit names, e.g. [m/s], [1/min] or [kg*m/s**2]")


def _parse_tree(text, where: Where) -> ast.AST:
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise where.error(f"expected an expression, got {type(text).__name__}")
    if isinstance(text, (int, float)):
        if not math.isfinite(text):
            raise where.error("number is not finite")
        return ast.Constant(text)
    if len(text) > MAX_LENGTH:
        raise where.error(f"expression longer than {MAX_LENGTH} characters")
    if not text.strip():
        raise where.error("empty expression")
    try:
        return _parse(text)
    except SyntaxError as exc:
        raise where.error(f"cannot parse '{_quoted(text)}': {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise where.error(f"cannot parse '{_quoted(text)}': too many operations in one chain for "
                          "Python's parser (at most about a thousand terms)") from None
    except ValueError:
        raise where.error(f"cannot parse '{_quoted(text)}'") from None


def _quoted(text) -> str:
    """``text`` as a message quotes it: whole up to 120 characters, else its start and its
    length (an imported linear form can run to thousands; a bad input is one short line)."""
    text = str(text).strip()
    return text if len(text) <= 120 else f"{text[:100]}... ({len(text)} characters)"


def _source(text) -> str:
    return _python_syntax(text) if isinstance(text, str) else ""


def _python_syntax(text: str) -> str:
    """``text`` as Python writes it: ``^`` is the power, as engineers and SpaceEx write it
    (``x^2``, ``[m/s^2]``), so it becomes ``**`` (with its precedence: ``m/s^2`` is
    ``m/(s^2)``); Python's ``^`` (exclusive or) has no meaning here."""
    return text.strip().replace("^", "**")


def parse_quantity(text, names: Mapping[str, sympy.Expr], where: Where, units: UnitSystem = SI,
                   dims: DimensionContext | None = None) -> tuple[sympy.Expr, Form | None]:
    """Parse an arithmetic expression (no comparison): sympy value and dimension form (None
    for a plain number, or when ``dims`` is None)."""
    tree = _parse_tree(text, where)
    if dims is not None:
        dims.brackets = []
    try:
        value, form = _Parser(names, where, units, dims, _source(text)).expr(tree)
    except (RecursionError, OverflowError, MemoryError, ZeroDivisionError):
        raise where.error(f"expression '{_quoted(text)}' is too large to evaluate") from None
    _check_numbers(value, text, where)
    return value, form


def _check_numbers(value: sympy.Expr, text, where: Where) -> None:
    """Every number folded into ``value`` fits a float: ``1e308*1e308`` folds to 1e616, which
    the back-ends would evaluate as inf (and inf - inf as NaN); and every part of it without a
    variable is a finite real number: ``sqrt(-1)`` (the imaginary unit), ``log(0)`` (complex
    infinity), ``asin(2)`` (complex) and ``exp(exp(exp(10)))`` (beyond a float) would make a
    flow or a bound no real model has, which a back-end could only misread."""
    for number in value.atoms(sympy.Number):
        try:
            finite = math.isfinite(float(number))
        except (TypeError, ValueError, OverflowError):
            finite = False
        if not finite:
            raise where.error(f"expression '{_quoted(text)}' holds a number out of the floating-point range")
    walk = sympy.preorder_traversal(value)
    for part in walk:
        if part.free_symbols:
            continue
        walk.skip()                     # its parts are parts of this constant
        if part.is_Number:
            continue
        try:
            z = complex(sympy.N(part, 17))
            real = math.isfinite(z.real) and z.imag == 0
        except (TypeError, ValueError, OverflowError, ZeroDivisionError):
            real = False
        if not real:
            raise where.error(f"expression '{_quoted(text)}': '{part}' is not a finite real number")


def parse_expr(text, names: Mapping[str, sympy.Expr], where: Where, units: UnitSystem = SI,
               dims: DimensionContext | None = None) -> sympy.Expr:
    """Parse an arithmetic expression (no comparison) to sympy."""
    return parse_quantity(text, names, where, units, dims)[0]


def parse_comparison(text, names: Mapping[str, sympy.Expr], where: Where,
                     units: UnitSystem = SI, dims: DimensionContext | None = None) -> list[Comparison]:
    """Parse ``a <= b`` (or a chain ``a <= b <= c``, or one equality ``a == b``) to a list of
    comparisons."""
    tree = _parse_tree(text, where)
    if not isinstance(tree, ast.Compare):
        raise where.error(f"expected a comparison such as 'x <= 1', got '{_quoted(text)}'")
    parser = _Parser(names, where, units, dims, _source(text))
    if dims is not None:
        dims.brackets = []
    nodes = [tree.left] + list(tree.comparators)
    try:
        operands = [parser.expr(node) for node in nodes]
    except (RecursionError, OverflowError, MemoryError, ZeroDivisionError):
        raise where.error(f"expression '{_quoted(text)}' is too large to evaluate") from None
    for value, _ in operands:
        _check_numbers(value, text, where)
    result = []
    if len(tree.ops) == 1 and isinstance(tree.ops[0], ast.Eq):     # an equality: two opposite rows
        (lhs, lf), (rhs, rf) = operands
        form = parser.meet(nodes[0], lf, nodes[1], rf, "compared with")
        dimension, unit = dims.display(form, dims.brackets) if dims is not None else (None, None)
        return [Comparison(lhs, "==", rhs, dimension, unit)]
    for i, op in enumerate(tree.ops):
        if type(op) not in _COMPARE:
            raise where.error(f"only <=, <, >=, > (or one ==) are allowed in '{_quoted(text)}'")
        (lhs, lf), (rhs, rf) = operands[i], operands[i + 1]
        form = parser.meet(nodes[i], lf, nodes[i + 1], rf, "compared with")
        dimension, unit = dims.display(form, dims.brackets) if dims is not None else (None, None)
        result.append(Comparison(lhs, _COMPARE[type(op)], rhs, dimension, unit))
    return result


def _parse(text: str) -> ast.expr:
    """The expression tree of ``text``; Python's warnings about it (``1abc``: "invalid decimal
    literal") are not printed, since a bad input is reported in one line."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SyntaxWarning)
        return ast.parse(_python_syntax(text), mode="eval").body


def side_text(text, shown: str) -> str:
    """How an error shows an expression: ``100[N]`` as written, anything else followed by its
    dimension ``shown`` (``abs(vx) [m/min]``)."""
    if isinstance(text, str):
        try:
            if _is_literal(_parse(text)):
                return text.strip()
        except (SyntaxError, ValueError, RecursionError):
            pass
    return f"{text} {shown}"


def parse_unit(text, where: Where) -> tuple[float, tuple]:
    """A unit on its own (``m/min``, ``kg*m/s**2``, ``1``): SI value and dimension."""
    if isinstance(text, int) and not isinstance(text, bool) and text == 1:
        return 1.0, DIMENSIONLESS
    if not isinstance(text, str) or not text.strip():
        raise where.error("expected a unit such as m, m/s or kg*m/s**2 (1 for a pure number)")
    tree = _parse_tree(text, where)
    return _Parser({}, where, SI, None, text.strip())._unit(tree)

