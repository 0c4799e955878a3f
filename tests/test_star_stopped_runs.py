"""star names the invariant faces its reachable sets meet where no transition is enabled, and
where sampled runs stop there (reach.backends.star.stops): a SAFE then holds for each run while
it lasts. Held against the closed form of a model whose runs stop, and against one whose stop
faces no run reaches."""

from __future__ import annotations

import json
import re

import yaml

from reach.cli import main as cli
from reach.model import load_model


def model_and_property(tmp_path, target_invariant: str):
    """x' = y' = 1 from x in [0, 1], y in [0, 5] under x <= 5; the urgent jump at x >= 5 into
    `out` needs ``target_invariant`` after it. A run reaches x = 5 at t = 5 - x0 with
    y = y0 + 5 - x0 in [4, 10]."""
    doc = {"name": "handover", "state": ["x", "y", "t"], "horizon": 10,
           "modes": {"go": {"flow": {"x": 1, "y": 1, "t": 1}, "invariant": ["x <= 5"]},
                     "out": {"flow": {"x": 0, "y": 0, "t": 1}, "invariant": [target_invariant]}},
           "transitions": [{"from": "go", "to": "out", "guard": ["x >= 5"], "urgent": True}],
           "initial": {"mode": "go", "box": {"x": [0, 1], "y": [0, 5], "t": 0}}}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(doc))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "ymax", "kind": "safety", "modes": ["go", "out"], "require": ["y <= 20"]}]}))
    return str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml")


def test_a_safe_names_where_its_runs_stop_and_from_when(tmp_path, capsys):
    """`out` needs y <= 3: every run (y >= 4 at x = 5) stops at x = 5, the first at t = 4
    (x0 = 1). The sets meet the face from a cell that starts no later than t = 4 (cells are
    10/60 long); the sampled runs confirm it, the first at t = 4 (a corner of the box)."""
    m, p = model_and_property(tmp_path, "y <= 3")
    assert cli(["check", m, p, "-b", "star", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    met = row["details"]["stop_faces_met"]
    assert "mode 'go' at the boundary of x <= 5" in met
    assert 4.0 - 2 * 10 / 60 <= float(re.search(r"from t = ([0-9.e+-]+)", met).group(1)) <= 4.0
    note = row["details"]["stopped_runs"]
    assert "in mode 'go' at the boundary of x <= 5" in note
    assert abs(float(re.search(r"the first at t = ([0-9.e+-]+)", note).group(1)) - 4.0) < 1e-3
    runs, stopped = re.search(r"of (\d+) sampled runs, .*: (\d+) in mode", note).groups()
    assert runs == stopped                        # every run stops
    assert cli(["check", m, p, "-b", "star"]) == 0
    assert "some stop where no transition is enabled" in capsys.readouterr().out


def test_a_stop_face_no_run_reaches_is_not_named(tmp_path, capsys):
    """`out` needs y <= 11: the lint, without reachability, names the face in part (y > 11 at
    x = 5 fails it); every run reaches x = 5 with y <= 10, so star names nothing."""
    m, p = model_and_property(tmp_path, "y <= 11")
    assert any("boundary of x <= 5" in finding for finding in load_model(m).lints)
    assert cli(["check", m, p, "-b", "star", "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["status"] == "safe" and "stopped_runs" not in row["details"]
    assert "stop_faces_met" not in row["details"]


def test_runs_cut_by_the_budget_are_not_named_as_stopped(tmp_path):
    """Runs the time budget cuts are not runs the model stops: with no time left nothing is
    sampled (the faces met are named alone), and a simulation cut at once marks every run cut."""
    import numpy as np

    from reach.backends.star.stops import sampled_stops
    from reach.model.simulate import Simulator

    m, _ = model_and_property(tmp_path, "y <= 3")
    model = load_model(m)
    met = {("go", "x <= 5"): 3.9}
    assert sampled_stops(model, met, 0.0) == {"stop_faces_met": "mode 'go' at the boundary of x <= 5 (from t = 3.9)"}
    runs = Simulator(model).run(np.array([[0.0, 0.0, 0.0], [1.0, 5.0, 0.0]]), deadline=0.0)
    assert runs.cut == 2 and sorted(runs.cut_rows.tolist()) == [0, 1]
    assert sampled_stops(model, met, 30.0)["stopped_runs"].count("in mode 'go'") == 1   # with time: they stop
