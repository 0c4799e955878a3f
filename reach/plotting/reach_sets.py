"""Pictures of the reachable sets back-ends computed (``reach plot MODEL PROPS --backend B``).

Each back-end's :attr:`reach.result.Result.sets` are projected onto the two axes (outer polygons,
:meth:`reach.result.SetPiece.polygon`), merged to at most ``cap`` per back-end and mode
(:func:`reach.sets.simplify.merged_polygons`: convex hulls, so still outer), and drawn coloured by
mode: star segments filled, taylor step boxes outlined, Monte Carlo runs as thin lines on top (a
sampled run outside a set would show a soundness problem at a glance). The unsafe pieces of the
properties that can be drawn in the plane are shaded red (targets green,
:mod:`reach.plotting.requirements`); a counterexample run is drawn in black.
The legend (an entry per back-end and mode, styled as drawn) sits below the axes and the title
is wrapped to their width (:mod:`reach.plotting.layout`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reach.plotting.requirements import drawable, regions

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
    polygons by exact axis intervals (:func:`tightened`)."""
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
                    polys = [p.polygon(ax, ay, exact=True) for p in sets]
                    budget -= need
                else:
                    polys = [p.polygon(ax, ay, exact=False) for p in sets]
                    if exact:
                        budget = tightened(sets, polys, ax, ay, budget)
                out[backend][mode] = ("polygons", merged_polygons(polys, cap))
            elif runs:
                out[backend][mode] = ("paths", [p.path(ax, ay) for p in runs])
    return out


def tightened(pieces, polygons, ax, ay, budget: int) -> int:
    """Cut the coefficient-box polygons of star pieces whose predicate has rows (where that bound
    can be loose) by the exact interval of each axis over the piece (two LPs per axis and member
    star), widest pieces first, while ``budget`` LPs remain; returns what is left. The cut keeps
    the polygon outer: the piece lies within both."""
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
            up = piece.support(np.stack([w, -w]), exact=True)
            d = np.eye(2)[axis]
            polygons[k] = clip(clip(polygons[k], d, up[0] + c), -d, up[1] - c)
    return budget


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


def set_style(backend: str, kind: str, colour) -> dict:
    """How the sets of ``backend`` in a mode of colour ``colour`` are drawn, as keyword arguments
    for both the collection (``PolyCollection`` for ``polygons``, ``LineCollection`` for
    ``paths``) and its legend handle (``Patch``, ``Line2D``), so the legend shows what is drawn."""
    from matplotlib.colors import to_rgb

    if kind == "paths":                 # sampled runs: thin lines, darker than the mode's sets
        return {"color": tuple(0.6 * np.array(to_rgb(colour))) + (0.8,), "linewidth": 0.6, "zorder": 4}
    style = STYLE.get(backend, STYLE["star"])
    return {"facecolor": colour if style["fill"] else "none", "edgecolor": colour, "alpha": style["alpha"],
            "linewidth": style["lw"] or 0.3, "zorder": 2 if style["fill"] else 3}


def grouped(props: dict[str, set], shown_modes: list[str]) -> dict[str, list[str]]:
    """``{modes: [property ids]}`` from ``{id: modes}``: the properties with the same modes
    together, the modes as text (``every mode drawn`` when they are all of several)."""
    out: dict[str, list[str]] = {}
    for prop, modes in sorted(props.items()):
        text = ("every mode drawn" if len(shown_modes) > 1 and set(modes) == set(shown_modes)
                else ", ".join(sorted(modes, key=shown_modes.index)))
        out.setdefault(text, []).append(prop)
    return out


#: how a requirement region is drawn (its legend patch alike)
REGION_STYLE = {"alpha": 0.12, "hatch": "//", "linewidth": 0.8, "zorder": 0}
WHAT = {"star": "star flowpipe segments (outer)", "taylor": "taylor step enclosures (rigorous)",
        "montecarlo": "montecarlo sampled runs"}


def plot_reach_sets(model, results_by_backend: dict, bound_props, axes, out: Path, exact: bool = True,
                    title: str | None = None, modes: list[str] | None = None, view=None, ax=None) -> dict:
    """Draw the sets of ``results_by_backend`` (``{backend: [Result]}``) on ``axes`` (two
    :class:`reach.plotting.axes.Axis`) into ``out`` (or onto the matplotlib ``ax`` given).
    ``modes``: only these; ``view``: ``(x0, x1, y0, y1)`` instead of the data's extent. Returns
    what was drawn: polygons and runs per back-end, and the properties not drawable here.

    The legend has one entry per back-end and mode drawn, styled as its sets are
    (:func:`set_style`), and sits below the axes, over no data; the title (one line of verdicts
    per back-end) is wrapped to the axes' width (:func:`reach.plotting.layout.arrange`). Each
    collection's gid is ``backend:mode``."""
    plt = pyplot()
    from matplotlib.collections import LineCollection, PolyCollection
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
    handles = []
    painted = set()
    for region in found:
        colour = "tab:red" if region.kind == "unsafe" else "tab:green"
        key = (region.kind, np.round(region.polygon, 12).tobytes())
        if key in painted:              # the same piece in another mode: shading twice darkens it
            continue
        painted.add(key)
        ax.add_patch(plt.Polygon(region.polygon, closed=True, facecolor=colour, edgecolor=colour, **REGION_STYLE))
    for kind, colour, text in (("unsafe", "tab:red", "unsafe"), ("target", "tab:green", "target")):
        props = {}
        for r in found:
            if r.kind == kind:
                props.setdefault(r.prop, set()).add(r.mode)
        if props:
            where = "; ".join(f"{', '.join(ps)} in {ms}" for ms, ps in grouped(props, shown_modes).items())
            handles.append(Patch(facecolor=colour, edgecolor=colour, label=f"{text}: {where}", **REGION_STYLE))
    counts = {}
    entries = {}                        # (backend, mode) -> legend handle
    for backend, modes_drawn in drawn.items():
        for mode, (kind, arrays) in modes_drawn.items():
            counts[f"{backend}/{mode}"] = len(arrays)
            style = set_style(backend, kind, colours[mode])
            what = WHAT.get(backend, backend) if kind == "polygons" else f"{backend} sampled runs"
            label = f"mode {mode}: {what}"
            if kind == "polygons":
                coll = PolyCollection(arrays, closed=True, facecolors=[style["facecolor"]],
                                      edgecolors=[style["edgecolor"]], alpha=style["alpha"],
                                      linewidths=style["linewidth"], zorder=style["zorder"])
                entries[backend, mode] = Patch(label=label, **style)
            else:
                coll = LineCollection(arrays, colors=[style["color"]], linewidths=style["linewidth"],
                                      zorder=style["zorder"])
                entries[backend, mode] = plt.Line2D([], [], label=label, **{**style, "linewidth": 1.2})
            coll.set_gid(f"{backend}:{mode}")
            ax.add_collection(coll)
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
    if own:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110)
        plt.close(fig)
    return {"sets": counts, "regions": len(found), "not_drawn": hidden, "counterexamples": len(cexs)}
