"""The hybrid automaton every back-end reads: modes with closed-loop flows, invariants,
transitions (urgent, or may-transitions over a clock window or a general guard), an initial
box or polytope, bounded nondeterministic inputs, a horizon and an optional Gaussian disturbance.

All expressions are over the state symbols only: a mode's control law has already been
substituted into its flow (``flow``) and is kept apart in ``control`` for properties that
speak of inputs (thrust bounds). Linear parts are extracted once at load time:
``Mode.linear = (A, b)`` with ``x' = A x + b`` and guards/invariants as ``H x <= g``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import sympy

from reach.errors import Where
from reach.model.constraints import Constraint, affine_coefficients, halfspaces, lambdify_margins
from reach.model.units import DimensionSystem, UnitSystem

#: states (bounded inputs included) and inputs of a model, at most: the symbolic flows and the
#: back-ends' matrices grow with the square of the count (20 000 states took 22 GB to load)
MAX_VARIABLES = 1_000


@dataclass
class Controller:
    """How a mode's inputs were obtained (kept for reports): kind, gain, design weights."""

    kind: str                                 # "gain" | "lqr" | "law" | "network"
    gain: np.ndarray | None = None            # u = gain @ s (after any setpoint shift)
    feedback: list[str] = field(default_factory=list)
    Q: np.ndarray | None = None
    R: np.ndarray | None = None


@dataclass
class Mode:
    """One discrete mode; ``flow[i]`` is the closed-loop derivative of state ``i``."""

    name: str
    symbols: list[sympy.Symbol]
    flow: list[sympy.Expr]
    control: dict[str, sympy.Expr]
    invariant: list[Constraint]
    controller: Controller | None = None
    where: Where | None = None
    timeless: bool = False                    # no time may pass here (SpaceEx flow ``false``)

    def __getstate__(self):
        """Pickled without the compiled functions (each is rebuilt on first use)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("rhs", "inputs", "invariant_margins")}

    @cached_property
    def linear(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(A, b)`` with ``x' = A x + b`` if the closed-loop flow is affine, else None."""
        n = len(self.symbols)
        A, b = np.zeros((n, n)), np.zeros(n)
        for i, f in enumerate(self.flow):
            coeffs = affine_coefficients(f, self.symbols)
            if coeffs is None:
                return None
            A[i], b[i] = coeffs
        return A, b

    @cached_property
    def invariant_halfspaces(self):
        """``(H, g)`` with the invariant equal to ``H x <= g``, or None if nonlinear."""
        return halfspaces(self.invariant, self.symbols)

    @cached_property
    def rhs(self):
        """Vectorised closed-loop flow: ``X (N, n) -> X' (N, n)``."""
        fn = sympy.lambdify([self.symbols], self.flow, modules="numpy", cse=True)

        def rhs(X: np.ndarray) -> np.ndarray:
            out = np.empty_like(X)
            for i, column in enumerate(fn(X.T)):
                out[:, i] = column
            return out

        return rhs

    @cached_property
    def inputs(self):
        """Vectorised control law: ``X (N, n) -> U (N, m)`` (inputs in ``control`` order)."""
        exprs = list(self.control.values())
        if not exprs:
            return lambda X: np.zeros((X.shape[0], 0))
        fn = sympy.lambdify([self.symbols], exprs, modules="numpy")
        return lambda X: np.stack([np.broadcast_to(np.asarray(c, dtype=float), X.shape[:1])
                                   for c in fn(X.T)], axis=1)

    @cached_property
    def invariant_margins(self):
        """Vectorised invariant constraint values ``g(X)``; the invariant holds where all <= 0."""
        return lambdify_margins(self.invariant, self.symbols)


@dataclass
class Transition:
    """A discrete jump ``source -> target``.

    ``urgent``: taken the first instant the guard holds. Otherwise a may-transition; when its
    guard is a window ``lo <= c <= hi`` on a clock ``c`` (rate 1 in the source mode),
    ``window = (index of c, lo, hi)`` and the switch instant is a nondeterministic choice
    in that window (the abort of the rendezvous benchmark).
    """

    name: str
    source: str
    target: str
    guard: list[Constraint]
    urgent: bool
    reset: dict[int, sympy.Expr] = field(default_factory=dict)
    window: tuple[int, float, float] | None = None
    where: Where | None = None


@dataclass
class LinearSet:
    """The polyhedron ``{x : A x <= b, E x == f}`` (``E`` may have no rows)."""

    A: np.ndarray
    b: np.ndarray
    E: np.ndarray
    f: np.ndarray


@dataclass
class InitialSet:
    """The initial mode and set: the box ``low <= x <= high`` (equal bounds: a fixed value), or,
    when ``polytope`` is given, exactly that polytope; ``low, high`` are then its tight bounding
    box and the box rows are among ``polytope.A, b``."""

    mode: str
    low: np.ndarray
    high: np.ndarray
    polytope: LinearSet | None = None

    @property
    def is_box(self) -> bool:
        return self.polytope is None


@dataclass
class BoundedInput:
    """A nondeterministic input with values in ``[low, high]``, carried as state ``index``.

    The state has flow 0 in every mode and is never reset, so a constant input
    (``varying=False``) is exactly a state with zero derivative; a varying one is any
    measurable signal ``u(t)`` in ``[low, high]`` and appears in no guard or invariant.
    """

    name: str
    index: int
    low: float
    high: float
    varying: bool


@dataclass
class Disturbance:
    """i.i.d. Gaussian kicks ``w_k ~ N(mean, cov)`` added to the ``enters`` states at ``t = k*step``.

    Discrete-time view (what the simulator does): with ``x[k]`` the state just before the kick
    at ``k*step``, ``x[k+1] = Phi (x[k] + E w_k)`` where ``Phi`` is the mode's transition
    matrix over one step and ``E`` selects the ``enters`` states.
    """

    mean: np.ndarray
    cov: np.ndarray
    enters: list[int]
    step: float


@dataclass
class HybridAutomaton:
    name: str
    description: str
    file: str
    units: UnitSystem
    constants: dict[str, float]
    state: list[str]
    inputs: list[str]
    modes: dict[str, Mode]
    transitions: list[Transition]
    initial: InitialSet
    horizon: float
    disturbance: Disturbance | None = None
    clocks: list[int] = field(default_factory=list)   # states with rate 1 in every mode
    bounded_inputs: list[BoundedInput] = field(default_factory=list)
    dimensions: DimensionSystem | None = None          # None: the model declares no units
    hints: dict = field(default_factory=dict)          # a SpaceEx cfg's iter-max

    @property
    def time_unit(self) -> str:
        """The unit of time to show: the model's, or none when the model declares no units."""
        return self.units.time if self.dimensions is not None else ""

    @property
    def varying_inputs(self) -> list[BoundedInput]:
        return [u for u in self.bounded_inputs if u.varying]

    @property
    def global_clock(self) -> int | None:
        """A state that measures elapsed time: rate 1 everywhere, starts at 0, never reset."""
        reset = {i for tr in self.transitions for i in tr.reset}
        for i in self.clocks:
            if i not in reset and self.initial.low[i] == 0 == self.initial.high[i]:
                return i
        return None

    def with_global_clock(self) -> tuple["HybridAutomaton", int]:
        """``(self, i)`` if state ``i`` is a global clock, else a copy with a state ``_time``
        appended (flow 1 in every mode, initial 0, never reset, in no guard) and its index."""
        clock = self.global_clock
        if clock is not None:
            return self, clock
        t = sympy.Symbol("_time", real=True)
        symbols = self.symbols + [t]
        modes = {}
        for name, m in self.modes.items():
            modes[name] = Mode(m.name, symbols, list(m.flow) + [sympy.Integer(1)], m.control,
                               m.invariant, m.controller, m.where, m.timeless)
        init = self.initial
        polytope = None
        if init.polytope is not None:
            P = init.polytope
            polytope = LinearSet(np.hstack([P.A, np.zeros((P.A.shape[0], 1))]), P.b,
                                 np.vstack([np.hstack([P.E, np.zeros((P.E.shape[0], 1))]),
                                            np.eye(1, self.n + 1, self.n)]),
                                 np.append(P.f, 0.0))
        initial = InitialSet(init.mode, np.append(init.low, 0.0), np.append(init.high, 0.0), polytope)
        transitions = [Transition(tr.name, tr.source, tr.target, tr.guard, tr.urgent, dict(tr.reset),
                                  tr.window, tr.where) for tr in self.transitions]
        copy = HybridAutomaton(self.name, self.description, self.file, self.units, self.constants,
                               self.state + ["_time"], self.inputs, modes, transitions, initial,
                               self.horizon, self.disturbance, self.clocks + [self.n],
                               bounded_inputs=list(self.bounded_inputs), dimensions=self.dimensions)
        return copy, self.n

    def dimension_of(self, name: str):
        """The dimension of a state, input or constant, or None if not known."""
        return None if self.dimensions is None else self.dimensions.of(name)

    @cached_property
    def symbols(self) -> list[sympy.Symbol]:
        return [sympy.Symbol(s, real=True) for s in self.state]

    def index(self, name: str) -> int:
        return self.state.index(name)

    @property
    def n(self) -> int:
        return len(self.state)

    @property
    def is_linear(self) -> bool:
        """Affine flows in every mode and linear invariants, guards and resets."""
        if any(m.linear is None or m.invariant_halfspaces is None for m in self.modes.values()):
            return False
        for tr in self.transitions:
            if halfspaces(tr.guard, self.symbols) is None:
                return False
            if any(affine_coefficients(e, self.symbols) is None for e in tr.reset.values()):
                return False
        return True

    def guard_halfspaces(self, transition: Transition):
        """``(H, g)`` with the guard equal to ``H x <= g``, or None if nonlinear."""
        return halfspaces(transition.guard, self.symbols)

    def outgoing(self, mode: str) -> list[Transition]:
        return [t for t in self.transitions if t.source == mode]

    @cached_property
    def stop_faces(self) -> list:
        """The invariant rows where runs may stop with no transition enabled, with the parts
        of their faces (:func:`reach.model.lint.stop_faces`). Computed on first use."""
        from reach.model.lint import stop_faces
        return stop_faces(self)

    @cached_property
    def lints(self) -> list[str]:
        """Structural findings (not errors), one line each: an initial set partly outside its
        invariant, invariant faces where runs stop, zero-dwell cycles, see
        :mod:`reach.model.lint`. Computed on first use."""
        from reach.model.lint import lint
        return lint(self)

    @cached_property
    def warnings(self) -> list[str]:
        """The findings a check warns of (:func:`reach.model.lint.lint` with ``check``)."""
        from reach.model.lint import lint
        return lint(self, check=True)
