"""star explores only up to the latest instant a property's unsafe pieces allow (rows that read
the clock alone, ``t <= T``): no run violates later, so what happens later cannot leave the
property undecided. Reference: the closed form ``x(t) = x0 + t`` of ``x' = 1``."""

from reach.checking import check_files
from reach.result import Status

MODEL = """name: late_chatter
state: [x, t]
modes:
  a: {flow: {x: 1, t: 1}}
  b: {flow: {x: 1, t: 1}}
transitions:
  - {from: a, to: b, guard: ["t >= 2"], urgent: true}
  - {from: b, to: a, guard: ["t >= 2"], urgent: true}
initial: {mode: a, box: {x: [0, 1], t: 0}}
horizon: 10
"""


def test_a_property_about_the_first_second_ignores_what_comes_later(tmp_path):
    """From t = 2 the urgent jumps a -> b -> a chatter at one instant (star: undecided, a
    possible zero-dwell cycle). Over [0, 1] x reaches 2 at most: avoiding x in [5, 10] then is
    SAFE, decided before the chatter; over [0, 1.5] avoiding x in [2.4, 10] is UNSAFE (x0 = 1
    reaches 2.4 at t = 1.4), with its counterexample by t = 1.5; a piece with no clock bound
    (x in [50, 60], never reached) is explored into the chatter: not SAFE."""
    (tmp_path / "m.yaml").write_text(MODEL)
    (tmp_path / "p.yaml").write_text(
        "properties:\n"
        "  - {id: first_second, kind: safety, avoid: {box: {t: [0, 1], x: [5, 10]}}}\n"
        "  - {id: early_unsafe, kind: safety, avoid: {box: {t: [0, 1.5], x: [2.4, 10]}}}\n"
        "  - {id: any_time, kind: safety, avoid: {box: {x: [50, 60]}}}\n")
    first, early, any_time = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "star")
    assert first.status is Status.SAFE
    assert early.status is Status.UNSAFE and 1.4 - 1e-6 <= early.counterexample.violation_time <= 1.5 + 1e-9
    assert any_time.status is Status.UNKNOWN
