"""Physical units in expressions: ``10[N]``, ``0.055[m/s]``, ``42164[km]``.

A model declares its base units (``units: {length: m, time: min, mass: kg}``, SI by
default); a bracketed unit after a number converts it to those base units, so the
ARCH thrust bound ``10[N]`` becomes 36000 kg m/min^2 in a minute-based model.
"""

from __future__ import annotations

from dataclasses import dataclass

# unit -> (value in SI, dimension exponents (length, time, mass))
UNITS: dict[str, tuple[float, tuple[int, int, int]]] = {
    "m": (1.0, (1, 0, 0)),
    "km": (1e3, (1, 0, 0)),
    "cm": (1e-2, (1, 0, 0)),
    "mm": (1e-3, (1, 0, 0)),
    "um": (1e-6, (1, 0, 0)),
    "s": (1.0, (0, 1, 0)),
    "min": (60.0, (0, 1, 0)),
    "h": (3600.0, (0, 1, 0)),
    "day": (86400.0, (0, 1, 0)),
    "kg": (1.0, (0, 0, 1)),
    "g": (1e-3, (0, 0, 1)),
    "N": (1.0, (1, -2, 1)),
    "mN": (1e-3, (1, -2, 1)),
    "uN": (1e-6, (1, -2, 1)),
    "rad": (1.0, (0, 0, 0)),
    "deg": (3.141592653589793 / 180.0, (0, 0, 0)),
    "J": (1.0, (2, -2, 1)),
}

BASE_KINDS = {"length": 0, "time": 1, "mass": 2}


@dataclass(frozen=True)
class UnitSystem:
    """The base units a model is written in."""

    length: str = "m"
    time: str = "s"
    mass: str = "kg"

    def factor(self, dimension: tuple[int, int, int]) -> float:
        """SI value of one model unit of the given dimension."""
        scale = 1.0
        for base, exponent in zip((self.length, self.time, self.mass), dimension):
            scale *= UNITS[base][0] ** exponent
        return scale

    def convert(self, si_value: float, dimension: tuple[int, int, int]) -> float:
        """Express an SI quantity in this system's units."""
        return si_value / self.factor(dimension)


SI = UnitSystem()


def check_base(kind: str, name: str) -> str | None:
    """Why ``name`` cannot be the base unit for ``kind`` (or None if it can)."""
    if name not in UNITS:
        return f"unknown unit '{name}'"
    dimension = UNITS[name][1]
    expected = [0, 0, 0]
    expected[BASE_KINDS[kind]] = 1
    if list(dimension) != expected:
        return f"'{name}' is not a unit of {kind}"
    return None
