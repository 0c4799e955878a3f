"""What a picture's axes are: a state, an input (its control law, mode by mode) or time.

An axis is resolved per mode to what :meth:`reach.result.SetPiece.polygon` takes: a state's name,
``(w, c)`` for an input whose control law in that mode is affine (``u = w . x + c``), or ``"time"``
for the time axis of a model without a state of that name. Labels carry the model's units.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
import sympy

from reach.errors import InputError
from reach.model.constraints import affine_coefficients
from reach.model.units import UNITS

TIME_NAMES = ("t", "time")


@dataclass(frozen=True)
class Axis:
    name: str
    kind: str           # "state", "input" or "time"
    label: str
    scale: float = 1.0  # displayed value = scale * model value (N for a force in kg, m, min)

    def of(self, model, mode: str):
        """The axis in ``mode`` for :meth:`SetPiece.polygon` (its displayed value); InputError
        for an input whose control law there is not affine in the state."""
        if self.kind == "time":
            return "time"
        if self.kind == "state":
            if self.scale == 1.0:
                return self.name
            return self.scale * np.eye(model.n)[model.state.index(self.name)], 0.0
        law = model.modes[mode].control.get(self.name, sympy.Integer(0))
        coeffs = affine_coefficients(law, model.symbols)
        if coeffs is None:
            raise InputError(f"input '{self.name}' is not an affine function of the state in mode "
                             f"'{mode}': it cannot be drawn from sets", field="--vars")
        return self.scale * np.asarray(coeffs[0], float), self.scale * float(coeffs[1])

    def is_time(self, model) -> bool:
        """Whether the axis shows elapsed time: the time axis, or a state that is the model's
        global clock (rate 1 in every mode, 0 at the start, never reset: its value is the time)."""
        return self.kind == "time" or (self.kind == "state" and model.global_clock is not None
                                       and model.state[model.global_clock] == self.name)

    def values(self, model, t, modes, X) -> np.ndarray:
        """The axis along a run: times ``t``, mode names ``modes``, states ``X`` (rows)."""
        X = np.asarray(X, dtype=float)
        if self.kind == "time":
            return np.asarray(t, dtype=float)
        if self.kind == "state":
            return self.scale * X[:, model.state.index(self.name)]
        out = np.empty(X.shape[0])
        for mode in set(modes):
            w, c = self.of(model, mode)
            sel = np.array([m == mode for m in modes])
            out[sel] = X[sel] @ w + c
        return out


#: named units shown instead of a compound model unit of the same dimension (kg*m/min**2 -> N)
NAMED = ("N", "J")


def unit_of(model, name: str) -> tuple[str, float]:
    """The unit a state or input is shown in and the factor from model units to it: the model's
    own unit, or a named SI unit of the same dimension where the model's is compound
    (``("N", 1/3600)`` for a force in kg, m, min); ``("", 1)`` when unknown or a pure number."""
    dim = model.dimension_of(name)
    if dim is None:
        return "", 1.0
    text = model.units.name(dim)
    if text == "1":
        return "", 1.0
    if any(op in text for op in "*/"):
        for named in NAMED:
            si, named_dim = UNITS[named]
            if tuple(named_dim) == tuple(dim):
                return named, model.units.factor(dim) / si
    return text, 1.0


def make_axis(model, name: str) -> Axis:
    name = name.strip()
    if name in model.state:
        kind = "state"
    elif name in model.inputs:
        kind = "input"
    elif name in TIME_NAMES:
        kind = "time"
    else:
        raise InputError(f"no state or input '{name}' in model '{model.name}' (states: "
                         f"{', '.join(model.state)}; inputs: {', '.join(model.inputs) or 'none'}; "
                         f"or t for time)", field="--vars")
    unit, scale = (model.time_unit, 1.0) if kind == "time" else unit_of(model, name)
    return Axis(name, kind, f"{'time' if kind == 'time' else name} [{unit}]" if unit else name, scale)


def parse_vars(model, text: str | None, bound_props) -> tuple[Axis, Axis]:
    """``--vars x,y`` as two axes; by default the pair of states most properties constrain
    together (each property votes once per pair of states one of its pieces names), else time
    and the state most properties constrain alone, else the first two states (one state: it
    against time)."""
    if text is not None:
        parts = [p for p in text.split(",")]
        if len(parts) != 2 or not all(p.strip() for p in parts):
            raise InputError(f"expected two names separated by a comma, got '{text}'", field="--vars")
        if parts[0].strip() == parts[1].strip():
            raise InputError("the two axes must differ", field="--vars")
        return make_axis(model, parts[0]), make_axis(model, parts[1])
    votes, singles = Counter(), Counter()
    for prop in bound_props:
        pairs, alone = set(), set()
        for pieces in (getattr(prop, "pieces", None) or {}).values():
            for piece in pieces:
                used = sorted({model.symbols.index(s) for c in piece for s in c.g.free_symbols
                               if s in model.symbols})
                if len(used) == 2:
                    pairs.add(tuple(used))
                if len(used) == 1:
                    alone.add(used[0])
        votes.update(pairs)
        singles.update(alone)
    if votes:
        (i, j), _ = min(votes.items(), key=lambda kv: (-kv[1], kv[0]))
        return make_axis(model, model.state[i]), make_axis(model, model.state[j])
    if singles:
        i, _ = min(singles.items(), key=lambda kv: (-kv[1], kv[0]))
        return make_axis(model, "t"), make_axis(model, model.state[i])
    if model.n == 1:
        return make_axis(model, "t"), make_axis(model, model.state[0])
    return make_axis(model, model.state[0]), make_axis(model, model.state[1])
