"""Requirement sets in the plane of a picture, from the properties' half-spaces.

An unsafe piece of a safety property is a conjunction ``H x <= g`` over the state (inputs already
replaced by the mode's control law). A row ``h`` can be drawn in the plane of the axes
``p = (w_x . x + c_x, w_y . x + c_y)`` exactly when ``h = a w_x + b w_y`` (least squares with a zero
residual): then ``h . x <= g`` reads ``a p_0 + b p_1 <= g + a c_x + b c_y``. A piece all of whose
rows can be drawn is the convex polygon cut from the view rectangle by them
(:func:`reach.sets.projection.clip`); a piece with a row in other variables is not drawn (its
property is named as such). A time axis that is not a state takes rows that do not involve it.

A mode's invariant is read the same way (:func:`invariant_rows`): the plotter cuts the mode's
sets by the constraints the plane shows. Against time, a requirement that applies in some modes
only is shaded over the stretches of time their drawn sets cover (:func:`time_spans`,
:func:`within_spans`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reach.model.constraints import halfspaces
from reach.sets.projection import clip


@dataclass
class Region:
    prop: str
    mode: str
    label: str
    polygon: np.ndarray        # vertices in the plane (within the view)
    kind: str = "unsafe"       # or "target"


def plane_rows(H, g, fx, fy, tol: float = 1e-9):
    """``(A, b)`` with ``H x <= g`` read as ``A p <= b`` in the plane; None if a row is not in the
    span of the axes' functionals (``fx``/``fy``: ``(w, c)``, or None for a time axis that is not
    a state: it only admits rows without it)."""
    cols = [f[0] for f in (fx, fy) if f is not None]
    if not cols:
        return None
    M = np.stack(cols, axis=1)                               # (n, k)
    A, b = [], []
    for h, gk in zip(np.atleast_2d(H), np.atleast_1d(g)):
        coef, *_ = np.linalg.lstsq(M, h, rcond=None)
        if np.linalg.norm(M @ coef - h) > tol * max(1.0, np.linalg.norm(h)):
            return None
        row, shift, k = np.zeros(2), 0.0, 0
        for axis, f in enumerate((fx, fy)):
            if f is not None:
                row[axis] = coef[k]
                shift += coef[k] * f[1]
                k += 1
        A.append(row)
        b.append(gk + shift)
    return np.array(A), np.array(b)


def functional(model, axis, mode):
    """An axis in ``mode`` as ``(w, c)`` over the model's states, None for a time axis."""
    spec = axis.of(model, mode)
    if isinstance(spec, str):
        if spec not in model.state:
            return None
        return np.eye(model.n)[model.state.index(spec)], 0.0
    return spec


def invariant_rows(model, axes, mode: str):
    """``(A, b)``: the constraints of ``mode``'s invariant that can be drawn on ``axes``, read as
    ``A p <= b`` in the plane (each constraint on its own: one in other variables, or nonlinear,
    is left out), or None when there is none. Every state a run has in the mode satisfies them,
    so a set of the mode cut by them still holds every reached state."""
    fx, fy = functional(model, axes[0], mode), functional(model, axes[1], mode)
    rows, bounds = [], []
    for constraint in model.modes[mode].invariant:
        hs = halfspaces([constraint], model.symbols)
        plane = None if hs is None else plane_rows(*hs, fx, fy)
        if plane is not None:
            rows.append(plane[0])
            bounds.append(plane[1])
    return (np.vstack(rows), np.concatenate(bounds)) if rows else None


def drawable(model, bound_props, axes, mode: str) -> set[str]:
    """Ids of the safety properties with an unsafe piece in ``mode`` that can be drawn on ``axes``."""
    out = set()
    fx, fy = functional(model, axes[0], mode), functional(model, axes[1], mode)
    for prop in bound_props:
        for piece in (getattr(prop, "pieces", None) or {}).get(mode, []):
            hs = halfspaces(piece, model.symbols)
            if hs is not None and plane_rows(*hs, fx, fy) is not None:
                out.add(prop.id)
                break
    return out


def regions(model, bound_props, axes, modes, view) -> tuple[list[Region], list[str], tuple]:
    """The drawable unsafe pieces of the safety properties (and the targets of reach
    properties) in the listed modes, cut to the view; the ids of the properties with pieces that
    cannot be drawn in this plane (``id (in part)`` when others are); and the view
    ``(x0, x1, y0, y1)``, widened to show the bound of an axis-parallel requirement that lies
    within one view span of it (a thrust limit just beyond the computed sets)."""
    drawable, hidden = [], []
    for prop in bound_props:
        entries = []
        if getattr(prop, "kind", "") == "safety":
            entries = [(m, piece, "unsafe") for m in prop.modes if m in modes for piece in prop.pieces.get(m, [])]
        elif getattr(prop, "target", None):
            entries = [(m, prop.target, "target") for m in modes[:1]]
        missed, drew = False, False
        for mode, piece, kind in entries:
            hs = halfspaces(piece, model.symbols)
            rows = None if hs is None else plane_rows(*hs, functional(model, axes[0], mode),
                                                      functional(model, axes[1], mode))
            if rows is None:
                missed = True
                continue
            drew = True
            drawable.append((prop.id, mode, " and ".join(dict.fromkeys(c.text for c in piece)), rows, kind))
        if missed:
            hidden.append(f"{prop.id} (in part)" if drew else prop.id)
    view = widened(view, [rows for *_, rows, _ in drawable])
    x0, x1, y0, y1 = view
    rect = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)
    out = []
    for prop_id, mode, label, (A, b), kind in drawable:
        poly = rect
        for a, bk in zip(A, b):
            poly = clip(poly, a, bk)
        if poly.shape[0] >= 3:
            out.append(Region(prop_id, mode, label, poly, kind))
    return out, hidden, view


def widened(view, row_sets) -> tuple:
    """``view`` grown to take in each axis-parallel bound ``p_k <= v`` (or ``>=``) lying at most
    one span beyond it, with a margin of 6 % of the new span."""
    lo = np.array([view[0], view[2]], dtype=float)
    hi = np.array([view[1], view[3]], dtype=float)
    span = hi - lo
    new_lo, new_hi = lo.copy(), hi.copy()
    for A, b in row_sets:
        for a, bk in zip(A, b):
            k = np.flatnonzero(a)
            if k.size != 1:
                continue
            k = int(k[0])
            v = bk / a[k]
            if lo[k] - span[k] <= v <= hi[k] + span[k]:
                new_lo[k], new_hi[k] = min(new_lo[k], v), max(new_hi[k], v)
    grow = 0.06 * (new_hi - new_lo)
    new_lo = np.where(new_lo < lo, new_lo - grow, new_lo)
    new_hi = np.where(new_hi > hi, new_hi + grow, new_hi)
    return float(new_lo[0]), float(new_hi[0]), float(new_lo[1]), float(new_hi[1])


def time_spans(arrays, k: int, least: float) -> list[tuple[float, float]]:
    """The stretches of axis ``k`` that ``arrays`` (polygons or runs: rows of points) cover, as
    sorted disjoint intervals: the union of their extents along it, each widened to at least
    ``least`` about its middle (the sets of a mode where no time passes sit at instants, whose
    stretch would not show)."""
    extents = []
    for a in arrays:
        if len(a):
            lo, hi = float(np.min(a[:, k])), float(np.max(a[:, k]))
            grow = max(0.0, least - (hi - lo)) / 2
            extents.append((lo - grow, hi + grow))
    out: list[tuple[float, float]] = []
    for lo, hi in sorted(extents):
        if out and lo <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], hi))
        else:
            out.append((lo, hi))
    return out


def within_spans(polygon: np.ndarray, spans, k: int) -> list[np.ndarray]:
    """The parts of ``polygon`` over each of the intervals ``spans`` of axis ``k`` (empty ones
    left out)."""
    d = np.eye(2)[k]
    parts = [clip(clip(polygon, d, hi), -d, -lo) for lo, hi in spans]
    return [p for p in parts if p.shape[0] >= 3]
