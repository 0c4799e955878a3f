"""Back-end options from the command line (``-o key=value``) or a suite's ``options:``: names, types
and ranges checked against the back-end's options dataclass, each problem one :class:`InputError`.

Ranges: a field may declare ``metadata={"min": a, "max": b, "open_min": True}``; without one, a
number must be finite, an integer at least 0 and a float greater than 0 (steps, tolerances and
budgets of zero or below would never end or mean nothing). A bool is never a number.
"""

from __future__ import annotations

import math
from dataclasses import field, fields

from reach.errors import InputError

_TYPES = {"float": float, "int": int, "bool": bool, "str": str, "None": type(None)}


#: an integer option without its own upper bound (cells, stars, LPs, jumps...) is at most this:
#: past it no count is meant, and a number such as 1e308 does not fit the machine's integers
MAX_COUNT = 10 ** 9


def ranged(default, low=None, high=None, open_low: bool = False):
    """A dataclass field with a range: ``low <= value <= high`` (``low < value`` if open_low)."""
    return field(default=default, metadata={"min": low, "max": high, "open_min": open_low})


def _range_error(value, spec: dict) -> str | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if not math.isfinite(value):
        return f"expected a finite number, got {value!r}"
    low, high, open_low = spec.get("min"), spec.get("max"), spec.get("open_min", False)
    if low is None and not spec:
        low, open_low = (0, False) if isinstance(value, int) else (0.0, True)
    if low is not None and (value < low or (open_low and value <= low)):
        return f"expected a number {'>' if open_low else '>='} {low:g}, got {value!r}"
    if high is not None and value > high:
        return f"at most {high:g} allowed, got {value!r}"
    if isinstance(value, int) and high is None and value > MAX_COUNT:
        return f"at most {MAX_COUNT:g} allowed for a count, got {value:.3g}"
    return None


def parse_options(cls, options: dict | None, backend: str) -> dict:
    """``options`` checked against the dataclass ``cls``: unknown names, values of the wrong
    type and numbers out of range are errors; an integer is accepted for a float field and an
    integral float for an integer field. Fields annotated with other types (an executor, a
    scheduler) pass as given."""
    options = dict(options or {})
    known = {f.name: f for f in fields(cls)}
    for name in sorted(options):
        where = f"options.{backend}.{name}"
        if name not in known:
            raise InputError(f"unknown {backend} option; known: {', '.join(sorted(known))}", field=where)
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
            raise InputError(f"expected {names}, got {value!r}", field=where)
        problem = _range_error(options[name], dict(known[name].metadata))
        if problem:
            raise InputError(problem, field=where)
    return options


def option_error(backend: str, name: str, message: str) -> InputError:
    """A bad value of a known option."""
    return InputError(message, field=f"options.{backend}.{name}")


def split_options(pairs: dict, backends: list[str]) -> dict[str, dict]:
    """``{backend: options}`` of the back-ends run, from ``{key or backend.key: value}``: a plain
    key goes to each, ``B.key`` to back-end ``B`` only (a ``B`` not run is bad input)."""
    out = {b: {} for b in backends}
    for key, value in pairs.items():
        head, dot, rest = key.partition(".")
        if dot and head in out:
            out[head][rest] = value
        elif dot:
            raise InputError(f"'{head}' is not a back-end run here ({', '.join(backends)})", field="--option")
        else:
            for b in backends:
                out[b][key] = value
    return out
