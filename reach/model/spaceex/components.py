"""SpaceEx components read from the XML tree: base components (locations, transitions) and
network components (binds of other components with ``map`` entries), with their lines."""

from __future__ import annotations

from dataclasses import dataclass, field

from reach.errors import InputError
from reach.paths import printable
from reach.model.spaceex.xmltree import Node

LAYOUT = {"note", "labelposition", "middlepoint", "waypoints", "beforemiddle", "aftermiddle"}
# transition attributes read here (source, target, asap, timedriven) or known to change nothing
# (bezier: how the model editor draws the edge); any other (priority, urgent, a misspelt ASAP)
# could change which jumps happen, so it is refused rather than read as absent
TRANSITION_ATTRIBUTES = {"source", "target", "asap", "timedriven", "bezier"}
PARAM_TYPES = ("real", "label")
DYNAMICS = ("any", "const", "explicit")


@dataclass
class Param:
    name: str
    type: str            # "real" | "label"
    local: bool
    dynamics: str        # "any" | "const" (| "explicit", treated as "any")
    line: int


@dataclass
class Text:
    """The text of an ``invariant``, ``flow``, ``guard`` or ``assignment`` and its line."""

    text: str
    line: int


@dataclass
class Location:
    id: str
    name: str
    invariant: Text | None
    flow: Text | None
    line: int


@dataclass
class Transition:
    source: str
    target: str
    label: str | None
    guard: Text | None
    assignment: Text | None
    asap: bool
    line: int


@dataclass
class Base:
    id: str
    params: dict[str, Param]
    locations: dict[str, Location]
    transitions: list[Transition]
    line: int


@dataclass
class Map:
    key: str
    value: str
    line: int


@dataclass
class Bind:
    component: str
    name: str            # the instance name ("as")
    maps: list[Map]
    line: int


@dataclass
class Network:
    id: str
    params: dict[str, Param]
    binds: list[Bind]
    line: int


@dataclass
class Document:
    file: str
    components: dict[str, Base | Network] = field(default_factory=dict)


def _error(file, node: Node, message: str) -> InputError:
    return InputError(message, file, line=node.line)


def _unsupported(file, node: Node, where: str) -> InputError:
    return _error(file, node, f"{where}: construct <{node.tag}> is not supported")


def read_document(root: Node, file: str) -> Document:
    if root.tag != "sspaceex":
        raise _error(file, root, f"expected a <sspaceex> document, got <{root.tag}>")
    doc = Document(file)
    for node in root.children:
        if node.tag == "note":
            continue
        if node.tag != "component":
            raise _unsupported(file, node, "sspaceex")
        cid = node.attrs.get("id")
        if not cid:
            raise _error(file, node, "component without an 'id'")
        if cid in doc.components:
            raise _error(file, node, f"duplicate component '{cid}'")
        doc.components[cid] = _component(node, cid, file)
    if not doc.components:
        raise _error(file, root, "no component")
    return doc


def _param(node: Node, file: str, where: str) -> Param:
    name = node.attrs.get("name", "")
    ptype = node.attrs.get("type", "")
    if not name:
        raise _error(file, node, f"{where}: param without a name")
    if ptype not in PARAM_TYPES:
        raise _error(file, node, f"{where}: param '{name}': construct type=\"{ptype}\" is not supported "
                     "(real or label)")
    if ptype == "real" and (node.attrs.get("d1", "1") != "1" or node.attrs.get("d2", "1") != "1"):
        raise _error(file, node, f"{where}: param '{name}': construct d1/d2 (a matrix param) is not supported")
    dynamics = node.attrs.get("dynamics", "any")
    if ptype == "real" and dynamics not in DYNAMICS:
        raise _error(file, node, f"{where}: param '{name}': construct dynamics=\"{dynamics}\" is not supported")
    local = _flag(node, "local", file, f"{where}: param '{name}'")
    return Param(name, ptype, local, "const" if dynamics == "const" else "any", node.line)


def _text(node: Node | None) -> Text | None:
    if node is None:
        return None
    return Text(node.text, node.line)


def _single(node: Node, tag: str, file: str, where: str) -> Node | None:
    """The one ``<tag>`` child of ``node``, or None. SpaceEx gives a location one invariant and
    one flow, a transition one label, guard and assignment (each a conjunction written with
    ``&``); a repeat is bad input at its line, never dropped, nor guessed to be a conjunction."""
    found = node.all(tag)
    if len(found) > 1:
        hint = ("a transition takes one label" if tag == "label"
                else f"write its conditions in one <{tag}>, joined with &")
        raise _error(file, found[1], f"{where}: a second <{tag}> (the first is at line {found[0].line}): "
                     f"SpaceEx reads one; {hint}")
    return found[0] if found else None


def _component(node: Node, cid: str, file: str) -> Base | Network:
    where = f"component '{cid}'"
    params: dict[str, Param] = {}
    locations: dict[str, Location] = {}
    transitions: list[Transition] = []
    binds: list[Bind] = []
    for child in node.children:
        if child.tag in LAYOUT:
            continue
        if child.tag == "param":
            p = _param(child, file, where)
            if p.name in params:
                raise _error(file, child, f"{where}: duplicate param '{p.name}'")
            params[p.name] = p
        elif child.tag == "location":
            loc = _location(child, file, where)
            if loc.id in locations:
                raise _error(file, child, f"{where}: duplicate location id '{loc.id}'")
            first = next((other for other in locations.values() if other.name == loc.name), None)
            if first is not None:
                # the cfg names locations, not ids: loc(c) == A would mean both, silently (SpaceEx's
                # editor renames a repeat, so there it means the first one only)
                shown = printable(loc.name)[:60]
                raise _error(file, child, f"{where}: duplicate location name '{shown}' (location id "
                             f"'{printable(first.id)[:20]}' at line {first.line} has it too); loc() in the cfg "
                             "names a location by its name: give each location its own")
            locations[loc.id] = loc
        elif child.tag == "transition":
            transitions.append(_transition(child, file, where))
        elif child.tag == "bind":
            bind = _bind(child, file, where)
            first = next((b for b in binds if b.name == bind.name), None)
            if first is not None:
                # two instances under one name would share every local variable and location
                shown = printable(bind.name)[:60]
                raise _error(file, child, f"{where}: bind '{shown}': duplicate instance name (as=\"{shown}\" is "
                             f"also bound at line {first.line}); each bind needs its own 'as'")
            binds.append(bind)
        else:
            raise _unsupported(file, child, where)
    if binds and (locations or transitions):
        raise _error(file, node, f"{where}: construct mixing <bind> with <location> is not supported")
    if binds:
        return Network(cid, params, binds, node.line)
    if not locations:
        raise _error(file, node, f"{where}: a base component needs at least one location")
    for tr in transitions:
        for end in (tr.source, tr.target):
            if end not in locations:
                raise InputError(f"{where}: transition to or from unknown location id '{end}'", file, line=tr.line)
        if tr.label is not None and getattr(params.get(tr.label), "type", None) != "label":
            # an undeclared label is in no alphabet: the transition would move alone, unsynchronised
            raise InputError(f"{where}: transition label '{tr.label}' is not declared (a <param "
                             f"name=\"{tr.label}\" type=\"label\"/> of the component)", file, line=tr.line)
    return Base(cid, params, locations, transitions, node.line)


def _location(node: Node, file: str, where: str) -> Location:
    lid = node.attrs.get("id")
    if not lid:
        raise _error(file, node, f"{where}: location without an 'id'")
    name = node.attrs.get("name") or f"loc{lid}"
    for child in node.children:
        if child.tag not in LAYOUT | {"invariant", "flow"}:
            raise _unsupported(file, child, f"{where}: location '{name}'")
    where = f"{where}: location '{name}'"
    return Location(lid, name, _text(_single(node, "invariant", file, where)),
                    _text(_single(node, "flow", file, where)), node.line)


def _flag(node: Node, name: str, file: str, where: str) -> bool:
    """A boolean attribute (``asap="true"``): true or false, any case; absent is false; anything
    else is a bad input at the element's line (a misspelt flag must not change the model)."""
    text = node.attrs.get(name, "false").strip().lower()
    if text not in ("true", "false"):
        raise _error(file, node, f"{where}: {name}=\"{node.attrs[name]}\": expected true or false")
    return text == "true"


def _transition(node: Node, file: str, where: str) -> Transition:
    for child in node.children:
        if child.tag not in LAYOUT | {"label", "guard", "assignment"}:
            raise _unsupported(file, child, f"{where}: transition")
    source, target = node.attrs.get("source"), node.attrs.get("target")
    if not source or not target:
        raise _error(file, node, f"{where}: transition without 'source' or 'target'")
    where = f"{where}: transition"
    _known_attributes(node, file, where)
    label = _single(node, "label", file, where)
    label_text = label.text.strip() if label is not None and label.text.strip() else None
    asap = _flag(node, "asap", file, where)
    if _flag(node, "timedriven", file, where):
        raise _error(file, node, f"{where}: construct timedriven=\"true\" is not supported")
    return Transition(source, target, label_text, _text(_single(node, "guard", file, where)),
                      _text(_single(node, "assignment", file, where)), asap, node.line)


def _known_attributes(node: Node, file: str, where: str) -> None:
    """Refuse a transition attribute outside :data:`TRANSITION_ATTRIBUTES`: SpaceEx's
    ``priority``, or a foreign or misspelt one (``urgent``, ``ASAP``: XML names are case
    sensitive), would otherwise be read as absent and turn a forced jump into a possible one."""
    for name in node.attrs:
        if name not in TRANSITION_ATTRIBUTES:
            shown = printable(f'{name}="{node.attrs[name]}"')[:80]
            raise _error(file, node, f"{where}: construct {shown} is not supported (a transition may "
                         "carry source, target, asap, timedriven and bezier)")


def _bind(node: Node, file: str, where: str) -> Bind:
    comp, name = node.attrs.get("component"), node.attrs.get("as")
    if not comp or not name:
        raise _error(file, node, f"{where}: bind without 'component' or 'as'")
    if "." in name:
        # instance paths are joined with dots: 'N.T' would be the instance T inside N
        raise _error(file, node, f"{where}: bind '{printable(name)[:60]}': an instance name ('as') cannot "
                     "contain a dot (a dot separates nested instances: 'N.T' is instance T inside N)")
    maps = []
    for child in node.children:
        if child.tag in LAYOUT:
            continue
        if child.tag != "map":
            raise _unsupported(file, child, f"{where}: bind '{name}'")
        key = child.attrs.get("key")
        if not key:
            raise _error(file, child, f"{where}: bind '{name}': map without a 'key'")
        maps.append(Map(key, child.text.strip(), child.line))
    return Bind(comp, name, maps, node.line)
