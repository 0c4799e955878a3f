"""Nonlinear segments in blocks of grid steps: classical RK4 over all runs at once.

The general path (:meth:`reach.model.simulate.Simulator.propagate`) steps classical RK4 with
``substeps`` steps of ``h = dt / substeps`` per grid step, on runs along the first axis and
the right-hand side assembled column by column; a segment is cut into chunks of a few hundred
runs to bound the memory of its whole ``(runs, steps, n)`` grid. Here the same scheme is
evaluated on states laid out as ``(n, R)`` (a state's values over the runs contiguous) for all
the runs of a chunk, a block of grid steps at a time (:mod:`reach.model.batch` does the
monitoring, guards and invariant on those blocks as for linear modes), with the flow split as

    ``f(x) = A x + b + g(x)``,

``A x + b`` the additive terms of the flow that are affine in the state (one matrix product
for every run) and ``g`` the others (one sympy-generated numpy function with common
subexpressions shared, evaluated on the rows that have any).

Accuracy. The scheme, the step and the grid are the general path's: a grid state differs from
``Simulator.propagate``'s only by rounding (the affine terms summed in another order), and from
the exact flow by the RK4 truncation error, locally ``O(h^5)`` per step and globally ``O(h^4)``
on a segment. On SRNA01 (2400 grid steps over 240 min, two substeps) the grid states agree
with ``scipy.integrate.solve_ivp`` (DOP853, ``rtol = 1e-12``) to ``1e-7 (1 + |x|_inf)`` over the
whole horizon (measured 3.0e-8; tests/test_batch_nonlinear.py): the scheme is the general
path's, so is its error; no bound is claimed for other flows beyond RK4's order. Guard entries between
grid points are located as on the general path (``Simulator._first_entry``: bisection on
RK4 propagation to ``h 2^-40``), for the runs that enter a guard in the block only.
"""

from __future__ import annotations

import numpy as np
import sympy

from reach.model.constraints import affine_coefficients


class SplitFlow:
    """``Z (n, R) -> Z' (n, R)``: the closed-loop flow of one mode as ``A Z + b + g(Z)``."""

    def __init__(self, flow, symbols):
        n = len(symbols)
        self.A, self.b = np.zeros((n, n)), np.zeros(n)
        rest = {}
        for i, f in enumerate(flow):
            other = []
            for term in sympy.Add.make_args(sympy.sympify(f)):
                coeffs = affine_coefficients(term, symbols)
                if coeffs is None:
                    other.append(term)
                else:
                    self.A[i] += coeffs[0]
                    self.b[i] += coeffs[1]
            if other:
                rest[i] = sympy.Add(*other)
        self.rows = list(rest)
        self.g = sympy.lambdify([symbols], list(rest.values()), modules="numpy", cse=True) if rest else None
        self.b_col = self.b[:, None]

    def __call__(self, Z: np.ndarray) -> np.ndarray:
        out = self.A @ Z
        out += self.b_col
        if self.g is not None:
            for i, value in zip(self.rows, self.g(Z)):
                out[i] += value
        return out


def rk4_step(f, Y: np.ndarray, h) -> np.ndarray:
    """One classical Runge-Kutta step of ``y' = f(y)`` from ``Y`` with step ``h`` (a number, or
    an array broadcasting against ``Y``: one step per run)."""
    k1 = f(Y)
    k2 = f(Y + 0.5 * h * k1)
    k3 = f(Y + 0.5 * h * k2)
    k4 = f(Y + h * k3)
    return Y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


class RK4Blocks:
    """Grid states of a nonlinear mode, a block at a time, by classical RK4 with ``substeps``
    steps per grid step ``dt`` (the general path's scheme)."""

    def __init__(self, flow: SplitFlow, dt: float, substeps: int):
        self.flow, self.h, self.substeps = flow, dt / substeps, substeps

    def step(self, Z: np.ndarray) -> np.ndarray:
        """The state one grid step after ``Z`` (n, R)."""
        for _ in range(self.substeps):
            Z = rk4_step(self.flow, Z, self.h)
        return Z

    def block(self, Z: np.ndarray, count: int) -> np.ndarray:
        """``(count, n, R)``: ``Z`` and the states at the next ``count - 1`` grid points."""
        out = np.empty((count,) + Z.shape)
        out[0] = Z
        for j in range(1, count):
            out[j] = self.step(out[j - 1])
        return out


class NonlinearTable:
    """What :func:`reach.model.batch.segment_chunk` needs of a nonlinear mode: the stacked rows
    ``L`` of the state, urgent guards and invariant (as :class:`reach.model.batch.LinearTable`),
    the grid states a block at a time, and guard entries by the general path's bisection."""

    nonlinear = True

    def __init__(self, sim, name: str):
        from reach.model.batch import ExtendedRows, stacked_rows
        self.L, self.guards, self.invariant = stacked_rows(sim, name)
        self.rows = ExtendedRows(self.L)
        self.name, self.sim, self.mode = name, sim, sim.model.modes[name]
        self.flow = SplitFlow(self.mode.flow, sim.model.symbols)
        self.steps = RK4Blocks(self.flow, sim.dt, sim.mode_substeps.get(name, sim.substeps))

    def weights(self, extra: list) -> tuple:
        """``(L_ext, offsets)``: the rows ``L`` with the observers' rows ``extra`` appended
        (:class:`reach.model.batch.ExtendedRows`); a block's margins are ``L_ext [x; 1]``."""
        return self.rows.get(extra, lambda L: L)

    def entry(self, X: np.ndarray, h: np.ndarray, guard) -> np.ndarray:
        return self.sim._first_entry(self.name, X, h, guard)

    def propagate(self, X: np.ndarray, h) -> np.ndarray:
        return self.sim.propagate(self.name, X, h)
