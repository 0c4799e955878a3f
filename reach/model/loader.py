"""Load a hybrid automaton from YAML (``models/*.yaml``).

Format (all expressions are strings parsed by :mod:`reach.model.expr`)::

    name: SRA02
    extends: _rendezvous_abort.yaml        # optional template; mappings merge, child wins
    description: ...
    units: {length: m, time: min, mass: kg}  # base units of the model (SI by default)
    constants: {n: 0.00438138, mc: 500[kg]} # in order; later ones may use earlier ones
    state: {x: m, y: m, vx: m/min, vy: m/min, t: min}   # or a plain list [x, y, vx, vy, t]
    inputs: {Fx: kg*m/min**2, Fy: kg*m/min**2}          # or [Fx, Fy]
    modes:
      approach:
        flow: {x: vx, vx: "3*n**2*x + 2*n*vy + Fx/mc", t: 1, ...}
        control: {gain: [[...], [...]], feedback: [x, y, vx, vy]}   # or lqr: {...}, or {Fx: expr},
                                                                     # or network: weights/net.npz
        invariant: ["x <= -100"]
    transitions:                            # a list, or a mapping name -> transition
      dock: {from: approach, to: rendezvous, guard: [...], urgent: true}
      abort: {from: [approach, rendezvous], to: passive, guard: ["t >= 120", "t <= 125"]}
    initial: {mode: approach, box: {x: [-925, -875], vx: 0, ...}}
    # or a polytope: {mode: M, box: {...} (optional, partial), constraints: ["x + y == 1", ...]}
    bounded_inputs: {u: {range: [0.8, 1], varying: true}}   # nondeterministic inputs
    horizon: 240
    disturbance: {gaussian: {mean: [0, 0], cov: [[..]]}, enters: [vx, vy], step: 10}

A mode's ``flow: false`` means no time may pass in it. Bounded inputs are appended to the
state (flow 0, initial interval = their range, never reset): see
:class:`reach.model.automaton.BoundedInput`.

Every error names file, line and field: ``models/x.yaml:14: modes.approach.flow.vx: unknown
name 'vyy'``.

Dimensions (:mod:`reach.model.units`). A model that gives ``units:`` or declares a state or
input unit is dimension-checked: a declaration ``vx: m/min`` (in the model's own units: the
values are model units; ``1`` for a pure number) and a constant's bracket (``mc: 500[kg]``)
fix dimensions, and the rest is inferred from how names meet: ``x' = vx`` makes ``vx`` a
length per time, ``Fx/mc`` added to an acceleration ties ``Fx`` to ``mc``. Flows, control
laws, resets, invariants, guards, initial values, the horizon (a time) and the disturbance
(mean in the units of the state it enters, covariance in their products, step a time) are
equations; a contradiction is an InputError at the field that brought it. A model with
neither is not checked (every dimension unknown). ``HybridAutomaton.dimensions`` keeps the
equations for the property files.
"""

from __future__ import annotations

import ast
import copy
import keyword
import unicodedata
from pathlib import Path

import numpy as np
import sympy

from reach import lp
from reach.errors import InputError, Where, not_a_mode
from reach.paths import printable, within
from reach.sets import Box
from reach.model.automaton import (MAX_VARIABLES, BoundedInput, Controller, Disturbance, HybridAutomaton, InitialSet,
                                   LinearSet, Mode, Transition)
from reach.model.constraints import affine_coefficients, from_comparisons
from reach.model.controllers import build_law, build_network_law
from reach.model.expr import (CONSTANTS, FUNCTIONS, DimensionContext, parse_comparison, parse_expr,
                               parse_quantity, parse_unit, side_text)
from reach.model.units import TIME, DimensionSystem, Form, UnitSystem, check_base
from reach.yamlio import Doc, load, merge

TOP_FIELDS = {"name", "extends", "description", "units", "constants", "state", "inputs", "modes",
              "transitions", "initial", "horizon", "disturbance", "notes", "bounded_inputs"}
MODE_FIELDS = {"flow", "control", "invariant", "description"}
TRANSITION_FIELDS = {"from", "to", "guard", "urgent", "reset", "description"}
RESERVED = set(FUNCTIONS) | set(CONSTANTS)
MAX_EXTENDS = 8
MIN_HORIZON = 1e-12            # model time units: below, horizon / 60 and its products underflow
MAX_HORIZON = 1e12             # model time units: beyond, grid steps of horizon / 60 overflow exp(A h)


def hint_problem(key: str, value) -> str | None:
    """What is wrong with a SpaceEx cfg hint's value (``sampling-time``: a positive time;
    ``iter-max``: a whole number, -1 for no bound), or None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        return "expected a number"
    if key == "sampling-time" and value <= 0:
        return "expected a positive time"
    if key == "iter-max" and (value != int(value) or value < -1):
        return "expected a whole number, -1 for no bound"
    if key == "iter-max" and value > MAX_ITER:
        return f"expected at most {MAX_ITER:g} (-1 for no bound)"
    return None


#: the largest ``iter-max`` read: star takes it as its jump bound ``max_jumps``, a count that
#: no option may set past 1e9 (:data:`reach.backends.options.MAX_COUNT`)
MAX_ITER = 10 ** 9


def bad_name(name) -> str | None:
    """Why ``name`` cannot name a state, input or constant, or None. Expressions are read by
    Python's parser, which brings every identifier to Unicode normal form NFKC (fullwidth ``ｘ``
    reads as ``x``, the ligature ``ﬁ`` as ``fi``): a name not in that form would be a second
    name for another one."""
    if not isinstance(name, str) or not name.isidentifier() or name.startswith("_"):
        return f"'{name}' is not a valid name"
    if keyword.iskeyword(name):
        return f"'{name}' is a Python keyword, which expressions cannot name (write '{name}_')"
    normal = unicodedata.normalize("NFKC", name)
    if normal != name:
        return f"'{name}' is not a valid name (expressions read it as '{normal}': write that)"
    return None


def read_with_templates(path: Path, depth: int = 0, chain=()) -> Doc:
    """The YAML document with its ``extends`` chain merged in. Templates are read only from the
    folder of the model file first named or the working folder (or below them): a model handed
    to reach cannot make it read, and quote in an error, a YAML file anywhere else."""
    doc = load(path)
    if not isinstance(doc.data, dict):
        raise InputError("a model file must be a mapping", doc.file, line=1)
    parent = doc.data.get("extends")
    if parent is None:
        return doc
    where = doc.where("extends")
    if not isinstance(parent, str):
        raise where.error("expected a file name")
    try:
        parent_path = (path.parent / parent).resolve()
        found = parent_path.exists()
    except (OSError, ValueError) as exc:      # a name too long for the file system, a NUL byte
        raise where.error(f"not a usable file name '{printable(parent[:80])}' ({exc.__class__.__name__})") from None
    if not found:
        raise where.error(f"no such file '{printable(parent)}'")
    if not parent_path.is_file():
        raise where.error(f"'{printable(parent)}' is not a regular file (a template must be a plain YAML file)")
    if parent_path in chain or depth >= MAX_EXTENDS:
        raise where.error("'extends' forms a cycle or is nested too deeply")
    if parent_path.suffix.lower() not in (".yaml", ".yml"):
        raise where.error(f"'{printable(parent)}' is not a .yaml or .yml file (a template is a model file)")
    root = (chain[0] if chain else path.resolve()).parent
    if not within(parent_path, [root, Path.cwd()]):     # nor are its contents quoted in an error
        raise where.error(f"'{printable(parent)}' lies outside the folder of the model file and the working "
                          f"folder: a template is read only from there (as a suite's files)")
    base = read_with_templates(parent_path, depth + 1, chain + (path.resolve(),))
    merged = merge(base, doc)
    merged.data.pop("extends", None)
    return merged


def load_model(path) -> HybridAutomaton:
    """Load and check a model file; raises :class:`InputError` on any problem."""
    path = Path(path)
    doc = read_with_templates(path)
    return _Builder(doc, str(path)).build()


def model_from_doc(doc: Doc) -> HybridAutomaton:
    """Build and check a model from a document made elsewhere (the SpaceEx import); the
    document is left as it was (the builder fills in zero flows of bounded inputs)."""
    return _Builder(Doc(copy.deepcopy(doc.data), doc.lines, doc.file), doc.file).build()



def _yaml_kind(value) -> str:
    """What YAML made of a scalar, for a message: ``a date``, ``bytes``, ``a number`` ..."""
    import datetime
    if isinstance(value, (datetime.date, datetime.datetime)):
        return "a date"
    if isinstance(value, bytes):
        return "bytes"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    return "a list" if isinstance(value, list) else "a mapping" if isinstance(value, dict) else "nothing"

class _Builder:
    def __init__(self, doc: Doc, file: str):
        self.doc = doc
        self.data = doc.data
        self.file = file

    def where(self, *keys) -> Where:
        return self.doc.where(*keys)

    def need(self, key):
        if key not in self.data:
            raise InputError(f"missing required field '{key}'", self.file, line=1)
        return self.data[key]

    # ----------------------------------------------------------- pieces
    def names_list(self, key, allow_empty=False) -> list[str]:
        """The names of ``state`` or ``inputs``: a list, or a mapping name -> unit (kept in
        ``self.declared``)."""
        value = self.data.get(key, []) if allow_empty else self.need(key)
        mapping = isinstance(value, dict)
        if (not mapping and not isinstance(value, list)) or (not value and not allow_empty):
            raise self.where(key).error("expected a list of names, or a mapping name: unit")
        names = list(value)
        seen = set()
        for i, name in enumerate(names):
            w = self.where(key, name if mapping else i)
            if why := bad_name(name):
                raise w.error(why)
            if name in RESERVED:
                raise w.error(f"'{name}' is a reserved function or constant name")
            if name in seen:
                raise w.error(f"duplicate name '{name}'")
            seen.add(name)
            if mapping:
                self.declared[name] = (value[name], w)
        return names

    def number(self, value, where: Where, names=None, dimension=None, what: str = "") -> float:
        """A number (constants and units allowed); with ``dimension`` (a :class:`Form`, or a
        fixed dimension) it must have that dimension (``what`` names it in the error)."""
        expr, form = parse_quantity(value, names if names is not None else self.constant_names, where,
                                    self.units, self.dims)
        if not expr.is_number:
            raise where.error("expected a number (constants allowed, no state variables)")
        result = complex(expr)
        if result.imag != 0 or not np.isfinite(result.real):
            raise where.error("expression does not evaluate to a finite real number")
        if dimension is not None and self.dims is not None:
            expected = dimension if isinstance(dimension, Form) else Form(const=dimension)
            self.dims.require(form, expected, where,
                              lambda got, want: f"{side_text(value, got)} given for {what} {want}")
        return result.real

    def make_dims(self, constants: list[str]) -> DimensionContext | None:
        """The dimension equations, starting from the declarations; None if the model declares no
        dimension anywhere: no unit for a state or input and no bracketed constant (then nothing is
        checked: a model written without units, such as a thermostat ``T' = -0.1 (T - 10)``, is not
        refused for its plain rate constant)."""
        raw = self.data.get("constants")
        bracketed = isinstance(raw, dict) and any(isinstance(v, str) and "[" in v for v in raw.values())
        if not self.declared and not bracketed:
            return None
        dims = DimensionContext(DimensionSystem(), self.units, frozenset(self.state + self.inputs + constants))
        for name, (unit, where) in self.declared.items():
            si, dim = parse_unit(unit, where)
            if abs(si / self.units.factor(dim) - 1) > 1e-9:
                raise where.error(f"'{unit}' is not in the model's units (values are in model units): "
                                  f"write {self.units.name(dim)}")
            dims.system.equate(Form.name(name), Form(const=dim))
            dims.system.written[name] = (unit, si, dim)
        return dims

    def build(self) -> HybridAutomaton:
        extra = set(self.data) - TOP_FIELDS
        if "properties" in extra:                # a property file given where the model goes
            raise self.where("properties").error("this is a property file, not a model (give the model "
                                                 "first, then the property file)")
        if extra:
            key = sorted(extra)[0]
            raise self.where(key).error(f"unknown field '{key}'")
        name = self.need("name")
        if not isinstance(name, str):       # YAML read it as a date, bytes, a number ...
            raise self.where("name").error(f"expected a name in text, got {_yaml_kind(name)} (quote it)")
        if not name.strip():
            raise self.where("name").error("expected a non-empty name")
        self.units = self.read_units()
        self.declared: dict = {}
        self.state = self.names_list("state")
        self.inputs = self.names_list("inputs", allow_empty=True)
        clash = set(self.state) & set(self.inputs)
        if clash:
            raise self.where("inputs").error(f"'{sorted(clash)[0]}' is both a state and an input")
        self.constants = self.read_constants()
        bounded = self.read_bounded_inputs()       # appends the bounded inputs to self.state
        if len(self.state) + len(self.inputs) > MAX_VARIABLES:
            raise self.where("state").error(f"{len(self.state) + len(self.inputs)} states and inputs (bounded "
                                            f"inputs included), more than the {MAX_VARIABLES} a model may have")
        self.symbols = [sympy.Symbol(s, real=True) for s in self.state]
        self.input_symbols = [sympy.Symbol(f"__input_{u}") for u in self.inputs]
        self.names = dict(self.constant_names)
        self.names.update(zip(self.state, self.symbols))
        self.names.update(zip(self.inputs, self.input_symbols))
        modes = self.read_modes()
        for timeless in self.timeless:
            modes[timeless].timeless = True
        transitions = self.read_transitions(modes)
        self.leave_at_once(modes, transitions)
        initial = self.read_initial_set(modes, bounded)
        horizon = self.number(self.need("horizon"), self.where("horizon"), dimension=TIME, what="the horizon")
        if horizon <= 0:
            raise self.where("horizon").error("horizon must be positive")
        if horizon < MIN_HORIZON:
            raise self.where("horizon").error(f"horizon {horizon:g} is below {MIN_HORIZON:g} time units: its grid "
                                              "steps would underflow (give the model a smaller time unit)")
        if horizon > MAX_HORIZON:
            raise self.where("horizon").error(f"horizon {horizon:g} is beyond {MAX_HORIZON:g} time units: "
                                              f"the grid steps' exponentials would overflow")
        clocks = [i for i in range(len(self.state))
                  if all(m.flow[i] == 1 for m in modes.values())]
        # a window is a span of the run's time: read on a clock that is the time (from 0, never
        # reset); a guard on another clock (a periodic timer reset at each tick) is a general guard
        reset = {i for tr in transitions for i in tr.reset}
        timers = [i for i in clocks if i not in reset and initial.low[i] == 0 == initial.high[i]]
        for tr in transitions:
            tr.window = self.window_of(tr, modes, timers)
        model = HybridAutomaton(
            name=name.strip(), description=str(self.data.get("description", "")).strip(),
            file=self.file, units=self.units, constants=self.constants, state=self.state,
            inputs=self.inputs, modes=modes, transitions=transitions, initial=initial,
            horizon=horizon, disturbance=self.read_disturbance(horizon), clocks=clocks, bounded_inputs=bounded,
            dimensions=None if self.dims is None else self.dims.system, hints=self.read_hints())
        self.check_bounded_inputs(model)
        self.check_initial_invariant(model)
        return model

    def check_initial_invariant(self, model: HybridAutomaton) -> None:
        """Bad input where no state of the initial set lies in the initial mode's (linear)
        invariant: no run starts, so every property would hold for want of runs (an empty
        invariant, ``th >= 0`` and ``th <= -1``, or a box on the wrong side of it). A set partly
        outside it is a lint (:func:`reach.model.lint.initial_outside`): those states start no run."""
        mode = model.modes[model.initial.mode]
        rows = initial_and_invariant(model)
        if rows is None:
            return
        A, b, E, f = rows
        box = Box(model.initial.low, model.initial.high)       # holds the initial set
        invariant = zip(A[:len(mode.invariant_halfspaces[1])], b)       # the first rows of A
        with np.errstate(all="ignore"):     # a row beyond the whole box needs no LP (nor one of 1e200s)
            least = [(-box.support(-h), c) for h, c in invariant]
        beyond = any(np.isfinite(v) and v > c + 1e-9 * (1 + abs(c)) for v, c in least)
        try:
            point = None if beyond else \
                lp.feasible_point(A, b, A_eq=E if E.shape[0] else None, b_eq=f if E.shape[0] else None)
        except lp.LPError:
            return
        if point is None:
            texts = ", ".join(c.text for c in mode.invariant)
            raise self.where("initial").error(
                f"no state of the initial set lies in the invariant of its mode '{mode.name}' "
                f"({texts[:100]}): no run would start, and every property would hold for want of runs")

    def read_units(self) -> UnitSystem:
        value = self.data.get("units", {})
        if not isinstance(value, dict):
            raise self.where("units").error("expected {length: m, time: s, mass: kg}")
        for key, unit in value.items():
            if key not in ("length", "time", "mass", "temperature"):
                raise self.where("units", key).error(
                    f"unknown base quantity '{key}' (length, time, mass, temperature)")
            why = check_base(key, unit) if isinstance(unit, str) else "expected a unit name"
            if why:
                raise self.where("units", key).error(why)
        return UnitSystem(**value)

    def read_constants(self) -> dict[str, float]:
        raw = self.data.get("constants", {})
        if not isinstance(raw, dict):
            raise self.where("constants").error("expected a mapping name: value")
        self.constant_names: dict[str, sympy.Expr] = {}
        for key in raw:
            if why := bad_name(key):
                raise self.where("constants", key).error(why)
            if key in RESERVED or key in self.state or key in self.inputs:
                raise self.where("constants", key).error(
                    f"constant '{key}' clashes with a reserved, state or input name")
        self.dims = self.make_dims(list(raw))
        values = {}
        for key in _dependency_order(raw, self.where):
            number = self.number(raw[key], self.where("constants", key), dimension=Form.name(key),
                                 what=f"constant {key}")
            values[key] = number
            self.constant_names[key] = sympy.Float(number)
        return values

    def read_modes(self) -> dict[str, Mode]:
        raw = self.need("modes")
        if not isinstance(raw, dict) or not raw:
            raise self.where("modes").error("expected a mapping of mode names")
        modes = {}
        for mname, spec in raw.items():
            w = self.where("modes", mname)
            if not isinstance(mname, str) or not mname.isidentifier():
                raise w.error(f"'{mname}' is not a valid mode name")
            if not isinstance(spec, dict):
                raise w.error("expected a mapping with 'flow'")
            extra = set(spec) - MODE_FIELDS
            if extra:
                raise self.where("modes", mname, sorted(extra)[0]).error(f"unknown field '{sorted(extra)[0]}'")
            flow_raw = spec.get("flow")
            if not isinstance(flow_raw, dict):
                raise w.error("missing 'flow' mapping (one derivative per state variable)")
            for var in flow_raw:
                if var not in self.state:
                    raise self.where("modes", mname, "flow", var).error(f"'{var}' is not a state variable")
            missing = [v for v in self.state if v not in flow_raw]
            if missing:
                raise self.where("modes", mname, "flow").error(f"no derivative given for '{missing[0]}'")
            open_flow = [self.rate(flow_raw[v], v, self.where("modes", mname, "flow", v)) for v in self.state]
            law, controller = self.read_control(mname, spec.get("control"), open_flow)
            substitution = {self.input_symbols[i]: law[u] for i, u in enumerate(self.inputs)}
            flow = [sympy.sympify(f).subs(substitution) for f in open_flow]
            invariant = []
            for j, text in enumerate(self.text_list(spec.get("invariant", []), ("modes", mname, "invariant"))):
                wj = self.where("modes", mname, "invariant", j)
                cons = from_comparisons(parse_comparison(text, self.names, wj, self.units, self.dims), text, wj)
                invariant.extend(c.substitute(substitution) for c in cons)
            modes[mname] = Mode(mname, self.symbols, flow, law, invariant, controller, w)
        return modes

    def rate(self, text, var: str, where: Where) -> sympy.Expr:
        """The flow of ``var``, whose dimension is ``var``'s per time."""
        expr, form = parse_quantity(text, self.names, where, self.units, self.dims)
        if self.dims is not None:
            self.dims.require(form, Form.name(var).minus(Form(const=TIME)), where,
                              lambda got, want: f"{side_text(text, got)} is not a rate of {var}: expected {want} "
                              f"(a plain number is a pure number: write a rate constant with its unit, e.g. "
                              f"0.1[1/{self.units.time}])")
        return expr

    def assigned(self, text, var: str, names, where: Where) -> sympy.Expr:
        """An expression that gives ``var`` its value (a control law, a reset)."""
        expr, form = parse_quantity(text, names, where, self.units, self.dims)
        if self.dims is not None:
            self.dims.require(form, Form.name(var), where,
                              lambda got, want: f"{side_text(text, got)} given for {var} {want}")
        return expr

    def check_control_dims(self, mname: str, spec: dict) -> None:
        """Set-points and Bryson maxima have the dimension of their state or input."""
        groups = [(("setpoint",), spec.get("setpoint"))]
        lqr = spec.get("lqr")
        if isinstance(lqr, dict) and isinstance(lqr.get("bryson"), dict):
            groups += [(("lqr", "bryson", k), lqr["bryson"].get(k)) for k in ("state", "input")]
        for path, values in groups:
            if not isinstance(values, dict):
                continue
            for name, value in values.items():
                if name in self.state or name in self.inputs:
                    self.number(value, self.where("modes", mname, "control", *path, name),
                                dimension=Form.name(name), what=name)

    def text_list(self, value, path) -> list[str]:
        if isinstance(value, str):
            return [value]
        if not isinstance(value, list) or not all(isinstance(v, (str, int, float)) for v in value):
            raise self.where(*path).error("expected a list of constraint strings")
        return [str(v) for v in value]

    def read_control(self, mname, spec, open_flow):
        w = self.where("modes", mname, "control")
        used = set().union(*(sympy.sympify(f).free_symbols for f in open_flow)) & set(self.input_symbols)
        if spec is None:
            if used:
                name = self.inputs[self.input_symbols.index(sorted(used, key=str)[0])]
                raise self.where("modes", mname).error(f"input '{name}' is used in the flow but the mode has no 'control'")
            return {u: sympy.Integer(0) for u in self.inputs}, None
        if not isinstance(spec, dict):
            raise w.error("expected a mapping: {input: expr}, {gain: K, feedback: [...]}, {lqr: {...}, feedback: [...]} "
                          "or {network: file.npz, feedback: [...]}")
        if "network" in spec:
            if not self.inputs:
                raise w.error("a network controller needs 'inputs'")
            return build_network_law(spec, self.symbols, self.state, self.inputs, w)
        if "gain" in spec or "lqr" in spec:
            if "gain" in spec and "lqr" in spec:
                raise w.error("give either 'gain' or 'lqr', not both")
            if not self.inputs:
                raise w.error("a gain or LQR controller needs 'inputs'")
            self.check_control_dims(mname, spec)
            return build_law(spec, open_flow, self.symbols, self.state, self.input_symbols, self.inputs, w,
                             lambda value, where: self.number(value, where))
        for u in spec:
            if u not in self.inputs:
                raise self.where("modes", mname, "control", u).error(f"'{u}' is not an input")
        state_names = {k: v for k, v in self.names.items() if v not in self.input_symbols}
        law = {}
        for u in self.inputs:
            if u not in spec:
                raise w.error(f"no control law for input '{u}'")
            law[u] = self.assigned(spec[u], u, state_names, self.where("modes", mname, "control", u))
        return law, Controller("law")

    def read_transitions(self, modes) -> list[Transition]:
        raw = self.data.get("transitions", [])
        if isinstance(raw, dict):
            items = list(raw.items())
        elif isinstance(raw, list):
            items = [(f"t{i}", t) for i, t in enumerate(raw)]
        else:
            raise self.where("transitions").error("expected a list or a mapping of transitions")
        out = []
        for key, spec in items:
            path = ("transitions", key) if isinstance(raw, dict) else ("transitions", int(key[1:]))
            w = self.where(*path)
            if not isinstance(spec, dict):
                raise w.error("expected a mapping with 'from', 'to' and 'guard'")
            extra = set(spec) - TRANSITION_FIELDS
            if extra:
                raise self.where(*path, sorted(extra)[0]).error(f"unknown field '{sorted(extra)[0]}'")
            for k in ("from", "to"):
                if k not in spec:
                    raise w.error(f"missing '{k}'")
            sources = spec["from"] if isinstance(spec["from"], list) else [spec["from"]]
            if not sources:
                raise self.where(*path, "from").error("expected a mode name or a non-empty list of mode names")
            for field, names in (("from", sources), ("to", [spec["to"]])):
                for s in names:
                    if not isinstance(s, str) or s not in modes:
                        raise not_a_mode(s, self.where(*path, field))
            urgent = spec.get("urgent", False)
            if not isinstance(urgent, bool):
                raise self.where(*path, "urgent").error("expected true or false")
            guard_text = self.text_list(spec.get("guard", []), path + ("guard",))
            reset_raw = spec.get("reset", {})
            if not isinstance(reset_raw, dict):
                raise self.where(*path, "reset").error("expected {state: expr}")
            reset = {}
            for var, value in reset_raw.items():
                if var not in self.state:
                    raise self.where(*path, "reset", var).error(f"'{var}' is not a state variable")
                reset[self.state.index(var)] = self.assigned(
                    value, var, {k: v for k, v in self.names.items() if v not in self.input_symbols},
                    self.where(*path, "reset", var))
            for source in sources:
                sub = {self.input_symbols[i]: modes[source].control[u] for i, u in enumerate(self.inputs)}
                guard = []
                for j, text in enumerate(guard_text):
                    wj = self.where(*path, "guard", j)
                    guard.extend(c.substitute(sub) for c in
                                 from_comparisons(parse_comparison(text, self.names, wj, self.units, self.dims),
                                                  text, wj))
                name = key if len(sources) == 1 else f"{key}:{source}"
                out.append(Transition(name, source, spec["to"], guard, urgent, reset, None, w))
        return out

    def window_of(self, tr: Transition, modes, clocks):
        """``(clock, lo, hi)`` if a may-transition's guard is an interval of one of ``clocks``."""
        if tr.urgent or not tr.guard:
            return None
        lo, hi, clock = -np.inf, np.inf, None
        for con in tr.guard:
            coeffs = affine_coefficients(con.g, self.symbols)
            if coeffs is None:
                return None
            a, c = coeffs
            nz = np.flatnonzero(a)
            if len(nz) != 1 or (clock is not None and nz[0] != clock) or nz[0] not in clocks:
                return None
            clock = int(nz[0])
            bound = -c / a[clock]
            if a[clock] > 0:
                hi = min(hi, bound)
            else:
                lo = max(lo, bound)
        if clock is None or not np.isfinite(lo) or not np.isfinite(hi):
            return None
        if lo > hi:
            raise tr.where.error(f"the guard window [{lo:g}, {hi:g}] is empty")
        return clock, float(lo), float(hi)

    def read_initial(self, modes) -> InitialSet:
        raw = self.need("initial")
        if not isinstance(raw, dict) or "mode" not in raw or "box" not in raw:
            raise self.where("initial").error("expected {mode: NAME, box: {var: [low, high] or value}}")
        extra = set(raw) - {"mode", "box"}
        if extra:
            raise self.where("initial", sorted(extra)[0]).error(f"unknown field '{sorted(extra)[0]}'")
        if not isinstance(raw["mode"], str) or raw["mode"] not in modes:
            raise not_a_mode(raw["mode"], self.where("initial", "mode"))
        box = raw["box"]
        if not isinstance(box, dict):
            raise self.where("initial", "box").error("expected {var: [low, high] or value}")
        for var in box:
            if var not in self.state:
                raise self.where("initial", "box", var).error(f"'{var}' is not a state variable")
        low, high = np.zeros(len(self.state)), np.zeros(len(self.state))
        for i, var in enumerate(self.state):
            if var not in box:
                raise self.where("initial", "box").error(f"no initial value for '{var}'")
            value = box[var]
            w = self.where("initial", "box", var)
            if isinstance(value, list):
                if len(value) != 2:
                    raise w.error("expected [low, high]")
                low[i], high[i] = (self.number(v, w, dimension=Form.name(var), what=var) for v in value)
                if low[i] > high[i]:
                    raise w.error(f"empty interval [{low[i]:g}, {high[i]:g}]")
            else:
                low[i] = high[i] = self.number(value, w, dimension=Form.name(var), what=var)
        return InitialSet(raw["mode"], low, high)

    def read_hints(self) -> dict:
        """A SpaceEx cfg's ``iter-max`` (an integer; -1: no bound) kept in ``notes`` by the
        import: an analysis hint, so that the imported model is checked as the SpaceEx files are
        (:func:`reach.backends.star.options.cfg_hints`). ``sampling-time`` (a positive time) is
        checked as the cfg's is but sets nothing. Notes in prose, or other keys, are the reader's
        only."""
        notes = self.data.get("notes")
        if not isinstance(notes, dict):
            return {}
        hints = {}
        for key in ("sampling-time", "iter-max"):
            if key not in notes:
                continue
            value = notes[key]
            if why := hint_problem(key, value):
                raise self.where("notes", key).error(why)
            if key == "iter-max":
                hints[key] = int(value)
        return hints

    def read_disturbance(self, horizon: float) -> Disturbance | None:
        raw = self.data.get("disturbance")
        if raw is None:
            return None
        w = self.where("disturbance")
        if not isinstance(raw, dict) or set(raw) != {"gaussian", "enters", "step"}:
            raise w.error("expected {gaussian: {mean: [...], cov: [[...]]}, enters: [states], step: T}")
        enters = raw["enters"]
        if not isinstance(enters, list) or not enters or any(e not in self.state for e in enters):
            raise self.where("disturbance", "enters").error("expected a non-empty list of state variables")
        for i, e in enumerate(enters):          # before mean and cov, whose lengths follow the list
            if e in enters[:i]:
                raise self.where("disturbance", "enters", i).error(
                    f"'{e}' is listed twice (list each state the kicks enter once)")
        p = len(enters)
        g = raw["gaussian"]
        if not isinstance(g, dict) or set(g) - {"mean", "cov"} or "cov" not in g:
            raise self.where("disturbance", "gaussian").error("expected {mean: [...], cov: [[...]] or diagonal}")
        mean_raw = g.get("mean", [0] * p)
        if not isinstance(mean_raw, list) or len(mean_raw) != p:
            raise self.where("disturbance", "gaussian", "mean").error(f"expected a list of {p} numbers")
        kick = [Form.name(e) for e in enters]
        mean = np.array([self.number(v, self.where("disturbance", "gaussian", "mean", i), dimension=kick[i],
                                     what=f"a kick on {enters[i]}")
                         for i, v in enumerate(mean_raw)])
        cov_raw = g["cov"]
        wc = self.where("disturbance", "gaussian", "cov")
        if not isinstance(cov_raw, list) or len(cov_raw) != p:
            raise wc.error(f"expected a {p}x{p} matrix or a diagonal of {p} numbers")
        if all(isinstance(r, list) for r in cov_raw):
            if any(len(r) != p for r in cov_raw):
                raise wc.error(f"expected a {p}x{p} matrix")
            cov = np.array([[self.number(v, wc, dimension=kick[i].plus(kick[j]),
                                         what=f"the covariance of {enters[i]} and {enters[j]}")
                             for j, v in enumerate(r)] for i, r in enumerate(cov_raw)])
        else:
            cov = np.diag([self.number(v, wc, dimension=kick[i].times(2), what=f"the variance of {enters[i]}")
                           for i, v in enumerate(cov_raw)])
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=0):
            raise wc.error("covariance is not symmetric")
        if np.min(np.linalg.eigvalsh(cov)) < -1e-9 * max(1e-300, np.max(np.abs(cov))):
            raise wc.error("covariance is not positive semidefinite")
        step = self.number(raw["step"], self.where("disturbance", "step"), dimension=TIME, what="the kick step")
        if step <= 0:
            raise self.where("disturbance", "step").error("step must be positive")
        from reach.model.simulate import MAX_STEPS
        if horizon / step > MAX_STEPS:
            raise self.where("disturbance", "step").error(f"horizon {horizon:g} / step {step:g} = {horizon / step:.3g} "
                                                          f"kicks; at most {MAX_STEPS:.0e} (a longer step)")
        return Disturbance(mean, cov, [self.state.index(e) for e in enters], step)

    # ------------------------------------------- polytopic initial sets, bounded inputs, timeless modes
    def read_bounded_inputs(self) -> list[BoundedInput]:
        """``bounded_inputs: {u: {range: [lo, hi], varying: bool}}``: appended to the state.

        Also prepares the raw modes so that the unchanged mode reader sees a zero flow for every
        bounded input and for every state of a ``flow: false`` mode (recorded in ``timeless``).
        """
        raw = self.data.get("bounded_inputs", {})
        if not isinstance(raw, dict):
            raise self.where("bounded_inputs").error("expected {name: {range: [low, high], varying: true/false}}")
        out = []
        if self.dims is not None:              # their dimensions are unknowns like the states'
            self.dims.names = self.dims.names | {k for k in raw if isinstance(k, str)}
        for name, spec in raw.items():
            w = self.where("bounded_inputs", name)
            if (why := bad_name(name)) or name in RESERVED:
                raise w.error(why or f"'{name}' is a reserved function or constant name")
            if name in self.state or name in self.inputs or name in self.constants:
                raise w.error(f"bounded input '{name}' clashes with a state, input or constant")
            if not isinstance(spec, dict) or "range" not in spec or set(spec) - {"range", "varying", "description"}:
                raise w.error("expected {range: [low, high], varying: true/false}")
            bounds = spec["range"]
            if not isinstance(bounds, list) or len(bounds) != 2:
                raise self.where("bounded_inputs", name, "range").error("expected [low, high]")
            wr = self.where("bounded_inputs", name, "range")
            low, high = (self.number(v, wr, dimension=Form.name(name), what=name) for v in bounds)
            if low > high:
                raise wr.error(f"empty interval [{low:g}, {high:g}]")
            varying = spec.get("varying", False)
            if not isinstance(varying, bool):
                raise self.where("bounded_inputs", name, "varying").error("expected true or false")
            out.append(BoundedInput(name, len(self.state) + len(out), low, high, varying))
        declared = list(self.state)
        self.state = declared + [u.name for u in out]
        self.timeless = []
        modes = self.data.get("modes")
        if isinstance(modes, dict):
            for mname, spec in modes.items():
                if not isinstance(spec, dict):
                    continue
                if spec.get("flow") is False:
                    spec["flow"] = {v: 0 for v in declared}
                    self.timeless.append(mname)
                flow = spec.get("flow")
                if isinstance(flow, dict):
                    for u in out:
                        if u.name in flow:
                            raise self.where("modes", mname, "flow", u.name).error(
                                f"'{u.name}' is a bounded input: it has no flow")
                        flow[u.name] = 0
        return out

    @staticmethod
    def leave_at_once(modes, transitions) -> None:
        """A mode left by an urgent transition whose guard always holds (none written; SpaceEx
        ``asap`` with the guard ``true``) lets no time pass: a run takes that jump, or another
        one enabled, at the instant it enters, or is blocked there, which is what a mode with
        ``flow: false`` means. It is marked so (flow zero), and every back-end treats it as one
        instant instead of following a flow that no run follows."""
        for tr in transitions:
            mode = modes[tr.source]
            if tr.urgent and not tr.guard and tr.window is None and not mode.timeless:
                mode.timeless = True
                mode.flow = [sympy.Integer(0)] * len(mode.flow)

    def read_initial_set(self, modes, bounded: list[BoundedInput]) -> InitialSet:
        """A box (the classic form) or a polytope ``box ∩ constraints``; bounded inputs start
        anywhere in their range. The polytope must be non-empty and bounded in every state."""
        raw = self.need("initial")
        if not isinstance(raw, dict) or "constraints" not in raw:
            if isinstance(raw, dict) and isinstance(raw.get("box"), dict):
                for u in bounded:
                    if u.name in raw["box"]:
                        raise self.where("initial", "box", u.name).error(
                            f"'{u.name}' is a bounded input: it starts anywhere in its range")
                    raw["box"][u.name] = [u.low, u.high]
            return self.read_initial(modes)
        extra = set(raw) - {"mode", "box", "constraints"}
        if extra:
            raise self.where("initial", sorted(extra)[0]).error(f"unknown field '{sorted(extra)[0]}'")
        if not isinstance(raw.get("mode"), str) or raw["mode"] not in modes:
            raise not_a_mode(raw.get("mode"), self.where("initial", "mode"))
        n = len(self.state)
        rows, rhs, eq_rows, eq_rhs, strict = [], [], [], [], []
        box = raw.get("box", {})
        if not isinstance(box, dict):
            raise self.where("initial", "box").error("expected {var: [low, high] or value}")
        for var, value in box.items():
            w = self.where("initial", "box", var)
            if var not in self.state:
                raise w.error(f"'{var}' is not a state variable")
            if any(u.name == var for u in bounded):
                raise w.error(f"'{var}' is a bounded input: it starts anywhere in its range")
            e = np.eye(n)[self.state.index(var)]
            pair = value if isinstance(value, list) else [value, value]
            if len(pair) != 2:
                raise w.error("expected [low, high]")
            lo, hi = (self.number(v, w, dimension=Form.name(var), what=var) for v in pair)
            rows += [-e, e]
            rhs += [-lo, hi]
        for u in bounded:
            e = np.eye(n)[u.index]
            rows += [-e, e]
            rhs += [-u.low, u.high]
        state_names = {k: v for k, v in self.names.items() if v not in self.input_symbols}
        for j, text in enumerate(self.text_list(raw["constraints"], ("initial", "constraints"))):
            w = self.where("initial", "constraints", j)
            for kind, g in _linear_relations(text, state_names, w, self.units, self.dims):
                coeffs = affine_coefficients(g, self.symbols)
                if coeffs is None:
                    raise w.error(f"'{text}' is not linear in the state")
                if any(coeffs[0][u.index] for u in bounded):
                    raise w.error("a bounded input starts anywhere in its range; do not constrain it here")
                (eq_rows if kind == "==" else rows).append(coeffs[0])
                (eq_rhs if kind == "==" else rhs).append(-coeffs[1])
                if kind != "==":
                    strict.append((len(rows) - 1, text) if kind == "<" else None)
        P = LinearSet(np.array(rows, float).reshape(-1, n), np.array(rhs, float),
                      np.array(eq_rows, float).reshape(-1, n), np.array(eq_rhs, float))
        low, high = _bounding_box(P, self.state, self.where("initial"))
        _open_part(P, [s for s in strict if s is not None], self.where("initial", "constraints"))
        axis_aligned = all(np.count_nonzero(r) <= 1 for r in np.vstack([P.A, P.E]))
        return InitialSet(raw["mode"], low, high, None if axis_aligned else P)

    def check_bounded_inputs(self, model: HybridAutomaton) -> None:
        """No reset of any bounded input; a varying one in no guard or invariant."""
        for tr in model.transitions:
            for u in model.bounded_inputs:
                if u.index in tr.reset:
                    raise tr.where.error(f"'{u.name}' is a bounded input and cannot be reset")
        for u in model.varying_inputs:
            sym = model.symbols[u.index]
            for m in model.modes.values():
                if any(sym in c.g.free_symbols for c in m.invariant):
                    raise m.where.error(f"the varying input '{u.name}' appears in an invariant "
                                        "(its bounds are its range)")
            for tr in model.transitions:
                if any(sym in c.g.free_symbols for c in tr.guard):
                    raise tr.where.error(f"the varying input '{u.name}' appears in a guard")


def _linear_relations(text, names, where: Where, units, dims=None):
    """``lhs == rhs`` as ``[("==", lhs - rhs)]``; any other comparison (chains too) as
    ``[("<=", g), ...]`` with ``g <= 0``, ``("<", g)`` where it is strict (the set is read as its
    closure once :func:`_open_part` finds it not empty)."""
    stripped = str(text).strip()
    try:
        tree = ast.parse(stripped, mode="eval").body
    except (SyntaxError, ValueError, RecursionError):
        tree = None
    if isinstance(tree, ast.Compare) and len(tree.ops) == 1 and isinstance(tree.ops[0], ast.Eq):
        lhs = ast.get_source_segment(stripped, tree.left)
        rhs = ast.get_source_segment(stripped, tree.comparators[0])
        g = parse_expr(f"({lhs}) - ({rhs})", names, where, units, dims)
        return [("==", sympy.expand(g))]
    return [("<" if c.strict else "<=", c.g)
            for c in from_comparisons(parse_comparison(stripped, names, where, units, dims), stripped, where)]


def _open_part(P: LinearSet, strict: list[tuple[int, str]], where: Where) -> None:
    """Bad input where the strict rows of ``P`` (``(row, text)``) leave it no point
    (:func:`reach.lp.strictly_feasible`: ``x > 1`` and ``x < 1``, whose closure is the point 1,
    where every run would start outside the written set). A set with points, or one the solver
    cannot decide, is then read as its closure, as invariants and guards are."""
    if not strict:
        return
    marked = np.zeros(P.A.shape[0], bool)
    marked[[i for i, _ in strict]] = True
    if lp.strictly_feasible(P.A, P.b, marked, A_eq=P.E, b_eq=P.f) is False:
        texts = ", ".join(sorted({t for _, t in strict}))
        raise where.error(f"the initial set is empty: its strict constraints ({texts[:80]}) leave no point "
                          "(a set with points is read as its closure)")


def initial_and_invariant(model: HybridAutomaton):
    """``(A, b, E, f)``: the initial set (its box, or its polytope) and the linear invariant of
    its mode, ``A x <= b, E x = f``; None where that invariant is not linear or is empty."""
    mode = model.modes[model.initial.mode]
    halfspaces = mode.invariant_halfspaces
    if halfspaces is None or not len(halfspaces[1]):
        return None
    H, g = (np.asarray(a, float) for a in halfspaces)
    n, init = model.n, model.initial
    A = [H.reshape(-1, n), -np.eye(n), np.eye(n)]
    b = [g.reshape(-1), -init.low, init.high]
    E, f = np.zeros((0, n)), np.zeros(0)
    if init.polytope is not None:
        A.append(init.polytope.A)
        b.append(init.polytope.b)
        E, f = init.polytope.E, init.polytope.f
    return np.vstack(A), np.concatenate(b), E, f


def _bounding_box(P: LinearSet, state: list[str], where: Where):
    """Tight bounds of every coordinate over ``P`` by LP; empty or unbounded is bad input."""
    n = len(state)
    A_eq = P.E if P.E.shape[0] else None
    b_eq = P.f if P.E.shape[0] else None
    A_ub = P.A if P.A.shape[0] else None
    b_ub = P.b if P.A.shape[0] else None
    try:
        if lp.feasible_point(A_ub, b_ub, A_eq=A_eq, b_eq=b_eq, n=n) is None:
            raise where.error("the initial set is empty")
        bounds = [(lp.maximize(e, A_ub, b_ub, A_eq=A_eq, b_eq=b_eq), lp.minimize(e, A_ub, b_ub, A_eq=A_eq, b_eq=b_eq))
                  for e in np.eye(n)]
    except lp.LPError as exc:
        raise where.error(f"the initial set's constraints cannot be solved ({exc})") from None
    low, high = np.zeros(n), np.zeros(n)
    for i, (hi, lo) in enumerate(bounds):
        if not (hi.optimal and lo.optimal):
            raise where.error(f"the initial set is unbounded in '{state[i]}'")
        low[i], high[i] = lo.value, hi.value
    return low, np.maximum(high, low)


def _dependency_order(raw: dict, where) -> list[str]:
    """Constant names ordered so that each comes after the constants it uses."""
    deps = {}
    for key, value in raw.items():
        names = set()
        if isinstance(value, str):
            try:
                names = {n.id for n in ast.walk(ast.parse(value.strip(), mode="eval")) if isinstance(n, ast.Name)}
            except (SyntaxError, ValueError, RecursionError):
                names = set()  # the parser reports the syntax error with its location
        deps[key] = names & set(raw) - {key}
    order, done = [], set()
    while len(order) < len(raw):
        ready = [k for k in raw if k not in done and deps[k] <= done]
        if not ready:
            stuck = next(k for k in raw if k not in done)
            raise where("constants", stuck).error(f"constants form a cycle through '{stuck}'")
        for k in ready:
            order.append(k)
            done.add(k)
    return order
