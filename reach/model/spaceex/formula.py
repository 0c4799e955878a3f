"""SpaceEx formulas: invariants, flows, guards, assignments, and the cfg's initial/forbidden sets.

Grammar (sspaceex 0.2, the part in scope)::

    formula := conj (("|" | "||") conj)*
    conj    := unit (("&" | "&&") unit)*
    unit    := "(" formula ")" | "true" | "false" | "loc(" [name] ")" "==" name | relation
    relation:= expr (op expr)+        op in <= < >= > == := =   (chains: a <= x <= b)
    expr    := arithmetic over numbers, names (dotted: inst.x), x' (a derivative), + - * / ^,
               calls of whitelisted functions

A formula is returned in disjunctive normal form: a list of conjunctions of atoms. Expressions
stay token lists until :func:`to_python` renames their names and writes Python syntax (``^`` ->
``**``) for the whitelisted expression parser (never ``eval``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import NamedTuple

from reach.errors import InputError
from reach.model.expr import FUNCTIONS

MAX_TERMS = 256
MAX_NESTING = 200       # parentheses within parentheses: Python's own parser allows no more
MAX_DIGITS = 4000       # digits in one number: Python reads no longer integer (4300 digits)
_TOKEN = re.compile(r"""
    (?P<num>(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*)
  | (?P<op><=|>=|==|:=|&&|\|\||[-+*/^(),<>=&|'])
  | (?P<space>\s+)
""", re.VERBOSE)
COMPARISONS = ("<=", ">=", "==", ":=", "=", "<", ">")


class Token(NamedTuple):
    kind: str          # "num" | "name" | "op"
    text: str


@dataclass
class Relation:
    """``parts[0] ops[0] parts[1] ...``; each part a token list."""

    parts: list[list[Token]]
    ops: list[str]


@dataclass
class Loc:
    """``loc(component) == location`` (component None: ``loc()``)."""

    component: str | None
    location: str


@dataclass
class Const:
    value: bool


class FormulaError(Exception):
    """A formula outside the accepted grammar; ``construct`` names what was met."""


def tokenize(text: str) -> list[Token]:
    out, pos = [], 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise FormulaError(f"unexpected character '{text[pos]}'")
        pos = m.end()
        if m.lastgroup == "num" and too_many_digits(m.group()):
            raise FormulaError(digits_message(m.group()))
        if m.lastgroup != "space":
            out.append(Token(m.lastgroup, m.group()))
    return out


def too_many_digits(number: str) -> bool:
    """Does ``number`` have more than :data:`MAX_DIGITS` digits? (No double needs them, and the
    expression parser would refuse it in Python's own words.)"""
    return sum(c.isdigit() for c in number) > MAX_DIGITS


def digits_message(number: str) -> str:
    digits = sum(c.isdigit() for c in number)
    return f"the number '{number[:20]}...' has too many digits ({digits}; at most {MAX_DIGITS})"


class _Parser:
    def __init__(self, tokens: list[Token]):
        self.t = tokens
        self.i = 0

    def peek(self, k: int = 0) -> Token | None:
        j = self.i + k
        return self.t[j] if j < len(self.t) else None

    def take(self, text: str | None = None) -> Token:
        tok = self.peek()
        if tok is None or (text is not None and tok.text != text):
            raise FormulaError(f"expected '{text}'" + (f" before '{tok.text}'" if tok else " at the end"))
        self.i += 1
        return tok

    def formula(self) -> list[list]:
        terms = self.conj()
        while self.peek() is not None and self.peek().text in ("|", "||"):
            self.take()
            terms = terms + self.conj()
            if len(terms) > MAX_TERMS:
                raise FormulaError(f"more than {MAX_TERMS} disjuncts (the import reads at most {MAX_TERMS}: each becomes a property of its own)")
        return terms

    def conj(self) -> list[list]:
        terms = self.unit()
        while self.peek() is not None and self.peek().text in ("&", "&&"):
            self.take()
            right = self.unit()
            if len(terms) == len(right) == 1:
                terms[0].extend(right[0])        # a plain conjunction: linear in its length
            else:
                terms = [a + b for a in terms for b in right]
            if len(terms) > MAX_TERMS:
                raise FormulaError(f"more than {MAX_TERMS} disjuncts (the import reads at most {MAX_TERMS}: each becomes a property of its own)")
        return terms

    def unit(self) -> list[list]:
        tok = self.peek()
        if tok is None:
            raise FormulaError("empty formula")
        if tok.text == "(" and self._group_is_formula():
            self.take("(")
            inner = self.formula()
            self.take(")")
            return inner
        if tok.kind == "name" and tok.text in ("true", "false") and self._ends_atom(1):
            self.take()
            return [[Const(tok.text == "true")]]
        if tok.kind == "name" and tok.text == "loc" and self.peek(1) is not None and self.peek(1).text == "(":
            self.take()
            self.take("(")
            comp = None
            if self.peek() is not None and self.peek().kind == "name":
                comp = self.take().text
            self.take(")")
            self.take("==")
            name = self.take()
            if name.kind != "name":
                raise FormulaError("expected a location name after 'loc(...) =='")
            return [[Loc(comp, name.text)]]
        return [[self.relation()]]

    def _ends_atom(self, k: int) -> bool:
        nxt = self.peek(k)
        return nxt is None or nxt.text in ("&", "&&", "|", "||", ")")

    def _group_is_formula(self, start: int | None = None) -> bool:
        """Does the parenthesis at the cursor (or at ``start``) enclose a formula (not an
        arithmetic term)? A group holding just another group, ``((x == 1))``, is one if that
        inner group is."""
        start = self.i if start is None else start
        depth = 0
        for j in range(start, len(self.t)):
            text = self.t[j].text
            if text == "(":
                depth += 1
            elif text == ")":
                depth -= 1
                if depth == 0:
                    inner = start + 1
                    return self.t[inner].text == "(" and self._closing(inner) == j - 1 and \
                        self._group_is_formula(inner)
            elif depth == 1 and (text in COMPARISONS or text in ("&", "&&", "|", "||")
                                 or (self.t[j].kind == "name" and text in ("true", "false", "loc"))):
                return True
        raise FormulaError("unbalanced parentheses")

    def _closing(self, start: int) -> int | None:
        """The index of the parenthesis closing the one at ``start``, or None."""
        depth = 0
        for j in range(start, len(self.t)):
            depth += {"(": 1, ")": -1}.get(self.t[j].text, 0)
            if depth == 0:
                return j
        return None

    def relation(self) -> Relation:
        parts, ops, current, depth = [], [], [], 0
        while True:
            tok = self.peek()
            if tok is None:
                break
            if depth == 0 and tok.text in ("&", "&&", "|", "||", ")"):
                break
            if tok.text == "(":
                depth += 1
            elif tok.text == ")":
                depth -= 1
            if depth == 0 and tok.kind == "op" and tok.text in COMPARISONS:
                parts.append(current)
                ops.append(tok.text)
                current = []
            else:
                if current and _juxtaposed(current[-1], tok):
                    raise FormulaError(f"missing operator between '{current[-1].text}' and '{tok.text}'")
                current.append(tok)
            self.i += 1
        parts.append(current)
        if not ops:
            raise FormulaError("expected a relation such as 'x <= 1'"
                               + (f", got '{' '.join(t.text for t in current)}'" if current else ""))
        if any(not p for p in parts):
            raise FormulaError("a relation has an empty side")
        return Relation(parts, ops)


def _juxtaposed(left: Token, right: Token) -> bool:
    """Two operands side by side with no operator between (``6 2``, ``x 1``, ``2 x``, ``) (``):
    a typo, never a product (``2*x`` must be written); a function call ``sin(`` is not one."""
    ends = left.kind in ("num", "name") or left.text in (")", "'")
    begins = right.kind in ("num", "name") or right.text == "("
    return ends and begins and not (left.kind == "name" and right.text == "(")


def _check_nesting(tokens: list[Token]) -> None:
    """Parentheses nested more than :data:`MAX_NESTING` deep are refused before the (recursive)
    parser meets them."""
    depth = 0
    for tok in tokens:
        depth += {"(": 1, ")": -1}.get(tok.text, 0)
        if depth > MAX_NESTING:
            raise FormulaError(f"too many nested parentheses (more than {MAX_NESTING})")


def parse_formula(text: str) -> list[list]:
    """``text`` in disjunctive normal form: ``[[atom, ...], ...]`` (``[[]]`` for an empty text)."""
    tokens = tokenize(text)
    if not tokens:
        return [[]]
    _check_nesting(tokens)
    parser = _Parser(tokens)
    terms = parser.formula()
    if parser.peek() is not None:
        raise FormulaError(f"unexpected '{parser.peek().text}'")
    return terms


def conjunction(text: str) -> list:
    """Atoms of a formula that must be a plain conjunction (invariants, flows, guards, resets)."""
    terms = parse_formula(text)
    if len(terms) != 1:
        raise FormulaError("disjunction '|'")
    return terms[0]


def names_in(tokens: list[Token]) -> list[str]:
    return [t.text for i, t in enumerate(tokens) if t.kind == "name"
            and not (i + 1 < len(tokens) and tokens[i + 1].text == "(")]


def is_primed_name(tokens: list[Token]) -> str | None:
    """The name of ``x'``, else None."""
    if len(tokens) == 2 and tokens[0].kind == "name" and tokens[1].text == "'":
        return tokens[0].text
    return None


def to_python(tokens: list[Token], rename) -> str:
    """Python text of an expression; ``rename(name)`` gives the text that replaces a name."""
    out = []
    for i, tok in enumerate(tokens):
        binary = i > 0 and (tokens[i - 1].kind != "op" or tokens[i - 1].text == ")")
        if tok.text in ("+", "-") and binary:
            out.append(f" {tok.text} ")
            continue
        if tok.text == "'":
            raise FormulaError("a derivative x' outside the left side of a flow")
        if tok.kind == "name":
            if i + 1 < len(tokens) and tokens[i + 1].text == "(":
                if tok.text not in FUNCTIONS:
                    raise FormulaError(f"function '{tok.text}'")
                out.append(tok.text)
            else:
                out.append(rename(tok.text))
        elif tok.text == "^":
            out.append("**")
        elif tok.text == ",":
            out.append(", ")
        else:
            out.append(tok.text)
    return "".join(out)


def formula_error(exc: FormulaError, what: str, text: str, file: str, line: int | None) -> InputError:
    short = " ".join(text.split())
    if len(short) > 80:
        short = short[:77] + "..."
    return InputError(f"{what}: construct not supported or malformed: {exc} (in '{short}')", file, line=line)
