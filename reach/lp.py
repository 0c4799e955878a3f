"""The one linear-programming layer: every LP in reach goes through here.

Problems have the form

    minimize  c^T x   subject to  A_ub x <= b_ub,  A_eq x = b_eq,  lo <= x <= hi

with free variables unless ``bounds`` says otherwise (no default of ``x >= 0``). They are
solved with HiGHS through highspy's bare solver (the model passed once, the solver run
directly: scipy's ``linprog`` around the same solver costs milliseconds a call in option
checks and matrix conversions, more than the small LPs of a check take). The result
is an :class:`LPResult` whose ``status`` is one of ``"optimal"``, ``"infeasible"`` or
``"unbounded"``; anything else (iteration limit, numerical trouble) raises
:class:`LPError`, so a caller never mistakes a solver failure for an answer.

HiGHS works with a primal feasibility tolerance of about 1e-7: "infeasible" means no
point satisfies the constraints to that tolerance. An infeasible verdict is the one a proof
rests on (an empty intersection with an unsafe set), and HiGHS's presolve has been seen to
give it for feasible, unbounded problems; it is therefore only accepted when the solver
without presolve confirms it. Presolve has also stopped with model status "unknown" on an
unbounded problem that the solver without it decides, so any status other than optimal or
unbounded is asked again without presolve before it counts as an error.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

OPTIMAL, INFEASIBLE, UNBOUNDED = "optimal", "infeasible", "unbounded"

#: rows whose largest coefficient is below this are scaled up before HiGHS sees them
SMALL_ROW = 1e-6
#: constraint-matrix entries (rows x variables) up to which :func:`maximize_many` skips presolve
PRESOLVE_ENTRIES = 100_000


class LPError(RuntimeError):
    """No verdict: the solver stopped without one (iteration limit, numerical difficulties), or
    the LP cannot be posed faithfully (a NaN or non-finite coefficient, which HiGHS would drop
    or reject, changing the polyhedron)."""


@dataclass
class LPResult:
    """``status``; on ``"optimal"`` the objective ``value`` (in the caller's sense: the
    maximum for :func:`maximize`) and a solution ``x``."""

    status: str
    value: float | None = None
    x: np.ndarray | None = None
    duals: np.ndarray | None = None     # the solver's duals of the A_ub rows (its signs)

    @property
    def optimal(self) -> bool:
        return self.status == OPTIMAL

    @property
    def infeasible(self) -> bool:
        return self.status == INFEASIBLE

    @property
    def unbounded(self) -> bool:
        return self.status == UNBOUNDED

    def support_value(self) -> float:
        """The maximum read as a support function: ``-inf`` if infeasible, ``+inf`` if unbounded."""
        if self.infeasible:
            return -np.inf
        if self.unbounded:
            return np.inf
        return self.value


def _bounds(bounds, n: int):
    """``(lo, hi)`` arrays from None (all free), ``(lo, hi)`` pairs (None for infinite) or a
    pair of arrays."""
    if bounds is None:
        return np.full(n, -np.inf), np.full(n, np.inf)
    if isinstance(bounds, tuple) and len(bounds) == 2 and np.ndim(bounds[0]) == 1:
        return np.asarray(bounds[0], dtype=float), np.asarray(bounds[1], dtype=float)
    lo = np.array([-np.inf if a is None else a for a, _ in bounds], dtype=float)
    hi = np.array([np.inf if b is None else b for _, b in bounds], dtype=float)
    return lo, hi


def _model(n: int, bounds, A_ub=None, b_ub=None, A_eq=None, b_eq=None, options=None):
    """A HiGHS model (highspy's bare solver: the wrapper class prints a banner) over ``n``
    variables with ``lo <= x <= hi`` (``bounds`` as in :func:`_bounds`), the rows
    ``A_ub x <= b_ub`` and ``A_eq x = b_eq`` (None or empty: none) and HiGHS ``options``."""
    from highspy import _core as highspy

    infinity = highspy.kHighsInf
    lo, hi = _bounds(bounds, n)
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise LPError("a variable bound is NaN")
    solver = highspy._Highs()
    solver.setOptionValue("output_flag", False)
    for key, value in (options or {}).items():
        solver.setOptionValue(key, value)
    # HiGHS rejects a row with a non-finite or huge coefficient and drops a NaN one from a kept
    # row; either would change the polyhedron silently, so both are errors here (UNKNOWN above)
    error = highspy.HighsStatus.kError
    if solver.addVars(n, np.where(np.isfinite(lo), lo, -infinity), np.where(np.isfinite(hi), hi, infinity)) == error:
        raise LPError("the LP's variable bounds were rejected")
    for A, low, high in ((A_ub, None, b_ub), (A_eq, b_eq, b_eq)):
        if A is None or np.size(A) == 0:
            continue
        A = np.asarray(A, dtype=float).reshape(-1, n)
        high = np.asarray(high, dtype=float).reshape(-1)
        low = np.full(A.shape[0], -infinity) if low is None else np.asarray(low, dtype=float).reshape(-1)
        if not np.isfinite(A).all() or np.isnan(high).any() or np.isnan(low).any():
            raise LPError("an LP row has a non-finite coefficient or a NaN bound")
        # HiGHS drops coefficients below 1e-9 (small_matrix_value): a row made only of such
        # (a clock pinned to within 1e-9 s, a tiny input column) would read 0 <= b and could
        # make a non-empty set infeasible. Such rows are scaled to a largest coefficient of 1
        # (the same half-space), unless that would push a bound past 1e15 (then the row's
        # bound dwarfs its coefficients and it is passed as it is)
        A, low, high = _scaled_rows(A, low, high)
        nz = A != 0
        starts = np.concatenate([[0], np.cumsum(nz.sum(axis=1))[:-1]]).astype(np.int32)
        if solver.addRows(A.shape[0], low, high, int(nz.sum()), starts, np.nonzero(nz)[1].astype(np.int32),
                          A[nz]) == error:
            raise LPError("the LP's rows were rejected (a coefficient too large for the solver)")
    return solver


def minimize(c, A_ub=None, b_ub=None, *, A_eq=None, b_eq=None, bounds=None,
             tolerance: float | None = None) -> LPResult:
    """Minimize ``c^T x`` over the polyhedron; ``bounds`` is None (all free), a list of
    ``(lo, hi)`` pairs (None for infinite) or a pair of arrays ``(lo, hi)``. ``tolerance``:
    HiGHS's primal and dual feasibility tolerance (None: its default, about 1e-7)."""
    from highspy import _core as highspy

    c = np.asarray(c, dtype=float)
    n = c.size
    if n == 0:                  # no variables: the constraints are plain inequalities
        ok = (A_ub is None or np.all(np.asarray(b_ub) >= -1e-9)) and \
             (A_eq is None or np.allclose(b_eq, 0.0, atol=1e-9))
        return LPResult(OPTIMAL, 0.0, np.zeros(0)) if ok else LPResult(INFEASIBLE)
    options = {} if tolerance is None else {"primal_feasibility_tolerance": tolerance,
                                            "dual_feasibility_tolerance": tolerance}
    if not np.isfinite(c).all():
        raise LPError("the LP's objective is not finite")
    solver = _model(n, bounds, A_ub, b_ub, A_eq, b_eq, options)
    solver.changeColsCost(n, np.arange(n, dtype=np.int32), c)
    status = highspy.HighsModelStatus
    s = _run(solver)
    if s not in (status.kOptimal, status.kUnbounded):   # presolve's "infeasible" or "unknown": again without it
        solver.setOptionValue("presolve", "off")
        solver.clearSolver()
        s = _run(solver)
    if s == status.kOptimal:
        solution = solver.getSolution()
        rows = 0 if A_ub is None else np.size(A_ub) // n
        return LPResult(OPTIMAL, float(solver.getInfo().objective_function_value),
                        np.asarray(solution.col_value, dtype=float),
                        np.asarray(solution.row_dual, dtype=float)[:rows])
    if s == status.kInfeasible:
        return LPResult(INFEASIBLE)
    if s == status.kUnbounded:
        return LPResult(UNBOUNDED)
    raise LPError(f"LP solver stopped without a verdict: {solver.modelStatusToString(s)}")


def _scaled_rows(A, low, high):
    """``low <= A x <= high`` with every row whose coefficients are all below
    :data:`SMALL_ROW` scaled to a largest coefficient of 1, unless that would push a bound
    past 1e15 (the same half-spaces; see :func:`_model`)."""
    scale = np.abs(A).max(axis=1) if A.size else np.zeros(A.shape[0])
    tiny = (scale > 0) & (scale < SMALL_ROW)
    if not np.any(tiny):
        return A, low, high
    with np.errstate(over="ignore", invalid="ignore"):
        factor = np.where(tiny, 1.0 / np.where(tiny, scale, 1.0), 1.0)
        size = np.maximum(np.abs(np.where(np.isfinite(low), low, 0.0)),
                          np.abs(np.where(np.isfinite(high), high, 0.0))) * factor
    factor = np.where(size <= 1e15, factor, 1.0)
    return A * factor[:, None], low * factor, high * factor


#: the time.perf_counter() instant at which LPs stop (:func:`deadline`)
_DEADLINE = [float("inf")]


@contextmanager
def deadline(at: float):
    """Every LP solved within stops at ``at`` (a ``time.perf_counter()`` instant; HiGHS's
    time limit): one stopped there decides nothing (``nan`` from :func:`maximize_many`, an
    :class:`LPError` from :func:`minimize`), as any solver failure. A search with a time
    budget then ends within it even where one LP of a large star would take minutes."""
    previous = _DEADLINE[0]
    _DEADLINE[0] = min(previous, at)
    try:
        yield
    finally:
        _DEADLINE[0] = previous


def _run(solver):
    """Solve, within the :func:`deadline`; the model status (``kSolveError`` if the run itself
    failed)."""
    from highspy import _core as highspy

    if _DEADLINE[0] < float("inf"):
        solver.setOptionValue("time_limit", max(1e-3, _DEADLINE[0] - time.perf_counter()))
    if solver.run() == highspy.HighsStatus.kError:
        return highspy.HighsModelStatus.kSolveError
    return solver.getModelStatus()


def maximize(c, A_ub=None, b_ub=None, *, A_eq=None, b_eq=None, bounds=None,
             tolerance: float | None = None) -> LPResult:
    """Maximize ``c^T x``; ``value`` is the maximum."""
    res = minimize(-np.asarray(c, dtype=float), A_ub, b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds,
                   tolerance=tolerance)
    if res.optimal:
        res.value = -res.value
    return res


def feasible_point(A_ub=None, b_ub=None, *, A_eq=None, b_eq=None, bounds=None, n: int | None = None):
    """A point of the polyhedron, or None if it is empty. ``n`` is needed only when no
    constraint matrix tells the dimension."""
    if n is None:
        n = np.shape(A_ub)[1] if A_ub is not None else np.shape(A_eq)[1]
    res = minimize(np.zeros(n), A_ub, b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds)
    return res.x if res.optimal else None


#: strict rows whose common slack cannot exceed this (a distance) leave no point
OPEN_SLACK = 1e-9


def strictly_feasible(A_ub, b_ub, strict, *, A_eq=None, b_eq=None) -> bool | None:
    """Whether ``A_ub x <= b_ub, A_eq x = b_eq`` has a point with the rows marked ``strict``
    held strictly: the largest common slack ``s <= 1`` of those rows (each scaled by its norm,
    so ``s`` is a distance from their hyperplanes) must exceed :data:`OPEN_SLACK`
    (``x > 1, x < 1`` has none, though its closure is the point 1). None where the solver
    gives no answer."""
    A_ub, b_ub = np.asarray(A_ub, float), np.asarray(b_ub, float)
    n = A_ub.shape[1]
    norms = np.linalg.norm(A_ub, axis=1)
    slack = np.where(np.asarray(strict, bool), np.where(norms > 0, norms, 1.0), 0.0)
    A = np.vstack([np.hstack([A_ub, slack[:, None]]), np.eye(n + 1)[-1:]])
    b = np.append(b_ub, 1.0)
    E = None if A_eq is None or not len(A_eq) else np.hstack([A_eq, np.zeros((len(A_eq), 1))])
    try:
        res = maximize(np.eye(n + 1)[-1], A, b, A_eq=E, b_eq=None if E is None else b_eq)
    except LPError:
        return None
    if res.infeasible:
        return False
    return None if not res.optimal else res.value > OPEN_SLACK


def maximize_many(C, A_ub, b_ub, bounds) -> np.ndarray:
    """``max_x C_k . x`` over ``{A_ub x <= b_ub, lo <= x <= hi}`` for every row ``C_k``:
    one HiGHS model, re-solved from the previous basis with each objective (the polyhedron
    is passed once), without presolve up to :data:`PRESOLVE_ENTRIES` constraint entries
    (these LPs are small and many: presolve costs more than it saves, about a quarter of the
    time on the aggregates of GRBX01-MES01), with it beyond (a star whose predicate grew to
    4953 rows over 382 coefficients took 32 s without presolve, 1.6 s with it); an infeasible
    verdict of presolve is confirmed without it, as above.
    ``bounds``: a pair of arrays ``(lo, hi)``. Values are read as support functions:
    ``-inf`` for all rows if the polyhedron is empty, ``+inf`` where unbounded. A row the
    warm start does not decide as optimal or unbounded is solved again from scratch (an
    infeasible verdict is trusted only then); ``nan`` where that decides nothing either (the
    caller falls back to a bound it can argue without the LP).

    Where every variable is bounded (a star's coefficient box), an optimal value is returned
    as the weak-duality bound of the solver's row duals (:class:`DualBound`), which holds
    whatever the solver's tolerances; otherwise as the solver's own value."""
    from highspy import _core as highspy

    C = np.atleast_2d(np.asarray(C, dtype=float))
    n = C.shape[1]
    if not np.isfinite(C).all():
        raise LPError("the LP's objective is not finite")
    b_ub = np.asarray(b_ub, dtype=float).reshape(-1)
    if n == 0:                          # no variables: the polyhedron is R^0 or empty
        return np.full(C.shape[0], 0.0 if np.all(b_ub >= 0) else -np.inf)
    A_ub, _, b_ub = _scaled_rows(np.asarray(A_ub, dtype=float).reshape(b_ub.size, n),
                                 np.full(b_ub.shape, -np.inf), b_ub)
    presolve = A_ub.size > PRESOLVE_ENTRIES
    solver = _model(n, bounds, A_ub, b_ub, options={} if presolve else {"presolve": "off"})
    solver.changeObjectiveSense(highspy.ObjSense.kMaximize)
    index = np.arange(n, dtype=np.int32)
    values = np.empty(C.shape[0])
    status = highspy.HighsModelStatus
    lo, hi = _bounds(bounds, n)
    certificate = DualBound(A_ub, b_ub, lo, hi) if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) else None
    k, fresh = 0, True                  # the first run starts from scratch
    while k < C.shape[0]:
        size = np.abs(C[k]).max() if n else 0.0
        size = size if size > 0 else 1.0
        solver.changeColsCost(n, index, C[k] / size)       # the solver's dual tolerance is absolute
        s = _run(solver)
        if s == status.kOptimal:
            value = size * solver.getInfo().objective_function_value
            values[k] = certificate(C[k], size * np.asarray(solver.getSolution().row_dual, dtype=float)) \
                if certificate is not None else value
        elif s == status.kUnbounded:
            values[k] = np.inf
        elif not fresh:                 # anything else (infeasible too) once more, from scratch
            solver.clearSolver()
            fresh = True
            continue
        elif s == status.kInfeasible and presolve:      # presolve's infeasible: confirmed without it
            solver.setOptionValue("presolve", "off")
            solver.clearSolver()
            presolve = False
            continue
        elif s == status.kInfeasible:
            return np.full(C.shape[0], -np.inf)
        else:
            values[k] = np.nan
        k, fresh = k + 1, False
    return values


class DualBound:
    """Upper bounds of ``max c . x`` over ``{A x <= b, lo <= x <= hi}`` (``lo``, ``hi`` finite)
    that do not rest on the solver having converged: for every ``y >= 0`` and every such
    ``x``,

        c . x = y . A x + (c - A^T y) . x <= y . b + sum_j max(r_j lo_j, r_j hi_j),
        r = c - A^T y                                           (weak duality).

    Called with an objective and the solver's row duals, it takes ``y`` the part of the duals
    of their dominant sign (the solver's sign convention does not matter: either part is
    valid). Near the optimum the bound is the solver's value to
    within its tolerances (about 1e-7), but it is an upper bound even where that value falls
    short of the maximum (poor duals only make it looser). Pushed out by ``4 (m + n)`` units
    of rounding of the magnitudes summed; ``inf`` for duals that are not finite. The
    polyhedron's parts are prepared once for the many objectives of :func:`maximize_many`."""

    def __init__(self, A, b, lo, hi):
        self.A, self.abs_A = A, np.abs(A)
        self.open = ~np.isfinite(b)                     # a row with no upper bound takes no weight
        self.any_open = bool(self.open.any())
        self.b = np.where(self.open, 0.0, b)
        self.lo, self.hi = lo, hi
        self.magnitude = np.maximum(np.abs(lo), np.abs(hi))
        self.units = 4 * (A.shape[0] + A.shape[1]) * np.finfo(float).eps

    def __call__(self, c, duals) -> float:
        if duals.shape != self.b.shape or not np.isfinite(duals).all():
            return np.inf
        y = np.maximum(duals if duals.sum() >= 0 else -duals, 0.0)    # the duals' dominant sign
        if self.any_open:
            y[self.open] = 0.0
        r = c - y @ self.A
        re = r * np.where(r > 0, self.hi, self.lo)
        yb = y * self.b
        size = np.abs(yb).sum() + np.abs(re).sum() + (y @ self.abs_A + np.abs(c)) @ self.magnitude
        return float(yb.sum() + re.sum() + self.units * size)


def variable_bound(j: int, A, b, lo, hi, duals) -> float:
    """An upper bound of ``x_j`` over ``{A x <= b, lo <= x <= hi}`` that does not rest on the
    solver having converged, where ``x_j`` may be unbounded but every other variable is
    bounded (a star's coefficients and a depth): for every ``y >= 0`` with
    ``sigma = (A^T y)_j > 0`` and every such ``x``,

        sigma x_j <= y . b - sum_{i != j} (A^T y)_i x_i
                  <= y . b + sum_{i != j} max(-(A^T y)_i lo_i, -(A^T y)_i hi_i),

    tried with ``y`` the positive and the negative part of the solver's row ``duals``; the
    least of these and ``hi_j``, pushed out by ``4 (m + n)`` units of rounding of the
    magnitudes summed. ``inf`` where neither gives a bound."""
    best = float(hi[j])
    if duals is None or duals.shape != (A.shape[0],) or not np.all(np.isfinite(duals)):
        return best
    others = np.arange(A.shape[1]) != j
    for y in (np.maximum(duals, 0.0), np.maximum(-duals, 0.0)):
        y[~np.isfinite(b)] = 0.0
        weights = A.T @ y
        sigma = weights[j]
        if not sigma > 0:
            continue
        r = -weights[others]
        ends = np.where(r > 0, hi[others], np.where(r < 0, lo[others], 0.0))
        with np.errstate(invalid="ignore"):
            terms = np.concatenate([y * np.where(y > 0, b, 0.0), r * ends])
        if not np.all(np.isfinite(terms)):
            continue
        size = np.abs(terms).sum() + (np.abs(A.T) @ y)[others] @ np.maximum(np.abs(lo[others]), np.abs(hi[others]))
        top = terms.sum() + 4 * (A.shape[0] + A.shape[1]) * np.finfo(float).eps * size
        # the division by sigma rounds too: one more unit of the quotient's size
        best = min(best, float(top / sigma + 2 * np.finfo(float).eps * abs(top / sigma)))
    return best
