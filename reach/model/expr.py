"""Safe expression parsing: Python ``ast`` -> sympy through a whitelist.

Model and property files hold expressions as strings (``"3*n**2*x + 2*n*vy + Fx/mc"``,
``"abs(Fx) <= 10[N]"``). They are parsed with :mod:`ast` and only numbers, known names,
``+ - * / **``, calls of the functions in :data:`FUNCTIONS`, comparisons, and unit brackets
are accepted; everything else is an :class:`~reach.errors.InputError`. Nothing is ever
passed to ``eval`` or ``exec``, so a model file from a stranger cannot run code.
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from typing import Mapping

import sympy

from reach.errors import Where
from reach.model.units import SI, UNITS, UnitSystem

MAX_LENGTH = 4000
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

_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_COMPARE = {ast.LtE: "<=", ast.Lt: "<", ast.GtE: ">=", ast.Gt: ">"}


@dataclass(frozen=True)
class Comparison:
    """``lhs op rhs`` with op one of ``<= < >= >``."""

    lhs: sympy.Expr
    op: str
    rhs: sympy.Expr


class _Parser:
    def __init__(self, names: Mapping[str, sympy.Expr], where: Where, units: UnitSystem):
        self.names = names
        self.where = where
        self.units = units

    def fail(self, message: str):
        raise self.where.error(message)

    def expr(self, node: ast.AST, depth: int = 0) -> sympy.Expr:
        if depth > MAX_DEPTH:
            self.fail("expression nested too deeply")
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                self.fail(f"unexpected constant {node.value!r}")
            if not math.isfinite(node.value):
                self.fail("number is not finite")
            return sympy.Integer(node.value) if isinstance(node.value, int) else sympy.Float(node.value)
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id in CONSTANTS:
                return CONSTANTS[node.id]
            if node.id in FUNCTIONS:
                self.fail(f"'{node.id}' is a function; call it as {node.id}(...)")
            self.fail(f"unknown name '{node.id}'")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            operand = self.expr(node.operand, depth + 1)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            left = self.expr(node.left, depth + 1)
            right = self.expr(node.right, depth + 1)
            op = _BINARY[type(node.op)]
            if op == "+":
                return left + right
            if op == "-":
                return left - right
            if op == "*":
                return left * right
            if op == "/":
                if right == 0:
                    self.fail("division by zero")
                return left / right
            if right.is_number and abs(float(right)) > MAX_EXPONENT:
                self.fail(f"exponent {float(right):g} is too large (at most {MAX_EXPONENT})")
            if left == 0 and right.is_number and float(right) < 0:
                self.fail("division by zero")
            return left ** right
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name):
                self.fail("only plain function calls such as sqrt(x) are allowed")
            if node.func.id not in FUNCTIONS:
                self.fail(f"unknown function '{node.func.id}'")
            if node.keywords:
                self.fail(f"{node.func.id}() takes no keyword arguments")
            low, high = ARITY.get(node.func.id, (1, 1))
            if not low <= len(node.args) <= high:
                self.fail(f"{node.func.id}() takes {low if low == high else f'{low} to {high}'}"
                          f" argument{'s' if high > 1 else ''}, got {len(node.args)}")
            args = [self.expr(a, depth + 1) for a in node.args]
            return FUNCTIONS[node.func.id](*args)
        if isinstance(node, ast.Subscript):
            value = self.expr(node.value, depth + 1)
            return value * self.unit(node.slice)
        if isinstance(node, ast.Compare):
            self.fail("a comparison is not allowed here")
        self.fail(f"unsupported syntax '{type(node).__name__}'")

    def unit(self, node: ast.AST) -> sympy.Expr:
        """Scale factor of a bracketed unit expression, in the model's base units."""
        si, dimension = self._unit(node)
        return sympy.Float(self.units.convert(si, dimension))

    def _unit(self, node: ast.AST):
        if isinstance(node, ast.Name):
            if node.id not in UNITS:
                self.fail(f"unknown unit '{node.id}'")
            return UNITS[node.id]
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
        self.fail("a unit must be a product or quotient of unit names, e.g. [m/s] or [kg*m/s**2]")


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
        return ast.parse(text.strip(), mode="eval").body
    except SyntaxError as exc:
        raise where.error(f"cannot parse '{text}': {exc.msg}") from None
    except (ValueError, RecursionError, MemoryError):
        raise where.error(f"cannot parse '{text}'") from None


def parse_expr(text, names: Mapping[str, sympy.Expr], where: Where,
               units: UnitSystem = SI) -> sympy.Expr:
    """Parse an arithmetic expression (no comparison) to sympy."""
    tree = _parse_tree(text, where)
    try:
        return _Parser(names, where, units).expr(tree)
    except (RecursionError, OverflowError, MemoryError, ZeroDivisionError):
        raise where.error(f"expression '{text}' is too large to evaluate") from None


def parse_comparison(text, names: Mapping[str, sympy.Expr], where: Where,
                     units: UnitSystem = SI) -> list[Comparison]:
    """Parse ``a <= b`` (or a chain ``a <= b <= c``) to a list of comparisons."""
    tree = _parse_tree(text, where)
    if not isinstance(tree, ast.Compare):
        raise where.error(f"expected a comparison such as 'x <= 1', got '{text}'")
    parser = _Parser(names, where, units)
    try:
        operands = [parser.expr(tree.left)] + [parser.expr(c) for c in tree.comparators]
    except (RecursionError, OverflowError, MemoryError, ZeroDivisionError):
        raise where.error(f"expression '{text}' is too large to evaluate") from None
    result = []
    for i, op in enumerate(tree.ops):
        if type(op) not in _COMPARE:
            raise where.error(f"only <=, <, >=, > are allowed in '{text}'")
        result.append(Comparison(operands[i], _COMPARE[type(op)], operands[i + 1]))
    return result
