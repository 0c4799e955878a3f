"""taylor's rigorous sweep on an expanding flow: where the logarithmic-norm bound of
reach.backends.taylor.verified does not close (Van der Pol, mu = 1, the ARCH-COMP NLN VDP
instance), the stretch is a Taylor-model flowpipe (reach.backends.taylor.tm_flowpipe). The bound
is checked against dense solve_ivp runs from a grid of the initial box."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reach.backends.taylor import BACKEND
from reach.model.loader import load_model
from reach.result import Status
from reach.spec.properties import BoundEvent, bind, load_properties

warnings.filterwarnings("ignore", category=RuntimeWarning)


@pytest.fixture(scope="module")
def vdp():
    return load_model("tests/data/vanderpol.yaml")


@pytest.fixture(scope="module")
def sampled_peak(vdp):
    """Largest y over 7 s of solve_ivp runs (DOP853, rtol 1e-11) from a 9 x 9 grid of the box,
    on a dense grid of their dense output."""
    peak = -np.inf
    for x0 in np.linspace(1.25, 1.55, 9):
        for y0 in np.linspace(2.35, 2.45, 9):
            run = solve_ivp(lambda t, z: [z[1], (1 - z[0] ** 2) * z[1] - z[0]], (0, 7), [x0, y0],
                            method="DOP853", rtol=1e-11, atol=1e-12, dense_output=True)
            peak = max(peak, float(run.sol(np.linspace(0, 7, 7001))[1].max()))
    return peak


def _prop(vdp, tmp_path, limit: float) -> BoundEvent:
    path = tmp_path / "props.yaml"
    path.write_text(f"properties:\n  - {{id: y_max, kind: event, modes: [run], maximize: 'y', require: '<= {limit}'}}\n")
    return bind(load_properties(path)[0], vdp)


def test_the_flowpipe_proves_the_arch_bound_and_holds_the_sampled_peak(vdp, sampled_peak, tmp_path):
    """y <= 2.75 is SAFE with one level of refinement (the verified enclosure alone answers
    [-inf, inf]); the bound holds the sampled peak (about 2.679) and exceeds it by under 3 %."""
    result = BACKEND.check(vdp, _prop(vdp, tmp_path, 2.75), {"remainder": "rigorous", "refine": 1})
    assert result.status is Status.SAFE
    lo, hi = result.bound
    assert lo <= sampled_peak <= hi <= 1.03 * sampled_peak


def test_a_requirement_below_the_sampled_peak_is_never_safe(vdp, sampled_peak, tmp_path):
    """y <= 0.995 * peak is violated by a sampled run: the rigorous mode must not say SAFE."""
    result = BACKEND.check(vdp, _prop(vdp, tmp_path, round(0.995 * sampled_peak, 4)),
                           {"remainder": "rigorous", "refine": 1})
    assert result.status is not Status.SAFE
    assert result.bound[1] >= sampled_peak


def test_a_budget_cuts_the_flowpipe_short_and_says_so(vdp, tmp_path):
    """The flowpipe of the check above (several seconds) under ``max_seconds=0.5``: no step starts
    past it, the bound is unbounded, the reason names the option; nothing is kept for a later
    check, which, without the budget, proves the bound as before."""
    import time

    from reach.backends.taylor.problem import _ENCLOSURES, FLOWPIPE_SECONDS
    prop = _prop(vdp, tmp_path, 2.75)
    _ENCLOSURES.clear()                 # the checks above keep their stretches
    started = time.perf_counter()
    cut = BACKEND.check(vdp, prop, {"remainder": "rigorous", "max_seconds": 0.5})
    assert time.perf_counter() - started < FLOWPIPE_SECONDS / 4       # it stopped, not the flowpipe's own cap
    assert cut.status is Status.UNKNOWN and cut.bound[1] == np.inf
    assert "time budget of 0.5 s (option max_seconds)" in cut.details["note"]
    assert "refine" not in cut.details["note"]
    again = BACKEND.check(vdp, prop, {"remainder": "rigorous", "refine": 1})
    assert again.status is Status.SAFE
