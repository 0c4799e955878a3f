"""Plots people would rather look at than read: sample runs per mode."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from reach.backends.montecarlo import random_plan, structured_plan, switch_window
from reach.model.simulate import Simulator


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_model_runs(model, out: Path, runs: int = 20, seed: int = 0) -> None:
    """Sample runs (corners of the initial box and random ones): the first two states against
    each other (the only state against time), and every state against time, coloured by mode."""
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
    n = model.n
    fig, axes = plt.subplots(1 + (n + 1) // 2, 2, figsize=(11, 3.2 * (1 + (n + 1) // 2)))
    axes = np.atleast_2d(axes)
    plane = axes[0, 0]
    for i, (t, modes, states) in traj.path.items():
        for m_index, name in enumerate(names):
            sel = modes == m_index
            if not np.any(sel):
                continue
            across = states[sel, 1] if n > 1 else t[sel]          # one state: against time
            plane.plot(states[sel, 0], across, ".", ms=1, color=colours[name])
            for k in range(n):
                ax = axes[1 + k // 2, k % 2]
                ax.plot(t[sel], states[sel, k], ".", ms=1, color=colours[name])
    plane.set_xlabel(model.state[0])
    plane.set_ylabel(model.state[1] if n > 1 else f"time [{model.units.time}]")
    plane.set_title(f"{model.name}: {len(traj.path)} runs")
    for name in names:
        plane.plot([], [], "-", color=colours[name], label=name)
    plane.legend(loc="best", fontsize=8)
    axes[0, 1].axis("off")
    axes[0, 1].text(0, 0.5, model.description, wrap=True, fontsize=9)
    for k in range(n):
        ax = axes[1 + k // 2, k % 2]
        ax.set_ylabel(model.state[k])
        ax.set_xlabel(f"time [{model.units.time}]")
    for k in range(n, 2 * ((n + 1) // 2)):
        axes[1 + k // 2, k % 2].axis("off")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_abort_map(cells, times, window, out: Path, title: str) -> None:
    """Fig. 5 of the rendezvous paper: initial cells coloured by the latest safe abort time."""
    plt = _pyplot()
    import matplotlib.colors as mcolors

    lo, hi = window
    norm = mcolors.Normalize(vmin=lo, vmax=hi)
    cmap = plt.cm.viridis
    fig, ax = plt.subplots(figsize=(6.5, 6))
    for (low, high, _), t in zip(cells, times):
        colour = "lightgrey" if not np.isfinite(t) else cmap(norm(t))
        ax.add_patch(plt.Rectangle((low[0], low[1]), high[0] - low[0], high[1] - low[1],
                                   facecolor=colour, edgecolor="k", lw=0.5))
    ax.plot([0], [0], "r*", ms=12, label="target")
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, label="latest safe abort time")
    ax.legend(loc="lower left")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
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
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
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
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
