"""``reach plot`` when a back-end hands no sets to draw: which back-ends keep which sets (checked
on the back-ends themselves), and the picture and the console saying why nothing of a back-end
is drawn, read back through matplotlib's objects; the exit code stays the verdict's unless nothing
at all could be drawn, which is one line and exit 2.

Two small models: ``decay`` (``x' = -x/2``, deterministic), with a safety and an event property;
``drift`` (a double integrator kicked by Gaussian noise), with a safety, a reach and a
reach-avoid property."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from matplotlib.text import Text

from model_files import load_files
from reach.backends import BACKENDS, OPTIONS, backend
from reach.checking import check_model, resolve_backend
from reach.cli import main
from reach.plotting.missing import KEPT
from reach.result import Result, SetPiece, Status

DECAY = """
name: decay
state: [x, t]
modes:
  run:
    flow: {x: "-0.5*x", t: 1}
initial: {mode: run, box: {x: [1.0, 1.2], t: 0}}
horizon: 2
"""
DECAY_PROPERTIES = """
properties:
  - {id: low, kind: safety, modes: [run], require: ["x <= 2"]}
  - {id: peak, kind: event, modes: [run], maximize: x, require: "<= 2"}
"""
DRIFT = """
name: drift
state: [x, v]
modes:
  coast:
    flow: {x: v, v: 0}
initial: {mode: coast, box: {x: 0, v: 0.1}}
horizon: 10
disturbance:
  gaussian: {mean: [0], cov: ["0.0001"]}
  enters: [v]
  step: 5
"""
DRIFT_PROPERTIES = """
properties:
  - {id: near, kind: safety, modes: [coast], require: ["x <= 3"]}
  - {id: arrive, kind: reach, at: 10, target: {box: {x: [0.5, 1.5]}}, probability: {at_least: 0.5}}
  - {id: stay, kind: reach_avoid, at: 10, target: {box: {x: [0.5, 1.5]}}, safe: ["x <= 3"],
     probability: {at_least: 0.5}}
"""
SAMPLED = {"samples": 20, "optimise": False, "search_rounds": 0}
SAMPLED_OPTIONS = ["-o", "montecarlo.samples=20", "-o", "montecarlo.optimise=false", "-o", "montecarlo.search_rounds=0"]


def keeps_sets_option(name: str) -> bool:
    import importlib

    options = getattr(importlib.import_module(BACKENDS[name]), OPTIONS[name])
    return "keep_sets" in {f.name for f in dataclasses.fields(options)}


def test_what_the_picture_says_each_backend_keeps_is_what_it_keeps(tmp_path):
    """Each back-end checks every property of both models it handles with ``keep_sets`` (taylor
    rigorously): it hands sets exactly for the property kinds :data:`KEPT` lists for it; fsr has
    no such option and hands none."""
    seen = set()
    for name, (model_text, props_text) in {"decay": (DECAY, DECAY_PROPERTIES),
                                           "drift": (DRIFT, DRIFT_PROPERTIES)}.items():
        (tmp_path / name).mkdir()
        model, props = load_files(tmp_path / name, model_text, props_text)
        for b in BACKENDS:
            bound = [p for p in props.values() if backend(b).supports(model, p) is None]
            if not bound:
                continue
            options = {"keep_sets": True} if keeps_sets_option(b) else {}
            options.update({"taylor": {"remainder": "rigorous"}, "montecarlo": SAMPLED}.get(b, {}))
            for prop, result in zip(bound, check_model(resolve_backend(b), model, bound, options)):
                kinds = KEPT[b].kinds if b in KEPT else ()
                assert bool(result.sets) == (prop.kind in kinds), (b, prop.id, len(result.sets))
                seen.add((b, prop.kind))
    assert not keeps_sets_option("fsr") and "fsr" not in KEPT
    assert {("star", "safety"), ("taylor", "safety"), ("taylor", "event"), ("montecarlo", "safety"),
            ("montecarlo", "event"), ("montecarlo", "reach"), ("fsr", "reach"), ("fsr", "reach_avoid")} <= seen


def legend_texts(ax) -> list[str]:
    return [t.get_text().replace("\n", " ") for t in ax.get_legend().get_texts()]


def note(ax) -> Text | None:
    """The text written across the axes when nothing at all is drawn."""
    found = [t for t in ax.texts if t.get_gid() == "nothing drawn"]
    return found[0] if found else None


FAILED_SWEEP = "the bound is open on 100% of the box (mode 'run': the step size collapsed to 5.5e-07 at t = 1.3)"


def test_a_backend_with_nothing_drawn_gets_a_legend_entry_saying_why(tmp_path, draw):
    """Star's boxes are drawn; taylor, whose rigorous sweeps all failed, handed none: the legend
    says so with the reason its result gives, suggesting montecarlo (not asked for, keeping runs
    of safety properties), and nothing is written over the drawn sets."""
    model, props = load_files(tmp_path, DECAY, DECAY_PROPERTIES)
    bound = [props["low"]]
    box = SetPiece("run", 0.0, 1.0, "box", ("x", "t"), low=np.array([0.6, 0.0]), high=np.array([1.2, 1.0]))
    results = {"star": [Result("star", model.name, "low", Status.SAFE, sets=[box])],
               "taylor": [Result("taylor", model.name, "low", Status.UNKNOWN,
                                 details={"remainder": "rigorous (verified enclosure or flowpipe)",
                                          "reason": FAILED_SWEEP})]}
    ax, summary = draw(model, bound, results, "t", "x")
    assert [c.get_gid() for c in ax.collections] == ["star:run"]
    (entry,) = [t for t in legend_texts(ax) if t.startswith("taylor")]
    why = f"kept no step enclosures for low: {FAILED_SWEEP}; try --backend montecarlo"
    assert entry == f"taylor: nothing to draw: {why}"
    assert summary["nothing_drawn"] == {"taylor": why}
    assert note(ax) is None


def test_when_nothing_at_all_is_drawn_the_axes_say_why(tmp_path, draw):
    """fsr keeps no sets and montecarlo keeps no runs of a reach property: nothing is drawn, and
    the middle of the axes says so for each, within the axes."""
    model, props = load_files(tmp_path, DRIFT, DRIFT_PROPERTIES)
    bound = [props["arrive"]]
    results = {b: [Result(b, model.name, "arrive", status)] for b, status in
               (("fsr", Status.SAFE), ("montecarlo", Status.UNKNOWN))}
    ax, summary = draw(model, bound, results, "x", "v")
    assert not [c for c in ax.collections if c.get_gid()] and not summary["sets"]
    text = note(ax)
    assert text is not None and text.get_visible()
    words = text.get_text().replace("\n", " ")
    assert "fsr keeps no sets (it integrates the distribution of the states and computes no set)" in words
    assert "montecarlo keeps its sampled runs for safety and event properties only" in words
    assert "no back-end keeps sets for reach properties" in words
    renderer = ax.figure.canvas.get_renderer()
    box, axes_box = text.get_window_extent(renderer), ax.bbox
    assert axes_box.x0 <= box.x0 and box.x1 <= axes_box.x1 and axes_box.y0 <= box.y0 and box.y1 <= axes_box.y1


def test_an_unsupported_property_and_a_better_backend_are_named(tmp_path, draw):
    """star does not check an event property: the reason is star's own; montecarlo kept no runs
    here, and taylor (not asked for, handling it) is suggested."""
    model, props = load_files(tmp_path, DECAY, DECAY_PROPERTIES)
    bound = [props["peak"]]
    results = {"star": [Result("star", model.name, "peak", Status.UNSUPPORTED,
                               details={"reason": "the star back-end checks safety properties only"})],
               "montecarlo": [Result("montecarlo", model.name, "peak", Status.UNKNOWN)]}
    ax, summary = draw(model, bound, results, "t", "x")
    assert summary["nothing_drawn"] == {
        "star": "does not check peak: the star back-end checks safety properties only; try --backend taylor",
        "montecarlo": "kept no sampled runs for peak; try --backend taylor"}


def test_nothing_drawn_by_any_backend_is_one_line_and_exit_2(tmp_path, capsys):
    """``reach plot`` of a reach property with fsr alone: the verdict's line on the console, then
    one line on stderr saying nothing could be drawn and why (exit 2); the picture, written,
    says it too."""
    load_files(tmp_path, DRIFT, DRIFT_PROPERTIES)
    out = tmp_path / "pic.png"
    code = main(["plot", str(tmp_path / "model.yaml"), str(tmp_path / "props.yaml"), "-b", "fsr", "-p", "arrive",
                 "--out", str(out)])
    printed = capsys.readouterr()
    assert code == 2
    assert printed.out.splitlines() == ["fsr: arrive SAFE (0 sets)"]
    (line,) = printed.err.strip().splitlines()
    assert line.startswith("reach: --backend: nothing could be drawn: fsr keeps no sets") and str(out) in line
    assert out.stat().st_size > 10_000


def test_the_exit_code_stays_the_verdicts_when_another_backend_draws(tmp_path, capsys):
    """montecarlo draws its runs of ``near``; fsr draws nothing: the console says why, and the
    exit code is the verdicts' (3: montecarlo never proves, nothing violated)."""
    load_files(tmp_path, DRIFT, DRIFT_PROPERTIES)
    out = tmp_path / "pic.png"
    code = main(["plot", str(tmp_path / "model.yaml"), str(tmp_path / "props.yaml"), "-b", "montecarlo", "-b", "fsr",
                 "-p", "near", "-p", "arrive", "--vars", "x,v", "--out", str(out), *SAMPLED_OPTIONS])
    printed = capsys.readouterr()
    assert code == 3, printed
    assert "fsr: nothing to draw: does not check near: " in printed.out
    assert "keeps no sets (it integrates the distribution of the states and computes no set)" in printed.out
    assert printed.err == "" and out.stat().st_size > 10_000


def test_sets_cut_short_by_a_violation_are_said_to_be_partial(tmp_path, draw):
    """x' = -0.5 x from [1, 1.2]: ``x <= 1.1`` is violated at t = 0, so star stops there and its
    drawn sets are not all that is reachable; the legend says so. ``x <= 2`` holds: no such line."""
    from reach.plotting.reach_sets import cut_short

    model, props = load_files(tmp_path, DECAY, DECAY_PROPERTIES.replace(
        '  - {id: peak', '  - {id: early, kind: safety, modes: [run], require: ["x <= 1.1"]}\n  - {id: peak'))
    star = backend("star")
    for pid, partial in (("early", True), ("low", False)):
        results = {"star": [star.check(model, props[pid], {"keep_sets": True})]}
        assert results["star"][0].status.value == ("UNSAFE" if partial else "SAFE")
        ax, _ = draw(model, [props[pid]], results, "t", "x")
        said = [t for t in legend_texts(ax) if "stopped at the violation" in t]
        assert bool(said) == partial and cut_short(results, {"star": {"run": None}}) == said



def test_sets_of_an_undecided_check_are_said_to_be_maybe_partial():
    """An UNKNOWN check with sets (a budget or a cell refinement stopped it) may not have drawn
    all that is reachable, and the legend says so (before, only an UNSAFE check said its sets
    were cut short); one without sets, or a SAFE one, gets no such line."""
    from reach.plotting.reach_sets import cut_short
    from reach.result import Result, Status

    def star(status, sets):
        return Result("star", "m", "low", status, sets=sets)

    drawn = {"star": {"run": None}}
    assert cut_short({"star": [star(Status.UNKNOWN, ["a piece"])]}, drawn) == [
        "star: sets up to where its check of low stopped undecided (maybe not all that is reachable)"]
    assert cut_short({"star": [star(Status.UNKNOWN, [])]}, drawn) == []
    assert cut_short({"star": [star(Status.SAFE, ["a piece"])]}, drawn) == []
    assert cut_short({"montecarlo": [star(Status.UNKNOWN, ["a run"])]}, {"montecarlo": {"run": None}}) == []
