"""Suite files (``suite.yaml``): instances (model x property file), back-ends and their options,
and expected verdicts with their source.

    description: ...
    backends:
      montecarlo: {samples: 1000}     # options passed to the back-end
      star: {}
    instances:
      - id: SRA01
        model: models/SRA01.yaml
        properties: properties/rendezvous.yaml
        expect: {thrust: safe, los: safe, velocity: safe, collision: safe}
        source: ARCH-COMP AFF (SRA01 is safe)
        backends: [montecarlo, star]  # optional: a subset of the suite's back-ends
        options: {star: {step: 0.5}}  # optional: per back-end options over the suite's
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from reach.backends import BACKENDS, validate_options
from reach.errors import InputError, Where
from reach.paths import printable, within
from reach.yamlio import load

EXPECTATIONS = ("safe", "unsafe")


@dataclass
class Instance:
    id: str
    model: Path
    properties: Path
    expect_where: Where                     # the suite file's line of ``expect``, for its errors
    expect: dict[str, str] = field(default_factory=dict)
    source: str = ""
    backends: list[str] | None = None
    options: dict[str, dict] = field(default_factory=dict)


@dataclass
class Suite:
    description: str
    backends: dict[str, dict]
    instances: list[Instance]
    file: str

    def options(self, instance: Instance, backend: str) -> dict:
        """The back-end's options for one instance: the suite's, updated by the instance's."""
        return {**self.backends.get(backend, {}), **instance.options.get(backend, {})}


def load_suite(path) -> Suite:
    doc = load(path)
    data = doc.data
    if not isinstance(data, dict):
        raise InputError("a suite file is a mapping with 'backends' and 'instances'", doc.file, line=1)
    extra = set(data) - {"description", "backends", "instances"}
    if extra:
        raise doc.where(sorted(extra)[0]).error(f"unknown field '{sorted(extra)[0]}'")
    backends = data.get("backends")
    if not isinstance(backends, dict) or not backends:
        raise doc.where("backends").error("expected a mapping back-end: {options}")
    for name, options in backends.items():
        if name not in BACKENDS:
            raise doc.where("backends", name).error(f"unknown back-end '{name}' (known: {', '.join(BACKENDS)})")
        if options is not None and not isinstance(options, dict):
            raise doc.where("backends", name).error("expected a mapping of options")
        _valid_options(doc, name, options, ("backends", name))
    base = Path(doc.file).parent
    roots = (base, Path.cwd())      # instances' files are read only here (reach.paths.within)
    items = data.get("instances")
    if not isinstance(items, list) or not items:
        raise doc.where("instances").error("expected a non-empty list of instances")
    instances, seen = [], set()
    for i, item in enumerate(items):
        where = doc.where("instances", i)
        if not isinstance(item, dict) or not {"id", "model", "properties"} <= set(item):
            raise where.error("an instance needs id, model and properties")
        extra = set(item) - {"id", "model", "properties", "expect", "source", "backends", "options"}
        if extra:
            raise doc.where("instances", i, sorted(extra)[0]).error(f"unknown field '{sorted(extra)[0]}'")
        if item["id"] in seen:
            raise doc.where("instances", i, "id").error(f"duplicate instance id '{item['id']}'")
        seen.add(item["id"])
        expect = item.get("expect", {}) or {}
        if not isinstance(expect, dict) or any(v not in EXPECTATIONS for v in expect.values()):
            raise doc.where("instances", i, "expect").error("expected {property: safe|unsafe}")
        chosen = item.get("backends")
        if chosen is not None and (not isinstance(chosen, list) or not chosen or set(chosen) - set(backends)):
            raise doc.where("instances", i, "backends").error("expected a non-empty list of the suite's back-ends")
        options = item.get("options", {}) or {}
        if not isinstance(options, dict) or set(options) - set(backends) or \
                not all(isinstance(v, dict) for v in options.values()):
            raise doc.where("instances", i, "options").error("expected {back-end: {option: value}} for the suite's back-ends")
        for backend_name, given in options.items():
            _valid_options(doc, backend_name, {**(backends[backend_name] or {}), **given}, ("instances", i, "options"))
        for key in ("model", "properties"):
            path = base / str(item[key])
            if not path.is_file():
                raise doc.where("instances", i, key).error(f"no such file: {printable(item[key])}")
            if not within(path, roots):
                raise doc.where("instances", i, key).error(
                    f"{printable(item[key])} lies outside the suite's folder and the working folder: not read")
        instances.append(Instance(str(item["id"]), base / item["model"], base / item["properties"],
                                  doc.where("instances", i, "expect"), dict(expect),
                                  str(item.get("source", "")), chosen, options))
    return Suite(str(data.get("description", "")), {k: dict(v or {}) for k, v in backends.items()},
                 instances, doc.file)


def _valid_options(doc, backend: str, options, path: tuple) -> None:
    """The suite's options for ``backend`` checked as ``-o`` options are (names, types, ranges):
    a bad one is bad input at its line in the suite, before anything runs."""
    try:
        validate_options(backend, options)
    except InputError as exc:                   # named as in the suite: backends.star.step
        option = (exc.field or "").rsplit(".", 1)[-1]
        where = doc.where(*path)
        message = f"{option}: {exc.message}" if option and option in options else exc.message
        raise where.error(message) from None
