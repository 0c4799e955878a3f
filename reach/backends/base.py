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


def run(backend: Backend, model, prop, options: dict | None = None) -> Result:
    """``check`` guarded by ``supports``, timed."""
    reason = backend.supports(model, prop)
    if reason is not None:
        return unsupported(backend.name, model, prop, reason)
    start = time.perf_counter()
    result = backend.check(model, prop, options or {})
    result.seconds = time.perf_counter() - start
    return result

