"""The one result type every back-end returns, and the counterexample any back-end can replay.

Status semantics (strict):

* ``SAFE`` only from a sound argument; ``details`` says what it assumed.
* ``UNSAFE`` only with a concrete :class:`Counterexample` that the Monte Carlo simulator replays.
* ``UNKNOWN`` otherwise (Monte Carlo never says SAFE; it gives samples and an upper
  confidence bound on the violation probability).
* ``UNSUPPORTED`` when the back-end does not handle the model or property; ``details["reason"]``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path

import numpy as np


class Status(str, Enum):
    SAFE = "SAFE"
    UNSAFE = "UNSAFE"
    UNKNOWN = "UNKNOWN"
    UNSUPPORTED = "UNSUPPORTED"


@dataclass
class Counterexample:
    """A concrete run that violates a property: initial state, abort (switch) time, trajectory.

    ``model_file``/``property_file`` let ``reach replay`` rebuild everything; ``dt`` is the
    simulator step the violation was found with.
    """

    model: str
    property: str
    model_file: str
    property_file: str
    initial_state: list[float]
    switch_time: float | None
    violation_time: float
    violation_mode: str
    violation_state: list[float]
    dt: float
    trajectory: dict = field(default_factory=dict)   # {"t": [...], "mode": [...], "x": [[...]]}
    found_by: str = ""
    input_signal: dict | None = None   # {"step": h, "inputs": [names], "values": [[...] per piece]}

    def to_dict(self) -> dict:
        return _plain(asdict(self))

    @classmethod
    def from_dict(cls, data: dict) -> "Counterexample":
        names = {f for f in cls.__dataclass_fields__}
        return cls(**{k: v for k, v in data.items() if k in names})

    @classmethod
    def load(cls, path) -> "Counterexample":
        """Read a counterexample file (JSON under the size cap, fields checked); InputError otherwise.

        ``model_file`` and ``property_file`` must name model and property files by their suffix
        (``.yaml``/``.yml``, or SpaceEx ``.xml``/``.cfg``); they are opened by the loaders, which
        read only regular files under the size cap and never quote a file that is not a model.
        """
        from reach.errors import InputError
        from reach.paths import printable, read_text

        file = printable(str(path))
        text = read_text(path, (".json",), "counterexample file")
        try:
            data = json.loads(text)
        except (json.JSONDecodeError, RecursionError, ValueError) as exc:
            raise InputError(f"not a counterexample file: invalid JSON ({exc.__class__.__name__})", file) from None
        if not isinstance(data, dict):
            raise InputError("not a counterexample file (expected a JSON object)", file)
        for key, kinds in (("model_file", (".yaml", ".yml", ".xml")), ("property_file", (".yaml", ".yml", ".cfg"))):
            value = data.get(key)
            if not isinstance(value, str) or not value:
                raise InputError("not a counterexample file: expected a file name", file, key)
            if Path(value).suffix.lower() not in kinds:
                raise InputError(f"expected a {' or '.join(kinds)} file", file, key)
        if not isinstance(data.get("property"), str):
            raise InputError("not a counterexample file: expected a property id", file, "property")
        state = data.get("initial_state")
        if not isinstance(state, list) or not state or not all(_finite(v) for v in state):
            raise InputError("expected a list of finite numbers", file, "initial_state")
        for key in ("switch_time", "dt"):
            if data.get(key) is not None and not (_finite(data[key]) and data[key] >= 0):
                raise InputError("expected a finite number >= 0 or null", file, key)
        data.setdefault("switch_time", None)
        data.setdefault("dt", 0.0)
        for key, default in (("model", ""), ("violation_time", 0.0), ("violation_mode", ""),
                             ("violation_state", [])):
            data.setdefault(key, default)
        try:
            return cls.from_dict(data)
        except TypeError as exc:
            raise InputError(f"not a counterexample file ({exc})", file) from None

    def save(self, path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1))


@dataclass
class Result:
    backend: str
    model: str
    property: str
    status: Status
    seconds: float = 0.0
    probability: tuple[float, float] | None = None
    bound: tuple[float, float] | None = None
    coverage: float | None = None
    counterexample: Counterexample | None = None
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        out = {
            "backend": self.backend, "model": self.model, "property": self.property,
            "status": self.status.value.lower(), "seconds": self.seconds,
            "probability": self.probability, "bound": self.bound, "coverage": self.coverage,
            "counterexample": self.counterexample.to_dict() if self.counterexample else None,
            "details": self.details,
        }
        return _plain(out)


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))


def _plain(obj):
    """JSON-ready copy: numpy scalars/arrays to Python, tuples to lists, NaN/inf to strings."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        value = float(obj)
        return value if np.isfinite(value) else str(value)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, Enum):
        return obj.value
    return obj
