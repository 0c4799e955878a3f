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

Accuracy. The scheme, the step and the grid are the general path's: at the same substeps a grid
state differs from ``Simulator.propagate``'s only by rounding (the affine terms summed in another
order; where the Jacobian along the runs raised the substeps, see Stability, each path raises them
where its own runs ask, and both are stable there), and from
the exact flow by the RK4 truncation error, locally ``O(h^5)`` per step and globally ``O(h^4)``
on a segment. On SRNA01 (2400 grid steps over 240 min, two substeps) the grid states agree
with ``scipy.integrate.solve_ivp`` (DOP853, ``rtol = 1e-12``) to ``1e-7 (1 + |x|_inf)`` over the
whole horizon (measured 3.0e-8; tests/test_batch_nonlinear.py): the scheme is the general
path's, so is its error; no bound is claimed for other flows beyond RK4's order. Guard entries between
grid points are located as on the general path (``Simulator._first_entry``: bisection on
RK4 propagation to ``h 2^-40``), for the runs that enter a guard in the block only.

Stability. Explicit RK4 is stable where ``|h lambda| <~ 2.8`` for the eigenvalues ``lambda`` of
the flow's Jacobian; past it a step grows errors without bound, and a stiff flow makes
"violations" no run of the model makes. The substeps per grid step keep ``h rho(J) <=
STABLE_STEP`` (``rho`` the spectral radius, :func:`jacobian_radius`): set from the states the
runs start from (the initial box's centre, face centres and some corners: ``x' = -1000 (x - 1)``
at ``h = 0.005`` went from 1.75 to 141.9 in one grid step, a "violation" no run of the model
makes), and checked again every
:data:`STIFFNESS_CHECK` grid steps at states the runs reached, where a flow that stiffens along
its runs gets more substeps and those grid steps are taken again (:class:`RK4Blocks`;
``Simulator.more_substeps``) where one grid step at the two counts bears the estimate out (a
large Jacobian alone, as a network controller's ripple gives, raises nothing). A mode that would need more than :data:`MAX_SUBSTEPS` is too
stiff for RK4 at the step (:func:`beyond_rk4`): its runs are not simulated but made NaN at once,
which the callers report as runs the flow left undefined (:func:`too_stiff_text`), rather than
integrated unstably at a thousand times the cost.
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


#: RK4 is stable on ``h lambda`` out to about 2.8 on both the negative real and the imaginary
#: axis; substeps keep ``h rho(J)`` below this, with room for the Jacobian to grow between checks
STABLE_STEP = 1.5
MAX_SUBSTEPS = 1000             # per grid step: past it, a flow this stiff wants another integrator
                                # (a violation only the coarse steps make does not replay: replays.py)
STIFFNESS_CHECK = 16            # grid steps between two estimates of the Jacobian along the runs
STIFFNESS_PROBES = 8            # runs whose states each estimate looks at


def jacobian_radius(rhs, X: np.ndarray) -> float:
    """The largest spectral radius of the Jacobian of ``rhs`` ((K, n) -> (K, n)) over the finite
    states among ``X`` (K, n), by finite differences at two steps: an entry they disagree on is a
    kink of ``sign`` or ``sat`` at the state (a jump, not a rate) and counts as 0. NaN where the
    flow cannot be evaluated or no state is finite."""
    X = np.asarray(X, dtype=float)
    X = X[np.all(np.isfinite(X), axis=1)]
    if X.shape[0] == 0:
        return float("nan")
    K, n = X.shape
    d = 1e-7 * (1.0 + np.abs(X))                                        # (K, n)
    # one evaluation of every state moved along every axis by d and by d / 2
    moved = np.repeat(X[None], 2 * n + 1, axis=0)                       # (2n + 1, K, n)
    for j in range(n):
        moved[1 + j, :, j] += d[:, j]
        moved[1 + n + j, :, j] += d[:, j] / 2
    with np.errstate(all="ignore"):
        try:
            F = np.asarray(rhs(moved.reshape(-1, n)), dtype=float).reshape(2 * n + 1, K, n)
            full = (F[1:1 + n] - F[0]) / d.T[:, :, None]                # (n, K, n): column j, state, row
            half = (F[1 + n:] - F[0]) / (d.T[:, :, None] / 2)
            # a kink (sign, sat, abs at a probe) gives a quotient that doubles with half the
            # step: a jump, not a rate; only entries the two steps agree on count
            agree = np.abs(full - half) <= 0.1 * np.maximum(np.abs(full), np.abs(half)) + 1e-9
            J = np.where(agree, half, 0.0).transpose(1, 2, 0)           # (K, row, column)
            J = np.where(np.isfinite(J), J, 0.0)
            return float(np.abs(np.linalg.eigvals(J)).max(initial=0.0))
        except (ArithmeticError, ValueError, TypeError, np.linalg.LinAlgError):
            return float("nan")


def substeps_for(dt: float, rho: float, least: int) -> int:
    """RK4 substeps per grid step ``dt`` keeping ``h rho <= STABLE_STEP``: at least ``least``,
    at most :data:`MAX_SUBSTEPS` (``least`` where ``rho`` is unknown)."""
    if not np.isfinite(rho) or rho <= 0:
        return least
    return int(min(MAX_SUBSTEPS, max(least, np.ceil(dt * rho / STABLE_STEP))))


def beyond_rk4(dt: float, rho: float) -> bool:
    """Whether no number of substeps up to :data:`MAX_SUBSTEPS` makes RK4 stable at ``rho``."""
    return bool(np.isfinite(rho) and dt * rho / STABLE_STEP > MAX_SUBSTEPS)


def too_stiff_text(dt: float, modes: dict) -> str:
    """What a simulation says of the modes ``{name: rho}`` too stiff for RK4 at step ``dt``."""
    worst = max(modes.values())
    return (f"mode {', '.join(repr(m) for m in modes)} is too stiff for RK4 at the step {dt:.3g} (the flow's "
            f"Jacobian has spectral radius {worst:.3g}: stable steps need more than {MAX_SUBSTEPS} substeps); "
            f"runs there were not simulated (their states are NaN): -o dt={MAX_SUBSTEPS * STABLE_STEP / worst:.3g} "
            f"or smaller takes them")


def probe_rows(X: np.ndarray, count: int = STIFFNESS_PROBES) -> np.ndarray:
    """Up to ``count`` finite rows of ``X`` (K, n), evenly spread (those among ``count`` evenly
    spread rows, or failing that any)."""
    step = max(1, X.shape[0] // count)
    rows = X[::step][:count]
    rows = rows[np.isfinite(rows).all(axis=1)]
    if rows.shape[0] or step == 1:
        return rows
    finite = X[np.isfinite(X).all(axis=1)]
    return finite[::max(1, finite.shape[0] // count)][:count]


def rk4_steps(f, Y: np.ndarray, h, count: int) -> np.ndarray:
    """``count`` classical Runge-Kutta steps of ``y' = f(y)`` from ``Y``, each of step ``h``."""
    for _ in range(count):
        Y = rk4_step(f, Y, h)
    return Y


def rk4_step(f, Y: np.ndarray, h) -> np.ndarray:
    """One classical Runge-Kutta step of ``y' = f(y)`` from ``Y`` with step ``h`` (a number, or
    an array broadcasting against ``Y``: one step per run)."""
    k1 = f(Y)
    k2 = f(Y + 0.5 * h * k1)
    k3 = f(Y + 0.5 * h * k2)
    k4 = f(Y + h * k3)
    return Y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


class RK4Blocks:
    """Grid states of a nonlinear mode, a block at a time, by classical RK4 with the simulator's
    substeps for the mode per grid step ``dt`` (the general path's scheme), raised where the
    states reached ask for more (module docstring, Stability)."""

    def __init__(self, flow: SplitFlow, sim, name: str):
        self.flow, self.sim, self.name, self.dt = flow, sim, name, sim.dt

    def step(self, Z: np.ndarray) -> np.ndarray:
        """The state one grid step after ``Z`` (n, R); NaN in a mode too stiff for RK4."""
        if self.name in self.sim.too_stiff:
            return np.full_like(Z, np.nan)
        substeps = self.sim.mode_substeps.get(self.name, self.sim.substeps)
        return rk4_steps(self.flow, Z, self.dt / substeps, substeps)

    def block(self, Z: np.ndarray, count: int) -> np.ndarray:
        """``(count, n, R)``: ``Z`` and the states at the next ``count - 1`` grid points; every
        :data:`STIFFNESS_CHECK` of them the Jacobian at the last is looked at, and where it asks
        for more substeps those grid steps are taken again with them."""
        out = np.empty((count,) + Z.shape)
        out[0] = Z
        j = 1
        while j < count:
            j1 = min(count, j + STIFFNESS_CHECK)
            for k in range(j, j1):
                out[k] = self.step(out[k - 1])
            if not self.sim.more_substeps(self.name, out[j - 1].T, out[j1 - 1].T):
                j = j1
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
        self.steps = RK4Blocks(self.flow, sim, name)

    def weights(self, extra: list) -> tuple:
        """``(L_ext, offsets)``: the rows ``L`` with the observers' rows ``extra`` appended
        (:class:`reach.model.batch.ExtendedRows`); a block's margins are ``L_ext [x; 1]``."""
        return self.rows.get(extra, lambda L: L)

    def entry(self, X: np.ndarray, h: np.ndarray, guard) -> np.ndarray:
        return self.sim._first_entry(self.name, X, h, guard)

    def propagate(self, X: np.ndarray, h) -> np.ndarray:
        return self.sim.propagate(self.name, X, h)
