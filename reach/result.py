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
