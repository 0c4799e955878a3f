"""Flattening a SpaceEx network: instances of base components, then their parallel composition.

Instantiation. A component bound as ``as`` inside an instance at path ``P`` gets the path
``P.as``. Each of its params is bound by the ``map`` of its bind (to a number, to a name of the
parent's scope, or to a dotted name ``inst.x`` of a sub-instance), or, if unmapped, is local to
the instance and named ``P.as.param``. Params of the analysed system itself keep their names.

Composition. The product of the instances' locations, built from the initial location
combinations and kept to the combinations reachable through the discrete graph (guards
ignored, so every combination that any run can visit is kept). A labelled transition of one
instance is taken together with one transition of the same label in every other instance whose
alphabet has that label (synchronisation on shared labels); unlabelled or local labels move one
instance alone. A product location's invariant and flow are the conjunctions of its parts; a
product transition's guard and assignment are the conjunctions of its parts, asap if any is.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass, field

from reach.errors import InputError
from reach.model.spaceex.components import Base, Document, Location, Text, Transition

MAX_DEPTH = 16
MAX_INSTANCES = 256
MAX_LOCATIONS = 20_000
MAX_TRANSITIONS = 200_000
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


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
    """One instance's contribution to a product location or transition."""

    instance: Instance
    text: Text | None


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
    locations: dict[tuple, ProductLocation] = field(default_factory=dict)
    transitions: list[ProductTransition] = field(default_factory=list)


def instantiate(doc: Document, system: str, line: int | None, cfg_file: str | None) -> Flat:
    """The base-component instances of ``system`` with every param bound."""
    if system not in doc.components:
        raise InputError(f"system: no component '{system}' in {doc.file}", cfg_file or doc.file, line=line)
    top = doc.components[system]
    globals_: dict[str, str] = {}
    for p in top.params.values():
        if p.type == "real":
            globals_[p.name] = p.dynamics
    flat = Flat([], globals_)
    top_binding = {p.name: Binding(name=p.name) for p in top.params.values()}
    _walk(doc, top, "", top_binding, flat, 0)
    return flat


def _walk(doc: Document, comp, path: str, binding: dict[str, Binding], flat: Flat, depth: int) -> None:
    if depth > MAX_DEPTH:
        raise InputError(f"binds nested deeper than {MAX_DEPTH} (a cycle?)", doc.file, line=comp.line)
    # unmapped params are local to this instance
    for p in comp.params.values():
        if p.name not in binding:
            gname = f"{path}.{p.name}" if path else p.name
            binding[p.name] = Binding(name=gname)
            if p.type == "real":
                flat.globals.setdefault(gname, p.dynamics)
    if isinstance(comp, Base):
        if len(flat.instances) >= MAX_INSTANCES:
            raise InputError(f"more than {MAX_INSTANCES} component instances", doc.file, line=comp.line)
        flat.instances.append(Instance(path, comp, binding))
        return
    for bind in comp.binds:
        if bind.component not in doc.components:
            raise InputError(f"bind '{bind.name}': no component '{bind.component}'", doc.file, line=bind.line)
        child = doc.components[bind.component]
        child_path = f"{path}.{bind.name}" if path else bind.name
        child_binding: dict[str, Binding] = {}
        for m in bind.maps:
            if m.key not in child.params:
                raise InputError(f"bind '{bind.name}': component '{child.id}' has no param '{m.key}'",
                                 doc.file, line=m.line)
            if m.key in child_binding:
                raise InputError(f"bind '{bind.name}': param '{m.key}' mapped twice", doc.file, line=m.line)
            child_binding[m.key] = _resolve_map(m, binding, path, child.params[m.key].type, doc.file)
        _walk(doc, child, child_path, child_binding, flat, depth + 1)
        for key, b in child_binding.items():
            if b.number is not None and child.params[key].dynamics != "const":
                raise InputError(f"bind '{bind.name}': the variable '{key}' is mapped to a number "
                                 "(only constants may be)", doc.file, line=bind.line)


def _resolve_map(m, binding, path, ptype, file) -> Binding:
    value = m.value
    if _NUMBER.match(value):
        if ptype == "label":
            raise InputError(f"map '{m.key}': a label cannot be mapped to a number", file, line=m.line)
        return Binding(number=value)
    if value in binding:
        return binding[value]
    if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)+", value):
        return Binding(name=f"{path}.{value}" if path else value)
    raise InputError(f"map '{m.key}': construct '{value}' is not supported (a number, or a name in scope)",
                     file, line=m.line)


def compose(flat: Flat, initial_locations: list[set[str] | None], file: str) -> None:
    """Fill ``flat.locations``/``transitions``: the product reachable from the initial locations.

    ``initial_locations[i]`` is the set of allowed location names of instance ``i`` (None: all).
    """
    inst = flat.instances
    for i, allowed in enumerate(initial_locations):
        if allowed is not None:
            names = {loc.name for loc in inst[i].component.locations.values()}
            unknown = allowed - names
            if unknown:
                raise InputError(f"initially: instance '{inst[i].path or inst[i].component.id}' has no "
                                 f"location '{sorted(unknown)[0]}'", file)
    choices = []
    for i, allowed in enumerate(initial_locations):
        locs = inst[i].component.locations.values()
        choices.append([loc.id for loc in locs if allowed is None or loc.name in allowed])
    alphabets = [i.alphabet for i in inst]
    todo = list(itertools.product(*choices))
    if len(todo) > MAX_LOCATIONS:
        raise InputError(f"more than {MAX_LOCATIONS} initial location combinations", file)
    seen = set(todo)
    while todo:
        key = todo.pop()
        flat.locations[key] = _product_location(inst, key)
        for tr in _successors(inst, alphabets, key):
            flat.transitions.append(tr)
            if len(flat.transitions) > MAX_TRANSITIONS:
                raise InputError(f"the composition has more than {MAX_TRANSITIONS} transitions", file)
            if tr.target not in seen:
                seen.add(tr.target)
                todo.append(tr.target)
                if len(seen) > MAX_LOCATIONS:
                    raise InputError(f"the composition has more than {MAX_LOCATIONS} locations", file)


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
                           [Part(i, loc.invariant) for i, loc in zip(inst, locs) if loc.invariant],
                           [Part(i, loc.flow) for i, loc in zip(inst, locs) if loc.flow],
                           locs[0].line)


def _successors(inst: list[Instance], alphabets, key) -> list[ProductTransition]:
    out = []
    by_label: dict[str, list[list[tuple[int, Transition]]]] = {}
    for i, instance in enumerate(inst):
        for tr in instance.component.transitions:
            if tr.source != key[i]:
                continue
            if tr.label is None:
                out.append(_combine(inst, key, [(i, tr)], None))
            else:
                by_label.setdefault(instance.label(tr.label), [])
    for label in by_label:
        participants = [i for i, a in enumerate(alphabets) if label in a]
        options = []
        for i in participants:
            mine = [(i, tr) for tr in inst[i].component.transitions
                    if tr.source == key[i] and tr.label is not None and inst[i].label(tr.label) == label]
            options.append(mine)
        if all(options):
            for combo in itertools.product(*options):
                out.append(_combine(inst, key, list(combo), label))
    return out


def _combine(inst, key, moves: list[tuple[int, Transition]], label) -> ProductTransition:
    target = list(key)
    for i, tr in moves:
        target[i] = tr.target
    return ProductTransition(tuple(key), tuple(target), label,
                             [Part(inst[i], tr.guard) for i, tr in moves if tr.guard],
                             [Part(inst[i], tr.assignment) for i, tr in moves if tr.assignment],
                             any(tr.asap for _, tr in moves), moves[0][1].line)
