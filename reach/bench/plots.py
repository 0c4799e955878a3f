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
    each other, and every state against time, coloured by mode."""
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
            plane.plot(states[sel, 0], states[sel, 1], ".", ms=1, color=colours[name])
            for k in range(n):
                ax = axes[1 + k // 2, k % 2]
                ax.plot(t[sel], states[sel, k], ".", ms=1, color=colours[name])
    plane.set_xlabel(model.state[0])
    plane.set_ylabel(model.state[1])
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
