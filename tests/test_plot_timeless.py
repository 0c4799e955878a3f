"""``reach plot`` of a mode where no time passes, and of sets cut at the horizon, read back through
matplotlib's objects.

The model: in ``rise`` (``x' = 1, y' = x - y``) from ``x0 in [0, 0.5]``, ``y = 0`` a run jumps at
``x = 2`` (``y := y + 1``) into ``jump`` (``flow: false``), which it leaves at once
(``y := y / 2``) into ``fall`` (``x' = -1``) and back to ``rise`` at ``x = 0``. So the states in
``jump`` exist at the instants ``2 - x0 + 4 k`` only, at ``x = 2``; at the first ones
``y = 2 + (t - 1) exp(-t)`` (closed form). Star and Monte Carlo run on it for real; star's last
segments run past the horizon (a step from states entered over half a time unit), so the cut
at the horizon is tested on them, and on hand-made sets whose exact points are known."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.colors import to_rgb, to_rgba
from matplotlib.lines import Line2D
from matplotlib.path import Path

from model_files import load_files
from reach.checking import check_model, resolve_backend
from reach.plotting.reach_sets import pyplot
from reach.result import Result, SetPiece, Status
from reach.sets import Box, Star

MODEL = """
name: kick
state: [x, y]
modes:
  rise:
    flow: {x: "1", y: "x - y"}
    invariant: ["x <= 2"]
  jump: {flow: false}
  fall:
    flow: {x: "-1", y: "x - y"}
    invariant: ["x >= 0"]
transitions:
  - {from: rise, to: jump, guard: ["x >= 2"], urgent: true, reset: {y: "y + 1"}}
  - {from: jump, to: fall, urgent: true, reset: {y: "0.5*y"}}
  - {from: fall, to: rise, guard: ["x <= 0"], urgent: true}
initial: {mode: rise, box: {x: [0, 0.5], y: 0}}
horizon: 10
"""
PROPERTIES = """
properties:
  - {id: low, kind: safety, modes: [rise, jump, fall], require: ["y <= 2.5"]}
"""
HORIZON = 10.0
PERIOD = 4.0                 # rise 2 - x0, jump, fall 2, rise x0 again: jumps every 4 time units
WINDOW = (1.5, 2.0)          # the jump instants 2 - x0 modulo the period
ROUNDING = 1e-7             # how far a drawn time may pass 0 or the horizon (a back-end's clock rounding)
SAMPLED = {"keep_sets": True, "samples": 40, "optimise": False, "search_rounds": 0}


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    """``(model, bound properties, {backend: results})`` of star and montecarlo on the model."""
    model, props = load_files(tmp_path_factory.mktemp("kick"), MODEL, PROPERTIES)
    bound = list(props.values())
    results = {"star": check_model(resolve_backend("star"), model, bound, {"keep_sets": True}),
               "montecarlo": check_model(resolve_backend("montecarlo"), model, bound, SAMPLED)}
    assert results["star"][0].status == Status.SAFE
    return model, bound, results


def artists(ax) -> dict:
    """The artists of sets by their gid ``backend:mode``."""
    return {a.get_gid(): a for a in [*ax.collections, *ax.lines] if a.get_gid()}


def points(line: Line2D) -> np.ndarray:
    """A line's points (rows), the NaN rows between its pieces left out."""
    xy = np.asarray(line.get_xydata(), dtype=float)
    return xy[~np.isnan(xy).any(axis=1)]


def pieces(line: Line2D) -> list[np.ndarray]:
    """A line's pieces: its points split at the NaN rows."""
    xy = np.asarray(line.get_xydata(), dtype=float)
    chunks = np.split(xy, np.flatnonzero(np.isnan(xy).any(axis=1)))
    chunks = [c[~np.isnan(c).any(axis=1)] for c in chunks]
    return [c for c in chunks if len(c)]


def legend_handle(ax, starts: str):
    legend = ax.get_legend()
    (handle,) = [h for t, h in zip(legend.get_texts(), legend.legend_handles)
                 if t.get_text().replace("\n", " ").startswith(starts)]
    return handle


def look(line: Line2D) -> tuple:
    """How a line appears: colour (alpha included), line style and width, marker and its size."""
    return (tuple(np.round(to_rgba(line.get_color(), line.get_alpha()), 3)), line.get_linestyle(),
            line.get_linewidth(), line.get_marker(), line.get_markersize())


def at_jump_instants(t, tol: float = 1e-6) -> np.ndarray:
    phase = np.asarray(t) % PERIOD
    return (phase >= WINDOW[0] - tol) & (phase <= WINDOW[1] + tol)


def test_states_where_no_time_passes_are_drawn_at_the_jump_instants(checked, draw):
    """Against time: star's sets and the sampled states in ``jump`` are lines with markers in the
    mode's colour (a shade of it for the runs), at the jump instants of every period, the first
    sampled ones at the closed form; star's sets hold every sampled state; the legend entries
    look like them."""
    model, bound, results = checked
    ax, _ = draw(model, bound, results, "t", "y")
    drawn = artists(ax)
    star, sampled = drawn["star:jump"], drawn["montecarlo:jump"]
    for line in (star, sampled):
        assert isinstance(line, Line2D) and line.get_visible()
        assert line.get_marker() not in ("", " ", "None", "none", None) and line.get_markersize() >= 3
    jump = np.array(to_rgb(pyplot().cm.tab10(list(model.modes).index("jump"))))
    assert np.allclose(to_rgb(star.get_color()), jump)
    assert np.allclose(np.cross(to_rgb(sampled.get_color()), jump), 0, atol=1e-9)   # a shade of it

    states = points(sampled)
    visits = [p for p in results["montecarlo"][0].sets if p.mode == "jump"]
    assert len(states) == len(visits) >= 2 * SAMPLED["samples"]
    assert at_jump_instants(states[:, 0]).all()
    first = states[states[:, 0] < PERIOD]
    assert len(first) >= SAMPLED["samples"] / 2
    assert np.allclose(first[:, 1], 2 + (first[:, 0] - 1) * np.exp(-first[:, 0]), atol=1e-6)

    outlines = pieces(star)
    assert {int(t // PERIOD) for p in outlines for t in p[:, 0]} == {0, 1, 2}     # three periods to 10
    assert all(at_jump_instants(p[:, 0]).all() for p in outlines)
    boxes = [(p.min(axis=0) - 1e-6, p.max(axis=0) + 1e-6) for p in outlines]
    assert all(any(np.all(lo <= s) and np.all(s <= hi) for lo, hi in boxes) for s in states)

    assert look(legend_handle(ax, "mode jump: star")) == look(star)
    assert look(legend_handle(ax, "mode jump: montecarlo")) == look(sampled)


def test_states_where_no_time_passes_in_the_state_plane(checked, draw):
    """Against x: the states in ``jump`` are drawn at x = 2 (the guard), y from 2.11 to 2.24
    (the jump's y + 1 over the three periods), within the view."""
    model, bound, results = checked
    ax, _ = draw(model, bound, results, "x", "y")
    drawn = artists(ax)
    x0, x1 = ax.get_xlim()
    for gid in ("star:jump", "montecarlo:jump"):
        xy = points(drawn[gid])
        assert len(xy) and np.allclose(xy[:, 0], 2.0, atol=1e-6), gid
        assert np.all((xy[:, 1] > 2.11) & (xy[:, 1] < 2.24)), gid
        assert x0 < 2.0 < x1


def drawn_x(ax) -> np.ndarray:
    """Every time value drawn by a set's artist (the x-data of collections and lines)."""
    out = []
    for gid, artist in artists(ax).items():
        if isinstance(artist, Line2D):
            out.append(points(artist)[:, 0])
        else:
            out += [p.vertices[:, 0] for p in artist.get_paths()]
    return np.concatenate(out)


def test_star_segments_past_the_horizon_are_cut_there_and_hold_the_runs(checked, draw):
    """Star's last segments reach a third of a time unit past the horizon; drawn, no set goes
    past it, the sets still reach it, and every sampled state up to it lies in star's drawn
    polygons of its mode (the cut polygons still hold what is reached)."""
    model, bound, results = checked
    assert max(p.t1 for p in results["star"][0].sets) > HORIZON + 0.1        # the segments' clocks
    ax, _ = draw(model, bound, results, "t", "y")
    x = drawn_x(ax)
    assert x.min() >= -ROUNDING and x.max() <= HORIZON + ROUNDING
    drawn = artists(ax)
    assert max(p.vertices[:, 0].max() for p in drawn["star:fall"].get_paths()) >= HORIZON - 1e-6
    for mode in ("rise", "fall"):
        runs = [run.path("time", "y") for run in results["montecarlo"][0].sets if run.mode == mode]
        late = np.vstack(runs)
        late = late[late[:, 0] >= HORIZON - 0.5]
        held = np.zeros(len(late), dtype=bool)
        for polygon in drawn[f"star:{mode}"].get_paths():
            held |= within(Path(polygon.vertices), late, 2e-6)
        assert len(late) and held.all(), (mode, late[~held])


def within(polygon: Path, points: np.ndarray, tol: float) -> np.ndarray:
    """Which ``points`` lie in ``polygon`` or within ``tol`` of it (either orientation)."""
    return polygon.contains_points(points, radius=tol) | polygon.contains_points(points, radius=-tol)


def test_sets_past_the_horizon_are_cut_to_it_and_keep_every_state_before(tmp_path, draw):
    """A star over ``(x, y, time)`` whose time runs from 9.3 to 10.3, and a box dated [9.9, 10.4]:
    drawn against time, both end at the horizon 10 and hold every point reached by then (the
    star's, exactly: ``time = 9.8 + a/2``, ``y = 1 + a + 0.3 b`` over ``a, b in [-1, 1]``)."""
    model, props = load_files(tmp_path, MODEL, PROPERTIES)
    star = Star([0.0, 1.0, 9.8], [[0.0, 1.0], [1.0, 0.3], [0.5, 0.0]], box=Box(-np.ones(2), np.ones(2)))
    segment = SetPiece("fall", 9.3, 10.3, "star", ("x", "y", "time"), (star,))
    box = SetPiece("rise", 9.9, 10.4, "box", ("x", "y"), low=np.array([0.0, 0.5]), high=np.array([1.0, 0.8]))
    results = {"star": [Result("star", model.name, "low", Status.SAFE, sets=[segment])],
               "taylor": [Result("taylor", model.name, "low", Status.SAFE, sets=[box])]}
    ax, _ = draw(model, list(props.values()), results, "t", "y")
    drawn = artists(ax)
    (cut,) = [p.vertices for p in drawn["star:fall"].get_paths()]
    (rect,) = [p.vertices for p in drawn["taylor:rise"].get_paths()]
    for polygon in (cut, rect):
        assert polygon[:, 0].max() == pytest.approx(HORIZON, abs=ROUNDING)
    assert rect[:, 0].min() == pytest.approx(9.9) and (rect[:, 1].min(), rect[:, 1].max()) == pytest.approx((0.5, 0.8))
    a, b = np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-1, 1, 41))
    time, y = 9.8 + 0.5 * a.ravel(), 1 + a.ravel() + 0.3 * b.ravel()
    reached = np.stack([time, y], axis=1)[time <= HORIZON]
    assert reached[:, 0].max() == pytest.approx(HORIZON)                   # the grid meets the cut
    inside = within(Path(cut), reached, 1e-9)
    assert inside.all(), reached[~inside]
