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
import math
import os
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path

import numpy as np


class Status(str, Enum):
    SAFE = "SAFE"
    UNSAFE = "UNSAFE"
    UNKNOWN = "UNKNOWN"
    UNSUPPORTED = "UNSUPPORTED"


#: states of a counterexample's trajectory kept for pictures, at most (:func:`thinned`): a run of
#: 600 s at a step of 0.0026 s wrote a 38 MB file, past what a replay reads
MAX_TRAJECTORY_POINTS = 4000
MAX_TRAJECTORY_VALUES = 120_000     # numbers in a trajectory: a file of a few MB, under replay's read limit


def thinned(trajectory: dict, violation_time: float) -> dict:
    """The trajectory ``{"t", "mode", "x"}`` with at most :data:`MAX_TRAJECTORY_POINTS` states,
    fewer for a wide state (at most :data:`MAX_TRAJECTORY_VALUES` numbers, at least 100
    states): the first and last, those on each side of a mode change, the one nearest the
    violation and evenly spaced others. It draws the run; the replay simulates it again from
    the initial state, the signal and the transitions."""
    t = trajectory.get("t") if isinstance(trajectory, dict) else None
    x = trajectory.get("x") if isinstance(trajectory, dict) else None
    width = 2 + (len(x[0]) if isinstance(x, list) and x and isinstance(x[0], list) else 0)
    limit = min(MAX_TRAJECTORY_POINTS, max(100, MAX_TRAJECTORY_VALUES // width))
    if not isinstance(t, list) or len(t) <= limit:
        return trajectory
    count = len(t)
    modes = trajectory.get("mode") or [""] * count
    near = min(range(count), key=lambda k: abs(t[k] - violation_time)) if _finite(violation_time) else 0
    changes = np.array(sorted({j for k in range(1, count) if modes[k] != modes[k - 1] for j in (k - 1, k)}), int)
    half = limit // 2
    if changes.size > half:                  # many jumps: an even share of them
        changes = changes[np.linspace(0, changes.size - 1, half).round().astype(int)]
    keep = {0, count - 1, near} | set(changes.tolist())
    spread = np.linspace(0, count - 1, max(0, limit - len(keep))).round().astype(int)
    rows = sorted(keep | set(spread.tolist()))
    return {key: [value[k] for k in rows] if isinstance(value, list) and len(value) == count else value
            for key, value in trajectory.items()}


def _drawable(trajectory) -> bool:
    """Whether a counterexample file's ``trajectory`` is what :func:`thinned` and the pictures
    read: an object whose ``t`` (finite numbers), ``mode`` (names) and ``x`` (lists of numbers:
    a run that left the real numbers is drawn up to there), where given, have one entry per
    point (the replay simulates the run again; the trajectory only draws it)."""
    if trajectory is None:
        return True
    if not isinstance(trajectory, dict):
        return False
    t, mode, x = trajectory.get("t"), trajectory.get("mode"), trajectory.get("x")
    if t is None:
        return mode is None and x is None
    if not isinstance(t, list) or not all(_finite(v) for v in t):
        return False
    if mode is not None and not (isinstance(mode, list) and len(mode) == len(t) and all(isinstance(m, str) for m in mode)):
        return False
    return x is None or (isinstance(x, list) and len(x) == len(t) and all(
        isinstance(row, list) and all(_number(v) for v in row) for row in x))


#: how :func:`_plain` writes the non-finite floats (JSON has no NaN): a run that left the
#: real numbers (``sqrt`` of a negative) keeps its rows past that point in the file
NON_FINITE = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}


def _number(value) -> bool:
    """A JSON number, or a non-finite float as :func:`_plain` wrote it."""
    return (isinstance(value, (int, float)) and not isinstance(value, bool)) or (
        isinstance(value, str) and value in NON_FINITE)


def _decoded(trajectory):
    """``trajectory`` (checked by :func:`_drawable`) with its ``x`` strings read back as floats."""
    x = trajectory.get("x") if isinstance(trajectory, dict) else None
    if not isinstance(x, list):
        return trajectory
    return {**trajectory, "x": [[NON_FINITE[v] if isinstance(v, str) else v for v in row] for row in x]}


@dataclass
class Counterexample:
    """A concrete run that violates a property: initial state, abort (switch) time, trajectory.

    ``model_file``/``property_file`` let ``reach replay`` rebuild everything; ``dt`` is the
    simulator step the violation was found with; ``transitions`` names the transition the run
    took at each of its jumps, in order (None in files written before it was kept: such a run
    replays taking the first enabled transition at every jump).
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
    transitions: list[str] | None = None   # the transition taken at each jump, in order

    def __post_init__(self):
        self.trajectory = thinned(self.trajectory, self.violation_time)

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
            data = json.loads(text.removeprefix("\ufeff"))        # a byte-order mark an editor added
        except json.JSONDecodeError as exc:
            raise InputError(f"not a counterexample file: invalid JSON ({exc.msg})", file, line=exc.lineno) from None
        except (RecursionError, ValueError) as exc:
            raise InputError(f"not a counterexample file: invalid JSON ({exc.__class__.__name__})", file) from None
        if not isinstance(data, dict):
            raise InputError("not a counterexample file (expected a JSON object)", file)
        for key, kinds in (("model_file", (".yaml", ".yml", ".xml")), ("property_file", (".yaml", ".yml", ".cfg"))):
            value = data.get(key)
            if not isinstance(value, str) or not value:
                raise InputError("not a counterexample file: expected a file name", file, key)
            if Path(value).suffix.lower() not in kinds:
                raise InputError(f"expected a {' or '.join(kinds)} file", file, key)
            beside = Path(path).parent / value
            if not Path(value).is_absolute() and beside.exists():
                data[key] = str(beside)     # relative to the counterexample (else, older files: the working folder)
        if not isinstance(data.get("property"), str):
            raise InputError("not a counterexample file: expected a property id", file, "property")
        state = data.get("initial_state")
        if not isinstance(state, list) or not state or not all(_finite(v) for v in state):
            raise InputError("expected a list of finite numbers", file, "initial_state")
        for key in ("switch_time", "dt"):
            if data.get(key) is not None and not (_finite(data[key]) and data[key] >= 0):
                raise InputError("expected a finite number >= 0 or null", file, key)
        if not _drawable(data.get("trajectory", {})):
            raise InputError("expected an object of lists t (numbers), mode (names) and x (states), one entry "
                             "per point", file, "trajectory")
        if data.get("trajectory") is not None:
            data["trajectory"] = _decoded(data["trajectory"])
        transitions = data.get("transitions")
        if transitions is not None and not (isinstance(transitions, list)
                                            and all(isinstance(name, str) for name in transitions)):
            raise InputError("expected a list of transition names or null", file, "transitions")
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
        """Write the file; ``model_file`` and ``property_file`` are stored relative to its folder
        (as written, if on another drive), so a replay finds them from any working folder."""
        data = self.to_dict()
        folder = Path(path).resolve().parent
        for key in ("model_file", "property_file"):
            try:
                data[key] = os.path.relpath(Path(data[key]).resolve(), folder)
            except ValueError:
                pass
        Path(path).write_text(json.dumps(data, indent=1))


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
    sets: list = field(default_factory=list, repr=False)   # [SetPiece], only when asked (keep_sets)

    def to_dict(self) -> dict:
        """JSON-ready; the computed sets appear only as their summary (:func:`sets_summary`)."""
        out = {
            "backend": self.backend, "model": self.model, "property": self.property,
            "status": self.status.value.lower(), "seconds": self.seconds,
            "probability": self.probability, "bound": self.bound, "coverage": self.coverage,
            "counterexample": self.counterexample.to_dict() if self.counterexample else None,
            "details": self.details,
        }
        if self.sets:
            out["sets"] = sets_summary(self.sets)
        return _plain(out)


@dataclass
class SetPiece:
    """A set a back-end computed: every state a run may have in ``mode`` during ``[t0, t1]`` lies
    in it (``kind`` ``star``, ``box``), or the states one sampled run visited (``run``).

    * ``star``: the convex hull of ``stars`` (:class:`reach.sets.Star` over ``names``) plus the box
      ``[-bloat, bloat]`` -- e.g. a flowpipe segment of the star back-end: the hull of two grid
      stars plus the interpolation error bound;
    * ``box``: ``[low, high]`` (a step enclosure of taylor's rigorous sweep);
    * ``run``: ``times`` and ``points`` (rows) of a simulated run (Monte Carlo).

    ``names``: the coordinates (the back-end's state, which may carry an added clock).
    """

    mode: str
    t0: float
    t1: float
    kind: str
    names: tuple
    stars: tuple = ()
    bloat: np.ndarray | None = None
    low: np.ndarray | None = None
    high: np.ndarray | None = None
    times: np.ndarray | None = None
    points: np.ndarray | None = None

    def coordinate(self, name: str) -> int | None:
        """Index of ``name`` in ``names``; None for the time axis (``t`` or ``time`` when not a
        coordinate)."""
        if name in self.names:
            return self.names.index(name)
        if name in ("t", "time"):
            return None
        raise KeyError(name)

    def functional(self, axis) -> tuple[np.ndarray, float] | None:
        """An axis as ``(w, c)`` with value ``w . x + c`` over ``names``; None for time (a name
        that is not a coordinate). ``axis``: a coordinate's name or ``(w, c)`` itself (``w`` over
        the model's states; an added clock coordinate gets weight 0)."""
        n = len(self.names)
        if isinstance(axis, str):
            k = self.coordinate(axis)
            return None if k is None else (np.eye(n)[k], 0.0)
        w, c = axis
        row = np.zeros(n)
        row[:len(w)] = w
        return row, float(c)

    def support(self, W: np.ndarray, exact: bool = True) -> np.ndarray:
        """Upper bounds of ``max w . x`` over the piece for the rows ``w`` of ``W`` (over ``names``):
        exact for boxes (``w . c + |w| . r``); for stars the largest member's support (one LP per
        row when ``exact`` and its predicate has rows, else the coefficient-box bound) plus
        ``|w| . bloat``."""
        from reach.sets.projection import star_support

        W = np.atleast_2d(W)
        if self.kind == "box":
            c, r = (self.high + self.low) / 2, (self.high - self.low) / 2
            return W @ c + np.abs(W) @ r
        if self.kind == "run":
            return np.max(self.points @ W.T, axis=0)
        value = np.max([star_support(s, W, exact) for s in self.stars], axis=0)
        return value + (0.0 if self.bloat is None else np.abs(W) @ self.bloat)

    def polygon(self, x, y, directions: int | None = None, exact: bool = True) -> np.ndarray:
        """Vertices of an outer polygon of the projection onto the axes ``x``, ``y`` (names or
        ``(w, c)``, see :meth:`functional`); no rows if the piece is empty.

        Two functionals: support functions in ``directions`` plane directions
        (:func:`reach.sets.projection.outer_polygon`; the plane direction ``d`` lifts to
        ``d_0 w_x + d_1 w_y``). A time axis that is not a coordinate is the interval ``[t0, t1]``:
        the projection lies in ``[t0, t1]`` times the interval of the other axis."""
        from reach.sets.projection import DIRECTIONS, outer_polygon

        if self.kind == "run":
            raise ValueError("a sampled run is a path, not a set")
        fx, fy = self.functional(x), self.functional(y)
        if fx is None or fy is None:
            other = fy if fx is None else fx
            if other is None:
                return np.array([[self.t0, self.t0], [self.t1, self.t1]])
            w, c = other
            up = self.support(np.stack([w, -w]), exact)
            lo, hi = -up[1] + c, up[0] + c
            if not lo <= hi:
                return np.zeros((0, 2))
            rect = np.array([[self.t0, lo], [self.t1, lo], [self.t1, hi], [self.t0, hi]])
            return rect if fx is None else rect[:, ::-1][[0, 3, 2, 1]]
        (wx, cx), (wy, cy) = fx, fy

        def support(D):
            return self.support(np.outer(D[:, 0], wx) + np.outer(D[:, 1], wy), exact) + D @ [cx, cy]

        return outer_polygon(support, directions or DIRECTIONS)

    def path(self, x, y) -> np.ndarray:
        """The run's points on the axes ``x``, ``y`` (rows); time where an axis is time."""
        cols = []
        for axis in (x, y):
            f = self.functional(axis)
            cols.append(self.times if f is None else self.points @ f[0] + f[1])
        return np.stack(cols, axis=1)


#: at most this many pieces are summarised per mode and kind in a result's JSON
SUMMARY_PIECES = 50


def sets_summary(pieces: list) -> dict:
    """Per mode and kind: the number of pieces, the time they span, and the interval hull of at
    most ``SUMMARY_PIECES`` merged runs of consecutive pieces (each a box over ``names``) -- a
    picture's worth, not the sets themselves."""
    from reach.sets.simplify import merged_boxes

    out = {}
    for (mode, kind), group in _grouped(pieces).items():
        entry = {"pieces": len(group), "t": [min(p.t0 for p in group), max(p.t1 for p in group)],
                 "names": list(group[0].names)}
        if kind != "run":
            entry["boxes"] = [{"t": [t0, t1], "low": lo, "high": hi}
                              for t0, t1, lo, hi in merged_boxes(group, SUMMARY_PIECES)]
        out[f"{mode}/{kind}"] = entry
    return out


def _grouped(pieces: list) -> dict:
    groups: dict = {}
    for p in pieces:
        groups.setdefault((p.mode, p.kind), []).append(p)
    return groups


def _finite(value) -> bool:
    """A finite number as a float holds it (a JSON integer of 400 digits is not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


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
