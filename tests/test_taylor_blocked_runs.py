"""taylor where runs stop at an invariant no urgent transition leaves: the automaton ends them
there, so the rigorous sweep's lower end of a maximum (what every run is proved to reach) may
only come from states where every run is proved still going (reach.backends.taylor.problem,
ModeCode.alive). Checked against the closed form of the stopped runs and Monte Carlo."""

from __future__ import annotations

import numpy as np

from model_files import load_files
from reach.backends.montecarlo import BACKEND as MONTECARLO
from reach.backends.taylor import BACKEND as TAYLOR
from reach.result import Status

#: th' = w, w' = 0.5 (wc - w), wc in [0.9, 1.1]: th grows at about 1 per second, and th <= 2 with
#: no way out stops every run at th = 2 (by t <= 2.23 s) of a 10 s horizon
STUCK = """
    name: stuck
    state: [th, w, t]
    bounded_inputs:
      wc: {range: [0.9, 1.1]}
    modes:
      slew:
        flow: {th: w, w: "0.5*(wc - w)", t: 1}
        invariant: ["th <= 2"]
    initial: {mode: slew, box: {th: [0, 0.2], w: [0.9, 1.1], t: 0}}
    horizon: 10
"""

#: the same slew left through an urgent guard on the invariant's boundary: no run stops
LEFT = STUCK.replace("initial:", """transitions:
      - {from: slew, to: hold, guard: ["th >= 2"], urgent: true}
    initial:""").replace("""        invariant: ["th <= 2"]
""", """        invariant: ["th <= 2"]
      hold:
        flow: {th: 0, w: 0, t: 1}
""")

PROPS = """
    properties:
      - {id: reach_target, kind: event, modes: [slew], maximize: th, require: ">= 3"}
      - {id: reach_near, kind: event, modes: [slew, hold], maximize: th, require: ">= 1.9"}
"""


def latest_stop(wc: float, th0: float, w0: float) -> float:
    """When th reaches 2 from (th0, w0) with input wc: th(t) = th0 + wc t + 2 (w0 - wc)(1 - e^{-t/2})."""
    t = np.linspace(0, 10, 200001)
    th = th0 + wc * t + 2 * (w0 - wc) * (1 - np.exp(-t / 2))
    return float(t[np.argmax(th >= 2)])


def test_a_maximum_that_stopped_runs_never_reach_is_not_proved(tmp_path):
    """Every run stops at th = 2 (the latest at t = 2.22 s: th0 = 0, w0 = wc = 0.9), so max th
    >= 3 fails on every run; the rigorous sweep used to follow the flow on to th = 8.9 and say
    SAFE. Now it is UNSAFE with a replayed run, as Monte Carlo finds."""
    assert 2.2 < latest_stop(0.9, 0.0, 0.9) < 2.23
    model, props = load_files(tmp_path, STUCK, PROPS)
    rigorous = TAYLOR.check(model, props["reach_target"], {"remainder": "rigorous"})
    assert rigorous.status is Status.UNSAFE
    assert rigorous.counterexample is not None and rigorous.counterexample.violation_mode == "slew"
    assert MONTECARLO.check(model, props["reach_target"], {"samples": 200, "optimise": False}).status is Status.UNSAFE
    estimated = TAYLOR.check(model, props["reach_target"], {})
    assert any("invariant boundary where no transition is enabled" in a for a in estimated.details["assumptions"])


def test_runs_leaving_through_an_urgent_guard_keep_their_proof(tmp_path):
    """With the urgent exit th >= 2 every run reaches th = 2 and holds there: max th >= 1.9 is
    proved (SAFE), across the switch, as before."""
    model, props = load_files(tmp_path, LEFT, PROPS)
    result = TAYLOR.check(model, props["reach_near"], {"remainder": "rigorous"})
    assert result.status is Status.SAFE
    assert not any("invariant boundary" in a for a in result.details["assumptions"])


#: the hand-over to B needs B's invariant y <= 0.5 after the jump; y stays near 0.9, so the jump
#: is never enabled and every run stops at x = 1 (t <= 1 of a 5 s horizon)
HANDOVER = """
    name: handover
    state: [x, y]
    modes:
      A:
        flow: {x: 1, y: "-0.1*y"}
        invariant: ["x <= 1"]
      B:
        flow: {x: 1, y: "-0.1*y"}
        invariant: ["y <= 0.5"]
    transitions:
      hand: {from: A, to: B, guard: ["x >= 1"], urgent: true}
    initial: {mode: A, box: {x: [0, 0.2], y: [0.9, 1.0]}}
    horizon: 5
"""


def test_a_jump_its_target_invariant_disables_does_not_carry_the_proof(tmp_path):
    """y(1) >= 0.9 e^{-0.1} = 0.81 > 0.5 when x reaches 1: no run enters B, every run ends at
    x = 1; max x >= 3 fails (UNSAFE, replayed), where following the jump would reach x = 5."""
    assert 0.9 * np.exp(-0.1) > 0.5
    model, props = load_files(tmp_path, HANDOVER, """
        properties:
          - {id: reach3, kind: event, modes: [A, B], maximize: x, require: ">= 3"}
    """)
    result = TAYLOR.check(model, props["reach3"], {"remainder": "rigorous"})
    assert result.status is Status.UNSAFE and result.counterexample.violation_mode == "A"


def test_a_safety_estimate_past_a_stop_says_so_in_its_line(tmp_path):
    """t <= 5 on the slew: every run stops at th = 2 by t = 2.23, so it holds; the estimate
    follows the flow on to t = 10 and cannot tell. The safety result carries the event's
    assumption and shows it in its line (it named nothing)."""
    from reach.report import line
    model, props = load_files(tmp_path, STUCK, """
    properties:
      - {id: th_cap, kind: safety, modes: [slew], require: ["t <= 5"]}
""")
    result = TAYLOR.check(model, props["th_cap"], {})
    assert result.status is Status.UNKNOWN
    assert "invariant boundary where no transition is enabled" in result.details["note"]
    assert "invariant boundary where no transition is enabled" in line(result, props["th_cap"], model)
