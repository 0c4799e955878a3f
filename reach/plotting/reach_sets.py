"""Pictures of the reachable sets back-ends computed (``reach plot MODEL PROPS --backend B``).

Each back-end's :attr:`reach.result.Result.sets` are projected onto the two axes (outer polygons,
:meth:`reach.result.SetPiece.polygon`), merged to at most ``cap`` per back-end and mode
(:func:`reach.sets.simplify.merged_polygons`: convex hulls, so still outer), and drawn coloured by
mode: star segments filled, taylor step boxes outlined, Monte Carlo runs as thin lines on top (a
sampled run outside a set would show a soundness problem at a glance). A mode where no time passes
(``flow: false``, SpaceEx ``flow false``) holds its states at instants only, where a filled
polygon or a run's line would be a segment or a point: its sets are drawn as outlines with a
marker at each vertex (:func:`instant_style`). Every set is cut by its mode's invariant where the
plane shows it (:func:`within_invariant`) and, on a time axis (time, or a state that is the
model's global clock), to ``[0, horizon]`` (:func:`within_horizon`). The unsafe pieces of the
properties that can be drawn in the plane are shaded red (targets green,
:mod:`reach.plotting.requirements`); against time, a requirement of only some of the modes drawn
is shaded over the times their sets cover (:func:`shade_requirements`). A counterexample run is
drawn in black. A back-end of which nothing is drawn (no sets kept for the property, a failed
sweep, :mod:`reach.plotting.missing`) is named with the reason: in the legend, or across the
axes when nothing at all is drawn (:func:`nothing_drawn`). The legend (an entry per back-end and
mode, styled as drawn) sits below the axes and the title is wrapped to their width
(:mod:`reach.plotting.layout`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reach.plotting.requirements import drawable, invariant_rows, regions
from reach.result import Status

STYLE = {                    # back-end -> how its sets are drawn
    "star": {"fill": True, "alpha": 0.35, "lw": 0.0},
    "taylor": {"fill": False, "alpha": 0.9, "lw": 0.6},
}
CAP = 400                    # polygons per back-end and mode
LP_BUDGET = 2000             # LPs a picture may spend on star pieces (see projected)


def pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def chosen_pieces(results, checked: dict[str, set] | None = None, shown=None) -> dict[str, list]:
    """Per mode, the pieces of one result: preferably of a property checked in that mode
    (``checked``: mode -> property ids; its check refined the sets there, where another check
    may have kept a coarse aggregate), among those of a property drawn in the picture's plane
    (``shown``: mode -> ids; refined against what the picture shows), then the one with the most
    pieces (each check explores only the modes it needs)."""
    best: dict[str, tuple] = {}
    for r in results:
        by_mode: dict[str, list] = {}
        for piece in r.sets:
            by_mode.setdefault(piece.mode, []).append(piece)
        for mode, pieces in by_mode.items():
            rank = (r.property in (checked or {}).get(mode, ()), r.property in (shown or {}).get(mode, ()),
                    len(pieces))
            if mode not in best or rank > best[mode][0]:
                best[mode] = (rank, pieces)
    return {mode: pieces for mode, (_, pieces) in best.items()}


def checked_modes(bound_props) -> dict[str, set]:
    """mode -> ids of the properties that constrain it."""
    out: dict[str, set] = {}
    for prop in bound_props:
        for mode in getattr(prop, "modes", None) or []:
            out.setdefault(mode, set()).add(prop.id)
    return out


def projected(model, results_by_backend: dict, axes, exact: bool, cap: int = CAP, checked=None, modes=None,
              bound_props=None):
    """``{backend: {mode: ("polygons" | "paths", [arrays])}}`` in the plane of ``axes`` (only
    ``modes`` if given). With ``exact``, LPs (at most ``LP_BUDGET``) make star polygons exact at
    their directions where a mode's pieces fit the budget, else cut the widest coefficient-box
    polygons by exact axis intervals (:func:`tightened`). Polygons are cut by the mode's invariant
    where it can be drawn in the plane (:func:`within_invariant`) and, on a time axis, to the
    model's horizon (:func:`within_horizon`)."""
    from reach.sets.projection import DIRECTIONS
    from reach.sets.simplify import merged_polygons

    out, budget = {}, LP_BUDGET
    for backend, results in results_by_backend.items():
        out[backend] = {}
        shown = {m: drawable(model, bound_props or [], axes, m) for m in model.modes}
        for mode, pieces in chosen_pieces(results, checked, shown).items():
            if modes is not None and mode not in modes:
                continue
            ax, ay = axes[0].of(model, mode), axes[1].of(model, mode)
            runs = [p for p in pieces if p.kind == "run"]
            sets = [p for p in pieces if p.kind != "run"]
            if sets:
                need = sum(DIRECTIONS * len(p.stars) for p in sets
                           if p.kind == "star" and any(s.predicate.A.shape[0] for s in p.stars))
                if exact and need <= budget:            # every polygon from exact supports
                    polys = [exact_polygon(p, ax, ay) for p in sets]
                    budget -= need
                else:
                    polys = [p.polygon(ax, ay, exact=False) for p in sets]
                    if exact:
                        budget = tightened(sets, polys, ax, ay, budget)
                inside = invariant_rows(model, axes, mode)
                polys = [within_horizon(within_invariant(p, inside), axes, model) for p in polys]
                out[backend][mode] = ("polygons", merged_polygons(polys, cap))
            elif runs:
                out[backend][mode] = ("paths", [p.path(ax, ay) for p in runs])
    return out


def tightened(pieces, polygons, ax, ay, budget: int) -> int:
    """Cut the coefficient-box polygons of star pieces whose predicate has rows (where that bound
    can be loose) by the exact interval of each axis over the piece (two LPs per axis and member
    star), widest pieces first, while ``budget`` LPs remain; returns what is left. The cut keeps
    the polygon outer: the piece lies within both. An axis whose LP stops without a verdict is
    not cut."""
    from reach.lp import LPError
    from reach.sets.projection import clip

    def width(k):
        poly = polygons[k]
        return float(np.max(np.ptp(poly, axis=0) / scale)) if poly.shape[0] else 0.0

    todo = [k for k, p in enumerate(pieces) if p.kind == "star" and polygons[k].shape[0]
            and any(s.predicate.A.shape[0] for s in p.stars)]
    if not todo:
        return budget
    every = np.vstack([polygons[k] for k in range(len(pieces)) if polygons[k].shape[0]])
    scale = np.maximum(np.ptp(every, axis=0), 1e-300)
    for k in sorted(todo, key=width, reverse=True):
        piece = pieces[k]
        cost = 4 * len(piece.stars)
        if budget < cost:
            break
        budget -= cost
        for axis, f in enumerate((piece.functional(ax), piece.functional(ay))):
            if f is None:
                continue
            w, c = f
            try:
                up = piece.support(np.stack([w, -w]), exact=True)
            except LPError:
                continue
            d = np.eye(2)[axis]
            polygons[k] = clip(clip(polygons[k], d, up[0] + c), -d, up[1] - c)
    return budget


def exact_polygon(piece, ax, ay) -> np.ndarray:
    """The outer polygon of ``piece`` from exact supports (:meth:`reach.result.SetPiece.polygon`),
    or from coefficient-box bounds where an LP stops without a verdict (outer too)."""
    from reach.lp import LPError

    try:
        return piece.polygon(ax, ay, exact=True)
    except LPError:
        return piece.polygon(ax, ay, exact=False)


def within_invariant(polygon: np.ndarray, rows) -> np.ndarray:
    """``polygon`` cut by the half-planes ``rows`` (``(A, b)``: ``A p <= b``, the drawable part of
    its mode's invariant, :func:`reach.plotting.requirements.invariant_rows`; None: as is).

    A set of a mode may reach past the invariant where the plane does not show its own bounds:
    a star piece drawn from coefficient-box bounds (past the LP budget) ignores its predicate,
    which holds the invariant, and the interpolation error bloats a flowpipe segment on every
    side. Every state a run has in the mode satisfies the invariant, so the cut polygon still
    holds every reached state."""
    from reach.sets.projection import clip

    if rows is None:
        return polygon
    for a, b in zip(*rows):
        polygon = clip(polygon, a, b)
    return polygon


#: the cut at the horizon lies this fraction of it beyond (a clock's rounding), so that a set
#: a back-end dates at the horizon is kept
HORIZON_SLACK = 1e-9


def within_horizon(polygon: np.ndarray, axes, model) -> np.ndarray:
    """``polygon`` cut to the times ``[0, horizon]`` of ``model`` where one of ``axes`` shows
    time (the time axis, or a state that is the model's global clock: :meth:`Axis.is_time`; else
    as is).

    A back-end's last pieces may run past the horizon: a flowpipe segment of star spans a whole
    time step from states entered over a spread of times, so its clock coordinate (the time
    axis) may reach up to a step plus that spread beyond the horizon. The cut polygon is still
    outer: a state reached by the horizon lies in the set at a time in ``[0, horizon]``, so its
    point in the plane lies both in the polygon and in that strip. (Cutting a piece's member
    stars instead would not be: their hull would miss the part of a segment between a member
    before the horizon and one past it.)"""
    from reach.sets.projection import clip

    for k, axis in enumerate(axes):
        if axis.is_time(model):
            horizon = axis.scale * model.horizon
            slack = HORIZON_SLACK * max(1.0, abs(horizon))
            d = np.eye(2)[k]
            polygon = clip(clip(polygon, d, horizon + slack), -d, slack)
    return polygon


def counterexamples(model, results_by_backend: dict, axes) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(label, path, violation point)`` of every UNSAFE result's counterexample run."""
    out = []
    for backend, results in results_by_backend.items():
        for r in results:
            cex = r.counterexample
            if cex is None or not cex.trajectory.get("x"):
                continue
            tr = cex.trajectory
            path = np.stack([a.values(model, tr["t"], tr["mode"], tr["x"]) for a in axes], axis=1)
            point = np.array([a.values(model, [cex.violation_time], [cex.violation_mode],
                                       [cex.violation_state])[0] for a in axes])
            out.append((f"{backend}: {r.property} counterexample", path, point))
    return out


def _view(drawn, cexs) -> tuple[float, float, float, float]:
    points = [np.zeros((0, 2))]
    for modes in drawn.values():
        for _, arrays in modes.values():
            points += [a for a in arrays if a.size]
    points += [c[1] for c in cexs]
    pts = np.vstack(points)
    if pts.shape[0] == 0:
        return 0.0, 1.0, 0.0, 1.0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = np.maximum(hi - lo, 1e-9 * np.maximum(1.0, np.abs(hi)))
    lo, hi = lo - 0.06 * span, hi + 0.06 * span
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def run_colour(colour) -> tuple:
    """The colour of the sampled runs in a mode of colour ``colour``: darker than its sets."""
    from matplotlib.colors import to_rgb

    return tuple(0.6 * np.array(to_rgb(colour))) + (0.8,)


def set_style(backend: str, kind: str, colour) -> dict:
    """How the sets of ``backend`` in a mode of colour ``colour`` are drawn, as keyword arguments
    for both the collection (``PolyCollection`` for ``polygons``, ``LineCollection`` for
    ``paths``) and its legend handle (``Patch``, ``Line2D``), so the legend shows what is drawn."""
    if kind == "paths":                 # sampled runs: thin lines, darker than the mode's sets
        return {"color": run_colour(colour), "linewidth": 0.6, "zorder": 4}
    style = STYLE.get(backend, STYLE["star"])
    return {"facecolor": colour if style["fill"] else "none", "edgecolor": colour, "alpha": style["alpha"],
            "linewidth": style["lw"] or 0.3, "zorder": 2 if style["fill"] else 3}


def instant_style(kind: str, colour) -> dict:
    """How the sets in a mode where no time passes are drawn, as keyword arguments for both their
    line (:func:`draw_instants`) and its legend handle.

    Such a mode holds each state for an instant, so against time its set is a point or a thin
    segment (the states at the instants they enter), and a filled polygon or a run's line would
    not show. A back-end's set is drawn as its outline (a bar where it is a segment) with a
    marker at every vertex (a dot where it is a point); a sampled run's state (one per visit: no
    time passes and no state changes there) as a smaller, darker marker. Both lie over the
    counterexample runs, which pass through the same states."""
    if kind == "paths":
        return {"color": run_colour(colour), "linestyle": "none", "marker": ".", "markersize": 4.0,
                "zorder": 5.2}
    return {"color": colour, "alpha": 0.8, "linewidth": 1.5, "marker": "o", "markersize": 3.5, "zorder": 5.1}


def outlines(polygons: list[np.ndarray]) -> np.ndarray:
    """The closed outlines of ``polygons`` (rows of vertices) as one array, a row of NaN between
    two (where a matplotlib line breaks)."""
    gap = np.full((1, 2), np.nan)
    return np.vstack([part for p in polygons for part in (p, p[:1], gap)] or [np.zeros((0, 2))])


def draw_instants(ax, kind: str, arrays: list[np.ndarray], label: str, colour):
    """Draw the sets of a mode where no time passes on ``ax`` as one line (:func:`instant_style`):
    polygons as outlines, runs as their states; returns the line and its legend handle."""
    from matplotlib.lines import Line2D

    style = instant_style(kind, colour)
    points = outlines(arrays) if kind == "polygons" else np.vstack(arrays)
    line = Line2D(points[:, 0], points[:, 1], **style)
    ax.add_line(line)
    return line, Line2D([], [], label=label, **style)


def draw_flowing(ax, backend: str, kind: str, arrays: list[np.ndarray], label: str, colour):
    """Draw the sets of ``backend`` in a mode where time passes on ``ax`` as one collection
    (:func:`set_style`): polygons filled or outlined, runs as lines; returns the collection and
    its legend handle."""
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    style = set_style(backend, kind, colour)
    if kind == "polygons":
        coll = PolyCollection(arrays, closed=True, facecolors=[style["facecolor"]],
                              edgecolors=[style["edgecolor"]], alpha=style["alpha"],
                              linewidths=style["linewidth"], zorder=style["zorder"])
        handle = Patch(label=label, **style)
    else:
        coll = LineCollection(arrays, colors=[style["color"]], linewidths=style["linewidth"],
                              zorder=style["zorder"])
        handle = Line2D([], [], label=label, **{**style, "linewidth": 1.2})
    ax.add_collection(coll)
    return coll, handle


def set_label(backend: str, mode: str, kind: str, timeless: bool) -> str:
    """The legend's words for the sets of ``backend`` in ``mode`` (``timeless``: no time passes there)."""
    if not timeless:
        what = WHAT.get(backend, backend) if kind == "polygons" else f"{backend} sampled runs"
        return f"mode {mode}: {what}"
    what = WHAT_AT_INSTANTS.get(backend, f"{backend} sets") if kind == "polygons" else f"{backend} sampled states"
    return f"mode {mode}: {what} at its instants (no time passes)"


def grouped(props: dict[str, set], shown_modes: list[str]) -> dict[tuple, list[str]]:
    """``{modes: [property ids]}`` from ``{id: modes}``: the properties with the same modes
    together, the modes in the order drawn."""
    out: dict[tuple, list[str]] = {}
    for prop, modes in sorted(props.items()):
        out.setdefault(tuple(sorted(modes, key=shown_modes.index)), []).append(prop)
    return out


def modes_text(modes, shown_modes: list[str]) -> str:
    """``modes`` as text: ``every mode drawn`` when they are all of several, else their names."""
    return "every mode drawn" if len(shown_modes) > 1 and set(modes) == set(shown_modes) else ", ".join(modes)


#: how a requirement region is drawn (its legend patch alike)
REGION_STYLE = {"alpha": 0.12, "hatch": "//", "linewidth": 0.8, "zorder": 0}
#: the narrowest stretch of time a requirement is shaded over, as a fraction of the view's time
#: span (the sets of a mode where no time passes sit at instants)
INSTANT_WIDTH = 0.004
WHAT = {"star": "star flowpipe segments (outer)", "taylor": "taylor step enclosures (rigorous)",
        "montecarlo": "montecarlo sampled runs"}
WHAT_AT_INSTANTS = {"star": "star sets (outer)", "taylor": "taylor enclosures (rigorous)"}


def shade_requirements(ax, model, axes, found, drawn: dict, shown_modes: list[str], view) -> list:
    """Shade the requirement regions ``found`` (:func:`reach.plotting.requirements.regions`) on
    ``ax``; returns their legend handles. Each patch has gid ``kind:modes`` (``unsafe:rebound``).

    An unsafe region of properties in only some of the modes drawn applies only while a run is
    in those modes. Against time it is shaded over the stretches of time that their drawn sets
    cover (:func:`reach.plotting.requirements.time_spans`), and its legend entry says so; in a
    plane of two states, which does not tell the modes' times apart, over the whole view, the
    legend naming the modes. A region shared by several properties or modes is shaded once
    (shading twice darkens it)."""
    plt = pyplot()
    from matplotlib.patches import Patch

    from reach.plotting.requirements import time_spans, within_spans

    k = next((i for i, axis in enumerate(axes) if axis.is_time(model)), None)
    shades: dict = {}                   # (kind, polygon) -> (kind, polygon, modes, property ids)
    for region in found:
        key = (region.kind, np.round(region.polygon, 12).tobytes())
        shade = shades.setdefault(key, (region.kind, region.polygon, set(), set()))
        shade[2].add(region.mode)
        shade[3].add(region.prop)
    restricted = set()                  # ids of the properties shaded over some times only
    for kind, polygon, modes, ids in shades.values():
        colour = "tab:red" if kind == "unsafe" else "tab:green"
        parts = [polygon]
        if k is not None and kind == "unsafe" and modes != set(shown_modes):
            arrays = [a for by_mode in drawn.values() for mode, (_, some) in by_mode.items() if mode in modes
                      for a in some]
            least = INSTANT_WIDTH * (view[2 * k + 1] - view[2 * k])
            parts = within_spans(polygon, time_spans(arrays, k, least), k)
            restricted |= ids
        for part in parts:
            patch = plt.Polygon(part, closed=True, facecolor=colour, edgecolor=colour, **REGION_STYLE)
            patch.set_gid(f"{kind}:{','.join(sorted(modes, key=shown_modes.index))}")
            ax.add_patch(patch)
    handles = []
    for kind, colour in (("unsafe", "tab:red"), ("target", "tab:green")):
        props: dict = {}
        for r in found:
            if r.kind == kind:
                props.setdefault(r.prop, set()).add(r.mode)
        groups = []
        for modes, ids in grouped(props, shown_modes).items():
            text = f"{', '.join(ids)} in {modes_text(modes, shown_modes)}"
            if kind == "unsafe" and restricted & set(ids):
                text += f" only (shaded while sets are in {modes_text(modes, shown_modes)})"
            groups.append(text)
        if groups:
            handles.append(Patch(facecolor=colour, edgecolor=colour, label=f"{kind}: {'; '.join(groups)}",
                                 **REGION_STYLE))
    return handles


def nothing_drawn(model, results_by_backend: dict, drawn: dict, bound_props) -> dict[str, str]:
    """``{backend: why}`` for each back-end of which nothing is drawn: why its results hold no
    sets (:func:`reach.plotting.missing.why_no_sets`, the same reason said once) and what would
    draw them (:func:`reach.plotting.missing.suggestion`), or that none of its sets shows in the
    modes and times drawn."""
    from reach.plotting.missing import suggestion, why_no_sets

    props = {p.id: p for p in bound_props}
    out = {}
    for backend, results in results_by_backend.items():
        if any(len(arrays) for _, arrays in drawn.get(backend, {}).values()):
            continue
        if any(r.sets for r in results):
            out[backend] = "none of its sets shows in the modes and times drawn"
            continue
        reasons = [why_no_sets(backend, r, props[r.property]) for r in results]
        reasons.append(suggestion(backend, model, [props[r.property] for r in results], list(results_by_backend)))
        out[backend] = "; ".join(why for why in dict.fromkeys(reasons) if why)
    return out


def cut_short(results_by_backend: dict, drawn: dict) -> list[str]:
    """A legend line per exploring back-end (not Monte Carlo, whose runs are whole) whose drawn
    sets end where its check stopped: at a violation (UNSAFE), what is drawn is not all that is
    reachable; undecided (UNKNOWN: a budget, a cell refinement could not clear), it may not be."""
    out = []
    for backend, results in results_by_backend.items():
        if backend == "montecarlo" or not drawn.get(backend):
            continue
        stopped = [r.property for r in results if r.status == Status.UNSAFE and r.sets]
        undecided = [r.property for r in results if r.status == Status.UNKNOWN and r.sets]
        if stopped:
            out.append(f"{backend}: sets only up to where its check of {', '.join(stopped)} stopped at the "
                       f"violation (not all that is reachable)")
        if undecided:
            out.append(f"{backend}: sets up to where its check of {', '.join(undecided)} stopped undecided "
                       f"(maybe not all that is reachable)")
    return out


def missing_text(backend: str, why: str) -> str:
    """The words for a back-end of which nothing is drawn (:func:`nothing_drawn`)."""
    return f"{backend}: nothing to draw: {why}"


def say_missing(ax, missing: dict[str, str]):
    """Write why nothing is drawn of any back-end across the middle of ``ax`` (a paragraph per
    back-end), wrapped to its width (call once the layout is done); returns the text artist
    (gid ``nothing drawn``)."""
    from reach.plotting.layout import fit_text

    text = "\n\n".join(["Nothing to draw:"] + [f"{b} {why}" for b, why in missing.items()])
    note = ax.text(0.5, 0.5, "", transform=ax.transAxes, ha="center", va="center", multialignment="left",
                   fontsize=10, bbox={"facecolor": "white", "edgecolor": "0.6", "boxstyle": "round,pad=0.6"},
                   zorder=7, gid="nothing drawn")
    fit_text(note, text, 0.85 * ax.bbox.width, ax.figure.canvas.get_renderer())
    return note


def plot_reach_sets(model, results_by_backend: dict, bound_props, axes, out: Path, exact: bool = True,
                    title: str | None = None, modes: list[str] | None = None, view=None, ax=None) -> dict:
    """Draw the sets of ``results_by_backend`` (``{backend: [Result]}``) on ``axes`` (two
    :class:`reach.plotting.axes.Axis`) into ``out`` (or onto the matplotlib ``ax`` given).
    ``modes``: only these; ``view``: ``(x0, x1, y0, y1)`` instead of the data's extent. Returns
    what was drawn: polygons and runs per back-end (``sets``), the properties not drawable here,
    and why nothing is drawn of some back-ends (``nothing_drawn``: ``{backend: why}``,
    :func:`nothing_drawn`).

    The legend has one entry per back-end and mode drawn, styled as its sets are
    (:func:`set_style`), and sits below the axes, over no data; the title (one line of verdicts
    per back-end) is wrapped to the axes' width (:func:`reach.plotting.layout.arrange`). Each
    artist of sets (a collection; a line in a mode where no time passes) has gid ``backend:mode``.
    A back-end of which nothing is drawn gets a legend entry saying why; when nothing at all is
    (no set, no counterexample run), that is written across the axes instead (:func:`say_missing`)."""
    plt = pyplot()
    from matplotlib.patches import Patch

    from reach.plotting.layout import arrange

    drawn = projected(model, results_by_backend, axes, exact, checked=checked_modes(bound_props), modes=modes,
                      bound_props=bound_props)
    cexs = counterexamples(model, results_by_backend, axes)
    view = view or _view(drawn, cexs)
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(8, 6.5), layout="constrained")
    names = list(model.modes)
    colours = {m: plt.cm.tab10(i % 10) for i, m in enumerate(names)}
    shown_modes = sorted({m for d in drawn.values() for m in d}, key=names.index)
    found, hidden, view = regions(model, bound_props, axes, shown_modes, view)
    handles = shade_requirements(ax, model, axes, found, drawn, shown_modes, view)
    counts = {}
    entries = {}                        # (backend, mode) -> legend handle
    for backend, modes_drawn in drawn.items():
        for mode, (kind, arrays) in modes_drawn.items():
            counts[f"{backend}/{mode}"] = len(arrays)
            timeless = model.modes[mode].timeless
            label = set_label(backend, mode, kind, timeless)
            if timeless:
                artist, entries[backend, mode] = draw_instants(ax, kind, arrays, label, colours[mode])
            else:
                artist, entries[backend, mode] = draw_flowing(ax, backend, kind, arrays, label, colours[mode])
            artist.set_gid(f"{backend}:{mode}")
    handles += [entries[b, m] for m in shown_modes for b in drawn if (b, m) in entries]
    for label, path, point in cexs:
        ax.plot(path[:, 0], path[:, 1], "-", color="k", lw=1.2, zorder=5)
        ax.plot(*point, "X", color="k", ms=9, zorder=6)
    if cexs:
        by_backend = {}
        for label, _, _ in cexs:
            backend, _, rest = label.partition(": ")
            by_backend.setdefault(backend, []).append(rest.removesuffix(" counterexample"))
        text = "; ".join(f"{b}: {', '.join(ps)}" for b, ps in by_backend.items())
        handles.append(plt.Line2D([], [], color="k", marker="X", lw=1.2, label=f"counterexample runs ({text})"))
    missing = nothing_drawn(model, results_by_backend, drawn, bound_props)
    anything = any(counts.values()) or bool(cexs)
    if anything:
        handles += [Patch(facecolor="none", edgecolor="none", label=missing_text(b, why)) for b, why in missing.items()]
        handles += [Patch(facecolor="none", edgecolor="none", label=text)
                    for text in cut_short(results_by_backend, drawn)]
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_xlabel(axes[0].label)
    ax.set_ylabel(axes[1].label)
    ax.grid(True, alpha=0.25)
    if title is None:
        verdicts = "\n".join(f"{b}: " + ", ".join(f"{r.property} {r.status.value}" for r in rs)
                              for b, rs in results_by_backend.items())
        title = f"{model.name}: {axes[1].name} against {axes[0].name}\n{verdicts}"
    arrange(ax, title, handles, legend_title="not drawable in this plane: " + ", ".join(hidden) if hidden else None,
            grow=own)
    if not anything and missing:
        say_missing(ax, missing)
    if own:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110)
        plt.close(fig)
    return {"sets": counts, "regions": len(found), "not_drawn": hidden, "counterexamples": len(cexs),
            "nothing_drawn": missing}
