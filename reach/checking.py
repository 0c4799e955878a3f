"""Check a model file against a property file with one back-end: the core of ``reach check``,
and the exit code of a list of results (the command-line contract of DESIGN.md):

* 0: every property SAFE (a probability: its threshold proved met);
* 1: a violation: UNSAFE (always with a replayed counterexample) or a probability interval wholly
  below its threshold;
* 3: undecided: some UNKNOWN or UNSUPPORTED, nothing violated.

(2, bad input, is an :class:`InputError` raised before any result exists.) A property whose
``modes`` the model lacks is bad input, unless the property says ``optional: true``: then, on a
model with none of its modes, it is not applicable and left out of the exit code (a check
where no property applies is undecided, 3: nothing was proved).
"""

from __future__ import annotations

import difflib

from reach.backends import available, backend, validate_options
from reach.backends.base import input_reason, run, unsupported
from reach.errors import InputError
from reach.model import load_model
from reach.result import Result, Status
from reach.spec import bind, load_properties
from reach.spec.properties import BoundSafety


def resolve_backend(name: str):
    """The named back-end; only its module is imported (a check does not pay for the others)."""
    names = available()
    if name not in names:
        raise InputError(f"unknown back-end '{name}' (available: {', '.join(names)})", field="--backend")
    return backend(name)


def check_files(model_path, property_path, backend_name: str, options: dict | None = None,
                only: list[str] | None = None) -> list[Result]:
    """Load, bind and check every property (or those in ``only``); one Result per property."""
    backend = resolve_backend(backend_name)
    validate_options(backend_name, options)
    model, props = load_bound(model_path, property_path, only)
    return check_model(backend, model, props, options)


def load_bound(model_path, property_path, only: list[str] | None = None):
    """``(model, properties bound to it)``: every property of the file, or those in ``only``,
    each checked against the model's modes."""
    model = load_model(model_path)
    props = load_properties(property_path)
    if only:
        unknown = set(only) - {p.id for p in props}
        if unknown:
            raise InputError(f"no property '{sorted(unknown)[0]}' in {property_path}", field="--property")
        props = [p for p in props if p.id in only]
    for prop in props:
        check_modes(prop, model)
    return model, [bind(p, model) for p in props]


def check_modes(prop, model) -> None:
    """A listed mode the model lacks is an InputError unless the property is ``optional``."""
    if not isinstance(prop.raw.get("optional", False), bool):
        raise prop.where("optional").error("expected true or false")
    modes = prop.raw.get("modes")
    if not isinstance(modes, list) or prop.raw.get("optional") is True:
        return
    for k, mode in enumerate(modes):
        if mode not in model.modes:
            close = difflib.get_close_matches(str(mode), list(model.modes), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else f" (modes: {', '.join(model.modes)})"
            raise prop.where("modes", k).error(
                f"model '{model.name}' has no mode '{mode}'{hint}; write 'optional: true' in the property "
                "to skip it on models without its modes")


def not_applicable(result: Result) -> bool:
    """An optional property on a model that has none of its modes."""
    return result.status == Status.UNSUPPORTED and bool(result.details.get("not_applicable"))


def violated(result: Result) -> bool:
    """UNSAFE, or a probability interval wholly below the property's threshold (``at_least``
    in the details, put there by :func:`check_model`). A sampled probability is judged by its
    ``verdict_interval`` where it has one (montecarlo's, at :data:`reach.stats.VERDICT_CONFIDENCE`): its 95 %
    interval misses the truth once in twenty, and with a fixed seed the same property would
    fail a pipeline on every run."""
    if result.status == Status.UNSAFE:
        return True
    at_least = result.details.get("at_least")
    interval = result.details.get("verdict_interval", result.probability)
    return interval is not None and at_least is not None and float(interval[1]) < float(at_least)


def exit_code(results: list[Result]) -> int:
    """0 all SAFE, 1 a violation, 3 undecided (see the module docstring); 3 also when no
    property applied (every one optional and not applicable): nothing was proved."""
    relevant = [r for r in results if not not_applicable(r)]
    if any(violated(r) for r in relevant):
        return 1
    return 0 if relevant and all(r.status == Status.SAFE for r in relevant) else 3


#: why a property with an empty unsafe set holds, whatever the model does
EMPTY_UNSAFE_SET = ("the unsafe set is empty: no piece of it lies in a mode of the model (a SpaceEx forbidden set "
                    "naming only location combinations the composition never reaches), or every piece has a "
                    "constant constraint that no state meets (forbidden = false, a requirement such as 0 <= 1); "
                    "nothing was explored")


def _vacuous(backend, model, prop) -> Result:
    """SAFE for a property whose unsafe set is empty, by that argument alone; UNKNOWN from
    montecarlo, which never says SAFE (DESIGN: a sampler proves nothing), with the argument."""
    if backend.name == "montecarlo":
        return Result(backend.name, model.name, prop.id, Status.UNKNOWN, details={
            "reason": f"no run can violate it ({EMPTY_UNSAFE_SET}); montecarlo never says SAFE, a formal "
                      f"back-end (star, taylor) does here", "violating_runs": 0})
    return Result(backend.name, model.name, prop.id, Status.SAFE, details={"argument": EMPTY_UNSAFE_SET})


def check_model(backend, model, bound: list, options: dict | None = None, done=None) -> list[Result]:
    """Check bound properties; back-ends with ``check_many`` share work across properties. For
    star, a SpaceEx cfg's hint that the model keeps (``iter-max``) becomes an option default
    (:func:`reach.backends.star.options.cfg_hints`), so an imported model is checked as its
    SpaceEx files are. ``done(prop, result)``, if given, is called as each result is final, in
    the order of ``bound`` (a long property file shows its answers as they come)."""
    if backend.name == "star" and model.hints:
        from reach.backends.star.options import cfg_hints
        options = cfg_hints(model.hints, options)
    results: dict[int, Result] = {}
    todo = []
    for prop in bound:
        absent = getattr(prop, "missing_modes", [])
        if absent and not getattr(prop, "modes", True):
            results[id(prop)] = unsupported(backend.name, model, prop,
                                            f"not applicable: the model has no mode {', '.join(absent)}")
            results[id(prop)].details["not_applicable"] = True
            continue
        if isinstance(prop, BoundSafety) and prop.empty:
            results[id(prop)] = _vacuous(backend, model, prop)
            continue
        reason = input_reason(backend, model) or backend.supports(model, prop)
        if reason is not None:
            results[id(prop)] = unsupported(backend.name, model, prop, reason)
        else:
            todo.append(prop)
    shown = 0

    def announce() -> None:             # the results now final at the head of ``bound``
        nonlocal shown
        while shown < len(bound) and id(bound[shown]) in results:
            prop = bound[shown]
            if getattr(prop, "at_least", None) is not None:
                results[id(prop)].details.setdefault("at_least", float(prop.at_least))
            if done is not None:
                done(prop, results[id(prop)])
            shown += 1

    announce()
    if todo and hasattr(backend, "check_many"):
        for prop, result in zip(todo, backend.check_many(model, todo, options or {})):
            results[id(prop)] = result
    else:
        for prop in todo:
            results[id(prop)] = run(backend, model, prop, options)
            announce()
    announce()
    return [results[id(p)] for p in bound]


def is_spaceex(path) -> bool:
    return str(path).lower().endswith(".xml")


def check_spaceex(xml_path, cfg_path, backend_name: str, options: dict | None = None):
    """Check a SpaceEx model against its cfg's forbidden set: one property whose id is the cfg's
    file name and whose unsafe set is the union of the forbidden terms. Returns
    ``(results, model, documents, {id: bound property})``. A cfg that forbids nothing is bad
    input (a run would prove nothing). For star the cfg's ``iter-max`` becomes an option
    default, as for the imported model (:func:`check_model`)."""
    from reach.model.spaceex import load_spaceex
    from reach.spec.properties import BoundSafety

    backend = resolve_backend(backend_name)
    validate_options(backend_name, options)
    model, props, docs = load_spaceex(xml_path, cfg_path)
    if not props:
        from reach.errors import InputError
        from reach.model.spaceex import read_cfg
        cfg = read_cfg(cfg_path)
        raise InputError("the cfg forbids nothing: there is no property to check (add a forbidden "
                         "set; 'reach import' converts the model alone)", str(cfg_path),
                         "forbidden", cfg.line("forbidden") or 1)
    bound = [bind(p, model) for p in props]
    modes = [m for m in model.modes if any(m in b.modes for b in bound)]
    pieces = {m: [piece for b in bound for piece in b.pieces.get(m, [])] for m in modes}
    merged = BoundSafety(docs.property_id, modes, pieces, model.symbols, str(cfg_path),
                         f"forbidden set of {cfg_path}")
    return check_model(backend, model, [merged], options), model, docs, {merged.id: merged}
