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
