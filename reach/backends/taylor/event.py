"""Event maps (section 2.2, eqs. 5-14): from initial deviations to the state, time and value of a
quantity at an event ``E(x) = 0`` of a run.

Two kinds of event are used: the extremum of a quantity ``q`` along the run, where
``E = dq/dt = grad q . f`` vanishes, and the crossing of a surface ``E = g(x) = 0`` (a face of an
urgent guard). Both go through the same three stages:

1. detection on the nominal run: the step node nearest the event, then the best of a dense
   sampling of the nominal solution over the two neighbouring steps;
2. refinement of the nominal event time (eqs. 5-9): with ``t_e = t_e + dt``, the Picard
   iteration ``x_{k+1} = x_e + int_0^dt f(x_k)`` (eq. 6) run ``n + 1`` times gives ``x_e(dt)``
   exactly to order ``n`` (eq. 7); ``E(dt)`` (eq. 8) is inverted and evaluated at ``E = 0``
   (eq. 9), and repeated from the refined point until the correction is negligible;
3. the map (eqs. 10-14): the DA state over the scaled deviations ``xi`` and ``dt`` is propagated to
   the refined ``t_e``, Picard-expanded in ``dt`` (eq. 11), ``E(xi, dt)`` (eq. 12) is stacked with
   the identity in ``xi`` (eq. 13), the map is inverted, ``E = 0`` enforced, and the result
   ``dt*(xi)`` substituted back (eq. 14).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reach.backends.taylor.da import DA, algebra, invert, stack
from reach.backends.taylor.flow import step_sizes
from reach.backends.taylor.lockstep import BATCH, Propagation, run_one


@dataclass
class EventMap:
    """Taylor maps in the scaled deviations ``xi`` (``[-1, 1]`` on the subdomain) at one event."""

    time: DA              # t*(xi)
    state: list[DA]       # x*(xi) (eq. 14)


def picard(f, x_e: list, dt_var: int, order: int) -> list:
    """Expansion in ``xi_{dt_var}`` (the time deviation) of the run through ``x_e`` (eq. 6)."""
    x = list(x_e)
    for _ in range(order + 1):
        rates = f(x)
        x = [a + r.integrate(dt_var) for a, r in zip(x_e, rates)]
    return x


@dataclass
class Picard:
    """A request (:mod:`.lockstep`): the Picard expansion (eq. 6) of the run through the DA state
    ``x`` in ``xi_{dt_var}``, and the event ``E`` on it. Requests of the same flow and event
    are answered as one batch: the states stacked as DAs of shape ``(B,)``."""

    f: object
    event: object
    x: list
    dt_var: int
    order: int

    batch = BATCH
    length = 1

    def key(self):
        alg = self.x[0].alg
        return (type(self).__name__, self.f, self.event, alg.order, alg.nvars, len(self.x), self.dt_var,
                self.order)

    @staticmethod
    def expand(requests: list["Picard"]) -> tuple[list[DA], DA]:
        """The expansions ``x`` and events ``E`` of the requests, stacked (shape ``(B,)``)."""
        first = requests[0]
        alg = first.x[0].alg
        x_e = [DA(alg, np.stack([r.x[i].c for r in requests])) for i in range(len(first.x))]
        x = picard(first.f, x_e, first.dt_var, first.order)
        return x, first.event(x)

    @staticmethod
    def answer(requests: list["Picard"]) -> list[tuple]:
        """``(x, E)`` of each request."""
        x, E = Picard.expand(requests)
        return [([xi[b] for xi in x], E[b]) for b in range(len(requests))]


@dataclass
class EventSolve(Picard):
    """A request: the event map (eqs. 11-14) about the state ``x`` at the nominal event, in the
    deviations ``xi`` and the time deviation ``xi_{dt_var}`` (the last variable). Answered as one
    batch: the Picard expansions, the inversions of eq. (13) and the substitutions of eq. (14) of
    all requests run on stacked DAs."""

    @staticmethod
    def answer(requests: list["EventSolve"]) -> list[tuple]:
        """``(dt*(xi), x*(xi))`` of each request."""
        x, E = Picard.expand(requests)
        dt, state = solve_event(x, E)
        return [(dt[b], [s[b] for s in state]) for b in range(len(requests))]


def solve_event(x: list[DA], E: DA) -> tuple[DA, list[DA]]:
    """``dt*(xi)`` and ``x*(xi) = x(xi, dt*(xi))`` (eqs. 13-14) from the expansions ``x`` and the
    event ``E`` in the deviations ``xi`` and the time deviation (the last variable), for DAs of
    any batch shape: ``(xi, dt) -> (xi, E - E(0))`` is inverted, ``E = 0`` enforced."""
    alg = E.alg
    m = alg.nvars - 1
    G = invert([DA.var(alg, j) for j in range(m)] + [E])           # eq. (13), inverted
    target = algebra(alg.order, m)
    xi = [DA.var(target, j) for j in range(m)]
    dt = G[m].compose(xi + [DA.const(target, -E.cons)])             # E = 0 enforced
    return dt, stack(x).compose(xi + [dt]).unstack()                 # eq. (14)


def refine_time(f, event, state_at, t_e: float, order: int, passes: int = 8):
    """Nominal event time and state by eqs. (5)-(9): ``(t*, x(t*))``.

    ``state_at(t)`` is the nominal state (a dense solution). The refinement is repeated from
    the refined time until the correction falls below ``1e-13 (1 + |t|)`` (at most ``passes``
    times); restarting from ``state_at`` keeps the Picard truncation error of a long first
    correction out of the result.
    """
    return run_one(refine_time_steps(f, event, state_at, t_e, order, passes))


def refine_time_steps(f, event, state_at, t_e: float, order: int, passes: int = 8):
    """:func:`refine_time` as a generator that yields its Picard expansions (:class:`Picard`)."""
    alg = algebra(order, 1)
    for _ in range(passes):
        _, E = yield Picard(f, event, [DA.const(alg, v) for v in state_at(t_e)], 0, order)
        if abs(E.c[1]) == 0.0:
            raise ArithmeticError("degenerate event: dE/dt = 0 at the detected time")
        dt = float(invert([E])[0](np.array([[-E.cons]]))[0])
        t_e += dt
        if abs(dt) < 1e-13 * (1.0 + abs(t_e)):
            break
    return t_e, np.asarray(state_at(t_e), dtype=float)


def initial_state(alg, center, half_width, uncertain: list[int]) -> list[DA]:
    """``x0_i = center_i + half_width_i xi_j`` for the ``j``-th uncertain state ``i`` (eq. 3)."""
    return [DA.var(alg, uncertain.index(i), c, half_width[i]) if i in uncertain else DA.const(alg, c)
            for i, c in enumerate(center)]


def event_map(f, event, x0: list[DA], nodes: np.ndarray, t_e: float, order: int) -> EventMap:
    """The map of eq. (14) from ``xi`` to the event, around the refined nominal time ``t_e``.

    ``x0``: the state at ``nodes[0]`` as DAs in the ``m`` scaled deviations (the initial box, or
    the state entering a mode); ``nodes``: RK step nodes of the nominal run from there;
    ``event(x) -> DA`` is ``E``. Times are counted from ``nodes[0]``.
    """
    return run_one(event_map_steps(f, event, x0, nodes, t_e, order))


def event_map_steps(f, event, x0: list[DA], nodes: np.ndarray, t_e: float, order: int):
    """:func:`event_map` as a generator that yields its propagation (:mod:`.lockstep`).

    The state is carried to ``t_e`` in the ``m`` deviations and embedded in the algebra with the
    time deviation afterwards: the flow does not touch the new variable, so this is the same
    polynomial as propagating in ``m + 1`` variables, at the cost of ``m``."""
    m = x0[0].alg.nvars
    alg = algebra(order, m + 1)
    x_e = yield Propagation(f, list(x0), step_sizes(nodes, t_e))
    x_e = [x.embed(alg) for x in x_e]
    dt, state = yield EventSolve(f, event, x_e, m, order)          # eqs. (11)-(14)
    return EventMap(dt + t_e, state)


def fixed_time_map(f, x0: list[DA], nodes: np.ndarray, T: float) -> EventMap:
    """The transfer map of eq. (4) at a fixed time ``T`` (an event that does not move)."""
    return run_one(fixed_time_map_steps(f, x0, nodes, T))


def fixed_time_map_steps(f, x0: list[DA], nodes: np.ndarray, T: float):
    """:func:`fixed_time_map` as a generator that yields its propagation."""
    x = yield Propagation(f, list(x0), step_sizes(nodes, T))
    return EventMap(DA.const(x0[0].alg, T), x)


def local_extrema(values: np.ndarray, sense: str) -> list[int]:
    """Interior grid indices where ``values`` has a local minimum (``min``) or maximum (``max``)."""
    v = values if sense == "max" else -values
    inner = np.flatnonzero((v[1:-1] >= v[:-2]) & (v[1:-1] > v[2:])) + 1
    return inner.tolist()
