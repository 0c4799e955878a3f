"""Physical units and dimensions: ``10[N]``, ``0.055[m/s]``, ``state: {x: m, vx: m/min}``.

Units. A model declares its base units (``units: {length: m, time: min, mass: kg}``, SI by
default); a bracketed unit after a number converts it to those base units, so the ARCH
thrust bound ``10[N]`` becomes 36000 kg m/min^2 in a minute-based model.

Dimensions. A dimension is the exponent vector ``(length, time, mass, temperature)`` with rational
entries (``sqrt(mu/r**3)`` has time exponent -1 from ``mu`` in m^3/s^2). Every state,
input and constant has an unknown dimension ``d_v``; an expression's dimension is then an
*affine form* ``sum_v c_v d_v + k`` (a product adds forms, a power ``e**p`` scales by ``p``,
a bracketed unit adds its constant exponents), and every sum, comparison, flow
(``d(x') = d_x - time``), control law, reset and initial value asks two forms to be equal.
These are linear equations over the rationals, the same matrix for each of the three base
dimensions, so :class:`DimensionSystem` keeps them in reduced row-echelon form: a new
equation is reduced by the rows so far; ``0 = 0`` adds nothing, ``0 = k != 0`` is a
mismatch (reported at the field that brought it), anything else becomes a row. A name's
dimension is known once its form reduces to a constant; declarations are just equations
that arrive first. A plain number (no bracket) is in model units of whatever it meets: in a
sum or comparison it takes the other side's dimension, as a factor it is dimensionless.

Why not pint or sympy.physics.units: both check the dimensions of quantities that are
already known. Here most dimensions are unknown and are inferred from how names meet
(``Fx/mc`` added to an acceleration ties the dimensions of ``Fx`` and ``mc``), which is the
linear system above; neither library solves it. Their unit tables would add little to the
spacecraft units below, and the exponent arithmetic is a few lines of exact
:class:`~fractions.Fraction` algebra.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

Dimension = tuple[Fraction, Fraction, Fraction, Fraction]


def dimension(length=0, time=0, mass=0, temperature=0) -> Dimension:
    return (Fraction(length), Fraction(time), Fraction(mass), Fraction(temperature))


DIMENSIONLESS = dimension()
TIME = dimension(time=1)

# unit -> (value in SI, dimension exponents (length, time, mass, temperature))
UNITS: dict[str, tuple[float, tuple[int, int, int, int]]] = {
    "m": (1.0, (1, 0, 0, 0)),
    "km": (1e3, (1, 0, 0, 0)),
    "cm": (1e-2, (1, 0, 0, 0)),
    "mm": (1e-3, (1, 0, 0, 0)),
    "um": (1e-6, (1, 0, 0, 0)),
    "s": (1.0, (0, 1, 0, 0)),
    "min": (60.0, (0, 1, 0, 0)),
    "h": (3600.0, (0, 1, 0, 0)),
    "day": (86400.0, (0, 1, 0, 0)),
    "kg": (1.0, (0, 0, 1, 0)),
    "g": (1e-3, (0, 0, 1, 0)),
    "N": (1.0, (1, -2, 1, 0)),
    "mN": (1e-3, (1, -2, 1, 0)),
    "uN": (1e-6, (1, -2, 1, 0)),
    "rad": (1.0, (0, 0, 0, 0)),
    "deg": (math.pi / 180.0, (0, 0, 0, 0)),
    "J": (1.0, (2, -2, 1, 0)),
    "W": (1.0, (2, -3, 1, 0)),
    "K": (1.0, (0, 0, 0, 1)),
    "mK": (1e-3, (0, 0, 0, 1)),
}

BASE_KINDS = {"length": 0, "time": 1, "mass": 2, "temperature": 3}


def known_units() -> str:
    """The unit names a model may use, for error messages."""
    return ", ".join(UNITS)


def _power(name: str, exponent: Fraction) -> str:
    if exponent == 1:
        return name
    text = str(exponent)
    return f"{name}**{text}" if exponent.denominator == 1 else f"{name}**({text})"


@dataclass(frozen=True)
class UnitSystem:
    """The base units a model is written in."""

    length: str = "m"
    time: str = "s"
    mass: str = "kg"
    temperature: str = "K"

    def factor(self, dim) -> float:
        """SI value of one model unit of the given dimension."""
        scale = 1.0
        for base, exponent in zip((self.length, self.time, self.mass, self.temperature), dim):
            scale *= UNITS[base][0] ** float(exponent)
        return scale

    def convert(self, si_value: float, dim) -> float:
        """Express an SI quantity in this system's units."""
        return si_value / self.factor(dim)

    def name(self, dim: Dimension) -> str:
        """The model unit of ``dim`` written as a bracket unit: ``kg*m/min**2``, ``1/s``, ``1``."""
        order = [(self.mass, dim[2]), (self.length, dim[0]), (self.temperature, dim[3]), (self.time, dim[1])]
        top = [_power(n, e) for n, e in order if e > 0]
        bottom = [_power(n, -e) for n, e in order if e < 0]
        numerator = "*".join(top) if top else "1"
        if not bottom:
            return numerator
        denominator = bottom[0] if len(bottom) == 1 else f"({'*'.join(bottom)})"
        return f"{numerator}/{denominator}"


SI = UnitSystem()


def check_base(kind: str, name: str) -> str | None:
    """Why ``name`` cannot be the base unit for ``kind`` (or None if it can)."""
    if name not in UNITS:
        return f"unknown unit '{name}' (known: {known_units()})"
    dim = UNITS[name][1]
    expected = [0, 0, 0, 0]
    expected[BASE_KINDS[kind]] = 1
    if list(dim) != expected:
        return f"'{name}' is not a unit of {kind}"
    return None


@dataclass(frozen=True)
class DisplayUnit:
    """The unit a requirement was written in: ``text`` (``N``, ``(m/s)**2``, ``""`` for a pure
    number) and ``scale``, the size of one such unit in model units (36000 for N in a
    kg, m, min model): a model value ``v`` reads ``v / scale`` of them."""

    text: str
    dimension: Dimension
    scale: float

    def of(self, model_value: float) -> float:
        return model_value / self.scale


def model_display(units: UnitSystem, dim: Dimension) -> DisplayUnit:
    """The model's own unit of ``dim`` (scale 1)."""
    text = units.name(dim)
    return DisplayUnit("" if text == "1" else text, dim, 1.0)


def bracket_display(units: UnitSystem, dim: Dimension, text: str, si: float,
                    unit_dim: Dimension) -> DisplayUnit | None:
    """``dim`` expressed in powers of a bracketed unit ``[text]``, if ``dim = k * unit_dim``."""
    if dim == DIMENSIONLESS:          # an angle in [deg] reads in degrees; a pure number as it is
        named = unit_dim == DIMENSIONLESS and text not in ("", "1")
        return DisplayUnit(text if named else "", dim, si if named else 1.0)
    ratios = {d / u for d, u in zip(dim, unit_dim) if u != 0}
    if len(ratios) != 1 or any(d != 0 for d, u in zip(dim, unit_dim) if u == 0):
        return None
    k = ratios.pop()
    simple = text.isidentifier()
    shown = text if k == 1 else _power(text if simple else f"({text})", k)
    return DisplayUnit(shown, dim, si ** float(k) / units.factor(dim))


# ------------------------------------------------------------------ dimension inference

ZERO = DIMENSIONLESS


def _add(a: Dimension, b: Dimension, k: Fraction = Fraction(1)) -> Dimension:
    return tuple(x + k * y for x, y in zip(a, b))


class Form:
    """``sum_v coeffs[v] * d_v + const``: a dimension affine in unknown dimensions ``d_v``."""

    __slots__ = ("coeffs", "const")

    def __init__(self, coeffs: dict | None = None, const: Dimension = ZERO):
        self.coeffs = {k: v for k, v in (coeffs or {}).items() if v != 0}
        self.const = const

    @classmethod
    def name(cls, name: str) -> "Form":
        return cls({name: Fraction(1)})

    def plus(self, other: "Form", k: Fraction = Fraction(1)) -> "Form":
        coeffs = dict(self.coeffs)
        for v, c in other.coeffs.items():
            coeffs[v] = coeffs.get(v, 0) + k * c
        return Form(coeffs, _add(self.const, other.const, k))

    def minus(self, other: "Form") -> "Form":
        return self.plus(other, Fraction(-1))

    def times(self, k: Fraction) -> "Form":
        return Form({v: k * c for v, c in self.coeffs.items()}, _add(ZERO, self.const, k))


class DimensionSystem:
    """The equations between unknown dimensions, in reduced row-echelon form.

    ``rows[p]`` is an equation ``form == 0`` with coefficient 1 on its pivot ``p`` and no
    other row's pivot in it, so reducing any form takes one pass over its names.
    """

    def __init__(self):
        self.rows: dict[str, Form] = {}
        #: the units states and inputs were declared in, as written: ``name -> (text, SI value,
        #: dimension)``, so a value of ``w: rad/s`` reads in rad/s, not in the ``1/s`` it reduces to
        self.written: dict[str, tuple] = {}

    def copy(self) -> "DimensionSystem":
        other = DimensionSystem()
        other.rows, other.written = dict(self.rows), dict(self.written)
        return other

    def reduce(self, form: Form) -> Form:
        out = form
        for v, c in form.coeffs.items():
            if v in self.rows:
                out = out.plus(self.rows[v], -c)
        return out

    def value(self, form: Form) -> Dimension | None:
        """The dimension ``form`` stands for, if the equations so far fix it."""
        reduced = self.reduce(form)
        return None if reduced.coeffs else reduced.const

    def of(self, name: str) -> Dimension | None:
        return self.value(Form.name(name))

    def equate(self, a: Form, b: Form) -> bool:
        """Add ``a == b``; False (and nothing added) if it contradicts the equations so far."""
        reduced = self.reduce(a.minus(b))
        if not reduced.coeffs:
            return reduced.const == ZERO
        pivot = next(iter(reduced.coeffs))
        row = reduced.times(1 / reduced.coeffs[pivot])
        for p, r in self.rows.items():
            if pivot in r.coeffs:
                self.rows[p] = r.plus(row, -r.coeffs[pivot])
        self.rows[pivot] = row
        return True
