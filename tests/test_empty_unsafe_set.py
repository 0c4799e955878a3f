"""A property whose unsafe set is empty by constants (SpaceEx ``forbidden = false``, a requirement
``0 <= 1``) is SAFE for every formal back-end without exploring: before, star explored the model and a
failed exploration (a jump limit, a linearisation that did not close) decided the verdict. montecarlo,
which never says SAFE (DESIGN), says UNKNOWN with the same argument and no violating run."""

from __future__ import annotations

import pytest

from reach.checking import check_model, resolve_backend
from reach.result import Status
from model_files import load_files

# x' = x^2 blows up at t = 1 / x0 < 1.9 (the horizon): star's linearisation cannot close, and the
# jump back and forth at x = 1 (closed guards both ways, no clock) would hit the jump limit
GROWING = """
name: grow
state: [x]
modes:
  a: {flow: {x: "x*x"}}
  b: {flow: {x: "x*x"}}
transitions:
  - {from: a, to: b, guard: ["x >= 1"]}
  - {from: b, to: a, guard: ["x <= 1"]}
initial: {mode: a, box: {x: [0.5, 0.6]}}
horizon: 1.9
"""


@pytest.mark.parametrize("backend", ["star", "montecarlo", "taylor"])
def test_an_empty_unsafe_set_is_safe_for_every_formal_back_end(tmp_path, backend):
    model, props = load_files(tmp_path, GROWING, """
        properties:
          - {id: nothing, kind: safety, modes: [a, b], require: ["0 <= 1"]}
          - {id: never, kind: safety, modes: [a], avoid: ["x >= 0", "1 <= 0"]}
          - {id: real, kind: safety, modes: [a, b], require: ["x <= 0.55"]}
    """)
    results = check_model(resolve_backend(backend), model, list(props.values()), {})
    if backend == "montecarlo":
        assert [r.status for r in results[:2]] == [Status.UNKNOWN, Status.UNKNOWN]
        assert all("unsafe set is empty" in r.details["reason"] for r in results[:2])
    else:
        assert [r.status for r in results[:2]] == [Status.SAFE, Status.SAFE]
        assert all("unsafe set is empty" in r.details["argument"] for r in results[:2])
    assert results[2].status is not Status.SAFE            # x0 = 0.6 breaks it at once
