"""Safety properties read as extrema of margins.

A safety property's unsafe set in a mode is a union of pieces ``{g_j <= 0 for all j}``
(:class:`~reach.spec.properties.BoundSafety`). For one piece the margin

    d(x) = max_j g_j(x)

is positive exactly outside it (for a ``require`` constraint ``c <= 0`` the piece is the single
``-c < 0`` and ``d = -c``). The property holds iff ``min d > 0`` over the run in the listed modes
(``>= 0`` when every ``g_j`` of the piece is strict), so each piece is one event "minimise ``d``,
require ``>= 0``":

* a required constraint is a smooth quantity, bounded through the event machinery (ADS, event
  maps and, with ``remainder: rigorous``, the verified sweep);
* an ``avoid`` set is the non-smooth ``max_j g_j``; its lower end over a step of the verified
  sweep is ``max_j`` of the Taylor-model lower ends of the ``g_j``
  (:class:`~reach.backends.taylor.problem.Largest`), so the set is excluded step by step through
  the rigorous enclosures only.

Where a rigorous bound leaves a margin open (a sweep that cannot show every run leaves a mode)
and the piece is one constraint (every ``avoid`` bound of a SpaceEx cfg, a requirement checked
with ``remainder: rigorous``), the same margin as a smooth event is searched with the estimated
remainder, and the centres and corners of its lowest subdomains are replayed: a run that
violates is an UNSAFE as any other (the replay decides, not the estimate).

A required linear constraint implied in a mode by one of the mode's invariant constraints
(``c = lambda c_inv + b`` with ``lambda > 0``, ``b <= 0``) holds there by the semantics of the
automaton (a run stays inside the invariant of its mode) and is not bounded there.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import sympy

from reach.model.constraints import affine_coefficients
from reach.result import Result, Status
from reach.spec.properties import BoundEvent, BoundSafety

STRICT_ZERO = float(np.finfo(float).tiny)   # "> 0" written as ">= the smallest positive number"


@dataclass
class Margin:
    """One unsafe piece as an event; ``event`` is None when invariants imply the constraint in
    every listed mode."""

    text: str
    event: BoundEvent | None
    implied_in: list[str]
    avoid: bool
    #: the same margin as a smooth event (a piece of one constraint), searched with the estimated
    #: remainder for a violation when a rigorous bound leaves it open; None for a piece of several
    smooth: BoundEvent | None = None


def margins(model, prop: BoundSafety) -> list[Margin]:
    """The margin events of a safety property, one per unsafe piece. A piece is known by the
    texts of its constraints (and, for pieces of the same texts in a mode, as the two sides of
    ``abs(e) <= c``, by its place among them): its ``g`` may differ from mode to mode (a control
    law substituted), and the modes need not share their pieces (a SpaceEx forbidden set whose
    terms name different locations)."""
    modes = [m for m in prop.modes if prop.pieces.get(m)]
    groups: dict = {}               # (texts, place among those texts) -> {mode: piece}
    sides: dict = {}                # texts -> how many pieces of those texts a mode has
    for m in modes:
        seen: dict = {}
        for piece in prop.pieces[m]:
            texts = tuple(c.text for c in piece)
            place = seen[texts] = seen.get(texts, 0) + 1
            groups.setdefault((texts, place), {})[m] = piece
            sides[texts] = max(sides.get(texts, 0), place)
    out = []
    for j, ((texts, place), per_mode) in enumerate(groups.items()):
        in_modes = list(per_mode)
        first = per_mode[in_modes[0]]
        avoid = len(first) > 1 or not first[0].text.startswith("not (")
        text = first[0].text[len("not ("):-1] if not avoid else " and ".join(texts)
        if sides[texts] > 1:        # abs(e) <= c: the constraints e <= c and -e <= c
            text += f" (side {place} of {sides[texts]})"
        implied = [] if avoid else [m for m in in_modes if _implied(model, m, per_mode[m][0])]
        listed = [m for m in in_modes if m not in implied]
        if not listed:
            out.append(Margin(text, None, implied, avoid))
            continue
        value = 0.0 if all(c.strict for c in first) else STRICT_ZERO
        units = {c.unit for c in first}

        def event_of(quantity):
            return BoundEvent(f"{prop.id}[{j}]", listed, "min", quantity, ">=", value, prop.symbols,
                              prop.file, f"margin of {text}", text=f"margin of {text}",
                              unit=next(iter(units)) if len(units) == 1 else None)

        smooth = event_of({m: per_mode[m][0].g for m in listed}) if len(first) == 1 else None
        event = event_of({m: tuple(c.g for c in per_mode[m]) for m in listed}) if avoid else smooth
        out.append(Margin(text, event, implied, avoid, smooth))
    return out


def _implied(model, mode: str, piece) -> bool:
    """Whether the required constraint ``-piece.g <= 0`` follows from one invariant constraint
    of ``mode`` (both linear): ``-piece.g = lambda g_inv + b`` with ``lambda > 0``, ``b <= 0``."""
    symbols = model.symbols
    required = affine_coefficients(sympy.expand(-piece.g), symbols)
    if required is None:
        return False
    a, b = required
    for c in model.modes[mode].invariant:
        coeffs = affine_coefficients(c.g, symbols)
        if coeffs is None:
            continue
        a_inv, b_inv = coeffs
        k = int(np.argmax(np.abs(a_inv)))
        if a_inv[k] == 0:
            continue
        lam = a[k] / a_inv[k]
        gap = b - lam * b_inv
        if lam > 0 and np.allclose(a, lam * a_inv, rtol=1e-12, atol=0.0) and \
                (gap < 0 or (gap == 0 and piece.strict and not c.strict) or (gap == 0 and c.strict)):
            return True
    return False


def check_safety(backend, model, prop: BoundSafety, opts, deadline):
    """Check every margin event of ``prop`` (options ``opts``, all within one ``deadline``) and
    combine: SAFE when each is SAFE (a rigorous lower end of the margin above the requirement)
    or implied by invariants; otherwise UNKNOWN with the margin bounds (estimated ones say so)
    and, for the first margin left open, why."""
    rows, statuses, lows, highs, counterexample = [], [], [], [], None
    assumptions = []            # each estimated margin's (details.assumptions)
    sets: list = []             # keep_sets: the enclosures of the first margin's sweeps (the same flow for each)
    for part in margins(model, prop):
        if part.event is None:
            rows.append({"constraint": part.text, "status": "SAFE",
                         "argument": f"implied by the invariant of {', '.join(part.implied_in)}"})
            statuses.append(Status.SAFE)
            continue
        result = backend.check_event(model, part.event, opts, deadline)
        sets = sets or result.sets
        if result.status != Status.SAFE and counterexample is None:
            counterexample = witness(model, prop, result)
            if counterexample is None and part.smooth is not None and \
                    result.details["remainder"] != "estimated" and not deadline.passed():
                search = backend.check_event(model, part.smooth, replace(opts, remainder="estimated"), deadline)
                counterexample = witness(model, prop, search)
                if counterexample is not None:      # the replayed run decides; its estimate is shown
                    result = search
        assumptions.append(result.details.get("assumptions", []))
        lo, hi = result.bound
        lows.append(lo)
        highs.append(hi)
        statuses.append(result.status)
        d = result.details
        rows.append({"constraint": part.text, "status": result.status.value, "margin_bound": [lo, hi],
                     "modes": part.event.modes, "implied_in": part.implied_in, "remainder": d["remainder"],
                     "subdomain_count": d["subdomain_count"], "share_meeting_requirement": d["share_meeting_requirement"],
                     **({"avoid": True} if part.avoid else {}),
                     **({"why": d.get("reason") or d.get("note")} if d.get("reason") or d.get("note") else {})})
    status = Status.SAFE if all(s == Status.SAFE for s in statuses) else Status.UNKNOWN
    assumed = list(dict.fromkeys(text for group in assumptions for text in group))
    if counterexample is not None:
        status = Status.UNSAFE
    details = {"constraints": rows,
               "method": "margin of every unsafe piece bounded along the run (min over the listed modes)"}
    if assumed and status != Status.SAFE:
        details["assumptions"] = assumed
        stops = [a for a in assumed if "no transition is enabled" in a]
        if stops:
            details["note"] = stops[0]
    if lows:
        lo, hi = min(lows), min(highs)
        details["margin_bound"] = [lo, hi]
        remainders = {r["remainder"] for r in rows if "remainder" in r}
        details["remainder"] = ", ".join(sorted(remainders))
    if status == Status.SAFE:
        details["argument"] = (
            "each required constraint (or the avoid set) has a margin whose verified lower bound over "
            "every run in the listed modes is positive (taylor rigorous sweep), or is implied by a mode "
            "invariant; see 'constraints'")
    else:
        open_rows = [r for r in rows if r["status"] != "SAFE"]
        whys = [r["why"] for r in open_rows if "why" in r]
        details["reason"] = ("margin not proved for " + "; ".join(r["constraint"] for r in open_rows)
                             + (f" ({whys[0]})" if whys else ""))
    if counterexample is not None:
        details["argument"] = ("a point of a subdomain whose margin bound reaches below zero (its centre or a "
                               "corner), mapped back to an initial state and switch time and replayed by the simulator")
        details.pop("reason", None)
    coverage = 1.0 if status == Status.SAFE else 0.0
    return Result(backend.name, model.name, prop.id, status, coverage=coverage, details=details,
                  counterexample=counterexample, sets=sets)


WITNESSES = 4      # subdomains whose centre and corners are replayed, per margin


def witness(model, prop, result, op: str = ">=", value: float = 0.0):
    """A replayed counterexample from the subdomains whose bounds reach furthest past the
    requirement ``extremum op value`` (a margin ``>= 0`` for a safety property, an event's own):
    their centres and corners, each an initial state (and switch time, the state after the
    model's own) that the simulator runs alone; None if none violates."""
    from reach.backends.montecarlo import replay

    side = 1 if op == ">=" else 0             # the end of a bound that a violation moves past
    rows = [r for r in result.details.get("subdomains", []) if np.isfinite(r["bound"][side])]
    rows.sort(key=lambda r: r["bound"][side] if op == ">=" else -r["bound"][side])
    names = result.details.get("variables", [])
    for row in rows[:WITNESSES]:
        if (row["bound"][0] > value) if op == ">=" else (row["bound"][1] < value):
            break
        low, high = np.asarray(row["low"]), np.asarray(row["high"])
        points = [0.5 * (low + high)] + [np.where(corner, high, low) for corner in _corners(len(low))]
        for point in points:
            x = 0.5 * (model.initial.low + model.initial.high)
            tau = None
            for name, value in zip(names, point):
                if name in model.state:
                    x[model.state.index(name)] = value
                else:
                    tau = float(value)
            if tau is None and any(not tr.urgent for tr in model.transitions):
                tau = _fixed_switch(model)
            rep = replay(model, prop, x, tau)
            if rep.violated:
                return rep.counterexample(model, prop, "taylor (subdomain point, replayed)")
    return None


def _corners(m: int, limit: int = 16) -> list[np.ndarray]:
    """Up to ``limit`` corners of a box in ``m`` variables (as masks of the upper ends)."""
    count = min(2 ** m, limit)
    return [np.array([(k >> j) & 1 for j in range(m)], dtype=bool) for k in range(count)]


def _fixed_switch(model) -> float:
    """The switch time of a window of one instant (no switch-time variable)."""
    _, lo, hi = next(tr.window for tr in model.transitions if not tr.urgent)
    return float(min(lo, model.horizon))
