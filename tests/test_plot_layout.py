"""The picture of ``reach plot`` read back through matplotlib's objects: the title (model, axes and
one line of verdicts per back-end, however long) renders inside the figure; the legend lies
outside the axes, so over none of the drawn sets; each legend entry looks like the collection it
names (same face and edge colours, alpha included).

The sets are made by hand (boxes drawn as star or taylor sets, sampled runs as montecarlo's) for
a model with 1, 4 or 9 modes and properties with long names, so no back-end runs."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.transforms import Bbox

from reach.model import load_model
from reach.plotting.axes import make_axis
from reach.plotting.reach_sets import plot_reach_sets, pyplot
from reach.result import Result, SetPiece, Status
from reach.spec import bind, load_properties

NAMES = ("x", "y")


def write_model(tmp_path, k: int):
    modes = "\n".join(f"  m{i}: {{flow: {{x: \"1\", y: \"0.5\"}}}}" for i in range(k))
    (tmp_path / "many.yaml").write_text(
        f"name: many_modes\nstate: [x, y]\nmodes:\n{modes}\n"
        "initial: {mode: m0, box: {x: [0, 0.1], y: [0, 0.1]}}\nhorizon: 1\n")
    every = ", ".join(f"m{i}" for i in range(k))
    props = "\n".join(
        f"  - {{id: requirement_{j}_with_a_rather_long_identifier, kind: safety, modes: [{every}], "
        f"require: [\"y <= {k + 2 + j}\"]}}" for j in range(6))
    (tmp_path / "props.yaml").write_text(f"properties:\n{props}\n")
    model = load_model(tmp_path / "many.yaml")
    bound = [bind(p, model) for p in load_properties(tmp_path / "props.yaml")]
    return model, bound


def boxes(k: int) -> list:
    """Per mode, a band of boxes across the whole x range (so data fill the axes' corners)."""
    out = []
    for i in range(k):
        for s in np.linspace(0, 9, 10):
            low = np.array([s, 0.9 * i + 0.1 * s])
            out.append(SetPiece(f"m{i}", s, s + 1, "box", NAMES, low=low, high=low + [1.0, 1.2]))
    return out


def runs(k: int) -> list:
    out = []
    for i in range(k):
        for j in range(3):
            t = np.linspace(0, 10, 30)
            pts = np.stack([t, 0.9 * i + 0.1 * t + 0.2 + 0.3 * j], axis=1)
            out.append(SetPiece(f"m{i}", 0.0, 10.0, "run", NAMES, times=t, points=pts))
    return out


def results(model, bound, k: int, backends) -> dict:
    statuses = [Status.UNKNOWN, Status.UNSAFE, Status.SAFE, Status.UNSUPPORTED]
    out = {}
    for b in backends:
        sets = runs(k) if b == "montecarlo" else boxes(k)
        out[b] = [Result(b, model.name, p.id, statuses[n % 4], sets=sets if n == 0 else [])
                  for n, p in enumerate(bound)]
    return out


@pytest.fixture
def kept(monkeypatch):
    """The figure ``plot_reach_sets`` saves, kept open (its ``plt.close`` does nothing)."""
    plt = pyplot()
    close = plt.close
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figures.append(fig))
    yield figures
    for fig in figures:
        close(fig)


def drawn_figure(tmp_path, kept, k, backends, title=None):
    model, bound = write_model(tmp_path, k)
    out = tmp_path / "pic.png"
    plot_reach_sets(model, results(model, bound, k, backends), bound, (make_axis(model, "x"), make_axis(model, "y")),
                    out, title=title)
    assert out.stat().st_size > 10_000
    (fig,) = kept
    fig.canvas.draw()                   # the layout saved (the figure's layout engine runs again)
    return fig, fig.axes[0], fig.canvas.get_renderer()


def inside(inner, outer, slack: float = 0.5) -> bool:
    return (inner.x0 >= outer.x0 - slack and inner.x1 <= outer.x1 + slack
            and inner.y0 >= outer.y0 - slack and inner.y1 <= outer.y1 + slack)


CASES = [(1, ("star", "montecarlo")), (4, ("star", "montecarlo")), (9, ("star", "taylor", "montecarlo"))]


@pytest.mark.parametrize("k, backends", CASES)
def test_title_with_long_verdicts_renders_inside_the_figure(tmp_path, kept, k, backends):
    fig, ax, renderer = drawn_figure(tmp_path, kept, k, backends)
    title = ax.title
    assert "requirement_5_with_a_rather_long_identifier" in title.get_text().replace("\n", " ")
    assert inside(title.get_window_extent(renderer), fig.bbox)
    assert title.get_window_extent(renderer).y0 >= ax.bbox.y1 - 0.5         # above the axes


def test_an_unbreakable_title_shrinks_to_fit(tmp_path, kept):
    fig, ax, renderer = drawn_figure(tmp_path, kept, 2, ("star",), title="many_modes:" + "_x" * 150)
    assert ax.title.get_fontsize() < 9
    assert inside(ax.title.get_window_extent(renderer), fig.bbox)


@pytest.mark.parametrize("k, backends", CASES)
def test_legend_lies_outside_the_axes_over_no_drawn_set(tmp_path, kept, k, backends):
    fig, ax, renderer = drawn_figure(tmp_path, kept, k, backends)
    legend = ax.get_legend()
    box = legend.get_window_extent(renderer)
    assert inside(box, fig.bbox), (box, fig.bbox)                          # visible, all of it
    assert box.y1 <= ax.bbox.y0 or box.x1 <= ax.bbox.x0 or box.x0 >= ax.bbox.x1 or box.y0 >= ax.bbox.y1
    assert box.y1 <= ax.xaxis.get_tightbbox(renderer).y0 + 0.5             # below the x label
    drawn = [c for c in ax.collections if c.get_gid()]
    assert len(drawn) == k * len(backends)
    for coll in drawn:
        extent = Bbox.union([coll.get_transform().transform_path(p).get_extents() for p in coll.get_paths()])
        assert inside(extent, ax.bbox, slack=2.0)            # the data are in view ...
        assert not box.overlaps(extent), coll.get_gid()      # ... and not under the legend
    assert ax.bbox.height >= 4.0 * fig.dpi                                  # the legend did not squeeze the axes


def look(artist) -> tuple:
    """``(kind, face or None, edge)`` as RGBA, alpha included: how a collection or a legend handle
    appears (a face of alpha 0 is none)."""
    if isinstance(artist, (matplotlib.collections.LineCollection, matplotlib.lines.Line2D)):
        colour = (artist.get_edgecolor()[0] if isinstance(artist, matplotlib.collections.Collection)
                  else to_rgba(artist.get_color(), artist.get_alpha()))
        return "line", None, tuple(np.round(colour, 3))
    if isinstance(artist, matplotlib.collections.Collection):
        face, edge = artist.get_facecolor(), artist.get_edgecolor()[0]
        face = face[0] if len(face) else (0, 0, 0, 0)
    else:
        face, edge = artist.get_facecolor(), artist.get_edgecolor()
    return "area", None if face[3] == 0 else tuple(np.round(face, 3)), tuple(np.round(edge, 3))


SETS = ("flowpipe segments", "step enclosures", "sampled runs")


@pytest.mark.parametrize("k, backends", CASES)
def test_each_legend_entry_looks_like_what_is_drawn(tmp_path, kept, k, backends):
    """Every legend entry of sets has the look of a drawn collection, and the reverse; the entry
    naming mode m and back-end b looks like b's collection of mode m; the requirement entry
    looks like the shaded requirement."""
    fig, ax, renderer = drawn_figure(tmp_path, kept, k, backends)
    legend = ax.get_legend()
    entries = {t.get_text(): h for t, h in zip(legend.get_texts(), legend.legend_handles)}
    of_sets = {text: h for text, h in entries.items() if any(w in text.replace("\n", " ") for w in SETS)}
    drawn = [c for c in ax.collections if isinstance(c, matplotlib.collections.Collection)]
    assert len(of_sets) == len(drawn) == k * len(backends)
    assert {look(h) for h in of_sets.values()} == {look(c) for c in drawn}
    for coll in drawn:
        backend, mode = coll.get_gid().split(":")
        (handle,) = [h for text, h in of_sets.items() if text.startswith(f"mode {mode}: {backend}")]
        assert look(handle) == look(coll)
    assert len({look(c)[2][:3] for c in drawn if c.get_gid().startswith("star:")}) == k   # a colour per mode
    (unsafe,) = [h for text, h in entries.items() if text.startswith("unsafe")]
    shaded = [p for p in ax.patches if isinstance(p, matplotlib.patches.Polygon)]
    assert shaded and all(look(p) == look(unsafe) and p.get_hatch() == unsafe.get_hatch() for p in shaded)
