"""Why a back-end's result holds no sets to draw, in words for the picture and the console.

What a back-end hands the plotter (:attr:`reach.result.Result.sets`, with its option
``keep_sets``) depends on the back-end and the kind of property:

* star keeps its flowpipe segments; it checks safety properties only;
* taylor keeps the step enclosures of its rigorous sweeps (``remainder: rigorous``) of safety
  and event properties, and none when every sweep failed (the step size collapsed, too many
  mode switches): the result says why;
* montecarlo keeps sampled runs of safety and event properties, none for a probability;
* fsr keeps nothing: it integrates the distribution of the states, it computes no set.

:data:`KEPT` says so for the picture; tests/test_plot_missing.py checks it against the back-ends.
"""

from __future__ import annotations

from dataclasses import dataclass

from reach.result import Status


@dataclass(frozen=True)
class Kept:
    """What a back-end keeps for pictures, and for which kinds of property."""

    what: str
    kinds: tuple[str, ...]


KEPT = {
    "star": Kept("flowpipe segments", ("safety",)),
    "taylor": Kept("step enclosures", ("safety", "event")),
    "montecarlo": Kept("sampled runs", ("safety", "event")),
}

#: what a back-end that keeps no sets computes instead
COMPUTES = {"fsr": "it integrates the distribution of the states and computes no set"}


def why_no_sets(backend: str, result, prop) -> str:
    """Why ``result`` (of ``backend`` for the bound property ``prop``) holds no sets, as words
    following the back-end's name."""
    kept = KEPT.get(backend)
    if result.status == Status.UNSUPPORTED:
        return f"does not check {prop.id}: {result.details.get('reason', 'unsupported')}"
    if kept is None:
        return f"keeps no sets ({COMPUTES.get(backend, 'it hands none to pictures')})"
    if prop.kind not in kept.kinds:
        return f"keeps its {kept.what} for {' and '.join(kept.kinds)} properties only"
    if backend == "taylor" and not str(result.details.get("remainder", "")).startswith("rigorous"):
        return "keeps its step enclosures with remainder: rigorous only (-o taylor.remainder=rigorous)"
    told = result.details.get("reason") or result.details.get("note")
    return f"kept no {kept.what} for {prop.id}" + (f": {told}" if told else "")


def suggestion(backend: str, model, props, requested=()) -> str:
    """What would draw ``props`` (bound properties ``backend`` drew nothing of): ``try --backend
    B`` with the back-ends that keep sets for one of them and handle it (other than ``backend``
    and those ``requested``); ``no back-end keeps sets for ...`` when none keeps sets for their
    kinds; else nothing (an empty text)."""
    from reach.backends import backend as named

    kinds = list(dict.fromkeys(p.kind for p in props))
    if not any(kind in kept.kinds for kept in KEPT.values() for kind in kinds):
        return f"no back-end keeps sets for {' or '.join(k.replace('_', '-') for k in kinds)} properties"
    others = [b for b, kept in KEPT.items() if b != backend and b not in requested
              and any(p.kind in kept.kinds and named(b).supports(model, p) is None for p in props)]
    return f"try --backend {' or '.join(others)}" if others else ""
