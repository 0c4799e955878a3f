"""Back-end options from the command line (``-o key=value``) or a suite's ``options:``: names and
types checked against the back-end's options dataclass, each problem one :class:`InputError`."""

from __future__ import annotations

from dataclasses import fields

from reach.errors import InputError

_TYPES = {"float": float, "int": int, "bool": bool, "str": str, "None": type(None)}


def parse_options(cls, options: dict | None, backend: str) -> dict:
    """``options`` checked against the dataclass ``cls``: unknown names and values of the wrong
    type are errors; an integer is accepted for a float field and an integral float for an
    integer field. Fields annotated with other types (an executor, a scheduler) pass as given."""
    options = dict(options or {})
    known = {f.name: f for f in fields(cls)}
    for name in sorted(options):
        if name not in known:
            raise InputError(f"unknown {backend} option; known: {', '.join(sorted(known))}",
                             field=f"options.{backend}.{name}")
        annotation = known[name].type if isinstance(known[name].type, str) else known[name].type.__name__
        allowed = [_TYPES[t.strip()] for t in annotation.split("|") if t.strip() in _TYPES]
        if len(allowed) != len(annotation.split("|")):
            continue
        value = options[name]
        if int in allowed and type(value) is float and value.is_integer():
            options[name] = int(value)
        elif float in allowed and type(value) is int:        # not a bool
            options[name] = float(value)
        if not any(type(options[name]) is t for t in allowed):
            names = " or ".join("null" if t is type(None) else t.__name__ for t in allowed)
            raise InputError(f"expected {names}, got {value!r}", field=f"options.{backend}.{name}")
    return options


def option_error(backend: str, name: str, message: str) -> InputError:
    """A bad value of a known option."""
    return InputError(message, field=f"options.{backend}.{name}")
