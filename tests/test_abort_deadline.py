"""Verdicts that hinge on the approach mode's ``t <= t_abort_hi`` invariant (the forced abort).

In the shipped ARCH windows (``t_abort_hi >= 120 min``) every run docks at 108.8-111.6 min,
before the deadline can bind in mode 1; so the check uses the ARCH abort model with an early
window ``[60, 80] min``, in which the deadline forces the abort while the chaser is still
approaching. References, from the published mode-1 gain and the CWH matrix (no loader):

* the closed-loop position ``x(t) = [expm(A_cl t) x0]_1`` over the initial box (linear in ``x0``,
  so extreme at the box's corners) stays below ``-177`` m up to ``t = 80`` min;
* without an abort the chaser reaches ``x = -100`` m (the docking guard; ``solve_ivp`` event)
  after 108 min.

Hence "in mode 1, ``x <= -150`` m" holds exactly because the deadline ends mode 1 at 80 min:
with the model's invariant, star proves it and no sampled run violates it; with the deadline
removed (``x <= -100`` alone), star cannot prove it and Monte Carlo finds a run that never
aborts and replays.
"""

import numpy as np
import scipy.linalg
from scipy.integrate import solve_ivp

from arch import A_CL1, CORNERS, docking_event
from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.montecarlo import replay, switch_window
from reach.backends.star import BACKEND as STAR
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties

PROPERTIES = """description: mode 1 ends before the chaser comes within 150 m
properties:
  - id: far
    kind: safety
    modes: [approach]
    require: ["x <= -150[m]"]
  - id: deadline
    kind: safety
    modes: [approach, rendezvous]
    require: ["t <= 80.5[min]"]
"""


def early_abort(tmp_path, deadline=True):
    root = __import__("pathlib").Path.cwd()
    text = (f"name: early-abort\nextends: {root}/models/_rendezvous_abort.yaml\n"
            "constants: {t_abort_lo: 60, t_abort_hi: 80}\nhorizon: 160\n")
    if not deadline:
        text += 'modes:\n  approach:\n    invariant: ["x <= -100"]\n'
    path = tmp_path / ("early.yaml" if deadline else "no_deadline.yaml")
    path.write_text(text)
    props = tmp_path / "props.yaml"
    props.write_text(PROPERTIES)
    model = load_model(path)
    return model, {p.id: bind(p, model) for p in load_properties(props)}


def test_the_reference_trajectories():
    for t in np.linspace(0.0, 80.0, 81):
        E = scipy.linalg.expm(A_CL1 * t)
        assert max((E @ c)[0] for c in CORNERS) < -177.0
    for c in CORNERS:
        sol = solve_ivp(lambda t, s: A_CL1 @ s, [0, 200], c, events=docking_event, rtol=1e-10, atol=1e-9)
        assert 108.0 < sol.t_events[0][0] < 112.0


def test_the_deadline_forces_the_abort(tmp_path):
    model, props = early_abort(tmp_path)
    assert switch_window(model) == (60.0, 80.0, True)
    for pid in ("far", "deadline"):
        result = STAR.check(model, props[pid])
        assert result.status is Status.SAFE, (pid, result.details)
        sampled = MONTECARLO.check(model, props[pid], {"samples": 200, "search_rounds": 0})
        assert sampled.status is Status.UNKNOWN, pid          # no violation among the runs


def test_without_the_deadline_a_run_that_never_aborts_violates(tmp_path):
    model, props = early_abort(tmp_path, deadline=False)
    assert switch_window(model) == (60.0, 80.0, False)
    for pid in ("far", "deadline"):
        assert STAR.check(model, props[pid]).status is not Status.SAFE, pid
        sampled = MONTECARLO.check(model, props[pid], {"samples": 200, "search_rounds": 0})
        assert sampled.status is Status.UNSAFE, pid
        cex = sampled.counterexample
        assert replay(model, props[pid], np.array(cex.initial_state), cex.switch_time).violated
