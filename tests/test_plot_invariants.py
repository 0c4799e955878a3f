"""``reach plot`` of a model with invariants, a clock state and a requirement in one mode, read back
through matplotlib's objects.

The model: a cart rolls toward a bumper at ``x = 0`` (``inbound``), bounces (``v := -v/2``) into
``rebound`` and bounces there again; both modes keep ``x >= 0``, and the state ``t`` is a global
clock (rate 1, 0 at the start, never reset). Star runs on it for real: its pieces drawn from
coefficient-box bounds (past the LP budget, or ``--fast``) ignore their predicates, which hold the
invariant, and reach far below ``x = 0``; its last segments run past the horizon on the clock
``t``. The unsafe set ``x > 0.9`` applies in ``rebound`` only."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.path import Path
from matplotlib.patches import Polygon

from model_files import load_files
from reach.checking import check_model, resolve_backend
from reach.result import Result, SetPiece, Status

MODEL = """
name: bumper
state: [x, v, t]
modes:
  inbound:
    flow: {x: v, v: "-0.01", t: 1}
    invariant: ["x >= 0"]
  rebound:
    flow: {x: v, v: "-0.01", t: 1}
    invariant: ["x >= 0"]
transitions:
  - {from: inbound, to: rebound, guard: ["x <= 0", "v <= 0"], urgent: true, reset: {v: "-0.5*v"}}
  - {from: rebound, to: rebound, guard: ["x <= 0", "v <= 0"], urgent: true, reset: {v: "-0.5*v"}}
initial: {mode: inbound, box: {x: [1.0, 1.2], v: [-0.2, -0.1], t: 0}}
horizon: 14
"""
PROPERTIES = """
properties:
  - {id: apex, kind: safety, modes: [rebound], require: ["x <= 0.9"]}
  - {id: approach, kind: safety, modes: [inbound, rebound], require: ["v >= -0.3"]}
"""
HORIZON = 14.0
FIRST_BOUNCE = (4.45, 8.5)    # the runs reach x = 0 between these times (x0 / |v0| with the pull)
ROUNDING = 1e-7
SAMPLED = {"keep_sets": True, "samples": 40, "optimise": False, "search_rounds": 0}


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    """``(model, bound properties, {backend: results})`` of star and montecarlo on ``apex``."""
    model, props = load_files(tmp_path_factory.mktemp("bumper"), MODEL, PROPERTIES)
    bound = [props["apex"]]
    results = {"star": check_model(resolve_backend("star"), model, bound, {"keep_sets": True}),
               "montecarlo": check_model(resolve_backend("montecarlo"), model, bound, SAMPLED)}
    return model, bound, results


def polygons(ax, gid: str) -> list[np.ndarray]:
    """The vertices of each polygon of the collection with ``gid``."""
    (coll,) = [c for c in ax.collections if c.get_gid() == gid]
    return [p.vertices for p in coll.get_paths()]


def held(polygons_, points: np.ndarray, tol: float) -> np.ndarray:
    """Which ``points`` lie in one of ``polygons_`` or within ``tol`` of it."""
    out = np.zeros(len(points), dtype=bool)
    for vertices in polygons_:
        path = Path(vertices)
        out |= path.contains_points(points, radius=tol) | path.contains_points(points, radius=-tol)
    return out


@pytest.mark.parametrize("exact", [True, False])
def test_star_sets_stay_in_the_invariant_and_the_horizon_and_hold_the_runs(checked, draw, exact):
    """Star's pieces drawn from their coefficient boxes reach far below the invariant ``x >= 0``
    and past the horizon on the clock ``t``; drawn (with LPs as far as the budget goes, and
    without, ``--fast``), no polygon does, the sets still reach both bounds, and every sampled
    state lies in star's polygons of its mode."""
    model, bound, results = checked
    pieces = results["star"][0].sets
    boxes = [p.polygon("t", "x", exact=False) for p in pieces]
    assert min(b[:, 1].min() for b in boxes if len(b)) < -0.1                  # what a box draws
    assert max(p.t1 for p in pieces) > HORIZON + 0.1
    ax, _ = draw(model, bound, results, "t", "x", exact)
    for mode in ("inbound", "rebound"):
        drawn = polygons(ax, f"star:{mode}")
        every = np.vstack(drawn)
        assert every[:, 1].min() >= -ROUNDING and every[:, 1].min() <= 1e-6, mode
        assert every[:, 0].min() >= -ROUNDING and every[:, 0].max() <= HORIZON + ROUNDING, mode
        runs = np.vstack([run.path("t", "x") for run in results["montecarlo"][0].sets if run.mode == mode])
        inside = held(drawn, runs, 1e-6)
        assert inside.all(), (mode, runs[~inside][:5])
    assert np.vstack(polygons(ax, "star:rebound"))[:, 0].max() >= HORIZON - 1e-6


def test_a_clock_that_is_reset_is_not_cut_at_the_horizon(tmp_path, draw):
    """A state ``t`` that a transition resets is no measure of time: a box dated past the
    horizon keeps its extent along it; the same box against the global clock ``t`` is cut."""
    first = 'reset: {v: "-0.5*v"}}\n  - {from: rebound'
    reset = MODEL.replace(first, first.replace("}}", ", t: 0}}"))
    for text, top in ((MODEL, HORIZON), (reset, HORIZON + 1.0)):
        model, props = load_files(tmp_path, text, PROPERTIES)
        box = SetPiece("rebound", 13.0, 15.0, "box", ("x", "v", "t"), low=np.array([0.2, 0.0, 13.0]),
                       high=np.array([0.4, 0.1, 15.0]))
        results = {"taylor": [Result("taylor", model.name, "apex", Status.SAFE, sets=[box])]}
        ax, _ = draw(model, [props["apex"]], results, "t", "x")
        (rect,) = polygons(ax, "taylor:rebound")
        assert rect[:, 0].max() == pytest.approx(top, abs=ROUNDING)


def unsafe_patches(ax, gid: str) -> list[np.ndarray]:
    return [p.get_xy() for p in ax.patches if isinstance(p, Polygon) and p.get_gid() == gid]


def legend_texts(ax) -> list[str]:
    return [t.get_text().replace("\n", " ") for t in ax.get_legend().get_texts()]


def test_a_requirement_of_one_mode_is_shaded_only_while_sets_are_in_it(checked, draw):
    """Against time, ``x > 0.9`` of ``rebound`` is shaded from the first time a drawn set is in
    ``rebound`` (the first bounce) to the horizon, not over the start, where every run is
    ``inbound``; its legend entry says it applies in ``rebound`` only."""
    model, bound, results = checked
    ax, _ = draw(model, bound, results, "t", "x", exact=False)
    shaded = unsafe_patches(ax, "unsafe:rebound")
    assert shaded
    rebound = np.vstack(polygons(ax, "star:rebound") + [run.path("t", "x") for run in results["montecarlo"][0].sets
                                                         if run.mode == "rebound"])
    first = rebound[:, 0].min()
    assert FIRST_BOUNCE[0] - 0.5 < first < FIRST_BOUNCE[1]
    start = min(p[:, 0].min() for p in shaded)
    end = max(p[:, 0].max() for p in shaded)
    assert start == pytest.approx(first, abs=1e-6) and end == pytest.approx(HORIZON, abs=1e-6)
    assert all(p[:, 1].min() == pytest.approx(0.9) for p in shaded)
    (entry,) = [t for t in legend_texts(ax) if t.startswith("unsafe:")]
    assert "apex in rebound only" in entry and "while sets are in rebound" in entry


def test_a_requirement_of_every_mode_drawn_is_shaded_over_the_whole_time(tmp_path, draw):
    """``v >= -0.3`` applies in both modes drawn: its band spans the whole view, no ``only``."""
    model, props = load_files(tmp_path, MODEL, PROPERTIES)
    bound = [props["approach"]]
    sets = [SetPiece(m, t0, t0 + 1, "box", ("x", "v", "t"), low=np.array([0.0, -0.2, t0]),
                     high=np.array([1.0, 0.1, t0 + 1])) for m, t0 in (("inbound", 0.0), ("rebound", 6.0))]
    ax, _ = draw(model, bound, {"taylor": [Result("taylor", model.name, "approach", Status.SAFE, sets=sets)]}, "t", "v")
    (band,) = unsafe_patches(ax, "unsafe:inbound,rebound")
    assert (band[:, 0].min(), band[:, 0].max()) == pytest.approx(ax.get_xlim())
    (entry,) = [t for t in legend_texts(ax) if t.startswith("unsafe:")]
    assert entry == "unsafe: approach in every mode drawn"


def test_in_the_state_plane_a_requirement_of_one_mode_covers_the_view(checked, draw):
    """Against ``x`` and ``v``, which do not tell the modes' times apart, ``x > 0.9`` of
    ``rebound`` is shaded over the whole height of the view, its legend naming the mode."""
    model, bound, results = checked
    ax, _ = draw(model, bound, results, "x", "v", exact=False)
    (band,) = unsafe_patches(ax, "unsafe:rebound")
    assert band[:, 0].min() == pytest.approx(0.9)
    assert (band[:, 1].min(), band[:, 1].max()) == pytest.approx(ax.get_ylim())
    (entry,) = [t for t in legend_texts(ax) if t.startswith("unsafe:")]
    assert entry == "unsafe: apex in rebound"


def test_a_star_whose_lps_stop_is_drawn_from_its_box_cut_by_the_invariant(tmp_path, draw, monkeypatch):
    """A star piece ``x = 0.5 + 0.6 a``, its predicate ``x >= 0`` (``a >= -5/6``), in a box
    ``a in [-1, 1]``: drawn exactly, x spans [0, 1.1]; when every LP stops without a verdict the
    picture is still drawn, from the coefficient box (x down to -0.1) cut by the invariant: the
    same span."""
    from reach.lp import LPError
    from reach.sets import Box, HPolytope, Star

    model, props = load_files(tmp_path, MODEL, PROPERTIES)
    star = Star([0.5, -0.1, 6.0], [[0.6, 0.0], [0.0, 0.05], [0.5, 0.0]], HPolytope([[-0.6, 0.0]], [0.5]),
                Box(-np.ones(2), np.ones(2)))
    piece = SetPiece("rebound", 5.5, 6.5, "star", ("x", "v", "t"), (star,))
    results = {"star": [Result("star", model.name, "apex", Status.SAFE, sets=[piece])]}
    assert piece.polygon("t", "x", exact=False)[:, 1].min() == pytest.approx(-0.1)
    spans = []
    for stopped in (False, True):
        if stopped:
            def no_verdict(self, direction):
                raise LPError("LP solver stopped without a verdict: Solve error")
            monkeypatch.setattr(Star, "support", no_verdict)
        ax, _ = draw(model, [props["apex"]], results, "t", "x")
        (polygon,) = polygons(ax, "star:rebound")
        spans.append((polygon[:, 1].min(), polygon[:, 1].max()))
    assert spans[0] == pytest.approx((0.0, 1.1), abs=1e-9) and spans[1] == pytest.approx(spans[0], abs=1e-9)
