"""Extremal input signals of star's witnesses: the bang-bang input that attains the input's
exact support, and single-instant forbidden sets (``t == T``) found UNSAFE with it."""

from __future__ import annotations

import numpy as np
import pytest
import sympy
from scipy.integrate import solve_ivp

from reach.backends.star.flowpipe import AffineFlow
from reach.backends.star.witnesses import SIGNAL_GRID_FACTOR, SIGNAL_PIECES, extremal_signal, signal_pieces
from reach.checking import check_spaceex
from reach.errors import Where
from reach.model.constraints import Constraint, violation_test
from reach.result import Status

from tests.test_star_aff import write
from tests.test_star_general_lha import bound_property, replayed


def _run(step, values, t):
    """x'' = -x + u from rest under the piecewise-constant ``values`` (scipy, tight)."""
    def rhs(s, y):
        u = values[min(int(s / step), len(values) - 1), 0]
        return [y[1], -y[0] + u]
    edges = np.arange(len(values) + 1) * step
    y = np.zeros(2)
    for a, b in zip(edges[:-1], edges[1:]):                 # piece by piece: no kink inside a step
        y = solve_ivp(rhs, (a, min(b, t)), y, rtol=1e-11, atol=1e-12, first_step=1e-4).y[:, -1]
    return y[0]


@pytest.mark.parametrize("t,maximum", [(np.pi, 2.0), (2 * np.pi, 4.0)])
def test_extremal_signal_attains_the_closed_form_maximum(t, maximum):
    """x(t) = int_0^t sin(t - s) u(s) ds <= int_0^t |sin| = 2 at pi (u = 1), 4 at 2 pi (u = -1
    then +1: a bang-bang signal no constant input reaches; a constant gives u (1 - cos t))."""
    flow = AffineFlow(np.array([[0.0, 1.0], [-1.0, 0.0]]), np.zeros(2), np.array([[0.0], [1.0]]),
                      np.array([1.0]))
    step, values = extremal_signal(flow, np.array([1.0, 0.0]), t, [-1.0], [1.0], pieces=200)
    assert np.all(np.abs(values) == 1.0)
    switches = int(np.count_nonzero(np.diff(values[:, 0])))
    assert switches == (0 if t < 4 else 1)
    assert _run(step, values, t) == pytest.approx(maximum, abs=1e-3)


OSCILLATOR = '''<component id="osc">
 <param name="x" type="real" local="false" dynamics="any"/>
 <param name="v" type="real" local="false" dynamics="any"/>
 <param name="t" type="real" local="false" dynamics="any"/>
 <param name="u" type="real" local="false" dynamics="any" controlled="false"/>
 <location id="1" name="run"><invariant>-1 &lt;= u &lt;= 1</invariant>
  <flow>x' == v &amp; v' == -x + u &amp; t' == 1</flow></location>
</component>
'''


@pytest.mark.parametrize("bound,status", [(3.9, Status.UNSAFE), (4.2, Status.SAFE)])
def test_single_instant_forbidden_set(tmp_path, bound, status):
    """x(2 pi) >= bound at the instant t == 2 pi (the shape of Building BDU02): the maximum 4
    needs the bang-bang input, constant inputs give x(2 pi) = 0. Below 4: UNSAFE, replayed
    with the witness's input signal; above: SAFE."""
    T = float(2 * np.pi)
    xml, cfg = write(tmp_path, OSCILLATOR, f'system = osc\ninitially = "x == 0 & v == 0 & t == 0"\n'
                     f'forbidden = "x >= {bound} & t == {T!r}"\ntime-horizon = 7\n')
    (result,), *_ = check_spaceex(xml, cfg, "star", {"step": 7 / 80})
    assert result.status is status, result.details.get("reason")
    if status is Status.UNSAFE:
        ce = result.counterexample
        assert ce.violation_time == pytest.approx(T, abs=1e-9)
        assert ce.violation_state[0] >= bound
        values = np.array(ce.input_signal["values"])
        assert set(np.unique(values)) == {-1.0, 1.0}            # bang-bang, not held constant
        assert _run(ce.input_signal["step"], values, T) >= bound   # independent replay (scipy)


def test_an_equality_is_met_up_to_rounding_and_the_other_rows_robustly():
    x, t = sympy.symbols("x t")
    where = Where("p", 1)
    piece = [Constraint(x - 1, True, "x < 1", where), Constraint(t - 20, False, "t <= 20", where),
             Constraint(20 - t, False, "t >= 20", where)]
    test = violation_test(piece, [x, t])
    X = np.array([[0.5, 20.0], [0.5, 20.0 + 1e-12], [0.5, 20.0 + 1e-6], [1.0, 20.0], [0.5, 19.0]])
    inside, depth = test(X)
    assert inside.tolist() == [True, True, False, False, False]
    assert depth[0] == pytest.approx(-0.5)
    assert np.all(depth[2:] >= 0)
    closed = violation_test(piece[:2], [x, t])                  # no equality: the robust test as before
    assert closed(np.array([[0.5, 20.0]]))[0].tolist() == [False]


def test_signal_pieces_keep_the_replay_grid_bounded():
    """An instant early on a long horizon (2 pi of 63000, the simulator's default step 26.25)
    gets fewer, longer pieces, so the replay's grid (a divisor of the piece length) stays within
    SIGNAL_GRID_FACTOR times the default grid; the coarser bang-bang signal still reaches past
    3.9 at 2 pi (closed-form maximum 4, one switch at pi), checked by scipy."""
    base = 63000 / 2400
    pieces = signal_pieces(2 * np.pi, base)
    assert 1 <= pieces < SIGNAL_PIECES
    assert 2 * np.pi / pieces >= base / SIGNAL_GRID_FACTOR
    assert signal_pieces(20.0, 20 / 2400) == SIGNAL_PIECES          # the Building's instant: unchanged
    flow = AffineFlow(np.array([[0.0, 1.0], [-1.0, 0.0]]), np.zeros(2), np.array([[0.0], [1.0]]),
                      np.array([1.0]))
    step, values = extremal_signal(flow, np.array([1.0, 0.0]), 2 * np.pi, [-1.0], [1.0], pieces)
    assert _run(step, values, 2 * np.pi) > 3.9


@pytest.mark.parametrize("bound, status", [(-0.01, Status.SAFE), (0.5, Status.UNSAFE)])
def test_a_witness_at_the_first_instant_is_no_bad_input(tmp_path, bound, status):
    """y - 2 x = int_0^t (u - 1) ds >= 0 for u in [1, 2]: a bound below 0 holds, one above 0
    fails from the start (t = 0 itself). The closest approach of the first is at t = 0, where an
    extremal signal would aim at an instant of 1e-8 (a 5e9-piece signal); such a candidate is
    no replay at all, not a bad input, and the answer stands on its own."""
    from reach.checking import check_files
    (tmp_path / "m.yaml").write_text(
        "name: havoc\nstate: [x, y]\nbounded_inputs:\n  u: {range: [1, 2], varying: true}\n"
        "modes:\n  running: {flow: {x: 1, y: \"1 + u\"}, invariant: [\"x <= 5\"]}\n"
        "initial: {mode: running, box: {x: 0, y: 0}}\nhorizon: 20\n")
    (tmp_path / "p.yaml").write_text(
        f"properties:\n  - {{id: above, kind: safety, require: [\"y - 2*x >= {bound}\"]}}\n")
    (result,) = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "star")
    assert result.status is status


def test_extremal_signal_follows_the_path_through_jumps_and_resets():
    """A path ``A, B, A, B`` switching at 1, 2, 3 (``y' = u - 0.1 y`` in A, ``y' = -u - 0.1 y``
    in B) and a reset ``y+ = 2 y`` at the last jump: ``y(4) = int_0^4 e^{-0.1 (4 - s)} k(s)
    sigma(s) u(s) ds`` with ``sigma = +1, -1, +1, -1`` and ``k = 2`` before 3, 1 after, so the
    maximum takes ``u = sigma`` (the signal flips at each jump, which the last mode's flow alone
    would never ask for) and is ``2 * 10 (e^{-0.1} - e^{-0.4}) + 10 (1 - e^{-0.1})``."""
    A = np.array([[-0.1]])
    up = AffineFlow(A, np.zeros(1), np.array([[1.0]]), np.array([1.0]))
    down = AffineFlow(A, np.zeros(1), np.array([[-1.0]]), np.array([1.0]))
    one, two = np.eye(1), 2 * np.eye(1)
    earlier = [(up, 1.0, one), (down, 2.0, one), (up, 3.0, two)]
    step, values = extremal_signal(down, np.array([1.0]), 4.0, [-1.0], [1.0], pieces=400, earlier=earlier)
    sigma = np.array([1.0, -1.0, 1.0, -1.0])[np.minimum((np.arange(400) * step / 1.0).astype(int), 3)]
    assert np.array_equal(values[:, 0], sigma)
    y = 0.0
    for k, (flow, u) in enumerate(zip([up, down, up, down], sigma[::100])):     # exact, piece by piece
        Phi, psi = AffineFlow(A, flow.B[:, 0] * u).step(1.0)
        y = (Phi @ [y] + psi)[0] * (2.0 if k == 2 else 1.0)
    truth = 2 * 10 * (np.exp(-0.1) - np.exp(-0.4)) + 10 * (1 - np.exp(-0.1))
    assert y == pytest.approx(truth, rel=1e-12)
    held = extremal_signal(down, np.array([1.0]), 4.0, [-1.0], [1.0], pieces=400)[1]
    assert np.all(held[:, 0] == -1.0)                       # the last mode alone: no flip


FLIP = """
name: flip
state: [y, c]
bounded_inputs:
  u: {range: [-1, 1], varying: true}
modes:
  A: {flow: {y: "u - 0.1*y", c: "1"}, invariant: ["c <= 1"]}
  B: {flow: {y: "-u - 0.1*y", c: "1"}, invariant: ["c <= 1"]}
transitions:
  - {from: A, to: B, guard: ["c >= 1"], reset: {c: "0"}, urgent: true}
  - {from: B, to: A, guard: ["c >= 1"], reset: {c: "0"}, urgent: true}
initial: {mode: A, box: {y: [0, 0], c: [0, 0]}}
horizon: 4
"""


def test_a_witness_whose_input_flips_at_each_jump_replays(tmp_path):
    """In the flip model the largest ``y(4) = 10 (1 - e^{-0.4})`` needs ``u = +1`` in A and
    ``-1`` in B: the input held constant, or the bang-bang signal of the witness mode's flow
    alone (``u = -1`` throughout), reaches about 0. A bound 0.05 % below the maximum was
    UNKNOWN; the signal of the witness's path (adjoint through the jumps) replays it."""
    from reach.backends.star import BACKEND

    truth = 10 * (1 - np.exp(-0.4))
    (tmp_path / "m.yaml").write_text(FLIP)
    (tmp_path / "p.yaml").write_text(f"properties:\n  - {{id: p, kind: safety, require: ['y <= {float(truth * 0.9995)!r}']}}\n")
    model, prop = bound_property(tmp_path)
    result = BACKEND.check(model, prop, {"finer_retry": False})
    assert result.status is Status.UNSAFE, result.details.get("reason")
    assert replayed(model, prop, result)[0].violated
