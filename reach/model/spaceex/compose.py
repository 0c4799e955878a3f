"""Flattening a SpaceEx network: instances of base components, then their parallel composition.

Instantiation. A component bound as ``as`` inside an instance at path ``P`` gets the path
``P.as`` (an ``as`` is unique in its network and has no dot, so two instances never share a
path, nor their locals a name). Each of its params is bound by the ``map`` of its bind (to a
number, to a name of the parent's scope, or to a dotted name ``inst.x``: a param ``x`` of an
instance ``inst`` of the same network that its bind leaves unmapped), or, if unmapped, is local
to the instance and named ``P.as.param`` (with a warning when the network has a param of that
name: see :func:`_shadowed`). Params of the analysed system itself keep their names.
A constant, or a variable that no flow or assignment of its component sets (an input), may be
mapped to a number: it is that number in the instance.

Composition. The product of the instances' locations, built from the initial location
combinations and kept to the combinations reachable through the discrete graph (guards
ignored, so every combination that any run can visit is kept). A labelled transition of one
instance is taken together with one transition of the same label in every other instance whose
alphabet has that label (synchronisation on shared labels); unlabelled or local labels move one
instance alone. A product location's invariant and flow are the conjunctions of its parts; a
product transition's guard and assignment are the conjunctions of its parts, asap if any is.

Sizes. A product grows exponentially with the instances, so it is counted while it is built,
never materialised first: at most ``MAX_LOCATIONS`` location combinations (initial ones by
their count, before any is made), at most ``MAX_SIZE`` locations, transitions and relations in
their texts together (what the conversion and the loader then parse, one by one), and a
synchronised label's combinations counted before they are made.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field

from reach.errors import InputError
from reach.model.spaceex.components import Base, Bind, Document, Location, Network, Text, Transition
from reach.model.spaceex.formula import digits_message, too_many_digits

MAX_DEPTH = 16
MAX_INSTANCES = 256
MAX_LOCATIONS = 20_000
MAX_SIZE = 100_000
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_AND = re.compile(r"&&?")


@dataclass
class Binding:
    """What a local name stands for: a global variable/label name, or a number (text)."""

    name: str | None = None
    number: str | None = None


@dataclass
class Instance:
    path: str
    component: Base
    binding: dict[str, Binding]        # param name -> binding
    line: int | None = None            # the line of its bind (of the system's component for the system itself)

    def label(self, local: str) -> str:
        b = self.binding.get(local)
        if b is not None and b.name is not None:
            return b.name
        return f"{self.path}.{local}" if self.path else local

    @property
    def alphabet(self) -> set[str]:
        labels = {self.label(p.name) for p in self.component.params.values() if p.type == "label"}
        return labels | {self.label(t.label) for t in self.component.transitions if t.label}


@dataclass
class Part:
    """One instance's contribution to a product location or transition: a text and the
    location or transition of the instance's component where it is written."""

    instance: Instance
    text: Text
    source: Location | Transition

    @property
    def context(self) -> str:
        """Where the text is written, as messages show it: ``location 'on'``, ``transition on -> off``."""
        if isinstance(self.source, Location):
            return f"location '{self.source.name}'"
        locations = self.instance.component.locations
        return f"transition {locations[self.source.source].name} -> {locations[self.source.target].name}"


@dataclass
class ProductLocation:
    key: tuple[str, ...]                # location id per instance
    names: tuple[str, ...]              # location name per instance
    invariants: list[Part]
    flows: list[Part]
    line: int


@dataclass
class ProductTransition:
    source: tuple[str, ...]
    target: tuple[str, ...]
    label: str | None
    guards: list[Part]
    assignments: list[Part]
    asap: bool
    line: int


@dataclass
class Flat:
    instances: list[Instance]
    globals: dict[str, str]             # global real name -> "any" | "const"
    file: str                           # the XML file
    system: str                         # the analysed component's id
    line: int                           # and its line
    declared: dict[str, int] = field(default_factory=dict)   # global real name -> its param's line
    warnings: list[str] = field(default_factory=list)        # one line each, as the CLI shows them
    locations: dict[tuple, ProductLocation] = field(default_factory=dict)
    transitions: list[ProductTransition] = field(default_factory=list)

    def label(self, key: tuple) -> str:
        """A product location as messages show it: ``on``, or ``A.off, B.idle`` in a network."""
        names = self.locations[key].names
        if len(self.instances) == 1:
            return names[0]
        return ", ".join(f"{i.path or i.component.id}.{name}" for i, name in zip(self.instances, names))

    def error(self, message: str) -> InputError:
        """Bad input about the system as a whole, at its component's line."""
        return InputError(message, self.file, f"component '{self.system}'", self.line)


def instantiate(doc: Document, system: str, line: int | None, cfg_file: str | None) -> Flat:
    """The base-component instances of ``system`` with every param bound."""
    if system not in doc.components:
        raise InputError(f"system: no component '{system}' in {doc.file}", cfg_file or doc.file, line=line)
    top = doc.components[system]
    globals_: dict[str, str] = {}
    for p in top.params.values():
        if p.type == "real":
            globals_[p.name] = p.dynamics
    flat = Flat([], globals_, doc.file, system, top.line,
                declared={p.name: p.line for p in top.params.values() if p.type == "real"})
    top_binding = {p.name: Binding(name=p.name) for p in top.params.values()}
    _walk(doc, top, "", top_binding, flat, 0, top.line)
    return flat


def _walk(doc: Document, comp, path: str, binding: dict[str, Binding], flat: Flat, depth: int,
          line: int) -> None:
    """Instantiate ``comp`` at ``path`` (bound at ``line``), its sub-instances below it."""
    if depth > MAX_DEPTH:
        raise InputError(f"binds nested deeper than {MAX_DEPTH} (a cycle?)", doc.file, line=comp.line)
    # unmapped params are local to this instance
    for p in comp.params.values():
        if p.name not in binding:
            gname = f"{path}.{p.name}" if path else p.name
            binding[p.name] = Binding(name=gname)
            if p.type == "real":
                _new_local(flat, gname, p.dynamics, doc.file,
                           f"bind '{path.rsplit('.', 1)[-1]}': param '{p.name}'", line)
                flat.declared[gname] = p.line
    if isinstance(comp, Base):
        if len(flat.instances) >= MAX_INSTANCES:
            raise InputError(f"more than {MAX_INSTANCES} component instances", doc.file, line=comp.line)
        for name, b in binding.items():
            written = b.number is not None and _written(comp, name)
            if written:
                where, what, at = written
                raise InputError(f"the variable '{name}' is mapped to the number {b.number} (at instance "
                                 f"'{path}'), but this {what} sets it (only a variable that no flow or "
                                 "assignment sets, an input, may be fixed to a number)",
                                 doc.file, f"component '{comp.id}': {where}: {what}", at)
        flat.instances.append(Instance(path, comp, binding, line))
        return
    for bind in comp.binds:
        if bind.component not in doc.components:
            raise InputError(f"bind '{bind.name}': no component '{bind.component}'", doc.file, line=bind.line)
        child = doc.components[bind.component]
        child_path = f"{path}.{bind.name}" if path else bind.name
        child_binding: dict[str, Binding] = {}
        scope = _Scope(doc, comp, bind, binding, path)
        for m in bind.maps:
            if m.key not in child.params:
                raise scope.error(m, f"component '{child.id}' has no param '{m.key}'")
            if m.key in child_binding:
                raise scope.error(m, f"param '{m.key}' mapped twice")
            child_binding[m.key] = _resolve_map(m, child.params[m.key], scope)
        flat.warnings += _shadowed(comp, bind, child, child_binding, child_path, doc.file)
        _walk(doc, child, child_path, child_binding, flat, depth + 1, bind.line)


def _shadowed(network, bind, child, mapped: dict[str, Binding], path: str, file: str) -> list[str]:
    """One warning per param of ``child`` that ``bind`` leaves unmapped although ``network``
    declares a param of the same name. SpaceEx tools differ here (HyST makes the param local to
    the instance, as this import does; CORA's converter keeps its name, joining the network's),
    so the reading is kept, and said: a label left so no longer synchronises with the network's."""
    found = []
    for p in child.params.values():
        if p.name in mapped or p.local or p.name not in network.params:
            continue
        kind = "label" if network.params[p.name].type == "label" else "variable"
        found.append(f"{file}:{bind.line}: bind '{bind.name}': the {p.type} '{p.name}' of component "
                     f"'{child.id}' is not mapped, so it is the instance's own '{path}.{p.name}', not the "
                     f"{kind} '{p.name}' of network '{network.id}' (line {network.params[p.name].line}); map "
                     f"it (<map key=\"{p.name}\">{p.name}</map>) to join them")
    return found


def _new_local(flat: Flat, name: str, dynamics: str, file: str, field: str, line: int) -> None:
    """Register the local variable ``name`` (``path.param``) of a new instance. Instance names
    are unique in their network and have no dot (:mod:`.components`), so the only name it can
    meet is a dotted param of the system itself (``T.k``): one variable would then stand for
    two, silently; that is bad input at the bind's line."""
    if name in flat.globals:
        raise InputError(f"the local variable '{name}' of this instance has the name of a param of the "
                         f"system '{flat.system}' (two variables under one name)", file, field, line)
    flat.globals[name] = dynamics


def _written(comp: Base, name: str) -> tuple[str, str, int] | None:
    """Where a flow (``name' == ...``) or an assignment (``name := ...``, ``name' == ...``,
    ``name = ...``) of ``comp`` sets the variable ``name``: ``(location or transition, "flow"
    or "assignment", line)``, or None."""
    derivative = re.compile(rf"(?<![\w.]){re.escape(name)}\s*'")
    target = re.compile(rf"^\s*{re.escape(name)}\s*(:=|'|=(?!=))")
    for loc in comp.locations.values():
        if loc.flow is not None and derivative.search(loc.flow.text):
            return f"location '{loc.name}'", "flow", loc.flow.line
    for tr in comp.transitions:
        if tr.assignment is not None and any(target.match(part) for part in _AND.split(tr.assignment.text)):
            ends = comp.locations[tr.source].name, comp.locations[tr.target].name
            return f"transition {ends[0]} -> {ends[1]}", "assignment", tr.assignment.line
    return None


@dataclass
class _Scope:
    """Where a map's value is read: the network ``component`` (bound at ``path``, its params
    bound by ``binding``), inside its ``bind`` being read."""

    doc: Document
    component: Network
    bind: Bind
    binding: dict[str, Binding]
    path: str

    def error(self, m, message: str) -> InputError:
        """Bad input at the map ``m``'s line, naming its bind and key."""
        return InputError(message, self.doc.file, f"bind '{self.bind.name}': map '{m.key}'", m.line)


def _resolve_map(m, param, scope: _Scope) -> Binding:
    """What the map ``m`` binds ``param`` (a param of the bound component) to: a number, a param
    of the network, or a param of another of its instances (``inst.x``)."""
    value = m.value
    if _NUMBER.match(value):
        if param.type == "label":
            raise scope.error(m, "a label cannot be mapped to a number")
        if too_many_digits(value):
            raise scope.error(m, digits_message(value))
        if not math.isfinite(float(value)):
            raise scope.error(m, f"the number {value} is not finite")
        return Binding(number=value)
    if value in scope.binding:
        declared = scope.component.params.get(value)
        if declared is not None and declared.type != param.type:
            raise _mismatch(m, param, scope, declared.type, f"'{value}' of component '{scope.component.id}'")
        return scope.binding[value]
    if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)+", value):
        _check_dotted(m, param, scope)
        return Binding(name=f"{scope.path}.{value}" if scope.path else value)
    raise scope.error(m, f"construct '{value}' is not supported (a number, or a name in scope)")


def _check_dotted(m, param, scope: _Scope) -> None:
    """``inst.x`` (``inst.sub.x``) must name an instance bound in the network (in it, in turn)
    and a param of its component that its bind leaves unmapped: that param is the instance's
    own variable ``inst.x``; any other name would be a fresh variable, silently unconnected."""
    *instances, name = m.value.split(".")
    network, where = scope.component, f"network '{scope.component.id}'"
    bind = None
    for inst in instances:
        if not isinstance(network, Network):
            raise scope.error(m, f"'{m.value}': {where} is a base component's, with no instance '{inst}'")
        bind = next((b for b in network.binds if b.name == inst), None)
        if bind is None:
            known = ", ".join(b.name for b in network.binds)
            raise scope.error(m, f"'{m.value}': '{inst}' is no instance in {where} (its instances: {known})")
        network = scope.doc.components.get(bind.component)
        if network is None:
            raise InputError(f"bind '{bind.name}': no component '{bind.component}'", scope.doc.file, line=bind.line)
        where = f"instance '{inst}' (component '{network.id}')"
    target = network.params.get(name)
    if target is None:
        raise scope.error(m, f"'{m.value}': '{name}' is no param of {where}")
    mapped = next((x for x in bind.maps if x.key == name), None)
    if mapped is not None:
        raise scope.error(m, f"'{m.value}': the bind of '{bind.name}' maps '{name}' to '{mapped.value}' "
                             f"(line {mapped.line}); map to that instead")
    if target.type != param.type:
        raise _mismatch(m, param, scope, target.type, f"'{m.value}'")


def _mismatch(m, param, scope: _Scope, other: str, named: str) -> InputError:
    """A map that binds ``param`` to a param of the other type (``other``, ``named`` so)."""
    return scope.error(m, f"binds the {param.type} '{param.name}' to the {other} {named} "
                          "(a real maps to a real, a label to a label)")


def compose(flat: Flat, initial_locations: list[set[str] | None]) -> None:
    """Fill ``flat.locations``/``transitions``: the product reachable from the initial locations,
    counted as it is built (see the module docstring).

    ``initial_locations[i]`` is the set of allowed location names of instance ``i`` (None: all).
    """
    inst = flat.instances
    choices = [[loc.id for loc in i.component.locations.values() if allowed is None or loc.name in allowed]
               for i, allowed in zip(inst, initial_locations)]
    combinations = math.prod(len(c) for c in choices)
    if combinations > MAX_LOCATIONS:
        raise flat.error(f"more than {MAX_LOCATIONS} initial location combinations ({combinations}: the product "
                         f"of the {len(inst)} instances' locations): fix each instance's initial location in "
                         "the cfg's initially with loc(INSTANCE) == LOCATION, or analyse a smaller network")
    size = _Size(flat)
    outgoing = {id(i.component): _outgoing(i.component) for i in inst}
    alphabets = [i.alphabet for i in inst]
    todo = list(itertools.product(*choices))
    seen = set(todo)
    while todo:
        key = todo.pop()
        location = _product_location(inst, key)
        size.add_location(location)
        flat.locations[key] = location
        for tr in _successors(inst, alphabets, outgoing, key, size):
            flat.transitions.append(tr)
            if tr.target not in seen:
                if len(seen) >= MAX_LOCATIONS:
                    raise flat.error(f"the composition of its {len(inst)} instances reaches more than "
                                     f"{MAX_LOCATIONS} location combinations: analyse a smaller network "
                                     "(fewer instances, or fewer locations in them)")
                seen.add(tr.target)
                todo.append(tr.target)


class _Size:
    """The running size of a product: its locations and transitions and the relations in their
    texts (a text's relations counted by its ``&``, each text once)."""

    def __init__(self, flat: Flat):
        self.flat = flat
        self.total = 0
        self.relations: dict[int, int] = {}

    def weight(self, parts: list[Part]) -> int:
        total = 0
        for part in parts:
            key = id(part.text)
            if key not in self.relations:
                self.relations[key] = len(_AND.findall(part.text.text)) + 1
            total += self.relations[key]
        return total

    def add_location(self, location: ProductLocation) -> None:
        self.add(1 + self.weight(location.invariants) + self.weight(location.flows))

    def add_transition(self, transition: ProductTransition) -> None:
        self.add(1 + self.weight(transition.guards) + self.weight(transition.assignments))

    def add(self, amount: int) -> None:
        self.total += amount
        if self.total > MAX_SIZE:
            instances = len(self.flat.instances)
            raise self.flat.error(
                f"too large to import: more than {MAX_SIZE} locations, transitions and relations in their "
                f"texts" + (f" after composing its {instances} instances" if instances > 1 else "")
                + f" (at {len(self.flat.locations)} location combinations): analyse a smaller network")

    def room(self, count: int, label: str) -> None:
        """Refuse before making ``count`` synchronised transitions of ``label`` that cannot fit."""
        if self.total + count > MAX_SIZE:
            raise self.flat.error(f"too large to import: label '{label}' synchronises transitions into {count} "
                                  f"combinations in one location combination, more than the {MAX_SIZE} "
                                  "locations, transitions and relations the import handles")


def _outgoing(component: Base) -> dict[str, list[Transition]]:
    """The component's transitions by source location id."""
    out: dict[str, list[Transition]] = {}
    for tr in component.transitions:
        out.setdefault(tr.source, []).append(tr)
    return out


def blocked_labels(flat: Flat) -> list[str]:
    """One line per label that blocks transitions for good: an instance has the label in its
    alphabet (a label param) but no transition takes it, so the transitions of the other
    instances labelled with it can never synchronise (a slip more often than a wish)."""
    takers: dict[str, list[str]] = {}
    for instance in flat.instances:
        for label in {instance.label(t.label) for t in instance.component.transitions if t.label}:
            takers.setdefault(label, []).append(instance.path or instance.component.id)
    found = []
    for label, taking in takers.items():
        idle = [i.path or i.component.id for i in flat.instances
                if label in i.alphabet and (i.path or i.component.id) not in taking]
        if idle:
            found.append(f"label '{label}': {', '.join(idle)} declare{'s' if len(idle) == 1 else ''} it "
                         f"but no transition of {'it' if len(idle) == 1 else 'theirs'} takes it, so the "
                         f"transitions labelled '{label}' in {', '.join(taking)} are never taken "
                         f"(synchronisation on shared labels)")
    return found


def _product_location(inst: list[Instance], key) -> ProductLocation:
    locs: list[Location] = [i.component.locations[k] for i, k in zip(inst, key)]
    return ProductLocation(key, tuple(loc.name for loc in locs),
                           [Part(i, loc.invariant, loc) for i, loc in zip(inst, locs) if loc.invariant],
                           [Part(i, loc.flow, loc) for i, loc in zip(inst, locs) if loc.flow],
                           locs[0].line)


def _successors(inst: list[Instance], alphabets, outgoing, key, size: _Size) -> list[ProductTransition]:
    out = []
    labels: dict[str, None] = {}                 # in the order met
    for i, instance in enumerate(inst):
        for tr in outgoing[id(instance.component)].get(key[i], []):
            if tr.label is None:
                out.append(_combine(inst, key, [(i, tr)], None))
                size.add_transition(out[-1])
            else:
                labels[instance.label(tr.label)] = None
    for label in labels:
        options = [[(i, tr) for tr in outgoing[id(inst[i].component)].get(key[i], [])
                    if tr.label is not None and inst[i].label(tr.label) == label]
                   for i, alphabet in enumerate(alphabets) if label in alphabet]
        size.room(math.prod(len(o) for o in options), label)
        for combo in itertools.product(*options):
            out.append(_combine(inst, key, list(combo), label))
            size.add_transition(out[-1])
    return out


def _combine(inst, key, moves: list[tuple[int, Transition]], label) -> ProductTransition:
    target = list(key)
    for i, tr in moves:
        target[i] = tr.target
    return ProductTransition(tuple(key), tuple(target), label,
                             [Part(inst[i], tr.guard, tr) for i, tr in moves if tr.guard],
                             [Part(inst[i], tr.assignment, tr) for i, tr in moves if tr.assignment],
                             any(tr.asap for _, tr in moves), moves[0][1].line)
