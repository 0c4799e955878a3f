"""Verification back-ends; each module exposes one object with ``name``, ``supports``, ``check``."""

from __future__ import annotations

import importlib

# name -> module path; a module is imported only when its back-end is asked for
BACKENDS = {
    "montecarlo": "reach.backends.montecarlo",
    "star": "reach.backends.star",
    "fsr": "reach.backends.fsr",
    "taylor": "reach.backends.taylor",
}


def available() -> list[str]:
    """Names of the back-ends whose module exists in this installation."""
    names = []
    for name, module in BACKENDS.items():
        if importlib.util.find_spec(module) is not None:
            names.append(name)
    return names


def registry() -> dict:
    return {name: importlib.import_module(BACKENDS[name]).BACKEND for name in available()}
