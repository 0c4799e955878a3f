"""A composed SpaceEx network and its cfg as the plain model and property documents the YAML
loaders read, so that the normal loader and its checks build the automaton.

Variables. A real with a flow in some location is a state. A real with no flow anywhere is
* an alias when a location's invariant defines it, ``y == e`` (``e`` free of ``y``): ``y`` is
  replaced by ``e`` there (outputs such as Building's ``y1 == x25``);
* a varying bounded input when the invariants only bound it by numbers (``0.8 <= u <= 1``); where
  locations bound it by different intervals, ``u`` stands in each for ``lo + (hi - lo) u_share``,
  ``u_share`` in ``[0, 1]`` the input;
* otherwise bad input (an unbounded input).
A flow that bounds a derivative by numbers (``1 <= x' & x' <= 2``, a rectangular automaton) lets
``x`` move at any rate in the interval, changing at any instant: ``x' == x_rate`` for a varying
bounded input ``x_rate`` in that interval (one per variable); where locations bound ``x'`` by
different intervals, ``x' == lo + (hi - lo) x_rate_share`` with ``x_rate_share`` in ``[0, 1]``. A bound on one side only, one that
couples derivatives (``x' + y' <= 1``) or reads the state, is bad input.
A state with flow 0 in every location that no transition assigns, the cfg's initial set does not
mention, and the invariants only bound by the same interval everywhere, is a constant bounded
input (Building BLDC01's ``u1' == 0``). Constants bound to numbers are substituted. A constant
bound to no number whose value (or range) the cfg's ``initially`` gives (``tmax == 20``, a common
SpaceEx idiom) is a state with flow 0 in every location.

Initial set (SpaceEx semantics): the cfg's ``initially`` intersected with the invariant of the
initial location; without ``loc()`` the initial locations are the location combinations whose
invariant meets the set (an LP), entered from a timeless start mode when there are several,
each with the set as its own aliases define it. Relations on time-varying inputs alone are
dropped with a note, unless they hold nowhere in the inputs' ranges (an empty set: bad input).
The set's strict bounds are kept strict to decide whether it is empty (``x > 1 & x < 1`` is, bad
input), and a set that is not empty is then read as its closure, as invariants and guards are.

Constants. A ``dynamics="const"`` param keeps its value: a flow other than ``k' == 0`` or an
assignment that sets it (in its component, or through a bind mapping a variable onto it) is
bad input at its line.

Sizes. The composition bounds the texts to read (:mod:`.compose`); once the variables are
known, at most ``MAX_VARIABLES`` states and inputs and ``MAX_MATRIX_ENTRIES`` entries of the
flow matrices (one square of the variables per location) are accepted, before the loader
builds any matrix.

Names in the cfg. Every name in ``initially`` and ``forbidden`` must be a variable of the
model (a state, an input, or an alias in the locations concerned), written in full or by a
unique dotted suffix, and every ``loc()`` term an instance and one of its locations. Anything
else is bad input at the cfg's line: SpaceEx would read an unknown name as one more free
variable, so a typo would silently change the initial set or forbid every state.
"""

from __future__ import annotations

import keyword
import re
from dataclasses import dataclass, field

import numpy as np
import sympy

from reach import lp
from reach.errors import InputError, Where
from reach.paths import few, printable
from reach.model.automaton import MAX_VARIABLES
from reach.model.constraints import affine_coefficients
from reach.model.expr import CONSTANTS, FUNCTIONS, parse_expr
from reach.model.loader import hint_problem
from reach.model.spaceex.compose import Flat, Instance, Part, blocked_labels
from reach.model.spaceex.formula import (Const, FormulaError, Loc, Relation, Token, conjunction, formula_error,
                                         is_primed_name, names_in, parse_formula, to_python)

RESERVED = set(FUNCTIONS) | set(CONSTANTS) | {"true", "false", "loc"}
# names a SpaceEx model may give a variable (lambda, in, if, None) that the expression parser,
# which reads Python syntax, cannot take as names: renamed like RESERVED ones (lambda -> lambda_)
KEYWORDS = set(keyword.kwlist)
MAX_MATRIX_ENTRIES = 25_000_000
_NAME = re.compile(r"(?<![\w.])[A-Za-z_][\w.]*")     # a (dotted) name in a written relation


@dataclass
class Atoms:
    """A conjunction read from one instance's text, names already global."""

    relations: list[tuple[Relation, Instance]] = field(default_factory=list)
    false: bool = False


class Converter:
    def __init__(self, flat: Flat, xml_file: str):
        self.flat = flat
        self.file = xml_file
        self.lines: dict[tuple, tuple[str, int]] = {}
        self.parsed: dict[tuple[int, int], Atoms] = {}

    # ------------------------------------------------------------------ names
    def global_of(self, instance: Instance, local: str, field: str, line: int) -> str:
        """The global name behind ``local`` in ``instance`` (numbers come back as ``#value``)."""
        b = instance.binding.get(local)
        if b is None:
            # a name the component does not declare: SpaceEx treats it as a param of the
            # component; here that is a typo more often than not
            raise InputError(f"unknown name '{local}' (the component's params: {few(instance.component.params)})",
                             self.file, field, line)
        if b.number is not None:
            return "#" + b.number
        return b.name

    @staticmethod
    def field_of(part: Part, what: str) -> str:
        """Where a text is written: ``component 'heater': location 'on': flow``."""
        return f"component '{part.instance.component.id}': {part.context}: {what}"

    def parse(self, part: Part, what: str) -> Atoms:
        """The atoms of an instance's text, names made global; each (instance, text) is read
        once, however many product locations or transitions it is part of."""
        key = (id(part.instance), id(part.text))
        if key not in self.parsed:
            self.parsed[key] = self._parse(part, self.field_of(part, what))
        return self.parsed[key]

    def _parse(self, part: Part, field: str) -> Atoms:
        text = part.text
        try:
            atoms = conjunction(text.text)
        except FormulaError as exc:
            raise formula_error(exc, field, text.text, self.file, text.line) from None
        out = Atoms()
        for atom in atoms:
            if isinstance(atom, Const):
                out.false |= not atom.value
            elif isinstance(atom, Loc):
                raise InputError("construct loc() is only allowed in the cfg", self.file, field, text.line)
            else:
                out.relations.append((self._globalise(atom, part.instance, field, text.line), part.instance))
        return out

    def _globalise(self, rel: Relation, instance: Instance, field: str, line: int) -> Relation:
        parts = []
        for tokens in rel.parts:
            new = []
            for i, t in enumerate(tokens):
                called = i + 1 < len(tokens) and tokens[i + 1].text == "("
                if t.kind == "name" and not called:
                    if t.text in RESERVED and t.text not in instance.binding:
                        # a constant (pi) is a number to the rest of the import
                        new.append(Token("num", t.text) if t.text in CONSTANTS else t)
                        continue
                    g = self.global_of(instance, t.text, field, line)
                    new.append(Token("num", f"({g[1:]})") if g.startswith("#") else Token("name", g))
                else:
                    new.append(t)
            parts.append(new)
        return Relation(parts, rel.ops)


def _joined(tokens) -> str:
    """Tokens as written, a prime on its name (``y'``), others apart by a space."""
    return "".join(("" if t.text == "'" or k == 0 else " ") + t.text for k, t in enumerate(tokens))


def yaml_names(used: list[str]) -> dict[str, str]:
    """Identifiers for global names: the last dotted part if unique, else the path with ``_``;
    a name the written model cannot use (a function or constant such as ``pi``, a Python
    keyword such as ``lambda``) gets a ``_`` appended (``pi_``, ``lambda_``)."""
    last = {}
    for g in used:
        last.setdefault(g.split(".")[-1], []).append(g)
    out, taken = {}, set()
    for g in sorted(used, key=lambda s: (s.count("."), s)):
        short = g.split(".")[-1]
        name = short if len(last[short]) == 1 else g.replace(".", "_")
        name = re.sub(r"\W", "_", name)
        if not name.isidentifier() or name.startswith("_"):
            name = "v_" + name.lstrip("_")
        while name in RESERVED or name in KEYWORDS or name in taken:
            name += "_"
        out[g] = name
        taken.add(name)
    return out


def _fresh(stem: str, taken: set) -> str:
    """``stem``, or ``stem2``, ``stem3``, ... : the first not in ``taken`` (a name the import
    makes for an input of its own, beside the model's variables)."""
    name, k = stem, 1
    while name in taken:
        k += 1
        name = f"{stem}{k}"
    return name


def _share_of(lo: float, hi: float, share: str) -> list[Token]:
    """The tokens of ``(lo) + (hi - lo)*share``: the value in ``[lo, hi]`` that the input
    ``share`` (in ``[0, 1]``) picks."""
    return [Token("op", "("), Token("num", repr(float(lo))), Token("op", ")"), Token("op", "+"),
            Token("op", "("), Token("num", repr(float(hi - lo))), Token("op", ")"), Token("op", "*"),
            Token("name", share)]


class Identifiers:
    """Unique identifiers made from texts: ``a``, then ``a_2``, ``a_3``, ... Each base keeps
    its next number, so n equal texts cost n steps, not n squared."""

    def __init__(self, taken=()):
        self.taken = set(taken)
        self.next: dict[str, int] = {}

    def __call__(self, text: str) -> str:
        name = re.sub(r"\W", "_", text) or "m"
        if not name.isidentifier():
            name = "m_" + name
        base, k = name, self.next.get(name, 2)
        while name in self.taken:
            name = f"{base}_{k}"
            k += 1
        self.next[base] = k
        self.taken.add(name)
        return name


def property_id(cfg_file: str) -> str:
    """The id of the cfg's forbidden set: the cfg's file name without ``.cfg`` in letters, digits,
    ``_`` and ``-`` (``my model (v2).cfg`` -> ``my_model_v2``), ``forbidden`` if nothing is left."""
    name = cfg_file.replace("\\", "/").rsplit("/", 1)[-1]
    stem = name[:-4] if name.endswith(".cfg") else name
    return re.sub(r"[^A-Za-z0-9_-]+", "_", stem).strip("_-") or "forbidden"


def number_of(text: str) -> float | None:
    """The value of a constant expression text, or None if it has names."""
    try:
        value = parse_expr(text, {}, Where())
    except InputError:
        return None
    if not value.is_number:
        return None
    value = complex(value)
    return value.real if value.imag == 0 and np.isfinite(value.real) else None


def linear_rows(texts_eq: list[tuple[str, str]], names: dict[str, sympy.Symbol], symbols):
    """``(A, b, E, f)`` of relations given as ``(kind, "lhs - rhs")`` (kind ``<=`` or ``==``),
    or None if one is not linear."""
    A, b, E, f = [], [], [], []
    for kind, text in texts_eq:
        try:
            g = sympy.expand(parse_expr(text, names, Where()))
        except InputError:
            return None
        coeffs = affine_coefficients(g, symbols)
        if coeffs is None:
            return None
        (E if kind == "==" else A).append(coeffs[0])
        (f if kind == "==" else b).append(-coeffs[1])
    n = len(symbols)
    return (np.array(A, float).reshape(-1, n), np.array(b, float), np.array(E, float).reshape(-1, n),
            np.array(f, float))


def feasible(rows, n) -> bool:
    """Whether the rows have a common point; when the LP cannot say (LPError), True: keeping a
    location or transition that is in fact empty only costs time."""
    A, b, E, f = rows
    try:
        point = lp.feasible_point(A if len(b) else None, b if len(b) else None,
                                  A_eq=E if len(f) else None, b_eq=f if len(f) else None, n=n)
    except lp.LPError:
        return True
    return point is not None


def _strict(text: str) -> bool:
    """Whether a rendered comparison ``a op b`` is strict (``<`` or ``>``; rendered expressions
    hold no comparison of their own, so the first operator found is the relation's)."""
    for op in (" <= ", " < ", " >= ", " > "):
        if op in text:
            return op in (" < ", " > ")
    return False


def _closed(texts: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """Rendered comparisons with strict ones made non-strict (``x < 1`` -> ``x <= 1``): an
    invariant, as SpaceEx reads it (closed), where it joins the initial set's constraints."""
    return [(k, t.replace(" < ", " <= ", 1) if " < " in t else t.replace(" > ", " >= ", 1) if " > " in t else t)
            for k, t in texts]


def open_nonempty(texts: list[tuple[str, str]], closed: int, names, symbols, extra=()) -> bool:
    """Whether the relations ``texts`` (``(kind, "a op b")``, as :meth:`relation_texts` gives
    them) have a common point with their strict ones kept strict: ``texts[:closed]`` are read
    as written (the cfg's ``initially``), the rest as their closure (invariants, as SpaceEx
    reads them), and ``extra`` (``(kind, "lhs - rhs")``, closed) is added
    (:func:`reach.lp.strictly_feasible`: ``x > 1 & x < 1``, whose closure is the point 1, has
    none). True where that cannot be said (a nonlinear set, a solver without an answer):
    keeping a set that is in fact empty only costs time."""
    relations = [(k, _difference(t, k)) for k, t in texts] + list(extra)
    rows = linear_rows(relations, names, symbols)
    if rows is None:
        return True
    if not feasible(rows, len(symbols)):
        return False
    strict = [i < closed and k != "==" and _strict(t) for i, (k, t) in enumerate(texts)]
    strict += [False] * len(extra)
    mask = np.array([flag for (k, _), flag in zip(relations, strict) if k != "=="], bool)
    if not mask.any():
        return True
    A, b, E, f = rows
    return lp.strictly_feasible(A, b, mask, A_eq=E, b_eq=f) is not False


# ---------------------------------------------------------------------- the documents
@dataclass
class Documents:
    """The model and property documents (plain data) with the line of each field."""

    model: dict
    model_lines: dict
    properties: dict | None
    property_lines: dict
    property_id: str | None


def _pairs(rel: Relation):
    """Consecutive comparisons of a chain: ``[(lhs, op, rhs), ...]``."""
    return [(rel.parts[i], rel.ops[i], rel.parts[i + 1]) for i in range(len(rel.ops))]


def _only_name(tokens) -> str | None:
    return tokens[0].text if len(tokens) == 1 and tokens[0].kind == "name" else None


def _numeric(tokens) -> float | None:
    if names_in(tokens):
        return None
    return number_of(to_python(tokens, lambda n: n))


PURELY_DISCRETE = ("the system has no continuous variable (a variable with a flow; every location's flow "
                   "is 'false' or empty): a purely discrete automaton is not supported")


def _bound_of(rel: Relation, var: str):
    """``(lo, hi)`` if ``rel`` only bounds ``var`` by numbers: each comparison of the chain is
    affine in ``var`` alone (``a <= var <= b``, ``-var <= 9``, ``2*var >= -1``)."""
    if any(set(names_in(p)) - {var} for p in rel.parts) or not any(names_in(p) for p in rel.parts):
        return None
    symbol = sympy.Symbol("bounded_var", real=True)

    def rename(name: str) -> str:
        return "bounded_var" if name == var else name

    lo, hi = -np.inf, np.inf
    for lhs, op, rhs in _pairs(rel):
        if op not in ("<=", "<", ">=", ">"):
            return None
        if op in (">=", ">"):
            lhs, rhs = rhs, lhs
        try:
            g = parse_expr(f"({to_python(lhs, rename)}) - ({to_python(rhs, rename)})",
                           {"bounded_var": symbol}, Where())
        except InputError:
            return None
        coeffs = affine_coefficients(sympy.expand(g), [symbol])        # a var + c <= 0
        if coeffs is None or coeffs[0][0] == 0 or not np.isfinite(coeffs[1]):
            return None
        a, c = float(coeffs[0][0]), float(coeffs[1])
        if a > 0:
            hi = min(hi, -c / a)
        else:
            lo = max(lo, -c / a)
    return lo, hi


def _alias_of(rel: Relation, var: str):
    """The defining side ``e`` of ``var == e`` (``e`` free of ``var``), else None."""
    if rel.ops != ["=="] and rel.ops != ["="]:
        return None
    lhs, rhs = rel.parts
    if _only_name(lhs) == var and var not in names_in(rhs):
        return rhs
    if _only_name(rhs) == var and var not in names_in(lhs):
        return lhs
    return None


class DocumentBuilder(Converter):
    """Builds :class:`Documents` from a composed network and its cfg (see the module docstring)."""

    def __init__(self, flat: Flat, xml_file: str, cfg, name: str):
        super().__init__(flat, xml_file)
        self.cfg = cfg
        self.name = name

    # -------------------------------------------------------------- reading
    def read_locations(self):
        self.flows, self.invariants, self.timeless = {}, {}, set()
        self.invariant_fields: dict[tuple, list[str]] = {}      # where each invariant relation is written
        # (name, location key) -> (what, field, line): the first text read in that location
        # (or on a jump from it) that reads the name, for a message about a name that means
        # nothing there
        self.read_at: dict[tuple, tuple[str, str, int]] = {}
        self.rate_bounds: dict[tuple, dict] = {}     # location -> var -> (lo, hi, line) of rectangular flows
        self.rate_inputs: dict[str, tuple[str, float, float, int]] = {}     # var -> (input, lo, hi, line)
        for key, loc in self.flat.locations.items():
            flows = {}
            rates: dict[str, list] = {}             # var -> [lo, hi, line, part] of x' bounded by numbers
            for part in loc.flows:
                atoms = self.parse(part, "flow")
                if atoms.false:
                    self.timeless.add(key)
                for rel, _ in atoms.relations:
                    var = is_primed_name(rel.parts[0]) if rel.ops in (["=="], ["="]) else None
                    if var is None:
                        self._rate_bound(rel, part, key, rates)
                        continue
                    if var in flows:
                        raise InputError(f"two derivatives given for '{var}' in location '{self.flat.label(key)}'",
                                         self.file, self.field_of(part, "flow"), part.text.line)
                    rhs = _joined(rel.parts[1])
                    rhs = rhs if len(rhs) <= 40 else rhs[:37] + "..."
                    self._refuse_change_of_const(var, part, "flow", lambda local: f"the flow {local}' == "
                                                 f"{rhs} contradicts it, only {local}' == 0 agrees", rel.parts[1])
                    flows[var] = (rel.parts[1], part.text.line)
                    self._reads(rel.parts[1:], key, part, "flow")
            self.rate_bounds[key] = {var: self._rate_checked(var, lo, hi, line, part, flows)
                                     for var, (lo, hi, line, part) in rates.items()}
            self.flows[key] = flows
            invariant, fields = [], []
            for part in loc.invariants:
                atoms = self.parse(part, "invariant")
                if atoms.false:
                    raise InputError("construct 'false' (an empty location) is not supported", self.file,
                                     self.field_of(part, "invariant"), part.text.line)
                invariant += [(rel, part.text.line) for rel, _ in atoms.relations]
                fields += [self.field_of(part, "invariant")] * len(atoms.relations)
                for rel, _ in atoms.relations:
                    self._reads(rel.parts, key, part, "invariant")
            self.invariants[key] = invariant
            self.invariant_fields[key] = fields
        self._rate_flows()
        self.guards, self.assignments = [], []
        for tr in self.flat.transitions:
            guard = []
            for part in tr.guards:
                atoms = self.parse(part, "guard")
                if atoms.false:
                    guard = None
                    break
                guard += [(rel, part.text.line) for rel, _ in atoms.relations]
                for rel, _ in atoms.relations:
                    self._reads(rel.parts, tr.source, part, "guard")
            assign = {}
            for part in tr.assignments:
                for rel, _ in self.parse(part, "assignment").relations:
                    var = self._reset_target(rel, part)
                    self._refuse_change_of_const(var, part, "assignment",
                                                 lambda local: f"the assignment to {local} contradicts it")
                    if var in assign:
                        raise InputError(f"'{var}' assigned twice", self.file, self.field_of(part, "assignment"),
                                         part.text.line)
                    assign[var] = (rel.parts[1], part.text.line)
                    self._reads(rel.parts[1:], tr.source, part, "assignment")
            self.guards.append(guard)
            self.assignments.append(assign)
        # every global name under itself and each of its dotted suffixes (p.first.z: first.z, z)
        self.suffixes: dict[str, list[str]] = {}
        for g in self._order():
            parts = g.split(".")
            for k in range(len(parts)):
                self.suffixes.setdefault(".".join(parts[k:]), []).append(g)

    def _rate_bound(self, rel: Relation, part: Part, key, rates: dict) -> None:
        """Note a flow relation that bounds one derivative by numbers (``x' <= 10``,
        ``-x' <= -36``, ``0 <= x' <= 10``; strict bounds read as their closure, as invariants
        are) in ``rates``; any other relation of a flow is bad input."""
        primed = {t.text for p in rel.parts for i, t in enumerate(p)
                  if t.kind == "name" and i + 1 < len(p) and p[i + 1].text == "'"}
        bound = None
        if len(primed) == 1:
            var = primed.pop()
            marker = "primed_rate_"
            while any(marker in names_in(p) for p in rel.parts):      # a variable of that name: another
                marker += "_"
            parts = []
            for p in rel.parts:
                out = []
                for i, t in enumerate(p):
                    if t.text == "'" and i > 0 and p[i - 1].text == var:
                        continue
                    out.append(Token("name", marker) if t.kind == "name" and t.text == var
                               and i + 1 < len(p) and p[i + 1].text == "'" else t)
                parts.append(out)
            if not any(t.text == var for p in parts for t in p):      # x read unprimed too: not a bound
                bound = _bound_of(Relation(parts, rel.ops), marker)
        if bound is None:
            raise InputError(f"construct '{self._show(rel)}' is not supported (expected x' == expression, "
                             "or numbers bounding one derivative: 0 <= x' <= 10)", self.file,
                             self.field_of(part, "flow"), part.text.line)
        lo, hi, _, _ = rates.setdefault(var, [-np.inf, np.inf, part.text.line, part])
        rates[var][:2] = [max(lo, bound[0]), min(hi, bound[1])]
        self._reads(rel.parts, key, part, "flow")

    def _rate_checked(self, var: str, lo: float, hi: float, line: int, part: Part, flows: dict):
        """``(lo, hi, line)``: the rates ``lo <= var' <= hi`` a location allows (a rectangular
        flow), checked: bad input where an equality gives ``var'`` too, where a side is open,
        where the interval is empty, or where a ``dynamics="const"`` variable could move. Bounds
        that cross by rounding only (``0.1*3 <= x' & x' <= 0.3``) are read as the interval between
        them, which holds every rate either reading allows."""
        field = self.field_of(part, "flow")
        if var in flows:
            raise InputError(f"'{var}'' is given by an equality and bounded too (give one or the other)",
                             self.file, field, line)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise InputError(f"'{var}'' is bounded on one side only (an unbounded rate is not supported; "
                             f"give lo <= {var}' <= hi)", self.file, field, line)
        if lo > hi:
            if lo - hi > 8 * np.finfo(float).eps * max(abs(lo), abs(hi)):
                raise InputError(f"the bounds of '{var}'' admit no rate ({lo:.17g} > {hi:.17g})", self.file,
                                 field, line)
            lo, hi = hi, lo
        self._refuse_change_of_const(var, part, "flow", lambda local: f"the flow bound on {local}' changes it",
                                     [Token("num", repr(hi))] if lo == hi == 0 else None)
        return lo, hi, line

    def _rate_flows(self) -> None:
        """The flows of the rectangular variables (:meth:`_rate_checked`), one time-varying input
        per variable. Where every location that bounds ``x'`` by an interval (of positive width)
        bounds it by the same ``[lo, hi]``, ``x' == x_rate`` with ``x_rate`` in ``[lo, hi]``;
        where they differ, ``x' == lo + (hi - lo) x_rate_share`` in each location, with
        ``x_rate_share`` in ``[0, 1]`` (at any instant the same share of each location's
        interval, so each location's rates are exactly its own). Equal bounds are the rate
        itself."""
        intervals: dict[str, set] = {}
        for bounds in self.rate_bounds.values():
            for var, (lo, hi, line) in bounds.items():
                if lo < hi:
                    intervals.setdefault(var, {})[(lo, hi)] = line
        taken = set(self.flat.globals)
        for var, seen in intervals.items():
            shared = len(seen) == 1
            name = _fresh(f"{var}_rate" if shared else f"{var}_rate_share", taken)
            taken.add(name)
            (lo, hi), line = next(iter(seen.items()))
            self.rate_inputs[var] = (name, lo, hi, line) if shared else (name, 0.0, 1.0, line)
        for key, bounds in self.rate_bounds.items():
            for var, (lo, hi, line) in bounds.items():
                if lo == hi:
                    self.flows[key][var] = [Token("num", repr(float(lo)))], line
                    continue
                name, low, high, _ = self.rate_inputs[var]
                if (low, high) == (lo, hi):
                    self.flows[key][var] = [Token("name", name)], line
                    continue
                self.flows[key][var] = _share_of(lo, hi, name), line

    def _reads(self, parts, key, part: Part, what: str) -> None:
        """Note the names the token lists ``parts`` of ``part`` read in location ``key``."""
        for tokens in parts:
            for name in names_in(tokens):
                self.read_at.setdefault((name, key), (what, self.field_of(part, what), part.text.line))

    def _refuse_change_of_const(self, var: str, part: Part, what: str, change, rate=None) -> None:
        """Refuse a flow or assignment ``change`` of ``part`` that sets the variable ``var``
        (global) if a ``dynamics="const"`` param stands for it: the param of the component
        that writes it, or the param it is mapped onto by a bind (named with its line). SpaceEx
        keeps a constant through flows (``k' == 0``) and jumps (``k' == k``); reading the
        file's own change instead would turn the constant into a clock or a resettable state,
        and the file contradicts itself either way: bad input at the change's line.
        ``change(local)`` says what the change is, in the component's own name for it; a flow
        gives its ``rate`` (tokens), and the rate 0 is no change."""
        instance = part.instance
        locals_ = [n for n, b in instance.binding.items() if b.name == var] or [var]
        local = locals_[0]
        declared = next((p for n in locals_ if (p := instance.component.params.get(n)) is not None
                         and p.dynamics == "const"), None)
        if declared is not None:
            local = declared.name
            why = f"'{local}' is declared dynamics=\"const\" (line {declared.line}) and"
        elif self.flat.globals.get(var) == "const":
            bind = (f"bind '{instance.path}' (line {instance.line})" if instance.path
                    else f"component '{self.flat.system}'")
            why = (f"'{local}' is mapped by {bind} to '{var}', declared dynamics=\"const\" "
                   f"(line {self.flat.declared.get(var, '?')}), and")
        else:
            return
        if rate is not None:
            try:
                if _numeric(rate) == 0:
                    return
            except FormulaError:        # a function the import lacks: reported where the flow is read
                return
        raise InputError(f"{why} cannot change: {change(local)} (SpaceEx keeps a constant through flows "
                         "and jumps)",
                         self.file, self.field_of(part, what), part.text.line)

    def _reset_target(self, rel: Relation, part: Part) -> str:
        """The variable a relation of an assignment resets. SpaceEx reads an assignment as a
        relation between the values before the jump (unprimed names) and after it (primed):
        ``x' == e`` and its shorthand ``x := e`` are resets (also ``x = e``, as the published
        Platoon files write ``t=0``). ``x == e`` relates values before the jump: a condition on
        when the jump may happen, which belongs in the guard; it is refused, not read as a reset."""
        lhs, field = rel.parts[0], self.field_of(part, "assignment")
        op = rel.ops[0] if len(rel.ops) == 1 else None
        name, primed = _only_name(lhs), is_primed_name(lhs)
        if op == "==" and name is not None:
            raise InputError(f"'{self._show(rel)}' constrains the state before the jump (unprimed names are "
                             f"the values before it): put it in the guard, or write {name}' == ... or "
                             f"{name} := ... for a reset", self.file, field, part.text.line)
        var = primed if op == "==" else name or primed
        if op not in (":=", "==", "=") or var is None:
            raise InputError(f"construct '{self._show(rel)}' is not supported (expected x := "
                             "expression)", self.file, field, part.text.line)
        return var

    def _show(self, rel: Relation) -> str:
        text = " ".join(_joined(p) + (f" {rel.ops[i]}" if i < len(rel.ops) else "")
                        for i, p in enumerate(rel.parts))
        return text if len(text) <= 60 else text[:57] + "..."

    # -------------------------------------------------------------- variables
    def classify(self, cfg_names: set[str]):
        """States, bounded inputs (varying and constant) and aliases (see the module docstring)."""
        states = set()
        for flows in self.flows.values():
            states |= set(flows)
        if not states:
            raise self.flat.error(PURELY_DISCRETE)
        used_where: dict[str, set] = {}
        for key in self.flat.locations:
            for rel, _ in self.invariants[key]:
                for p in rel.parts:
                    for n in names_in(p):
                        used_where.setdefault(n, set()).add(key)
            for tokens, _ in self.flows[key].values():
                for n in names_in(tokens):
                    used_where.setdefault(n, set()).add(key)
        for tr, guard, assign in zip(self.flat.transitions, self.guards, self.assignments):
            for rel, line in guard or []:
                for p in rel.parts:
                    for n in names_in(p):
                        used_where.setdefault(n, set()).add(tr.source)
            for var, (tokens, line) in assign.items():
                for n in names_in(tokens):
                    used_where.setdefault(n, set()).add(tr.source)
        self._frozen_if_unread(states, used_where)
        for var in sorted((set(used_where) | cfg_names) - states):
            if self.flat.globals.get(var) == "const" and var in cfg_names:
                # a constant the cfg's initially gives its value (or range): flow 0 everywhere
                # (also one the system never reads, which only the cfg's forbidden set may)
                line = self._line_of(var)
                for key in self.flat.locations:
                    if key not in self.timeless:
                        self.flows[key][var] = ([Token("num", "0")], line)
                states.add(var)
        self.aliases: dict[tuple, dict[str, list]] = {key: {} for key in self.flat.locations}
        # where each alias is defined: (line, field) of its equality, for messages about it
        self.alias_at: dict[tuple, dict[str, tuple[int, str]]] = {key: {} for key in self.flat.locations}
        self.inputs: dict[str, tuple[float, float, bool]] = {
            name: (lo, hi, True) for name, lo, hi, _ in self.rate_inputs.values()}
        self.dropped: dict[tuple, set[int]] = {key: set() for key in self.flat.locations}
        for var in sorted(set(used_where) - states - set(self.inputs)):
            self._classify_free(var, used_where[var])
        for var in sorted(states):
            self._maybe_constant_input(var, cfg_names)
        self.states = [g for g in self._order() if g in states and g not in self.inputs]

    def _frozen_if_unread(self, states: set, read: dict) -> None:
        """A variable that jumps assign but that has no flow anywhere: bad input where a flow,
        invariant, guard, assignment or the cfg's forbidden set reads it. Where none does (a
        timer written on each jump and never read), its value changes no run: SpaceEx lets it
        move freely between jumps, and any motion gives the other variables the same runs, so it
        is kept as a state with flow 0 (its initial value from the cfg, else 0; its resets as written),
        and a warning says so."""
        self.unread: set[str] = set()      # such variables (their initial value, where the cfg gives none: 0)
        forbidden = {g for term in self.cfg_formula("forbidden") for a in term if isinstance(a, Relation)
                     for p in a.parts for n in names_in(p) for g in self.lookup(n)}
        for assign in self.assignments:
            for var, (_, line) in assign.items():
                if var in states:
                    continue
                if var in read or var in forbidden:
                    raise InputError(f"assignment: '{var}' has no flow anywhere (only states can be assigned)",
                                     self.file, line=line)
                states.add(var)
                self.unread.add(var)
                for key in self.flat.locations:
                    if key not in self.timeless:
                        self.flows[key][var] = ([Token("num", "0")], line)
                self.flat.warnings.append(
                    f"{self.file}:{line}: '{var}' has no flow and nothing reads it: kept as a state with flow 0 "
                    "(SpaceEx lets it move freely; its value changes no run; 0 at the start where the cfg gives none)")

    def check_size(self) -> None:
        """Refuse more variables, or flow matrices, than the import handles (the module docstring)."""
        n = len(self.states) + len(self.inputs)
        if n > MAX_VARIABLES:
            raise self.flat.error(f"{n} variables (states and inputs), more than the {MAX_VARIABLES} the import "
                                  "handles (flow matrices grow with their square)")
        entries = len(self.flat.locations) * (n + 1) ** 2
        if entries > MAX_MATRIX_ENTRIES:
            raise self.flat.error(f"too large to import: {len(self.flat.locations)} location combinations of {n} "
                                  f"variables need {entries} flow matrix entries, more than {MAX_MATRIX_ENTRIES}: "
                                  "analyse a smaller network")

    def _order(self) -> list[str]:
        """Variables in declaration order (the system's params first, then instance locals)."""
        return list(self.flat.globals) + sorted(set(v for f in self.flows.values() for v in f)
                                                 - set(self.flat.globals))

    def _classify_free(self, var: str, where: set):
        line = None
        if self.flat.globals.get(var) == "const":
            raise InputError(f"the constant '{var}' has no value (map it to a number in a bind, or give "
                             "it one in the cfg's initially)", self.file, *self._declared_at(var))
        aliased = {}
        bounds = {}
        where = sorted(where, key=str)      # one order, so that a message names the same line each run
        for key in where:
            for j, (rel, line) in enumerate(self.invariants[key]):
                e = _alias_of(rel, var)
                if e is not None and key not in aliased:
                    aliased[key] = (e, (line, self.invariant_fields[key][j]))
                    self.dropped[key].add(j)
                    continue
                b = _bound_of(rel, var)
                if b is not None:
                    bounds.setdefault(key, []).append((j, b))
        if aliased and set(aliased) == set(where):
            for key, (e, at) in aliased.items():
                self.aliases[key][var] = e
                self.alias_at[key][var] = at
            return
        if aliased:
            # an alias in some locations, read in another that does not define it: there it is
            # free (SpaceEx: any value at any instant); said at the reading text, naming both
            missing = next(key for key in where if key not in aliased)
            defined = next(iter(aliased))
            def_line = aliased[defined][1][0]
            what, field, at = self.read_at.get((var, missing), ("text", None, self.flat.locations[missing].line))
            raise InputError(f"'{var}' has no flow and is defined by an equality in location "
                             f"'{self.flat.label(defined)}' (line {def_line}) but not in "
                             f"'{self.flat.label(missing)}', where this {what} reads it (it would be free "
                             "there, any value at any instant: not supported)", self.file, field, at)
        uses_outside_flows = any(
            var in names_in(p) and j not in {i for i, _ in bounds.get(key, [])}
            for key in where for j, (rel, _) in enumerate(self.invariants[key]) for p in rel.parts)
        if bounds and not aliased and not uses_outside_flows:
            intervals, per_location = {}, {}
            for key in where:
                if key not in bounds:
                    raise InputError(f"'{var}' has no flow and is unbounded in location "
                                     f"'{self.flat.label(key)}' (an unbounded input is "
                                     "not supported)", self.file, f"location '{self.flat.label(key)}'",
                                     self.flat.locations[key].line)
                lo, hi = -np.inf, np.inf
                for j, (a, b) in bounds[key]:
                    lo, hi = max(lo, a), min(hi, b)
                    self.dropped[key].add(j)
                if not (np.isfinite(lo) and np.isfinite(hi)) or lo > hi:
                    raise InputError(f"the input '{var}' needs finite bounds low <= {var} <= high", self.file,
                                     line=self.invariants[key][bounds[key][0][0]][1])
                intervals.setdefault((lo, hi), key)
                per_location[key] = (lo, hi)
            if len(intervals) != 1:
                self._input_share(var, per_location, bounds)
                return
            (lo, hi), = intervals
            self.inputs[var] = (lo, hi, True)
            return
        if bounds and uses_outside_flows:           # bounded, but also read by another invariant
            key, j, line = next((key, j, ln) for key in where for j, (rel, ln) in enumerate(self.invariants[key])
                                if j not in {i for i, _ in bounds.get(key, [])}
                                and any(var in names_in(p) for p in rel.parts))
            raise InputError(f"the input '{var}' (no flow, bounded by numbers) also appears in the invariant "
                             f"'{printable(_written(self.invariants[key][j][0]))[:80]}' of location "
                             f"'{self.flat.label(key)}' (an input may only be bounded by numbers: not "
                             "supported)", self.file, line=line)
        field, declared = (None, line) if line else self._declared_at(var)
        raise InputError(f"'{var}' has no flow and is neither bounded by numbers in the invariants nor "
                         f"defined by an equality (construct not supported)", self.file, field, declared)

    def _input_share(self, var: str, per_location: dict, bounds: dict) -> None:
        """A time-varying input bounded by other numbers in other locations (HyST's
        hybridisation writes one such interval per location): one input ``var_share`` in
        ``[0, 1]``, and in each location ``var`` stands for ``lo + (hi - lo) var_share``, its own
        interval there (an alias of that location, :meth:`render`)."""
        name = _fresh(f"{var}_share", set(self.flat.globals) | set(self.inputs)
                      | {v for v, *_ in self.rate_inputs.values()})
        self._jumps_keep_input(var, per_location)
        self.inputs[name] = (0.0, 1.0, True)
        for key, (lo, hi) in per_location.items():
            j = bounds[key][0][0]
            self.aliases[key][var] = _share_of(lo, hi, name)
            self.alias_at[key][var] = (self.invariants[key][j][1], self.invariant_fields[key][j])

    def _jumps_keep_input(self, var: str, per_location: dict) -> None:
        """A jump keeps the input's value (SpaceEx: a variable no assignment sets is unchanged),
        so a run jumps only while ``var`` lies in both locations' intervals. Where they do not
        meet, the jump never fires: it is left out, and said. Where they meet in part of the
        source's interval, the value only matters to an assignment that reads it: such a jump
        is bad input (the share would hand it values the jump cannot have). Otherwise the
        runs can bring the input into the common part as they jump (its signal is free), and
        the jump is taken as written."""
        for k, tr in enumerate(self.flat.transitions):
            source, target = per_location.get(tr.source), per_location.get(tr.target)
            if source is None or target is None or self.guards[k] is None:
                continue
            lo, hi = max(source[0], target[0]) + 0.0, min(source[1], target[1]) + 0.0     # no -0
            where = f"transition {self.flat.label(tr.source)} -> {self.flat.label(tr.target)}"
            if lo > hi:
                self.guards[k] = None
                self.flat.warnings.append(
                    f"{self.file}:{tr.line}: {where} never fires: the input '{var}' keeps its value through "
                    f"a jump and lies in [{source[0]:g}, {source[1]:g}] before it, in [{target[0]:g}, "
                    f"{target[1]:g}] after it")
            elif (lo, hi) != source and any(var in names_in(tokens) for tokens, _ in self.assignments[k].values()):
                raise InputError(f"{where}: an assignment reads the input '{var}', which keeps its value through the "
                                 f"jump and so lies in [{lo:g}, {hi:g}] there, not in the whole of the source's "
                                 f"[{source[0]:g}, {source[1]:g}] (not supported)", self.file, line=tr.line)

    def _maybe_constant_input(self, var: str, cfg_names: set[str]):
        if var in cfg_names or any(var in a for a in self.assignments):
            return
        if any(self.flows[key].get(var) is None or _numeric(self.flows[key][var][0]) != 0
               for key in self.flat.locations):
            return
        if any(var in names_in(p) for g in self.guards for rel, _ in (g or []) for p in rel.parts):
            return
        intervals, marks = set(), []
        for key in self.flat.locations:
            lo, hi = -np.inf, np.inf
            for j, (rel, _) in enumerate(self.invariants[key]):
                if not any(var in names_in(p) for p in rel.parts):
                    continue
                b = _bound_of(rel, var)
                if b is None:
                    return
                lo, hi = max(lo, b[0]), min(hi, b[1])
                marks.append((key, j))
            intervals.add((lo, hi))
        if len(intervals) != 1:
            return
        (lo, hi), = intervals
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            return
        for key, j in marks:
            self.dropped[key].add(j)
        self.inputs[var] = (lo, hi, False)

    def _line_of(self, var: str) -> int | None:
        rate = next((line for name, _, _, line in self.rate_inputs.values() if name == var), None)
        return rate if rate is not None else self._declared_at(var)[1]

    def _declared_at(self, var: str) -> tuple[str | None, int | None]:
        """The field and line of the param that ``var`` stands for in the first instance that
        reads it (``component 'A': param 'k'``), or ``(None, None)``."""
        for inst in self.flat.instances:
            for p in inst.component.params.values():
                if inst.binding.get(p.name) and inst.binding[p.name].name == var:
                    return f"component '{inst.component.id}': param '{p.name}'", p.line
        return None, None

    # -------------------------------------------------------------- rendering
    def render(self, tokens, key, line: int | None, depth: int = 0, file: str | None = None,
               field: str | None = None) -> str:
        """``tokens`` as an expression of the written model in location ``key``, each alias
        replaced by its definition there. A problem is reported where its text is written: at
        ``file`` (the XML unless given; the cfg for its own relations) and ``line``, and inside
        an alias's definition at the defining invariant's line, not where the alias is read."""
        file = file or self.file

        def rename(g: str) -> str:
            if key is not None and g in self.aliases.get(key, {}):
                at, where = self.alias_at[key][g]
                if depth > 8:
                    raise InputError(f"aliases nest too deeply at '{g}'", self.file, where, at)
                return "(" + self.render(self.aliases[key][g], key, at, depth + 1, self.file, where) + ")"
            if g in self.yaml:
                return self.yaml[g]
            raise InputError(f"'{g}' is used where it has no value (no flow, bound or definition)",
                             file, field, line)
        try:
            return to_python(tokens, rename)
        except FormulaError as exc:
            raise InputError(f"construct not supported: {exc}", file, field, line) from None

    def relation_texts(self, rel: Relation, key, line, file: str | None = None,
                       field: str | None = None) -> list[tuple[str, str]]:
        """``[(kind, text)]``: ``("<=", "a <= b")`` per comparison, ``("==", "a == b")``
        (``file`` and ``field``: where ``rel`` is written, for messages; the XML by default)."""
        out = []
        for lhs, op, rhs in _pairs(rel):
            a, b = self.render(lhs, key, line, 0, file, field), self.render(rhs, key, line, 0, file, field)
            if op in (":=",):
                raise InputError("construct ':=' outside an assignment", file or self.file, field, line)
            out.append(("==", f"{a} == {b}") if op in ("==", "=") else ("<=", f"{a} {op} {b}"))
        return out

    @staticmethod
    def as_constraints(pairs) -> list[str]:
        """Texts the constraint parser reads: ``a == b`` becomes ``a <= b`` and ``a >= b``."""
        out = []
        for kind, text in pairs:
            if kind == "==":
                a, b = text.split(" == ", 1)
                out += [f"{a} <= {b}", f"{a} >= {b}"]
            else:
                out.append(text)
        return out

    # -------------------------------------------------------------- the model document
    def build(self) -> Documents:
        cfg = self.cfg
        init_terms = self.cfg_formula("initially", required=True)
        if len(init_terms) != 1:
            raise InputError("initially: construct '|' (a union of initial sets) is not supported",
                             cfg.file, line=cfg.line("initially"))
        init_atoms = init_terms[0]
        cfg_rel = [a for a in init_atoms if isinstance(a, Relation)]
        self.read_locations()
        cfg_names = {g for r in cfg_rel for p in r.parts for n in names_in(p) for g in self.lookup(n)}
        self.classify(cfg_names)
        if not self.states:
            raise self.flat.error(PURELY_DISCRETE)
        self.check_size()
        self.yaml = yaml_names(self.states + list(self.inputs))
        modes = Identifiers()
        self.mode_of = {key: modes("__".join(loc.names)) for key, loc in self.flat.locations.items()}
        data: dict = {"name": self.name}
        lines = self.lines
        lines[()] = (self.file, 1)
        data["description"] = f"imported from the SpaceEx model {self.file} (system '{cfg.text('system')}')"
        data["state"] = [self.yaml[s] for s in self.states]
        lines[("state",)] = (self.file, 1)
        if self.inputs:
            data["bounded_inputs"] = {self.yaml[v]: {"range": [lo, hi], "varying": varying}
                                      for v, (lo, hi, varying) in self.inputs.items()}
            for v in self.inputs:
                lines[("bounded_inputs", self.yaml[v])] = (self.file, self._line_of(v) or 1, f"input '{v}'")
        data["modes"] = {}
        for key, loc in self.flat.locations.items():
            m = self.mode_of[key]
            where = f"location '{self.flat.label(key)}'"          # the field a message on the mode names
            lines[("modes", m)] = (self.file, loc.line, where)
            spec: dict = {}
            if key in self.timeless:
                spec["flow"] = False
            else:
                flow = {}
                for s in self.states:
                    if s not in self.flows[key]:
                        raise InputError(f"location '{self.flat.label(key)}': no flow for '{s}' (SpaceEx "
                                         "leaves it free there; not supported)", self.file, line=loc.line)
                    tokens, line = self.flows[key][s]
                    flow[self.yaml[s]] = self.render(tokens, key, line)
                    lines[("modes", m, "flow", self.yaml[s])] = (self.file, line, f"{where}: flow")
                spec["flow"] = flow
            invariant = []
            for j, (rel, line) in enumerate(self.invariants[key]):
                if j in self.dropped[key]:
                    continue
                for text in self.as_constraints(self.relation_texts(rel, key, line)):
                    lines[("modes", m, "invariant", len(invariant))] = (self.file, line, f"{where}: invariant")
                    invariant.append(text)
            if invariant:
                spec["invariant"] = invariant
            data["modes"][m] = spec
        self.transitions_out = self.transitions_doc()
        self.extra_modes: dict = {}
        self.ignored: list[str] = []
        data["initial"] = self.initial_doc(init_atoms)
        data["modes"].update(self.extra_modes)
        data["transitions"] = self.transitions_out
        horizon = cfg.number("time-horizon")
        if horizon is None:
            raise cfg.missing("time-horizon")
        if horizon == -1:                   # SpaceEx: -1 explores until a fixpoint, unbounded
            raise InputError("time-horizon = -1: an unbounded horizon (SpaceEx's -1, up to a "
                             "fixpoint) is not supported; give a positive time", cfg.file,
                             "time-horizon", cfg.line("time-horizon"))
        if horizon < 0:
            raise InputError(f"time-horizon = {horizon:g}: expected a positive time (or SpaceEx's -1, "
                             "which reach does not support)", cfg.file, "time-horizon", cfg.line("time-horizon"))
        data["horizon"] = horizon
        lines[("horizon",)] = (cfg.file, cfg.line("time-horizon"), "time-horizon")
        notes = {"source": self.file, "config": cfg.file}
        for key in ("sampling-time", "iter-max"):
            if cfg.text(key) is not None:
                notes[key] = cfg.number(key)
                if why := hint_problem(key, notes[key]):
                    raise InputError(f"{key}: {why}, got '{cfg.text(key)}'", cfg.file, line=cfg.line(key))
        if self.extra_modes and notes.get("iter-max", -1) >= 0:
            # iter-max bounds the jumps of the SpaceEx model; the urgent jump out of the timeless
            # start mode added above (several initial locations) is not one of them, but star
            # counts every jump of a path against the bound it reads from notes (max_jumps). One
            # more keeps the cfg's bound on the model's own jumps: with iter-max = 0 a run may
            # still enter its initial location, and no model jump is allowed after it
            notes["iter-max"] = notes["iter-max"] + 1
            notes["iter-max-start"] = (f"iter-max is the cfg's {cfg.text('iter-max')} plus one: the jump out of "
                                       f"'{next(iter(self.extra_modes))}' into an initial location is counted "
                                       "by star but is not a jump of the SpaceEx model")
        blocked = blocked_labels(self.flat)
        if blocked:
            notes["blocked"] = blocked
        if self.flat.warnings or self.ignored:      # shown by check and import, one warning a line
            notes["ignored"] = self.flat.warnings + self.ignored
        data["notes"] = notes
        props, plines, pid = self.forbidden_doc()
        return Documents(data, lines, props, plines, pid)

    def transitions_doc(self) -> dict:
        out, names = {}, Identifiers()
        for tr, guard, assign in zip(self.flat.transitions, self.guards, self.assignments):
            if guard is None:
                continue                      # a guard 'false' never fires
            src, dst = self.mode_of[tr.source], self.mode_of[tr.target]
            base = tr.label.split(".")[-1] if tr.label else f"{src}_to_{dst}"
            name = names(base)
            path = ("transitions", name)
            where = f"transition {self.flat.label(tr.source)} -> {self.flat.label(tr.target)}"
            self.lines[path] = (self.file, tr.line, where)
            spec: dict = {"from": src, "to": dst}
            texts = []
            for rel, line in guard:
                for text in self.as_constraints(self.relation_texts(rel, tr.source, line)):
                    self.lines[path + ("guard", len(texts))] = (self.file, line, f"{where}: guard")
                    texts.append(text)
            if texts:
                spec["guard"] = texts
            if assign:
                reset = {}
                for var, (tokens, line) in assign.items():
                    if var in self.inputs:
                        raise InputError(f"assignment: '{var}' is an input and cannot be assigned",
                                         self.file, line=line)
                    reset[self.yaml[var]] = self.render(tokens, tr.source, line)
                    self.lines[path + ("reset", self.yaml[var])] = (self.file, line, f"{where}: assignment")
                spec["reset"] = reset
            if tr.asap:
                spec["urgent"] = True
            out[name] = spec
        return out

    # -------------------------------------------------------------- the cfg
    def cfg_formula(self, key: str, required: bool = False):
        text = self.cfg.text(key)
        if text is None or not text.strip():
            if required:
                if text is None:
                    raise self.cfg.missing(key)
                raise InputError(f"no '{key}'", self.cfg.file, line=self.cfg.line(key))
            return []
        try:
            return parse_formula(text)
        except FormulaError as exc:
            raise formula_error(exc, key, text, self.cfg.file, self.cfg.line(key)) from None

    def lookup(self, name: str) -> list[str]:
        """The global names a cfg name may mean: itself, else those with that dotted suffix."""
        matches = self.suffixes.get(name, [])
        return [name] if name in matches else matches

    def resolve(self, name: str, key, where_key: str) -> str:
        """A cfg name as the global name of a variable of the model in location ``key``; a name
        the system lacks, or that means nothing there, is bad input."""
        matches = self.lookup(name)
        if len(matches) > 1:
            raise self.cfg_error(where_key, f"'{name}' is ambiguous ({few(matches)}): write the instance's name")
        if not matches:
            variables = self.states + list(self.inputs) + sorted({a for d in self.aliases.values() for a in d})
            raise self.cfg_error(where_key, f"unknown name '{name}' (the system's variables: {few(variables)})")
        g = matches[0]
        if g in self.yaml or g in self.aliases[key]:
            return g
        if any(g in d for d in self.aliases.values()):
            raise self.cfg_error(where_key, f"'{name}' has no value in location '{self.flat.label(key)}' "
                                            "(an equality defines it in other locations only)")
        raise self.cfg_error(where_key, f"'{name}' takes no part in the system (no flow, bound or definition), "
                                        "so a constraint on it says nothing about the runs")

    def cfg_error(self, where_key: str, message: str) -> InputError:
        return InputError(message, self.cfg.file, where_key, self.cfg.line(where_key))

    def instance_of(self, comp: str | None, where_key: str) -> int:
        inst = self.flat.instances
        if comp is None:
            if len(inst) != 1:
                raise self.cfg_error(where_key, f"loc() without a component in a network of {len(inst)} components")
            return 0
        matches = [i for i, x in enumerate(inst) if x.path == comp or x.path.endswith("." + comp)
                   or (x.path == "" and x.component.id == comp)]
        if len(matches) > 1:
            raise self.cfg_error(where_key, f"loc({comp}) is ambiguous")
        if not matches:
            raise self.cfg_error(where_key, f"loc({comp}): no component instance '{comp}' "
                                            f"(the system's: {few(x.path or x.component.id for x in inst)})")
        return matches[0]

    def location_of(self, atom: Loc, where_key: str) -> int:
        """The instance a ``loc(component) == location`` term names, its location checked."""
        i = self.instance_of(atom.component, where_key)
        instance = self.flat.instances[i]
        names = [loc.name for loc in instance.component.locations.values()]
        if atom.location not in names:
            who = f"instance '{instance.path}'" if instance.path else f"component '{instance.component.id}'"
            raise self.cfg_error(where_key, f"{who} has no location '{atom.location}' (its locations: {few(names)})")
        return i

    def cfg_relation(self, rel: Relation, key, where_key: str) -> list[tuple[str, str]]:
        """The texts of a cfg relation in location ``key``, its names made global (a constant
        such as ``pi`` stays a number unless the system has a variable of that name)."""
        parts = [[Token("num", t.text) if t.kind == "name" and t.text in CONSTANTS and not self.lookup(t.text)
                  else t for t in p] for p in rel.parts]
        resolved = {n: self.resolve(n, key, where_key) for p in parts for n in names_in(p)}
        parts = [[Token("name", resolved[t.text]) if t.kind == "name" and t.text in resolved else t for t in p]
                 for p in parts]
        return self.relation_texts(Relation(parts, rel.ops), key, self.cfg.line(where_key), self.cfg.file,
                                   where_key)


    def _varying(self) -> dict[str, str]:
        """The time-varying inputs, ``{name in the written model: SpaceEx name}``."""
        return {self.yaml[v]: v for v, (_, _, vary) in self.inputs.items() if vary}

    def _initial_texts(self, atoms, key) -> list:
        """The texts of the cfg's initial relations in location ``key``, without those on
        time-varying inputs alone (``u == 0``: a value at one instant changes no run, since the
        input is any signal in its range), which are noted (``notes.ignored``)."""
        varying = self._varying()
        texts, on_inputs = [], []
        for a in (a for a in atoms if isinstance(a, Relation)):
            own = self.cfg_relation(a, key, "initially")
            names = {n for _, t in own for n in _NAME.findall(t)}
            if names and names <= varying.keys():
                on_inputs += own
                note = (f"{self.cfg.file}:{self.cfg.line('initially')}: initially: "
                        f"'{' and '.join(t for _, t in own)}' ignored: {', '.join(sorted(names))} "
                        "is a time-varying input, any signal in its range (its value at one instant "
                        "changes no run)")
                if note not in self.ignored:
                    self.ignored.append(note)
                continue
            texts += own
        self._inputs_can_start(on_inputs)
        given = {n for _, t in texts for n in _NAME.findall(t)}
        texts += [("==", f"{self.yaml[v]} == 0") for v in sorted(self.unread) if self.yaml[v] not in given]
        return texts

    def _inputs_can_start(self, texts) -> None:
        """The initial relations on time-varying inputs alone must hold somewhere in the
        inputs' ranges, or the initial set is empty (no run exists), which is bad input as an
        initial set 'false' is; when they can hold, they change no run and are dropped."""
        if not texts:
            return
        varying = self._varying()
        symbols = [sympy.Symbol(name, real=True) for name in varying]
        table = {s.name: s for s in symbols}
        ranges = []
        for name, v in varying.items():
            lo, hi, _ = self.inputs[v]
            ranges += [("<=", f"({name}) - ({hi})"), ("<=", f"({lo}) - ({name})")]
        if not open_nonempty(texts, len(texts), table, symbols, ranges):
            ranges = ", ".join(f"{name} in [{self.inputs[v][0]:g}, {self.inputs[v][1]:g}]"
                               for name, v in varying.items() if any(name in _NAME.findall(t) for _, t in texts))
            written = " and ".join(t for _, t in texts)
            written = written if len(written) <= 80 else written[:77] + "..."
            raise InputError(f"initially: the initial set is empty: '{written}' "
                             f"holds nowhere in the time-varying inputs' ranges ({ranges})",
                             self.cfg.file, line=self.cfg.line("initially"))

    def _no_input_in_initially(self, texts) -> None:
        """A time-varying input (a real with no flow, bounded by invariants) takes any value in
        its range at every instant: an initial constraint on it is refused at the cfg's line."""
        varying = self._varying()
        for _, text in texts:
            names = set(_NAME.findall(text))
            hit = next((v for name, v in varying.items() if name in names), None)
            if hit is not None:
                raise InputError(f"initially: '{hit}' is a time-varying input (no flow, bounded by the "
                                 f"invariants): it takes any value in its range at every instant, so "
                                 f"the initial set cannot constrain it", self.cfg.file,
                                 line=self.cfg.line("initially"))

    def initial_doc(self, atoms) -> dict:
        allowed: dict[int, set] = {}
        for a in atoms:
            if isinstance(a, Loc):
                i = self.location_of(a, "initially")
                allowed[i] = allowed.get(i, {a.location}) & {a.location}
            elif isinstance(a, Const) and not a.value:
                raise InputError("initially: the initial set is 'false' (empty)", self.cfg.file,
                                 line=self.cfg.line("initially"))
        candidates = [key for key, loc in self.flat.locations.items()
                      if all(loc.names[i] in names for i, names in allowed.items())]
        if not candidates:
            raise InputError("initially: no location matches the loc() terms", self.cfg.file,
                             line=self.cfg.line("initially"))
        symbols = [sympy.Symbol(self.yaml[g], real=True) for g in self.states + list(self.inputs)]
        table = {s.name: s for s in symbols}
        # strict bounds of initially are kept strict here (an empty open set is bad input, not
        # its closure's boundary: x > 1 & x < 1 is no point, not x = 1); a non-empty one is
        # then read as its closure, as invariants and guards are
        choice, alone = [], []
        for key in candidates:
            texts = self._initial_texts(atoms, key)
            self._no_input_in_initially(texts)
            written = len(texts)
            alone.append(list(texts))
            for j, (rel, line) in enumerate(self.invariants[key]):
                if j not in self.dropped[key]:
                    inv = self.relation_texts(rel, key, line)
                    if linear_rows([(k, _difference(t, k)) for k, t in inv], table, symbols) is not None:
                        texts += _closed(inv)
            bounds = [("<=", f"({self.yaml[v]}) - ({hi})") for v, (lo, hi, _) in self.inputs.items()] + \
                     [("<=", f"({lo}) - ({self.yaml[v]})") for v, (lo, hi, _) in self.inputs.items()]
            if open_nonempty(texts, written, table, symbols, bounds):
                choice.append((key, texts))
        if not choice:
            what = ("meets no location's invariant" if any(open_nonempty(t, len(t), table, symbols) for t in alone)
                    else "is empty (its constraints exclude each other)"
                    if not any(open_nonempty(t, 0, table, symbols) for t in alone)
                    else "is empty (its constraints exclude each other once its strict bounds are kept "
                         "strict: x > 1 & x <= 1 holds nowhere)")
            raise InputError(f"initially: the initial set {what}", self.cfg.file, line=self.cfg.line("initially"))
        self.lines[("initial",)] = (self.cfg.file, self.cfg.line("initially"), "initially")
        if len(choice) > 1:
            return self._start_mode(choice, atoms)
        key, texts = choice[0]
        return {"mode": self.mode_of[key], "constraints": [t for _, t in texts]}

    def _start_mode(self, choice, atoms) -> dict:
        """Several initial locations: a timeless mode ``start`` holding the cfg's set, with an
        urgent jump into each location whose (linear) invariant it meets. Properties do not
        look at ``start``: its states are checked where they land.

        The cfg's set is read in each location with that location's aliases (SpaceEx intersects
        ``initially`` with each location's invariant, where an equality ``y == x`` defines
        ``y``). Where they give the same texts everywhere (the usual case), ``start`` holds
        them. Where they differ (``y == x`` in A, ``y == -x`` in B), ``start`` holds a box around
        all of them and each jump's guard also holds that location's own reading, so a state
        enters a location only from that location's initial set."""
        start = Identifiers(set(self.mode_of.values()) | set(self.extra_modes))("start")
        self.extra_modes[start] = {"flow": False}
        self.lines[("modes", start)] = (self.cfg.file, self.cfg.line("initially"))
        own = {key: self._initial_texts(atoms, key) for key, _ in choice}
        first = own[choice[0][0]]
        if all(texts == first for texts in own.values()):
            texts, entry = first, {key: [] for key in own}
        else:
            texts = [t for t in first if all(t in other for other in own.values())] + self._hull(choice)
            entry = {key: self.as_constraints(own[key]) for key in own}
        names = Identifiers(self.transitions_out)
        # a simulator takes the first enabled urgent jump: locations where time passes first
        for key, _ in sorted(choice, key=lambda c: c[0] in self.timeless):
            guard = list(entry[key])
            for j, (rel, line) in enumerate(self.invariants[key]):
                if j not in self.dropped[key]:
                    guard += self.as_constraints(self.relation_texts(rel, key, line))
            name = names(f"{start}_to_{self.mode_of[key]}")
            self.transitions_out[name] = {"from": start, "to": self.mode_of[key], "urgent": True,
                                          **({"guard": guard} if guard else {})}
            self.lines[("transitions", name)] = (self.cfg.file, self.cfg.line("initially"))
        return {"mode": start, "constraints": [t for _, t in texts]}

    def _hull(self, choice) -> list[tuple[str, str]]:
        """Bounds ``("<=", "x >= lo")`` of a box holding every candidate's initial set (the cfg's
        relations and the linear invariant of its location, as ``choice`` holds them), by LP per
        state, widened by a hair so the solver's rounding cannot cut a state off (the jumps'
        guards then keep each location's own set). A set that is not linear cannot be
        bounded so: bad input asking for the initial location."""
        symbols = [sympy.Symbol(self.yaml[g], real=True) for g in self.states + list(self.inputs)]
        table = {s.name: s for s in symbols}
        bounds = [("<=", f"({self.yaml[v]}) - ({hi})") for v, (lo, hi, _) in self.inputs.items()] + \
                 [("<=", f"({lo}) - ({self.yaml[v]})") for v, (lo, hi, _) in self.inputs.items()]
        low, high = np.full(len(self.states), np.inf), np.full(len(self.states), -np.inf)
        for key, texts in choice:
            rows = linear_rows([(k, _difference(t, k)) for k, t in texts] + bounds, table, symbols)
            if rows is None:
                raise InputError("initially: construct not supported: a name the initial set reads is defined "
                                 "differently in the initial locations and the set is not linear there; give "
                                 "the initial location with loc(...) == ...", self.cfg.file,
                                 line=self.cfg.line("initially"))
            for i in range(len(self.states)):
                lo, hi = _extent(rows, i, len(symbols))
                low[i], high[i] = min(low[i], lo), max(high[i], hi)
        out = []
        for i, s in enumerate(self.states):
            if np.isfinite(low[i]):
                out.append(("<=", f"{self.yaml[s]} >= {low[i] - 1e-9 * max(1.0, abs(low[i])):.12g}"))
            if np.isfinite(high[i]):
                out.append(("<=", f"{self.yaml[s]} <= {high[i] + 1e-9 * max(1.0, abs(high[i])):.12g}"))
        return out

    def forbidden_doc(self):
        terms = self.cfg_formula("forbidden")
        pid = property_id(self.cfg.file)
        line = self.cfg.line("forbidden")
        props, plines = [], {}
        for term in terms:
            if any(isinstance(a, Const) and not a.value for a in term):
                continue
            modes = set(self.mode_of.values())
            for a in term:
                if isinstance(a, Loc):
                    i = self.location_of(a, "forbidden")
                    modes &= {self.mode_of[k] for k, loc in self.flat.locations.items() if loc.names[i] == a.location}
            if not modes:
                continue
            avoid = []
            for a in term:
                if isinstance(a, Relation):
                    texts = None
                    for key, mode in self.mode_of.items():     # aliases: the same text in every mode
                        if mode not in modes:
                            continue
                        t = self.cfg_relation(a, key, "forbidden")
                        if texts is not None and t != texts:
                            raise self.cfg_error("forbidden", "a name defined differently in different locations")
                        texts = t
                    avoid += self.as_constraints(texts)
            k = len(props)
            order = [m for m in self.mode_of.values() if m in modes]
            prop = {"id": pid, "kind": "safety", "modes": order,
                    "description": f"forbidden = {printable(self.cfg.text('forbidden'))[:200]}"}
            if avoid:
                prop["avoid"] = avoid
            else:
                prop["require"] = ["0 <= -1"]         # the whole of these modes is forbidden
            props.append(prop)
            plines[("properties", k)] = (self.cfg.file, line, "forbidden")
        if not props and terms:             # every term false, or on locations the product never has
            props.append({"id": pid, "kind": "safety", "modes": list(dict.fromkeys(self.mode_of.values())),
                          "description": f"forbidden = {printable(self.cfg.text('forbidden'))[:200]} (empty: "
                                         "no term names a location combination of the product, or each "
                                         "is false)",
                          "require": ["0 <= 1"]})     # nothing is forbidden anywhere
            plines[("properties", 0)] = (self.cfg.file, line, "forbidden")
        if not props:
            return None, {}, pid
        if len(props) > 1:
            for k, p in enumerate(props, start=1):
                p["id"] = f"{pid}-{k}"
        return {"properties": props}, plines, pid


def _extent(rows, i: int, n: int) -> tuple[float, float]:
    """``(min, max)`` of coordinate ``i`` over the rows ``(A, b, E, f)`` (infinite where
    unbounded, or where the solver gives no answer: a wider box only costs time)."""
    A, b, E, f = rows
    args = dict(A_ub=A if len(b) else None, b_ub=b if len(b) else None,
                A_eq=E if len(f) else None, b_eq=f if len(f) else None)
    e = np.eye(n)[i]
    try:
        lo, hi = lp.minimize(e, **args), lp.maximize(e, **args)
    except lp.LPError:
        return -np.inf, np.inf
    return (lo.value if lo.optimal else -np.inf), (hi.value if hi.optimal else np.inf)


def _written(rel) -> str:
    """A relation as its tokens read (``w <= x + 1``)."""
    parts = ["".join(tok.text for tok in part) for part in rel.parts]
    return " ".join(p + (f" {op}" if i < len(rel.ops) else "") for i, (p, op) in
                    enumerate(zip(parts, rel.ops + [""])))


def _difference(text: str, kind: str) -> str:
    """``a op b`` as the text ``(a) - (b)`` with ``<= 0`` (or ``== 0``) meaning the relation."""
    if kind == "==":
        a, b = text.split(" == ", 1)
        return f"({a}) - ({b})"
    for op in (" <= ", " < ", " >= ", " > "):
        if op in text:
            a, b = text.split(op, 1)
            return f"({a}) - ({b})" if op.strip() in ("<=", "<") else f"({b}) - ({a})"
    raise ValueError(text)
