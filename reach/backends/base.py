"""The back-end interface and registry.

A back-end takes a loaded :class:`~reach.model.automaton.HybridAutomaton` and a bound
property (:mod:`reach.spec.properties`) and returns a :class:`~reach.result.Result`. It never
reads YAML and never prints.
"""

from __future__ import annotations

import time
from typing import Protocol

from reach.result import Result, Status


class Backend(Protocol):
    name: str

    def supports(self, model, prop) -> str | None:
        """None if the back-end can check ``prop`` on ``model``, else the reason it cannot."""

    def check(self, model, prop, options: dict | None = None) -> Result:
        """Check one bound property; options are the back-end's own settings."""


def unsupported(backend: str, model, prop, reason: str) -> Result:
    return Result(backend, model.name, prop.id, Status.UNSUPPORTED, 0.0, details={"reason": reason})


def input_reason(backend, model) -> str | None:
    """Time-varying bounded inputs are carried as zero-flow states; only a back-end that treats
    them as inputs (class attribute ``varying_inputs = True``) may check such a model."""
    if model.varying_inputs and not getattr(backend, "varying_inputs", False):
        names = ", ".join(u.name for u in model.varying_inputs)
        return f"time-varying bounded inputs ({names}) are not supported by {backend.name}"
    return None


def run(backend: Backend, model, prop, options: dict | None = None) -> Result:
    """``check`` guarded by ``supports``, timed."""
    reason = input_reason(backend, model) or backend.supports(model, prop)
    if reason is not None:
        return unsupported(backend.name, model, prop, reason)
    start = time.perf_counter()
    result = backend.check(model, prop, options or {})
    result.seconds = time.perf_counter() - start
    return result

