"""Check a model file against a property file with one back-end: the core of ``reach check``."""

from __future__ import annotations

from reach.backends import registry
from reach.backends.base import input_reason, run, unsupported
from reach.errors import InputError
from reach.model import load_model
from reach.result import Result
from reach.spec import bind, load_properties


def resolve_backend(name: str):
    backends = registry()
    if name not in backends:
        raise InputError(f"unknown back-end '{name}' (available: {', '.join(backends)})", field="--backend")
    return backends[name]


def check_files(model_path, property_path, backend_name: str, options: dict | None = None,
                only: list[str] | None = None) -> list[Result]:
    """Load, bind and check every property (or those in ``only``); one Result per property."""
    backend = resolve_backend(backend_name)
    model = load_model(model_path)
    props = load_properties(property_path)
    if only:
        unknown = set(only) - {p.id for p in props}
        if unknown:
            raise InputError(f"no property '{sorted(unknown)[0]}' in {property_path}", field="--property")
        props = [p for p in props if p.id in only]
    return check_model(backend, model, [bind(p, model) for p in props], options)


def check_model(backend, model, bound: list, options: dict | None = None) -> list[Result]:
    """Check bound properties; back-ends with ``check_many`` share work across properties."""
    results: dict[int, Result] = {}
    todo = []
    for prop in bound:
        reason = input_reason(backend, model) or backend.supports(model, prop)
        if reason is not None:
            results[id(prop)] = unsupported(backend.name, model, prop, reason)
        else:
            todo.append(prop)
    if todo and hasattr(backend, "check_many"):
        for prop, result in zip(todo, backend.check_many(model, todo, options or {})):
            results[id(prop)] = result
    else:
        for prop in todo:
            results[id(prop)] = run(backend, model, prop, options)
    return [results[id(p)] for p in bound]


def is_spaceex(path) -> bool:
    return str(path).lower().endswith(".xml")


def check_spaceex(xml_path, cfg_path, backend_name: str, options: dict | None = None):
    """Check a SpaceEx model against its cfg's forbidden set: one property whose id is the cfg's
    file name and whose unsafe set is the union of the forbidden terms. Returns
    ``(results, model, documents)`` (no result when the cfg forbids nothing)."""
    from reach.model.spaceex import load_spaceex
    from reach.spec.properties import BoundSafety

    backend = resolve_backend(backend_name)
    model, props, docs = load_spaceex(xml_path, cfg_path)
    if not props:
        return [], model, docs
    bound = [bind(p, model) for p in props]
    modes = [m for m in model.modes if any(m in b.modes for b in bound)]
    pieces = {m: [piece for b in bound for piece in b.pieces.get(m, [])] for m in modes}
    merged = BoundSafety(docs.property_id, modes, pieces, model.symbols, str(cfg_path),
                         f"forbidden set of {cfg_path}")
    return check_model(backend, model, [merged], options), model, docs
