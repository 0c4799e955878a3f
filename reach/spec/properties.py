"""Property files and their binding to a model.

A property file (``properties/*.yaml``) is written once and checked against many models::

    properties:
      - id: thrust
        kind: safety                 # must hold at all times, in the listed modes
        modes: [approach, rendezvous]
        require: ["abs(Fx) <= 10[N]", "abs(Fy) <= 10[N]"]
      - id: collision
        kind: safety
        modes: [passive]
        avoid: {box: {x: [-0.1, 0.1], y: [-0.1, 0.1]}}
      - id: dock
        kind: reach                  # P(x(at) in target)
        at: 2110[s]
        target: {box: {x: [-5, 5], ...}}
        probability: {at_least: 0.6}
      - id: corridor
        kind: reach_avoid            # P(x(at) in target and x in safe at every step before)
        at: 1000[s]
        target: {...}
        safe: ["y >= -2.15[km]"]
        probability: {at_least: 0.8}
      - id: closest
        kind: event                  # extremum of a quantity along the run
        modes: [passive]
        minimize: "x**2 + y**2"
        require: ">= 0.01"

Loading checks the structure; :func:`bind` parses the expressions against one model (its
names, units and per-mode control laws) and produces the ``Bound*`` objects back-ends read.
Binding continues the model's dimension equations (:mod:`reach.model.units`): both sides of
every comparison, a box bound and its variable, an event quantity and its bound must agree,
``at`` is a time; a mismatch names the field and both sides
(``properties[1].require[0]: 0.055[m] compared with abs(vx) [m/min]``). Each constraint and
event keeps the unit its requirement was written in, for reports.
A safety requirement ``c1 and c2 and ...`` becomes the union of unsafe pieces ``not ci``;
an ``avoid`` set is one (convex) unsafe piece.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy

from reach.errors import InputError, Where, not_a_mode
from reach.model.constraints import Constraint, from_comparisons, halfspaces, violation_test
from reach.model.expr import DimensionContext, parse_comparison, parse_quantity, side_text
from reach.model.units import TIME, DisplayUnit, Form
from reach.yamlio import Doc, load

KINDS = ("safety", "reach", "reach_avoid", "event")
_FIELDS = {
    "safety": {"id", "kind", "description", "modes", "optional", "require", "avoid"},
    "reach": {"id", "kind", "description", "at", "target", "probability"},
    "reach_avoid": {"id", "kind", "description", "at", "target", "safe", "probability"},
    "event": {"id", "kind", "description", "modes", "optional", "minimize", "maximize", "require"},
}


@dataclass
class Property:
    """A property as written in the file (expressions still text), with its location."""

    id: str
    kind: str
    raw: dict
    doc: Doc
    path: tuple
    file: str

    def where(self, *keys) -> Where:
        return self.doc.where(*self.path, *keys)


@dataclass
class BoundSafety:
    """``pieces[mode]``: the unsafe set in that mode as a union of conjunctions ``g <= 0``."""

    id: str
    modes: list[str]
    pieces: dict[str, list[list[Constraint]]]
    symbols: list[sympy.Symbol]
    file: str = ""
    description: str = ""
    kind: str = "safety"
    missing_modes: list[str] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        """Whether no state is unsafe: every piece in every mode has a constant constraint that
        fails (``1 <= 0``: a SpaceEx ``forbidden = false``, a requirement ``0 <= 1``), or there
        are no pieces at all."""
        def never(c: Constraint) -> bool:
            g = sympy.sympify(c.g)
            return bool(g.is_number) and (float(g) > 0 or (c.strict and float(g) == 0))
        return all(any(never(c) for c in piece) for pieces in self.pieces.values() for piece in pieces)

    def halfspace_pieces(self, mode: str):
        """The unsafe pieces of ``mode`` as ``[(H, g)]`` with ``H x <= g``; None if any is nonlinear."""
        out = []
        for piece in self.pieces.get(mode, []):
            hs = halfspaces(piece, self.symbols)
            if hs is None:
                return None
            out.append(hs)
        return out

    def violation(self, mode: str, sources=None):
        """Vectorised test in ``mode``: ``X -> (violated, depth)``, None if no pieces there.

        For a piece ``{g_j <= 0 for all j}`` (``< 0`` for strict ones) the depth is
        ``max_j g_j``; over the union it is the minimum across pieces. ``violated`` asks for
        a depth beyond rounding error (see :func:`violation_test`, whose row magnitudes count
        ``sources`` where given: the simulator's :func:`reach.model.simulate.value_sources`);
        positive depth is a margin to the unsafe set.
        """
        tests = [violation_test(piece, self.symbols, sources) for piece in self.pieces.get(mode, [])]
        if not tests:
            return None

        def violation(X: np.ndarray):
            results = [t(X) for t in tests]
            violated = np.any(np.stack([r[0] for r in results], axis=1), axis=1)
            depth = np.min(np.stack([r[1] for r in results], axis=1), axis=1)
            return violated, depth

        return violation

    def constraints(self) -> list[Constraint]:
        """Every constraint of every unsafe piece."""
        return [c for pieces in self.pieces.values() for piece in pieces for c in piece]

    def dimensions(self) -> set:
        """The dimensions of those constraints (None for one without units)."""
        return {c.dimension for c in self.constraints()}

    def margin_unit(self) -> DisplayUnit | None:
        """The unit of a depth or margin into the unsafe pieces: the requirement's unit if every
        constraint of every piece has one dimension, else None (then depths are model units of
        mixed dimensions)."""
        dims = self.dimensions()
        if len(dims) != 1 or None in dims:
            return None
        return next((c.unit for c in self.constraints() if c.unit is not None), None)


@dataclass
class BoundReach:
    """``P(x(at) in target)``, ``target`` a conjunction of constraints."""

    id: str
    at: float
    target: list[Constraint]
    symbols: list[sympy.Symbol]
    at_least: float | None = None
    file: str = ""
    description: str = ""
    kind: str = "reach"


@dataclass
class BoundReachAvoid:
    """``P(x(at) in target and x(k*step) in safe for every step k*step < at)``."""

    id: str
    at: float
    target: list[Constraint]
    safe: list[Constraint]
    symbols: list[sympy.Symbol]
    at_least: float | None = None
    file: str = ""
    description: str = ""
    kind: str = "reach_avoid"


@dataclass
class BoundEvent:
    """Extremum (``sense`` min or max) of ``quantity[mode]`` over the run in ``modes``,
    required to satisfy ``op value``."""

    id: str
    modes: list[str]
    sense: str
    quantity: dict[str, sympy.Expr]
    op: str
    value: float
    symbols: list[sympy.Symbol]
    file: str = ""
    description: str = ""
    kind: str = "event"
    text: str = ""                      # the quantity as written
    unit: DisplayUnit | None = None     # the unit of the requirement's bound


# ---------------------------------------------------------------- loading

def load_properties(path) -> list[Property]:
    """Read a property file and check its structure (expressions are parsed by :func:`bind`)."""
    return properties_from_doc(load(path))


def properties_from_doc(doc: Doc) -> list[Property]:
    """The properties of a document read elsewhere (a SpaceEx cfg's forbidden set)."""
    data = doc.data
    if not isinstance(data, dict) or "properties" not in data:
        raise InputError("a property file needs a top-level 'properties:' list", doc.file, line=1)
    unknown = set(data) - {"properties", "description"}
    if unknown:
        key = sorted(unknown)[0]
        raise doc.where(key).error(f"unknown field '{key}' (expected 'properties')")
    items = data["properties"]
    if not isinstance(items, list) or not items:
        raise doc.where("properties").error("expected a non-empty list of properties")
    seen = set()
    out = []
    for i, item in enumerate(items):
        where = doc.where("properties", i)
        if not isinstance(item, dict):
            raise where.error("each property is a mapping with at least 'id' and 'kind'")
        for key in ("id", "kind"):
            if key not in item:
                raise where.error(f"missing '{key}'")
        pid, kind = item["id"], item["kind"]
        if not isinstance(pid, str) or not pid.replace("_", "").replace("-", "").isalnum():
            raise doc.where("properties", i, "id").error("id must be a name (letters, digits, _ or -)")
        if pid in seen:
            raise doc.where("properties", i, "id").error(f"duplicate property id '{pid}'")
        seen.add(pid)
        if kind not in KINDS:
            raise doc.where("properties", i, "kind").error(
                f"unknown kind '{kind}' (expected one of {', '.join(KINDS)})")
        extra = set(item) - _FIELDS[kind]
        if extra:
            key = sorted(extra)[0]
            raise doc.where("properties", i, key).error(f"unknown field '{key}' for {article(kind)} property")
        prop = Property(pid, kind, item, doc, ("properties", i), doc.file)
        _check_structure(prop)
        out.append(prop)
    return out


def article(kind: str) -> str:
    """``a safety``, ``an event``: the kind with its indefinite article."""
    return ("an " if kind[:1] in "aeiou" and kind else "a ") + kind


def _need(prop: Property, key: str):
    if key not in prop.raw:
        raise prop.where().error(f"{article(prop.kind)} property needs '{key}'")
    return prop.raw[key]


def _check_list_of_text(prop, key):
    value = prop.raw[key]
    if isinstance(value, (str, int, float)) and not isinstance(value, bool):
        return
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise prop.where(key).error("expected a constraint string or a non-empty list of them")


def _check_structure(prop: Property) -> None:
    raw = prop.raw
    if "modes" in raw and (not isinstance(raw["modes"], list) or not raw["modes"]
                           or not all(isinstance(m, str) for m in raw["modes"])):
        for i, mode in enumerate(raw["modes"] if isinstance(raw["modes"], list) else []):
            if isinstance(mode, bool):
                raise not_a_mode(mode, prop.where("modes", i))
        raise prop.where("modes").error("expected a non-empty list of mode names")
    if prop.kind == "safety":
        if ("require" in raw) == ("avoid" in raw):
            raise prop.where().error("a safety property needs exactly one of 'require' or 'avoid'")
        if "require" in raw:
            _check_list_of_text(prop, "require")
        else:
            _check_set(prop, "avoid")
    elif prop.kind in ("reach", "reach_avoid"):
        _need(prop, "at")
        _need(prop, "target")
        _check_set(prop, "target")
        if prop.kind == "reach_avoid":
            _need(prop, "safe")
            _check_list_of_text(prop, "safe")
        if "probability" in raw:
            p = raw["probability"]
            if not isinstance(p, dict) or set(p) != {"at_least"}:
                raise prop.where("probability").error("expected {at_least: P}")
            v = p["at_least"]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
                raise prop.where("probability", "at_least").error("expected a number in [0, 1]")
    else:
        if ("minimize" in raw) == ("maximize" in raw):
            raise prop.where().error("an event property needs exactly one of 'minimize' or 'maximize'")
        _need(prop, "require")
        if not isinstance(raw["require"], str):
            raise prop.where("require").error("expected a bound such as '<= 1' or '>= 0.1'")


def _check_set(prop: Property, key: str) -> None:
    value = prop.raw[key]
    if isinstance(value, dict):
        if set(value) != {"box"} or not isinstance(value["box"], dict) or not value["box"]:
            raise prop.where(key).error("expected {box: {name: [low, high], ...}} or a list of constraints")
        for name, bounds in value["box"].items():
            if not (isinstance(bounds, list) and len(bounds) == 2):
                raise prop.where(key, "box", name).error("expected [low, high]")
    else:
        _check_list_of_text(prop, key)


# ---------------------------------------------------------------- binding

def _shown_unit(dims: DimensionContext | None, form, brackets) -> tuple:
    """``(dimension, unit)`` of a checked quantity, ``(None, None)`` if unknown."""
    return dims.display(form, brackets) if dims is not None else (None, None)


def _set_constraints(prop: Property, key: str, names, units, dims=None) -> list[Constraint]:
    """A ``box`` or a list of constraint strings, as one conjunction."""
    value = prop.raw[key]
    if isinstance(value, dict):
        out = []
        for name, (low, high) in value["box"].items():
            where = prop.where(key, "box", name)
            if name not in names:
                raise where.error(f"unknown name '{name}'")
            var = names[name]
            bounds, brackets = [], []
            for text in (low, high):
                bound, form = parse_quantity(text, names, where, units, dims)
                if dims is not None:
                    brackets += dims.brackets
                    dims.require(form, Form.name(name), where,
                                 lambda got, want: f"{side_text(text, got)} compared with {name} {want}")
                bounds.append(bound)
            lo, hi = bounds
            if not (lo.is_number and hi.is_number):
                raise where.error("box bounds must be numbers")
            if float(lo) > float(hi):
                raise where.error(f"empty interval [{float(lo):g}, {float(hi):g}]")
            tags = _shown_unit(dims, Form.name(name), brackets)
            out.append(Constraint(sympy.expand(lo - var), False, f"{name} >= {low}", where, *tags))
            out.append(Constraint(sympy.expand(var - hi), False, f"{name} <= {high}", where, *tags))
        return out
    return _conjunction(prop, key, names, units, dims)


def _conjunction(prop: Property, key: str, names, units, dims=None) -> list[Constraint]:
    value = prop.raw[key]
    texts = [value] if not isinstance(value, list) else value
    out = []
    for j, text in enumerate(texts):
        where = prop.where(key, j) if isinstance(value, list) else prop.where(key)
        out.extend(from_comparisons(parse_comparison(text, names, where, units, dims), str(text), where))
    return out


def _time(prop: Property, names, units, dims=None) -> float:
    where = prop.where("at")
    text = prop.raw["at"]
    value, form = parse_quantity(text, {k: v for k, v in names.items() if v.is_number}, where, units, dims)
    if dims is not None:
        dims.require(form, Form(const=TIME), where,
                     lambda got, want: f"'at' must be a time {want}, got {side_text(text, got)}")
    if not value.is_number or float(value) < 0:
        raise where.error("'at' must be a non-negative time")
    return float(value)


def bind(prop: Property, model):
    """Parse ``prop``'s expressions against ``model`` and return the ``Bound*`` property.

    Inputs (``Fx``) are replaced by each mode's control law; constants and units come from
    the model. A safety or event property whose modes the model lacks is bound with
    ``missing_modes`` listed (and no pieces there): there is nothing to check in them.
    """
    symbols = model.symbols
    names = {name: sym for name, sym in zip(model.state, symbols)}
    names.update({k: sympy.Float(v) for k, v in model.constants.items()})
    input_symbols = {u: sympy.Symbol(f"__input_{u}") for u in model.inputs}
    names.update(input_symbols)
    units = model.units
    description = str(prop.raw.get("description", ""))
    dims = None
    if getattr(model, "dimensions", None) is not None:
        dims = DimensionContext(model.dimensions.copy(), units,
                                frozenset(list(model.state) + list(model.inputs) + list(model.constants)))

    def per_mode(expr, mode):
        law = model.modes[mode].control
        return expr.subs({input_symbols[u]: law.get(u, sympy.Integer(0)) for u in model.inputs})

    def state_only(constraints, where_key):
        for c in constraints:
            if c.g.free_symbols & set(input_symbols.values()):
                raise prop.where(where_key).error("inputs are not allowed here (only state variables)")
        return constraints

    if prop.kind in ("safety", "event"):
        requested = prop.raw.get("modes", list(model.modes))
        modes = [m for m in requested if m in model.modes]
        missing = [m for m in requested if m not in model.modes]
    if prop.kind == "safety":
        if "require" in prop.raw:
            safe = _conjunction(prop, "require", names, units, dims)
            generic = [[c.negated()] for c in safe]
        else:
            generic = [_set_constraints(prop, "avoid", names, units, dims)]
        pieces = {m: [[c.substitute({input_symbols[u]: model.modes[m].control.get(u, sympy.Integer(0))
                                     for u in model.inputs}) for c in piece] for piece in generic]
                  for m in modes}
        return BoundSafety(prop.id, modes, pieces, symbols, prop.file, description,
                           missing_modes=missing)
    if prop.kind == "event":
        sense = "min" if "minimize" in prop.raw else "max"
        key = "minimize" if sense == "min" else "maximize"
        expr, quantity_form = parse_quantity(prop.raw[key], names, prop.where(key), units, dims)
        quantity_brackets = list(dims.brackets) if dims is not None else []
        text = prop.raw["require"].strip()
        op = next((o for o in ("<=", ">=") if text.startswith(o)), None)
        if op is None:
            raise prop.where("require").error("expected '<= VALUE' or '>= VALUE'")
        bound_text = text[2:].strip()
        value, value_form = parse_quantity(bound_text, {k: v for k, v in names.items() if v.is_number},
                                           prop.where("require"), units, dims)
        if not value.is_number:
            raise prop.where("require").error("the bound must be a number")
        unit = None
        if dims is not None:
            brackets = dims.brackets + quantity_brackets
            dims.require(value_form, quantity_form, prop.where("require"),
                         lambda got, want: f"{side_text(bound_text, got)} compared with {prop.raw[key]} {want}")
            _, unit = _shown_unit(dims, quantity_form if quantity_form is not None else value_form,
                                          brackets)
        return BoundEvent(prop.id, modes, sense, {m: per_mode(expr, m) for m in modes}, op,
                          float(value), symbols, prop.file, description, text=str(prop.raw[key]), unit=unit)
    at = _time(prop, names, units, dims)
    if at > model.horizon * (1 + 1e-12):
        raise prop.where("at").error(f"'at' = {at:g} is beyond the model horizon {model.horizon:g}")
    target = state_only(_set_constraints(prop, "target", names, units, dims), "target")
    at_least = prop.raw.get("probability", {}).get("at_least")
    if prop.kind == "reach":
        return BoundReach(prop.id, at, target, symbols, at_least, prop.file, description)
    safe = state_only(_conjunction(prop, "safe", names, units, dims), "safe")
    return BoundReachAvoid(prop.id, at, target, safe, symbols, at_least, prop.file, description)
