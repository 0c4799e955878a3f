"""Uniform sampling of polytopic initial sets (reach.backends.montecarlo.initial_sampling):
the shares of sampled points against exact areas and lengths, on sets whose affine hull is
smaller than the equalities say (a box side of width 0, inequalities that pin a direction) and
on a thin strip that an axis box fills poorly. Monte Carlo's violation counts rest on this law."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.stats
import yaml

from reach.backends.montecarlo.initial_sampling import PolytopeSampler
from reach.cli import main as cli
from reach.model.automaton import LinearSet

SAMPLES = 4000


def sampler(A, b, E=None, f=None, low=None, high=None):
    A, b = np.asarray(A, float), np.asarray(b, float)
    n = A.shape[1]
    E = np.zeros((0, n)) if E is None else np.asarray(E, float)
    f = np.zeros(0) if f is None else np.asarray(f, float)
    return PolytopeSampler(LinearSet(A, b, E, f), np.asarray(low, float), np.asarray(high, float))


def box_rows(low, high):
    n = len(low)
    return np.vstack([np.eye(n), -np.eye(n)]), np.concatenate([high, -np.asarray(low)])


def test_a_segment_with_a_pinned_coordinate_is_sampled_uniformly_along_it():
    """th in [0.9, 1], w = 0, c = 0 (box sides of width 0) and u = -th - 1.5 w: a segment. Every
    sampled th used to be one end; now th is uniform on [0.9, 1] (Kolmogorov-Smirnov)."""
    low, high = [0.9, 0.0, -1.0, 0.0], [1.0, 0.0, -0.9, 0.0]
    A, b = box_rows(low, high)
    s = sampler(A, b, [[1.0, 1.5, 1.0, 0.0]], [0.0], low, high)
    X = s.uniform(SAMPLES, np.random.default_rng(1))
    assert s.d == 1 and np.all(s.contains(X))
    assert scipy.stats.kstest((X[:, 0] - 0.9) / 0.1, "uniform").pvalue > 1e-3


@pytest.mark.parametrize("pinned_by", ["box", "cycle"])
def test_a_thin_strip_is_sampled_by_area(pinned_by):
    """0 <= x - y <= 0.05 in the unit square, t = 0 (a box side, or x3 pinned by a cycle of
    inequalities t <= s, s <= t with s = 0): the strip fills 5 % of its box, so points come from
    hit-and-run. Shares of x <= 0.3 and x >= 0.7 against the exact areas, within 5 standard
    errors."""
    if pinned_by == "box":
        low, high = [0, 0, 0], [1, 1, 0]
        A, b = box_rows(low, high)
        A = np.vstack([A, [[-1, 1, 0], [1, -1, 0]]])
        b = np.concatenate([b, [0, 0.05]])
    else:
        low, high = [0, 0, -1, 0], [1, 1, 1, 0]
        A, b = box_rows(low, high)
        A = np.vstack([A, [[-1, 1, 0, 0], [1, -1, 0, 0], [0, 0, 1, -1], [0, 0, -1, 0]]])
        b = np.concatenate([b, [0, 0.05, 0, 0]])      # x3 <= x4 = 0 and x3 >= 0: x3 = 0
    s = sampler(A, b, low=low, high=high)
    X = s.uniform(SAMPLES, np.random.default_rng(2))
    assert np.all(s.contains(X)) and s.d == 2
    w = 0.05
    area = w - w * w / 2
    for share, exact in (((X[:, 0] <= 0.3).mean(), (0.3 * w - w * w / 2) / area),
                         ((X[:, 0] >= 0.7).mean(), 0.3 * w / area)):
        assert abs(share - exact) <= 5 * np.sqrt(exact * (1 - exact) / SAMPLES), (share, exact)


def test_monte_carlo_counts_violations_at_their_share_of_a_segment(tmp_path, capsys):
    """A still state on the segment u = -th - 1.5 w, th in [0.9, 1], w = 0: the runs with u in
    [-0.97, -0.955] are 15 % of it. The random runs' violation count is near 150 of 1000."""
    model = {"name": "seg", "state": ["th", "w", "u", "c"], "horizon": 1,
             "modes": {"hold": {"flow": {"th": 0, "w": 0, "u": 0, "c": 1}}},
             "initial": {"mode": "hold", "box": {"th": [0.9, 1.0], "w": 0, "c": 0},
                         "constraints": ["u == -th - 1.5*w"]}}
    props = {"properties": [{"id": "band", "kind": "safety", "modes": ["hold"],
                             "avoid": ["u >= -0.97", "u <= -0.955"]}]}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(props))
    assert cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "montecarlo",
                "-o", "optimise=false", "--json"]) == 1
    (row,) = json.loads(capsys.readouterr().out)
    share = row["details"]["violating_runs"] / row["details"]["random_runs"]
    assert abs(share - 0.15) <= 5 * np.sqrt(0.15 * 0.85 / row["details"]["random_runs"])


def test_taylor_does_not_refute_a_bound_from_outside_a_polytopic_initial_set(tmp_path, capsys):
    """x' = -0.1 x, y' = -0.1 y from the segment x + y = 1 in the unit square: x + y =
    e^{-0.1 t} <= 1, so max x + y <= 1.5 holds. taylor sweeps the bounding box, where (1, 1)
    reaches 2; a run from there is no run of the model, so it may not make an UNSAFE (its
    replay refuses it). The answer is SAFE or UNKNOWN, never UNSAFE."""
    model = {"name": "seg2", "state": ["x", "y"], "horizon": 5,
             "modes": {"go": {"flow": {"x": "-0.1*x", "y": "-0.1*y"}}},
             "initial": {"mode": "go", "box": {"x": [0, 1], "y": [0, 1]}, "constraints": ["x + y == 1"]}}
    props = {"properties": [{"id": "s", "kind": "event", "modes": ["go"], "maximize": "x + y",
                             "require": "<= 1.5"}]}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(model))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(props))
    for extra in ([], ["-o", "remainder=rigorous"]):
        code = cli(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "taylor", "--json", *extra])
        (row,) = json.loads(capsys.readouterr().out)
        assert code in (0, 3) and row["status"] in ("safe", "unknown"), row["status"]
