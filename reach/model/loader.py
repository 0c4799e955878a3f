"""Load a hybrid automaton from YAML (``models/*.yaml``).

Format (all expressions are strings parsed by :mod:`reach.model.expr`)::

    name: SRA02
    extends: _rendezvous_abort.yaml        # optional template; mappings merge, child wins
    description: ...
    units: {length: m, time: min, mass: kg}  # base units of the model (SI by default)
    constants: {n: 0.00438138, mc: 500}     # in order; later ones may use earlier ones
    state: [x, y, vx, vy, t]
    inputs: [Fx, Fy]
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
    horizon: 240
    disturbance: {gaussian: {mean: [0, 0], cov: [[..]]}, enters: [vx, vy], step: 10}

Every error names file, line and field: ``models/x.yaml:14: modes.approach.flow.vx: unknown
name 'vyy'``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import sympy

from reach.errors import InputError, Where
from reach.model.automaton import Controller, Disturbance, HybridAutomaton, InitialSet, Mode, Transition
from reach.model.constraints import affine_coefficients, from_comparisons
from reach.model.controllers import build_law, build_network_law
from reach.model.expr import CONSTANTS, FUNCTIONS, parse_comparison, parse_expr
from reach.model.units import UnitSystem, check_base
from reach.yamlio import Doc, load, merge

TOP_FIELDS = {"name", "extends", "description", "units", "constants", "state", "inputs", "modes",
              "transitions", "initial", "horizon", "disturbance", "notes"}
MODE_FIELDS = {"flow", "control", "invariant", "description"}
TRANSITION_FIELDS = {"from", "to", "guard", "urgent", "reset", "description"}
RESERVED = set(FUNCTIONS) | set(CONSTANTS)
MAX_EXTENDS = 8


def read_with_templates(path: Path, depth: int = 0, chain=()) -> Doc:
    """The YAML document with its ``extends`` chain merged in."""
    doc = load(path)
    if not isinstance(doc.data, dict):
        raise InputError("a model file must be a mapping", doc.file, line=1)
    parent = doc.data.get("extends")
    if parent is None:
        return doc
    where = doc.where("extends")
    if not isinstance(parent, str):
        raise where.error("expected a file name")
    parent_path = (path.parent / parent).resolve()
    if not parent_path.is_file():
        raise where.error(f"no such file '{parent}'")
    if parent_path in chain or depth >= MAX_EXTENDS:
        raise where.error("'extends' forms a cycle or is nested too deeply")
    base = read_with_templates(parent_path, depth + 1, chain + (path.resolve(),))
    merged = merge(base, doc)
    merged.data.pop("extends", None)
    return merged


def load_model(path) -> HybridAutomaton:
    """Load and check a model file; raises :class:`InputError` on any problem."""
    path = Path(path)
    doc = read_with_templates(path)
    return _Builder(doc, str(path)).build()


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
        value = self.data.get(key, []) if allow_empty else self.need(key)
        if not isinstance(value, list) or (not value and not allow_empty):
            raise self.where(key).error("expected a list of names")
        seen = set()
        for i, name in enumerate(value):
            if not isinstance(name, str) or not name.isidentifier() or name.startswith("_"):
                raise self.where(key, i).error(f"'{name}' is not a valid name")
            if name in RESERVED:
                raise self.where(key, i).error(f"'{name}' is a reserved function or constant name")
            if name in seen:
                raise self.where(key, i).error(f"duplicate name '{name}'")
            seen.add(name)
        return value

    def number(self, value, where: Where, names=None) -> float:
        expr = parse_expr(value, names if names is not None else self.constant_names, where, self.units)
        if not expr.is_number:
            raise where.error("expected a number (constants allowed, no state variables)")
        result = complex(expr)
        if result.imag != 0 or not np.isfinite(result.real):
            raise where.error("expression does not evaluate to a finite real number")
        return result.real

    def build(self) -> HybridAutomaton:
        extra = set(self.data) - TOP_FIELDS
        if extra:
            key = sorted(extra)[0]
            raise self.where(key).error(f"unknown field '{key}'")
        name = self.need("name")
        if not isinstance(name, str) or not name.strip():
            raise self.where("name").error("expected a non-empty name")
        self.units = self.read_units()
        self.state = self.names_list("state")
        self.inputs = self.names_list("inputs", allow_empty=True)
        clash = set(self.state) & set(self.inputs)
        if clash:
            raise self.where("inputs").error(f"'{sorted(clash)[0]}' is both a state and an input")
        self.constants = self.read_constants()
        self.symbols = [sympy.Symbol(s, real=True) for s in self.state]
        self.input_symbols = [sympy.Symbol(f"__input_{u}") for u in self.inputs]
        self.names = dict(self.constant_names)
        self.names.update(zip(self.state, self.symbols))
        self.names.update(zip(self.inputs, self.input_symbols))
        modes = self.read_modes()
        transitions = self.read_transitions(modes)
        initial = self.read_initial(modes)
        horizon = self.number(self.need("horizon"), self.where("horizon"))
        if horizon <= 0:
            raise self.where("horizon").error("horizon must be positive")
        clocks = [i for i in range(len(self.state))
                  if all(m.flow[i] == 1 for m in modes.values())]
        for tr in transitions:
            tr.window = self.window_of(tr, modes, clocks)
        model = HybridAutomaton(
            name=name.strip(), description=str(self.data.get("description", "")).strip(),
            file=self.file, units=self.units, constants=self.constants, state=self.state,
            inputs=self.inputs, modes=modes, transitions=transitions, initial=initial,
            horizon=horizon, disturbance=self.read_disturbance(), clocks=clocks)
        return model

    def read_units(self) -> UnitSystem:
        value = self.data.get("units", {})
        if not isinstance(value, dict):
            raise self.where("units").error("expected {length: m, time: s, mass: kg}")
        for key, unit in value.items():
            if key not in ("length", "time", "mass"):
                raise self.where("units", key).error(f"unknown base quantity '{key}' (length, time, mass)")
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
            if not isinstance(key, str) or not key.isidentifier() or key.startswith("_"):
                raise self.where("constants", key).error(f"'{key}' is not a valid name")
            if key in RESERVED or key in self.state or key in self.inputs:
                raise self.where("constants", key).error(
                    f"constant '{key}' clashes with a reserved, state or input name")
        values = {}
        for key in _dependency_order(raw, self.where):
            number = self.number(raw[key], self.where("constants", key))
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
            open_flow = [parse_expr(flow_raw[v], self.names, self.where("modes", mname, "flow", v), self.units)
                         for v in self.state]
            law, controller = self.read_control(mname, spec.get("control"), open_flow)
            substitution = {self.input_symbols[i]: law[u] for i, u in enumerate(self.inputs)}
            flow = [sympy.sympify(f).subs(substitution) for f in open_flow]
            invariant = []
            for j, text in enumerate(self.text_list(spec.get("invariant", []), ("modes", mname, "invariant"))):
                wj = self.where("modes", mname, "invariant", j)
                cons = from_comparisons(parse_comparison(text, self.names, wj, self.units), text, wj)
                invariant.extend(c.substitute(substitution) for c in cons)
            modes[mname] = Mode(mname, self.symbols, flow, law, invariant, controller, w)
        return modes

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
            law[u] = parse_expr(spec[u], state_names, self.where("modes", mname, "control", u), self.units)
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
            for s in sources + [spec["to"]]:
                if not isinstance(s, str) or s not in modes:
                    field = "from" if s in sources else "to"
                    raise self.where(*path, field).error(f"unknown mode '{s}'")
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
                reset[self.state.index(var)] = parse_expr(value, {k: v for k, v in self.names.items()
                                                                  if v not in self.input_symbols},
                                                          self.where(*path, "reset", var), self.units)
            for source in sources:
                sub = {self.input_symbols[i]: modes[source].control[u] for i, u in enumerate(self.inputs)}
                guard = []
                for j, text in enumerate(guard_text):
                    wj = self.where(*path, "guard", j)
                    guard.extend(c.substitute(sub) for c in
                                 from_comparisons(parse_comparison(text, self.names, wj, self.units), text, wj))
                name = key if len(sources) == 1 else f"{key}:{source}"
                out.append(Transition(name, source, spec["to"], guard, urgent, reset, None, w))
        return out

    def window_of(self, tr: Transition, modes, clocks):
        """``(clock, lo, hi)`` if a may-transition's guard is an interval of one clock."""
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
            raise self.where("initial", "mode").error(f"unknown mode '{raw['mode']}'")
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
                low[i], high[i] = self.number(value[0], w), self.number(value[1], w)
                if low[i] > high[i]:
                    raise w.error(f"empty interval [{low[i]:g}, {high[i]:g}]")
            else:
                low[i] = high[i] = self.number(value, w)
        return InitialSet(raw["mode"], low, high)

    def read_disturbance(self) -> Disturbance | None:
        raw = self.data.get("disturbance")
        if raw is None:
            return None
        w = self.where("disturbance")
        if not isinstance(raw, dict) or set(raw) != {"gaussian", "enters", "step"}:
            raise w.error("expected {gaussian: {mean: [...], cov: [[...]]}, enters: [states], step: T}")
        enters = raw["enters"]
        if not isinstance(enters, list) or not enters or any(e not in self.state for e in enters):
            raise self.where("disturbance", "enters").error("expected a non-empty list of state variables")
        p = len(enters)
        g = raw["gaussian"]
        if not isinstance(g, dict) or set(g) - {"mean", "cov"} or "cov" not in g:
            raise self.where("disturbance", "gaussian").error("expected {mean: [...], cov: [[...]] or diagonal}")
        mean_raw = g.get("mean", [0] * p)
        if not isinstance(mean_raw, list) or len(mean_raw) != p:
            raise self.where("disturbance", "gaussian", "mean").error(f"expected a list of {p} numbers")
        mean = np.array([self.number(v, self.where("disturbance", "gaussian", "mean", i))
                         for i, v in enumerate(mean_raw)])
        cov_raw = g["cov"]
        wc = self.where("disturbance", "gaussian", "cov")
        if not isinstance(cov_raw, list) or len(cov_raw) != p:
            raise wc.error(f"expected a {p}x{p} matrix or a diagonal of {p} numbers")
        if all(isinstance(r, list) for r in cov_raw):
            if any(len(r) != p for r in cov_raw):
                raise wc.error(f"expected a {p}x{p} matrix")
            cov = np.array([[self.number(v, wc) for v in r] for r in cov_raw])
        else:
            cov = np.diag([self.number(v, wc) for v in cov_raw])
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=0):
            raise wc.error("covariance is not symmetric")
        if np.min(np.linalg.eigvalsh(cov)) < -1e-9 * max(1e-300, np.max(np.abs(cov))):
            raise wc.error("covariance is not positive semidefinite")
        step = self.number(raw["step"], self.where("disturbance", "step"))
        if step <= 0:
            raise self.where("disturbance", "step").error("step must be positive")
        return Disturbance(mean, cov, [self.state.index(e) for e in enters], step)


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
