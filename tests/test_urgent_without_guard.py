"""An urgent transition whose guard always holds (none written; SpaceEx ``asap`` with ``true``)
lets no time pass in its mode: a run is in ``B`` only at the instant it enters, with ``x = 0``."""

from __future__ import annotations

import numpy as np
import pytest

from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.star import BACKEND as STAR
from reach.model.simulate import Simulator
from reach.result import Status
from model_files import load_files

PASSING_THROUGH = ("""
    name: passing_through
    state: [x]
    modes:
      A: {flow: {x: "1"}}
      B: {flow: {x: "1"}}
      C: {flow: {x: "1"}}
    transitions:
      in_b: {from: A, to: B, guard: ["x >= 0"], urgent: true}
      out_of_b: {from: B, to: C, urgent: true}
    initial: {mode: A, box: {x: [0, 0]}}
    horizon: 3
""", """
    properties:
      - {id: late_in_b, kind: safety, modes: [B], avoid: ["x >= 0.01"]}
      - {id: late_in_c, kind: safety, modes: [C], avoid: ["x >= 2.9"]}
""")


def test_a_mode_left_by_an_always_enabled_urgent_jump_is_one_instant(tmp_path):
    """star proves ``B`` is never occupied past ``x = 0`` (before: UNKNOWN, following B's flow
    for 3 s that no run follows), the runs pass through ``B`` at t = 0 and reach ``x = 3`` in
    ``C``, which both back-ends find."""
    model, props = load_files(tmp_path, *PASSING_THROUGH)
    assert model.modes["B"].timeless and not model.modes["A"].timeless
    traj = Simulator(model).run(np.array([[0.0]]), record=True)
    assert traj.transitions[0] == ["in_b", "out_of_b"]
    assert traj.final_state[0, 0] == pytest.approx(3.0)
    assert STAR.check(model, props["late_in_b"], {}).status is Status.SAFE
    assert MONTECARLO.check(model, props["late_in_b"], {"samples": 50}).status is Status.UNKNOWN
    for backend in (STAR, MONTECARLO):
        assert backend.check(model, props["late_in_c"], {"samples": 50} if backend is MONTECARLO else {}).status \
            is Status.UNSAFE
