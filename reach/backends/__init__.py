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


# name -> the options dataclass of its module (``from_dict`` checks names, types and ranges)
OPTIONS = {"montecarlo": "Options", "star": "StarOptions", "fsr": "Options", "taylor": "Options"}


def validate_options(name: str, options: dict | None) -> None:
    """Raise the InputError of the first bad option for back-end ``name``, before any work, so a
    typo is reported even when no property reaches the back-end."""
    getattr(importlib.import_module(BACKENDS[name]), OPTIONS[name]).from_dict(options or {})


def available() -> list[str]:
    """Names of the back-ends whose module exists in this installation."""
    names = []
    for name, module in BACKENDS.items():
        if importlib.util.find_spec(module) is not None:
            names.append(name)
    return names


def backend(name: str):
    """The back-end object of ``name`` (its module imported on first use)."""
    return importlib.import_module(BACKENDS[name]).BACKEND
