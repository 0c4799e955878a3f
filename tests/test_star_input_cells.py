"""Time-varying inputs carried by generators (star option ``input_cells``,
:class:`reach.backends.star.flowpipe.ChainInputs`): the block decomposition holds every
signal's effect (checked against scipy quadrature of random signals), and through a jump the
generators keep the input's directions that a box loses (checked against the closed-form least
value over all measurable signals)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.star import BACKEND
from reach.backends.star.flowpipe import AffineFlow
from reach.model import load_model
from reach.result import Status
from reach.spec import bind, load_properties
from model_files import load_files

PUSHED = """
name: pushed_then_released
state: [x, v, t]
bounded_inputs:
  u: {range: [-1, 1], varying: true}
modes:
  pushed: {flow: {x: v, v: "-x - v + u", t: 1}, invariant: ["t <= 3"]}
  released: {flow: {x: v, v: "-4*x - 0.5*v", t: 1}}
transitions:
  - {from: pushed, to: released, guard: ["t >= 3"]}
initial: {mode: pushed, box: {x: [0, 0], v: [0, 0], t: 0}}
horizon: 6
"""

A1 = np.array([[0.0, 1.0], [-1.0, -1.0]])
A2 = np.array([[0.0, 1.0], [-4.0, -0.5]])
B = np.array([0.0, 1.0])


def _least_x_after_release() -> float:
    """The least x any signal |u| <= 1 on [0, 3] reaches in ``released`` (t in [3, 6]):
    x(T) = int_0^3 g(s) u(s) ds with g(s) = [e^{A2 (T - 3)} e^{A1 (3 - s)} B]_x, least
    -int |g| (bang-bang on the sign of g), by quadrature on a fine grid, over T on a grid."""
    s = np.linspace(0.0, 3.0, 30001)
    G = np.array([sl.expm(A1 * (3.0 - si)) @ B for si in s])
    return min(-np.trapezoid(np.abs(G @ sl.expm(A2 * (T - 3.0)).T[:, 0]), s)
               for T in np.linspace(3.0, 6.0, 241))


def _check(folder, require: str, **options):
    (folder / "m.yaml").write_text(PUSHED)
    (folder / "p.yaml").write_text(f"properties: [{{id: p, kind: safety, modes: [released], require: '{require}'}}]\n")
    model = load_model(folder / "m.yaml")
    return BACKEND.check(model, bind(load_properties(folder / "p.yaml")[0], model), options)


def _proved_least_x(result) -> float:
    """The least x over the kept flowpipe pieces of ``released`` (each piece a hull of stars
    plus a box)."""
    low = np.inf
    for piece in result.sets:
        if piece.mode == "released":
            d = np.zeros(len(piece.names))
            d[piece.coordinate("x")] = -1.0
            bloat = 0.0 if piece.bloat is None else piece.bloat[piece.coordinate("x")]
            low = min(low, -max(s.support(d) for s in piece.stars) - bloat)
    return low


@pytest.fixture(scope="module")
def least():
    return _least_x_after_release()


@pytest.mark.parametrize("cells", [0, 15, 2])
def test_bound_after_the_jump_encloses_the_closed_form(tmp_path, least, cells):
    result = _check(tmp_path, "x >= -10", input_cells=cells, keep_sets=True)
    assert result.status is Status.SAFE
    assert _proved_least_x(result) <= least + 1e-9


def test_generators_keep_the_inputs_directions_through_the_jump(tmp_path, least):
    """The box of the input effect at the jump (0 blocks) is some 0.1 below the exact least x
    after it; generator blocks of two cells come within a fifth of that."""
    box = least - _proved_least_x(_check(tmp_path, "x >= -10", input_cells=0, keep_sets=True))
    generators = least - _proved_least_x(_check(tmp_path, "x >= -10", input_cells=2, keep_sets=True))
    assert 0 <= generators < box / 5


def test_a_bound_the_worst_signal_passes_is_never_safe(tmp_path, least):
    result = _check(tmp_path, f"x >= {least + 0.01}", input_cells=2)
    assert result.status is not Status.SAFE


def _integral(A, B, a, b):
    """``int_a^b e^{A r} B dr`` exactly (expm of the augmented matrix)."""
    n, p = B.shape
    M = np.zeros((n + p, n + p))
    M[:n, :n], M[:n, n:] = A, B
    return sl.expm(A * a) @ sl.expm(M * (b - a))[:n, n:]


@settings(max_examples=25, deadline=None)
@given(cells=st.integers(1, 4), h=st.floats(0.05, 1.0), seed=st.integers(0, 2**31 - 1))
def test_block_decomposition_holds_a_random_signal(cells, h, seed):
    """For a random piecewise-constant signal, the block's effect v = int_0^T G(r) u(T - r) dr
    (exact per piece) is S (x, y) plus at most eps, with x = int u / (T u_r) and
    y = int phi u / (T u_r) (phi = (2 r - T) / T), and (x, y) satisfies the coupling rows."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 3))
    Bm = rng.normal(size=(3, 2))
    u_r = rng.uniform(0.1, 2.0, size=2)
    flow = AffineFlow(A, np.zeros(3), Bm, u_r)
    S, eps = flow.input_block(h, cells)
    T = cells * h
    edges = np.concatenate([[0.0], np.sort(rng.uniform(0.0, T, size=5)), [T]])   # pieces in r
    values = rng.uniform(-1.0, 1.0, size=(6, 2)) * u_r
    v = sum(_integral(A, Bm, a, b) @ value for a, b, value in zip(edges[:-1], edges[1:], values))
    x = sum((b - a) * value for a, b, value in zip(edges[:-1], edges[1:], values)) / (T * u_r)
    y = sum(((b * b - a * a) - T * (b - a)) / T * value
            for a, b, value in zip(edges[:-1], edges[1:], values)) / (T * u_r)
    assert np.all(np.abs(x) + np.abs(y) <= 1 + 1e-12) and np.all(np.abs(y) <= 0.5 + 1e-12)
    assert np.all(np.abs(v - S @ np.concatenate([x, y])) <= eps + 1e-9 * (1 + np.abs(v)))


def test_a_check_past_its_memory_share_is_unknown_naming_memory(tmp_path, monkeypatch):
    """The resident set is read at chains and cells: beyond the share the answer is
    UNKNOWN with the reason, never an out-of-memory kill (here a share no process fits in)."""
    from reach.backends.star import explorer

    monkeypatch.setattr(explorer, "MEMORY_FRACTION", 1e-9)
    result = _check(tmp_path, "x >= -10", input_cells=2)
    assert result.status is Status.UNKNOWN and "memory" in result.details["reason"]


DOUBLE_INTEGRATOR = """
name: double_integrator
state: [x, v]
bounded_inputs:
  u: {range: [-1, 1], varying: true}
modes:
  go: {flow: {x: v, v: u}}
initial: {mode: go, box: {x: 0, v: 0}}
horizon: 2
"""


@pytest.mark.parametrize("bound,status", [(1.05, Status.SAFE), (0.95, Status.UNSAFE)])
def test_the_input_box_cut_along_the_requirement_decides_in_the_first_pass(tmp_path, bound, status):
    """``x - v = int_0^T (T - 1 - s) u(s) ds`` from rest, largest over |u| <= 1 and T <= 2 at
    T = 2 with u = sign(1 - s): 1. The box of the input effect (exact per state, not jointly)
    puts the largest x with the smallest v, at 2 + 2 = 4 over T = 2; cut along ``x - v`` by the
    input's exact support there, ``int_0^T |T - 1 - s| ds``, the first pass (one box per chain,
    no generators, no finer step) decides both sides, and its counterexample replays."""
    from reach.backends.montecarlo import replay

    model, props = load_files(tmp_path, DOUBLE_INTEGRATOR,
                              f"properties:\n  - {{id: p, kind: safety, require: ['x - v <= {bound}']}}\n")
    prop = props["p"]
    result = BACKEND.check(model, prop, {"finer_retry": False, "input_cells": 0})
    assert result.status is status
    assert "input effect carried as generators" not in result.details["semantics"]
    if status is Status.UNSAFE:
        c = result.counterexample
        assert replay(model, prop, c.initial_state, c.switch_time, input_signal=c.input_signal).violated


def test_the_memory_share_follows_an_address_space_limit():
    """Under ``ulimit -v`` (RLIMIT_AS) of 3 GiB the memory star may take a share of is at most
    3 GiB, not the machine's (a process killed at its limit is no answer); without one, it is at
    least that (this machine has more)."""
    import subprocess
    import sys

    code = ("import resource; from reach.memory import physical_bytes; free = physical_bytes(); "
            "resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, resource.RLIM_INFINITY)); "
            "print(free, physical_bytes())")
    free, limited = map(float, subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                              check=True).stdout.split())
    assert limited <= 3 * 2**30 and (free > 3 * 2**30 or free == limited)


ROTATING_EXIT = """
name: rotating_exit
state: [x, y]
bounded_inputs:
  u: {range: [-0.2, 0.2], varying: true}
modes:
  A: {flow: {x: y, y: "-x + u"}, invariant: ["x <= 1"]}
  B: {flow: {x: y, y: "-x"}}
transitions:
  - {from: A, to: B, guard: ["x >= 1"], urgent: true, reset: {x: "x - 2", y: "-y"}}
initial: {mode: A, box: {x: 0, y: 1}}
horizon: 3
"""


def test_a_check_leaves_no_cyclic_garbage_behind(tmp_path):
    """A check that refines cells and ends UNKNOWN leaves nothing for the cycle collector:
    every star it built is freed when it returns, so the next property of the same file starts
    with the memory the first one took (the failures' tracebacks held the frames they came
    through, each with its stars, and a replay's simulator and its crossings referred to each
    other, until the collector ran: 4.7 GiB held after one property of a four-property file,
    the last one then out of memory)."""
    import gc

    from reach.model.simulate import Simulator
    from reach.sets import Star

    model, props = load_files(tmp_path, ROTATING_EXIT,
                              "properties:\n  - {id: p, kind: safety, modes: [B], require: ['y >= -0.633']}\n")
    options = {"finer_retry": False, "max_refinements": 3, "max_unresolved": 1}   # stops in the search
    BACKEND.check(model, props["p"], options)           # compiled flows and caches in place
    gc.collect()
    gc.disable()
    try:
        gc.set_debug(gc.DEBUG_SAVEALL)
        result = BACKEND.check(model, props["p"], options)
        assert result.status is Status.UNKNOWN and result.details["refined_cells"] > 0
        del result
        gc.collect()
        left = [type(o).__name__ for o in gc.garbage
                if isinstance(o, (Star, Simulator, BaseException)) or type(o).__name__ in ("frame", "traceback")]
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        gc.enable()
    assert left == []
