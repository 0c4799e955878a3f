"""Plots people would rather look at than read: sample runs per mode."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from reach.backends.montecarlo import random_plan, structured_plan, switch_window
from reach.model.simulate import Simulator
from reach.paths import writable_file


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


#: matplotlib's warnings about the layout of a crowded figure (many panels, a legend of a hundred
#: modes): the picture is written as it stands, and they would be two lines on stderr naming
#: reach's source, not the user's input
LAYOUT_WARNINGS = ("Tight layout not applied", "Creating legend with loc=\"best\" can be slow")


def _save(fig, out: Path) -> None:
    """Lay out and write ``fig`` (its folder made), quiet about :data:`LAYOUT_WARNINGS`."""
    with warnings.catch_warnings():
        for message in LAYOUT_WARNINGS:
            warnings.filterwarnings("ignore", message=message, category=UserWarning)
        fig.tight_layout()
        writable_file(out, "--out", probe=False)
        fig.savefig(out, dpi=110)


def _clocks(model, traj) -> set[int]:
    """States that are clocks along every run (``x_k(t) - t`` constant): a straight line, no panel."""
    out = set()
    for k in range(model.n):
        if all(np.ptp(states[:, k] - t) < 1e-9 * max(1.0, float(np.max(np.abs(t)))) if t.size else True
               for t, _, states in traj.path.values()):
            out.add(k)
    return out


def _shade(ax, model, bound_props, axes, modes):
    """The drawable requirement pieces on a panel (``axes``: two plotting axes), in its limits."""
    from reach.plotting.requirements import regions

    view = (*ax.get_xlim(), *ax.get_ylim())
    found, _, view = regions(model, bound_props or [], axes, modes, view)
    for region in found:
        ax.add_patch(plt_polygon(region.polygon))
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    return sorted({r.prop for r in found})


def plt_polygon(vertices):
    plt = _pyplot()
    return plt.Polygon(vertices, closed=True, facecolor="tab:red", alpha=0.12, edgecolor="tab:red",
                       lw=0.8, hatch="//", zorder=0)


def plot_model_runs(model, out: Path, runs: int = 20, seed: int = 0, bound_props=None) -> None:
    """Sample runs (corners of the initial box and random ones), coloured by mode: a phase plane
    (the pair of states the properties constrain together, else the first two states that are
    not clocks) and every state that is not a clock against time, axes in the model's units, the
    requirement bounds of ``bound_props`` that can be drawn on a panel shaded."""
    from matplotlib.patches import Patch

    from reach.plotting.axes import make_axis, parse_vars

    plt = _pyplot()
    rng = np.random.default_rng(seed)
    window = switch_window(model)
    Xs, taus = structured_plan(model, window, rng=rng)
    keep = rng.permutation(Xs.shape[0])[: max(1, runs // 2)]
    Xr, taur = random_plan(model, window, max(1, runs - keep.size), rng)
    X = np.concatenate([Xs[keep], Xr])
    tau = None if window is None else np.concatenate([taus[keep], taur])
    traj = Simulator(model).run(X, tau, record=True)
    names = list(model.modes)
    colours = {m: plt.cm.tab10(i % 10) for i, m in enumerate(names)}
    clocks = _clocks(model, traj)
    shown = [k for k in range(model.n) if k not in clocks] or [0]
    free = [model.state[k] for k in shown]
    plane_axes = parse_vars(model, None, bound_props or [])
    if {a.name for a in plane_axes} & {model.state[k] for k in clocks} and len(free) >= 2:
        plane_axes = (make_axis(model, free[0]), make_axis(model, free[1]))
    phase = len(free) >= 2
    time_axis = make_axis(model, "time")
    panels = ([plane_axes] if phase else []) + [(time_axis, make_axis(model, name)) for name in free]
    cols = 2
    rows = (len(panels) + 1 + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(11, 3.3 * rows), squeeze=False)
    flat = list(axes.flat)
    visited = set()
    for p, (ax_x, ax_y) in enumerate(panels):
        ax = flat[p]
        for t, modes, states in traj.path.values():
            labels = [names[int(m)] for m in modes]
            xs, ys = ax_x.values(model, t, labels, states), ax_y.values(model, t, labels, states)
            for m_index, name in enumerate(names):
                sel = modes == m_index
                if np.any(sel):
                    visited.add(name)
                    ax.plot(xs[sel], ys[sel], ".", ms=1, color=colours[name])
        ax.set_xlabel(ax_x.label)
        ax.set_ylabel(ax_y.label)
        ax.grid(True, alpha=0.25)
        drawn = _shade(ax, model, bound_props, (ax_x, ax_y), names)
        handles = [Patch(color=colours[m], label=m) for m in names if m in visited]
        if drawn:
            handles.append(Patch(facecolor="tab:red", alpha=0.25, hatch="//", edgecolor="tab:red",
                                 label="unsafe: " + ", ".join(drawn)))
        if p == 0 or drawn:
            ax.legend(handles=handles, loc="best", fontsize=7)
    flat[0].set_title(f"{model.name}: {len(traj.path)} runs" + (" (phase plane)" if phase else ""))
    info = flat[len(panels)]
    info.axis("off")
    clock_names = ", ".join(model.state[k] for k in sorted(clocks))
    info.text(0, 0.5, model.description + (f"\n(clock {clock_names}: not drawn)" if clock_names else ""),
              wrap=True, fontsize=9)
    for ax in flat[len(panels) + 1:]:
        ax.axis("off")
    _save(fig, out)
    plt.close(fig)


def passive_margins(model, bound_props, cells, abort_times) -> tuple[np.ndarray, str]:
    """Closest approach to the unsafe sets of the modes entered through the abort window, per
    cell (its centre) and abort time: ``(margins (cells, times), unit)``, from one simulated run
    each. The margin is the property's depth ``max_j g_j`` of each unsafe piece (the distance
    outside a box in its sup norm), the smallest over the run after the abort; a sampled
    picture of where margins are thin, not a bound."""
    from reach.plotting.axes import unit_of

    targets = {tr.target for tr in model.transitions if tr.window is not None}
    tests = [prop.violation(mode) for prop in bound_props or [] for mode in targets
             if getattr(prop, "kind", "") == "safety" and prop.pieces.get(mode)]
    tests = [t for t in tests if t is not None]
    margins = np.full((len(cells), len(abort_times)), np.nan)
    if not tests:
        return margins, ""
    centres = np.array([(low + high) / 2 for low, high, _ in cells])
    X = np.repeat(centres, len(abort_times), axis=0)
    tau = np.tile(np.asarray(abort_times, float), len(cells))
    traj = Simulator(model).run(X, tau, record=True)
    index = {name: k for k, name in enumerate(model.modes)}
    for run, (t, modes, states) in traj.path.items():
        after = np.isin(modes, [index[m] for m in targets])
        if np.any(after):
            depth = np.min([test(states[after])[1] for test in tests], axis=0)
            margins[run // len(abort_times), run % len(abort_times)] = float(np.min(depth))
    return margins, unit_of(model, model.state[0])[0]


def plot_abort_map(cells, times, window, out: Path, title: str, time_unit: str = "",
                   margins: np.ndarray | None = None, abort_times=None, margin_unit: str = "") -> None:
    """Fig. 5 of the rendezvous paper: initial cells coloured by the latest safe abort time, a
    colour of their own for cells safe for every abort in the window; with ``margins`` a second
    panel: the closest approach after the abort per cell and abort time (log scale)."""
    plt = _pyplot()
    import matplotlib.colors as mcolors
    from matplotlib.patches import Patch

    lo, hi = window
    norm = mcolors.Normalize(vmin=lo, vmax=hi)
    cmap = plt.cm.viridis
    panels = 2 if margins is not None else 1
    fig, axes = plt.subplots(1, panels, figsize=(6.8 * panels, 6), squeeze=False)
    ax = axes[0, 0]
    unit = f" [{time_unit}]" if time_unit else ""
    whole = 0
    for (low, high, _), t in zip(cells, times):
        if not np.isfinite(t):
            colour = "lightgrey"
        elif t >= hi - 1e-9 * max(1.0, abs(hi)):
            colour, whole = "tab:green", whole + 1
        else:
            colour = cmap(norm(t))
        ax.add_patch(plt.Rectangle((low[0], low[1]), high[0] - low[0], high[1] - low[1],
                                   facecolor=colour, edgecolor="k", lw=0.5))
    ax.plot([0], [0], "r*", ms=12)
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=10)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax,
                 label=f"latest safe abort time{unit} (below the window's end)")
    ax.legend(handles=[Patch(color="tab:green", label=f"safe for every abort in [{lo:g}, {hi:g}]{unit} "
                                                      f"({whole} of {len(cells)} cells)"),
                       Patch(color="lightgrey", label="no safe abort found"),
                       plt.Line2D([], [], color="r", marker="*", ls="", ms=10, label="target")],
              loc="lower left", fontsize=8)
    if margins is not None:
        ax = axes[0, 1]
        angles = [c[2] for c in cells]
        positive = margins[np.isfinite(margins) & (margins > 0)]
        vmin = float(positive.min()) if positive.size else 1e-3
        vmax = float(positive.max()) if positive.size else 1.0
        shown = np.where(np.isfinite(margins), np.maximum(margins, vmin), np.nan)
        image = ax.pcolormesh(angles, abort_times, shown.T, shading="nearest", cmap=plt.cm.magma,
                              norm=mcolors.LogNorm(vmin=vmin, vmax=max(vmax, vmin * 1.01)))
        fig.colorbar(image, ax=ax, label=f"closest approach to the unsafe set after the abort"
                                         f"{f' [{margin_unit}]' if margin_unit else ''} (log)")
        ax.set_xlabel("cell angle [deg]")
        ax.set_ylabel(f"abort time{unit}")
        ax.set_title("Passive safety margin per cell (centre run) and abort time\n"
                     "(blank: that run does not switch, e.g. the abort guard no longer holds)", fontsize=10)
    _save(fig, out)
    plt.close(fig)


def plot_timeline(runs, modes: list[str], out: Path, title: str = "", time_unit: str = "",
                  zoom: tuple[float, float] | None = None) -> None:
    """Mode against time as a step chart, one line per run.

    ``runs``: ``[(label, t, mode_names)]`` with the visit times ``t`` (ascending) and the mode
    name at each (as recorded by :meth:`reach.model.simulate.Simulator.run`); ``modes`` fixes
    the order of the y axis. With ``zoom = (t0, t1)`` a second panel repeats the chart on that
    stretch of time (short phases such as a transient vanish at mission scale).
    """
    plt = _pyplot()
    panels = 2 if zoom else 1
    fig, axes = plt.subplots(panels, 1, figsize=(11, 3.4 * panels), squeeze=False)
    level = {m: i for i, m in enumerate(modes)}
    for p in range(panels):
        ax = axes[p, 0]
        for k, (label, t, names) in enumerate(runs):
            t = np.asarray(t, dtype=float)
            y = np.array([level[m] for m in names], dtype=float) + 0.08 * (k - (len(runs) - 1) / 2)
            ax.step(t, y, where="post", lw=1.4, label=label)
        ax.set_yticks(range(len(modes)))
        ax.set_yticklabels(modes)
        ax.set_xlabel(f"time [{time_unit}]" if time_unit else "time")
        ax.grid(True, axis="x", alpha=0.3)
        if p == 1:
            ax.set_xlim(*zoom)
            ax.set_title(f"zoom: {zoom[0]:g} to {zoom[1]:g} {time_unit}", fontsize=10)
        elif title:
            ax.set_title(title)
    axes[0, 0].legend(loc="lower right", fontsize=8)
    _save(fig, out)
    plt.close(fig)


def plot_subdomain_map(subdomains, variables: list[str], prop: dict, out: Path, title: str = "",
                       scale: float = 1.0, unit: str = "") -> None:
    """Fig. 4 of the Taylor-ADS paper: the ADS subdomains of a 2-D initial box, coloured by the worst
    end of their bound of the event on a red-to-green scale centred on the requirement (green meets
    it with margin, red breaks it), hatched when the bound straddles the requirement (undecided).

    ``subdomains``: rows of a taylor result (``low``, ``high``, ``bound``); ``prop``: ``{"op": "<=",
    "value": 1.0, "label": "L"}``; coordinates are multiplied by ``scale`` (e.g. 1e-3 for km).
    """
    plt = _pyplot()
    import matplotlib.colors as mcolors

    op, value = prop["op"], float(prop["value"])
    worst = np.array([r["bound"][1] if op == "<=" else r["bound"][0] for r in subdomains], dtype=float)
    finite = worst[np.isfinite(worst)]
    spread = float(np.max(np.abs(finite - value))) if finite.size else 1.0
    spread = spread if spread > 0 else 1.0
    norm = mcolors.TwoSlopeNorm(vcenter=value, vmin=value - spread, vmax=value + spread)
    cmap = plt.cm.RdYlGn_r if op == "<=" else plt.cm.RdYlGn
    fig, ax = plt.subplots(figsize=(7.5, 6))
    area = sum(np.prod(np.subtract(r["high"], r["low"])) for r in subdomains)
    shares = {"safe": 0.0, "unsafe": 0.0, "undecided": 0.0}
    for r, w in zip(subdomains, worst):
        lo, hi = r["bound"]
        safe = hi <= value if op == "<=" else lo >= value
        unsafe = lo > value if op == "<=" else hi < value
        kind = "safe" if safe else "unsafe" if unsafe else "undecided"
        shares[kind] += np.prod(np.subtract(r["high"], r["low"])) / area
        (x0, y0), (x1, y1) = np.multiply(r["low"], scale), np.multiply(r["high"], scale)
        colour = cmap(norm(w)) if np.isfinite(w) else "lightgrey"
        ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=colour, edgecolor="k", lw=0.6,
                                   hatch="///" if kind == "undecided" else None))
    ax.autoscale_view()
    ax.set_xlabel(f"{variables[0]} [{unit}]" if unit else variables[0])
    ax.set_ylabel(f"{variables[1]} [{unit}]" if unit else variables[1])
    label = prop.get("label", "event")
    ax.set_title(title or f"{len(subdomains)} subdomains: {100 * shares['safe']:.1f} % safe, "
                          f"{100 * shares['unsafe']:.1f} % unsafe, {100 * shares['undecided']:.1f} % undecided "
                          f"(hatched)", fontsize=10)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax,
                 label=f"worst bound of {label} on the subdomain (requirement {op} {value:g})")
    _save(fig, out)
    plt.close(fig)


def plot_proved_map(subdomains, colours, proved_boxes, attempts, out: Path, title: str = "",
                    zooms=(), unit: str = "m") -> None:
    """Fig. 4 with proved colours: the subdomains' outlines, each filled by what is proved of it
    (reach/bench/proved_map.py: proved safe, proved unsafe, undecided), the proved-safe boxes as
    filled patches (ringed, since a box of a few m^2 vanishes at the map's scale), and the boxes
    whose proof was attempted and not finished outlined in blue (solid: a subdomain, dashed: another
    box) with the flight time the flowpipe reached (on the main panel only where it fits).

    ``subdomains``: ``(low, high)`` pairs; ``colours``: one colour name per subdomain;
    ``proved_boxes``: ``(low, high)`` pairs; ``attempts``: ``{"low", "high", "label", "dashed"}`` per
    attempted box left undecided; ``zooms``: ``(low, high)`` windows drawn again in side panels."""
    plt = _pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from reach.bench.proved_map import PROVED_SAFE, PROVED_UNSAFE, UNDECIDED

    fill = {PROVED_SAFE: "tab:green", PROVED_UNSAFE: "tab:red", UNDECIDED: "0.92"}
    panels = len(zooms)
    fig = plt.figure(figsize=(6.5 + (3.5 if panels else 0), 9.5))
    grid = fig.add_gridspec(max(panels, 1), 2 if panels else 1, width_ratios=[1.6, 1] if panels else [1])
    main = fig.add_subplot(grid[:, 0])
    axes = [main] + [fig.add_subplot(grid[k, 1]) for k in range(panels)]
    windows = [None] + list(zooms)
    map_width = max(h[0] for _, h in subdomains) - min(lo[0] for lo, _ in subdomains)
    for ax, window in zip(axes, windows):
        for (low, high), name in zip(subdomains, colours):
            ax.add_patch(plt.Rectangle(low, high[0] - low[0], high[1] - low[1], facecolor=fill[name],
                                       edgecolor="0.35", lw=0.4))
        for low, high in proved_boxes:
            ax.add_patch(plt.Rectangle(low, high[0] - low[0], high[1] - low[1], facecolor=fill[PROVED_SAFE],
                                       edgecolor="darkgreen", lw=0.8))
        width = map_width if window is None else window[1][0] - window[0][0]
        for a in attempts:
            (x0, y0), (x1, y1) = a["low"], a["high"]
            ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, edgecolor="tab:blue",
                                       lw=1.2 if a["dashed"] else 1.6, ls="--" if a["dashed"] else "-"))
            # subdomains: in the upper half, clear of the rings, upright in tall ones; other boxes:
            # to the right of the box
            if a["dashed"]:
                x, y, place = x1, 0.5 * (y0 + y1), {"ha": "left", "va": "center"}
            else:
                x, y = 0.5 * (x0 + x1), y1 - 0.25 * (y1 - y0)
                place = {"ha": "center", "va": "center", "rotation": 90 if y1 - y0 > 2 * (x1 - x0) else 0}
            shown = window is None or (window[0][0] <= x <= window[1][0] and window[0][1] <= y <= window[1][1])
            if shown and x1 - x0 >= 0.04 * width:
                ax.text(x, y, a["label"], fontsize=6, color="tab:blue", **place)
        ax.set_aspect("equal")
    if proved_boxes:
        centres = np.array([0.5 * (np.asarray(lo) + np.asarray(hi)) for lo, hi in proved_boxes])
        main.scatter(centres[:, 0], centres[:, 1], s=90, facecolors="none", edgecolors="darkgreen", lw=1.4)
    main.autoscale_view()
    main.set_xlabel(f"x [{unit}]")
    main.set_ylabel(f"y [{unit}]")
    fig.suptitle(title, fontsize=9)
    count = {name: colours.count(name) for name in fill}
    main.legend(handles=[
        Patch(facecolor=fill[PROVED_SAFE], edgecolor="0.35", label=f"proved safe ({count[PROVED_SAFE]} subdomains)"),
        Patch(facecolor=fill[PROVED_UNSAFE], edgecolor="0.35",
              label=f"proved unsafe ({count[PROVED_UNSAFE]} subdomains)"),
        Patch(facecolor=fill[UNDECIDED], edgecolor="0.35", label=f"undecided ({count[UNDECIDED]} subdomains)"),
        Line2D([], [], marker="o", ls="", markerfacecolor=fill[PROVED_SAFE], markeredgecolor="darkgreen",
               ms=9, label=f"proved-safe box ({len(proved_boxes)}; ringed)"),
        Patch(fill=False, edgecolor="tab:blue", lw=1.6, label="subdomain attempted, not proved (flight time reached)"),
        Patch(fill=False, edgecolor="tab:blue", lw=1.2, ls="--", label="other box attempted, not proved"),
    ], loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=2, fontsize=7)
    for ax, (low, high) in zip(axes[1:], zooms):
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_title(f"zoom: x {low[0]:g}..{high[0]:g}, y {low[1]:g}..{high[1]:g} {unit}", fontsize=8)
        ax.tick_params(labelsize=7)
    _save(fig, out)
    plt.close(fig)
