"""Results read in the requirement's own units, next to the requirement.

A back-end answers in model units (a thrust bound in kg m/min^2 for a minute-based model);
a requirement was written ``<= 10[N]``. These pure functions of a :class:`~reach.result.Result`,
its bound property (:mod:`reach.spec.properties`) and the model turn the figures into that
unit (the constraint's or event's :class:`~reach.model.units.DisplayUnit`: a model value
``v`` reads ``v / scale``) and put them beside the requirement::

    max Fx in [7.396, 7.397] N <= 10 N, margin 2.603 N
    abs(Fx) <= 10[N], abs(Fy) <= 10[N]: closest margin 2.603 N

``line`` is the text summary, ``figures`` the same numbers for ``--json``. A violation found
reads as its counterexample (when, where, the margin at the violating state) and, for Monte
Carlo, how many of its i.i.d. runs violated (``violating runs: k of N``); the upper confidence
bound on the violation probability belongs to an undecided answer only (it stays in ``details``).

Margins: positive is room left before the requirement is violated. For an event bound
``[lo, hi]`` it is ``value - hi`` (``<=``) or ``lo - value`` (``>=``), the worst case over
the bound; for a safety property it is the smallest depth ``max_j g_j`` to any unsafe piece
over the sampled runs (:meth:`BoundSafety.violation`). A margin at or just below zero on a
run that was not reported as a violation is a touch: the run reaches the boundary within
the rounding tolerance ``1e-9 (1 + |x|)`` that a violation must exceed.
"""

from __future__ import annotations

import math

import numpy as np

from reach.model.constraints import NUMERICAL_TOLERANCE
from reach.result import Status, _plain

TOUCH = (f"touching: within the rounding tolerance {NUMERICAL_TOLERANCE:g}*(1 + m), m the magnitude the row "
         f"combines, not a violation")


def number(value: float, digits: int = 4) -> str:
    """``value`` to ``digits`` significant figures (``inf``/``nan`` spelled out)."""
    if value is None or not math.isfinite(value):
        return str(value)
    return f"{value:.{digits}g}"


def interval(low: float, high: float) -> str:
    """``[low, high]`` with just enough figures (4 to 10) to tell the ends apart."""
    for digits in range(4, 11):
        a, b = number(low, digits), number(high, digits)
        if a != b or low == high:
            break
    return f"[{a}, {b}]"


def _with_unit(text: str, unit) -> str:
    return f"{text} {unit.text}" if unit is not None and unit.text else text


def _in(unit, value: float) -> float:
    return value if unit is None else unit.of(value)


def _in_margin_unit(text: str, unit) -> str:
    """A margin or interval of margins (``text``, already in ``unit``) with its unit, or said to
    be in model units where the property's pieces mix dimensions (``unit`` None)."""
    return _with_unit(text, unit) + (" (model units)" if unit is None else "")


def margin_text(prop, value: float, digits: int = 4) -> str:
    """A margin of a safety property (model units) in its requirement's unit: ``-0.01271 deg``."""
    unit = prop.margin_unit()
    return _in_margin_unit(number(_in(unit, value), digits), unit)


MAX_REQUIREMENT_CHARS = 160     # a requirement longer than this is shown by its description


def requirement(prop) -> str:
    """The requirement as written: constraint texts, or the event's quantity and bound; a text
    longer than :data:`MAX_REQUIREMENT_CHARS` (an imported alias written out over hundreds of
    states) by the property's description, else cut short."""
    text = _requirement(prop)
    if len(text) <= MAX_REQUIREMENT_CHARS:
        return text
    described = getattr(prop, "description", "") or ""
    if described and len(described) <= MAX_REQUIREMENT_CHARS:
        return described
    return text[:MAX_REQUIREMENT_CHARS - 3] + "..."


def _requirement(prop) -> str:
    kind = getattr(prop, "kind", "")
    if kind == "event":
        return f"{prop.sense} {prop.text or 'quantity'} {prop.op} {_bound_value(prop)}"
    if kind == "safety":
        whole = _whole_modes(prop)
        if whole:
            return f"never in {_names(whole)}"
        # a required constraint c is stored as its negation, the unsafe piece "not (c)"
        texts = list(dict.fromkeys(con.text for pieces in prop.pieces.values()
                                   for piece in pieces for con in piece))
        if texts and all(t.startswith("not (") and t.endswith(")") for t in texts):
            return ", ".join(t[len("not ("):-1] for t in texts)
        return _avoid_text(prop.pieces) if texts else ""
    if kind in ("reach", "reach_avoid") and prop.at_least is not None:
        return f"P >= {number(prop.at_least)}"
    return ""


def _where(prop, model, shown: int = 4) -> str:
    """`` (in m1, m2)`` where a safety property applies in some of the model's modes only (a
    SpaceEx forbidden set with ``loc(...) ==``, a property's ``modes:``); the first ``shown``
    of them, then a count. Nothing where the requirement's text names the modes of each of its
    pieces already (:func:`_avoid_text`: pieces that differ from mode to mode)."""
    modes = list(getattr(prop, "pieces", {}) or [])
    if getattr(prop, "kind", "") != "safety" or model is None or not modes or len(modes) >= len(model.modes):
        return ""
    if len({tuple(map(_piece_text, pieces)) for pieces in prop.pieces.values()}) > 1 or _whole_modes(prop):
        return ""
    return f" (in {_names(modes, shown)})"


def _names(modes, shown: int = 4) -> str:
    """The first ``shown`` mode names, then a count."""
    return ", ".join(modes[:shown]) + (f" and {len(modes) - shown} more" if len(modes) > shown else "")


def _whole_mode(piece) -> bool:
    """Whether an unsafe piece holds everywhere (its constraints are true constants: a SpaceEx
    ``forbidden = "loc(b) == hit"`` forbids the mode itself, stored as ``require 0 <= -1``)."""
    return all(con.g.is_number and (con.g < 0 or (con.g == 0 and not con.strict)) for con in piece)


def _whole_modes(prop) -> list[str] | None:
    """The modes of a safety property that forbids being in them at all, if that is all it says."""
    pieces = getattr(prop, "pieces", None) or {}
    if pieces and all(ps and all(map(_whole_mode, ps)) for ps in pieces.values()):
        return list(pieces)
    return None


def _piece_text(piece) -> str:
    """An unsafe piece (a conjunction of constraints) as written, each text once (an equality is
    two constraints of one text)."""
    return " and ".join(dict.fromkeys(con.text for con in piece))


def _avoid_text(pieces_by_mode) -> str:
    """An unsafe set as written: the union of its pieces (conjunctions of constraints), each
    named once, with the modes it applies in where that is not every mode of the property:
    ``avoid I >= 20 or t >= 0.2 (in move_free)``."""
    modes: dict[str, list[str]] = {}
    for mode, pieces in pieces_by_mode.items():
        for piece in pieces:
            modes.setdefault(_piece_text(piece), []).append(mode)
    every = len(pieces_by_mode)
    alone = len(modes) == 1
    return "avoid " + " or ".join(
        (text if alone or " and " not in text else f"({text})")
        + ("" if len(where) == every else f" (in {', '.join(where)})")
        for text, where in modes.items())


def quantity(prop, value: float, digits: int = 4) -> str:
    """An event property's quantity ``value`` (model units) in its requirement's unit."""
    return _with_unit(number(_in(prop.unit, value), digits), prop.unit)


def _bound_value(prop) -> str:
    return quantity(prop, prop.value)


def figures(result, prop, model) -> dict:
    """The result's figures in the requirement's units (JSON-ready)."""
    out: dict = {"requirement": requirement(prop) + _where(prop, model)}
    kind = getattr(prop, "kind", "")
    d = result.details
    if kind == "event":
        unit = prop.unit
        out["unit"] = unit.text if unit is not None else None
        out["required"] = {"op": prop.op, "value": _in(unit, prop.value)}
        if result.bound is not None:
            lo, hi = (_in(unit, v) for v in result.bound)
            out["bound"] = [lo, hi]
            margin = (prop.value - result.bound[1]) if prop.op == "<=" else (result.bound[0] - prop.value)
            out["margin"] = _in(unit, margin)
        if "sampled_range" in d:
            out["sampled_range"] = [_in(unit, v) for v in d["sampled_range"]]
        if "closest_margin" in d:
            out["closest_margin"] = _in(unit, d["closest_margin"])
    elif kind == "safety":
        unit = prop.margin_unit()
        out["unit"] = unit.text if unit is not None else None
        if unit is None:
            out["unit_note"] = ("requirements of different dimensions: margins in model units"
                                if len(prop.dimensions()) > 1 else "margins in model units")
        if "closest_depth" in d:
            out["closest_margin"] = _in(unit, d["closest_depth"])
        if "margin_bound" in d:
            out["margin_bound"] = [_in(unit, v) for v in d["margin_bound"]]
        depth = _depth_at_violation(result.counterexample, prop)
        if depth is not None:
            out["violation_margin"] = _in(unit, depth)
    if result.probability is not None:
        out["probability"] = list(result.probability)
        if getattr(prop, "at_least", None) is not None:
            out["at_least"] = prop.at_least
    note = _margin_note(result, kind, out)
    if note:
        out["margin_note"] = note
    if result.counterexample is not None:
        out["time_unit"] = model.time_unit
    return out


def _depth_at_violation(cex, prop) -> float | None:
    """The margin (negative: how far past) of the counterexample's violating state."""
    return None if cex is None else margin_at(prop, cex.violation_mode, cex.violation_state)


def margin_at(prop, mode: str, state) -> float | None:
    """The margin of a bound property at one state in ``mode`` (negative: how far past its
    bound), None where the property says nothing there."""
    if mode not in prop.pieces or len(state) != len(prop.symbols):
        return None
    test = prop.violation(mode)
    if test is None:
        return None
    _, depth = test(np.asarray(state, dtype=float).reshape(1, -1))
    return float(depth[0]) if np.isfinite(depth[0]) else None


def _margin_note(result, kind: str, out: dict) -> str | None:
    """Why a margin at or below zero came with no violation (None if there is nothing to say)."""
    margin = out.get("margin", out.get("closest_margin"))
    if margin is None or margin > 0 or result.status in (Status.UNSAFE, Status.SAFE):
        return None
    d = result.details
    if d.get("note") or d.get("unreplayed") or d.get("undefined"):
        return d.get("note") or d.get("unreplayed") or d.get("undefined")
    if kind == "event" and "bound" in out and margin < 0:
        return "the bound reaches past the requirement: neither proved nor refuted"
    if kind == "event":
        return "touching: the extremum equals the bound, which the requirement allows"
    return TOUCH


def line(result, prop, model) -> str:
    """One line: the figures in the requirement's units beside the requirement."""
    from reach.checking import violated

    d = result.details
    if result.status == Status.UNSUPPORTED:
        return d.get("reason", "")
    f = figures(result, prop, model)
    kind = getattr(prop, "kind", "")
    parts = []
    if result.counterexample is not None:
        c = result.counterexample
        t = f" {model.time_unit}" if model.time_unit else ""
        abort = "" if c.switch_time is None else f", switch at t={c.switch_time:g}{t}"
        parts.append(f"violated at t={c.violation_time:.4g}{t} in {c.violation_mode}{abort}")
    if kind == "event":
        unit = prop.unit
        quantity = f"{prop.sense} {prop.text or 'quantity'}"
        required = f"{prop.op} {_bound_value(prop)}"
        if "bound" in f:
            lo, hi = f["bound"]
            shown = number(lo) if lo == hi else interval(lo, hi)
            parts.append(f"{quantity} in {_with_unit(shown, unit)} {required}, "
                         f"margin {_with_unit(number(f['margin']), unit)}")
        elif "sampled_range" in f:
            extreme = f["sampled_range"][1 if prop.sense == "max" else 0]
            parts.append(f"{quantity} sampled {_with_unit(number(extreme), unit)} {required}, "
                         f"closest margin {_with_unit(number(f['closest_margin']), unit)}")
        else:
            parts.append(f"{quantity} {required}")
    elif kind == "safety":
        text = f["requirement"]
        m = {} if _whole_modes(prop) else f     # being in the mode is the violation: no margin
        unit = prop.margin_unit()
        if "margin_bound" in m:
            text += f": smallest margin in {_in_margin_unit(interval(*m['margin_bound']), unit)}"
        if "closest_margin" in m and "violation_margin" not in m:
            text += f": closest margin {_in_margin_unit(number(m['closest_margin']), unit)}"
        if "violation_margin" in m:
            text += f": margin {_in_margin_unit(number(m['violation_margin']), unit)} at the violation"
        parts.append(text)
    if result.probability is not None:
        p = f"P in {interval(*result.probability)}"
        if "at_least" in f:
            p += f", required >= {number(f['at_least'])}"
            if violated(result):
                p += " (wholly below it: a violation, with no single run to show for it)"
        parts.append(p)
    if "margin_note" in f:
        parts.append(f["margin_note"])
    if result.status == Status.UNSAFE and "violating_runs" in d:
        parts.append(f"violating runs: {d['violating_runs']} of {d['random_runs']}"
                     + (" (the counterexample is a structured, aimed or search run)" if not d["violating_runs"] else ""))
    elif result.status != Status.UNSAFE and "violation_probability_upper_95" in d:
        parts.append(f"P(violation) <= {d['violation_probability_upper_95']:.2g} (95 %)")
    if d.get("undefined") and f.get("margin_note") != d["undefined"]:
        parts.append(d["undefined"])
    stopped = d.get("blocked_runs", 0) - d.get("cut_runs", 0)     # the budget's cuts are counted as blocked too
    if stopped > 0:
        total = d.get("structured_runs", 0) + d.get("random_runs", 0)
        parts.append(f"{stopped} of {total} runs stopped before the horizon and were watched "
                     f"up to there only (no transition allowed, or too many jumps in one step of "
                     f"{number(d['dt'])}: a smaller -o dt may carry them on)")
    if result.status == Status.SAFE and d.get("stopped_runs"):
        parts.append(str(d["stopped_runs"]))
    if result.status != Status.UNSAFE and d.get("note") and d["note"] != f.get("margin_note"):
        parts.append(str(d["note"]))
    if "method" in d:
        parts.append(str(d["method"]))
    if "remainder" in d:
        parts.append(f"remainder {d['remainder']}")
    if result.status == Status.UNKNOWN and d.get("reason"):
        parts.append(f"undecided: {d['reason']}")
    return "; ".join(parts)


def json_row(result, prop, model, counterexample_file: str | None = None) -> dict:
    """The ``--json`` row: the result's own keys, its figures in the requirement's units under
    ``report``, the model's warnings (:attr:`HybridAutomaton.warnings`) under ``model_warnings``
    where it has any, and no inline trajectory when the counterexample file holds it."""
    from reach.checking import violated

    row = {"property": result.property, "status": result.status.value.lower(), "seconds": result.seconds}
    row.update(result.to_dict())
    row["violated"] = violated(result)      # also a probability wholly below its threshold (no run)
    if getattr(model, "warnings", None):    # what a check warns of on stderr (runs an invariant stops)
        row["model_warnings"] = list(model.warnings)
    if prop is not None:
        row["report"] = _plain(figures(result, prop, model))
    if counterexample_file is not None:
        row["counterexample_file"] = counterexample_file
        if row.get("counterexample"):
            row["counterexample"].pop("trajectory", None)
            row["counterexample"]["trajectory_file"] = counterexample_file
    return row
