"""An early violation spares the rest of the chain: the exact interpolation errors are computed a
chunk at a time as the exploration reaches them (the same exploration as all at once), and a
failing cell whose witness run enters the piece between grid points is replayed before it is
refined. References: the closed form of two coupled oscillators (expm at the initial box's
corners) and of ``x'' = -x``."""

import importlib
import itertools

import numpy as np
import pytest
import scipy.linalg

from reach.backends.star import BACKEND
from reach.result import Status
from model_files import load_files

explorer = importlib.import_module("reach.backends.star.explorer")
flowpipe = importlib.import_module("reach.backends.star.flowpipe")     # (the package exports a function of that name)

COUPLED = """
name: coupled
state: [x, v, y, w]
modes:
  run:
    flow: {x: v, v: "-x + 0.3*y - 0.1*v", y: w, w: "-2*y + 0.3*x - 0.05*w"}
initial: {mode: run, box: {x: [0.9, 1.1], v: [-0.1, 0.1], y: [-0.2, 0.2], w: 0}}
horizon: 12
"""


def _least_x(horizon=12.0, samples=12001):
    A = np.array([[0, 1, 0, 0], [-1, -0.1, 0.3, 0], [0, 0, 0, 1], [0.3, 0, -2, -0.05]])
    step = scipy.linalg.expm(A * horizon / (samples - 1))
    low = np.inf
    for corner in itertools.product([0.9, 1.1], [-0.1, 0.1], [-0.2, 0.2], [0.0]):
        z = np.array(corner)
        for _ in range(samples):           # linear in the initial state: extremes at corners
            low = min(low, z[0])
            z = step @ z
    return low


def _check(text, tmp_path, require, options=None):
    props = f'properties: [{{id: p, kind: safety, modes: [run], require: ["{require}"]}}]'
    model, bound = load_files(tmp_path, text, props)
    return BACKEND.check(model, bound["p"], options or {})


@pytest.fixture(scope="module")
def least_x():
    return _least_x()


def _exact_cells(monkeypatch):
    """Count the grid stars whose exact interpolation error is computed."""
    seen = []
    original = explorer._chain_abs_bounds

    def counted(center, *args):
        seen.append(center.shape[0])
        return original(center, *args)

    monkeypatch.setattr(explorer, "_chain_abs_bounds", counted)
    return seen


@pytest.mark.parametrize("margin, expected", [(1.03, Status.SAFE), (0.97, Status.UNSAFE)])
def test_chunked_exact_errors_explore_as_one(monkeypatch, tmp_path, least_x, margin, expected):
    """One grid star per chunk gives the same verdict, cells, refinements and LPs as the whole
    chain at once, on a true bound (3 % beyond the least x) and on a violated one."""
    require = f"x >= {least_x * margin:.5f}"
    whole = _check(COUPLED, tmp_path, require)
    monkeypatch.setattr(flowpipe, "PRODUCT_BYTES", 1)
    chunked = _check(COUPLED, tmp_path, require)
    assert whole.status == chunked.status == expected
    for key in ("cells", "refined_cells", "lps", "deepest_refinement"):
        assert whole.details[key] == chunked.details[key], key


def test_an_early_violation_spares_the_later_exact_errors(monkeypatch, tmp_path, least_x):
    """x first dips below 0 near t = 1.6: with one grid star per chunk, the exact errors of the
    cells after the violation are never computed."""
    seen = _exact_cells(monkeypatch)
    whole = _check(COUPLED, tmp_path, "x >= 0.2")
    all_at_once = sum(seen)
    seen.clear()
    monkeypatch.setattr(flowpipe, "PRODUCT_BYTES", 1)
    chunked = _check(COUPLED, tmp_path, "x >= 0.2")
    assert whole.status == chunked.status == Status.UNSAFE
    assert chunked.counterexample.violation_time < 3.0
    assert sum(seen) < all_at_once / 2


SPRING = """
name: spring
state: [x, v]
modes:
  run:
    flow: {x: v, v: -x}
initial: {mode: run, box: {x: [0.99, 1.0], v: 0}}
horizon: 6
"""


def test_a_violation_between_grid_points_is_replayed_before_refining(monkeypatch, tmp_path):
    """x = x0 cos t dips below -0.995 only for |t - pi| < 0.1; the grid of step 0.5 has t = 3
    and 3.5 (x >= -0.99). The witness run, probed at 64 instants per step, enters the piece, so
    it is replayed at once: fewer cells refined than without the probe, and the run violates
    near t = pi."""
    probed = _check(SPRING, tmp_path, "x >= -0.995", {"step": 0.5})
    assert probed.status == Status.UNSAFE
    assert abs(probed.counterexample.violation_time - np.pi) < 0.1
    monkeypatch.setattr(explorer._Explorer, "_probed", lambda *args: False)
    refined = _check(SPRING, tmp_path, "x >= -0.995", {"step": 0.5})
    assert refined.status == Status.UNSAFE
    assert probed.details["refined_cells"] < refined.details["refined_cells"]
