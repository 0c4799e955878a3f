"""An event property on a chain of modes: the estimated candidate maps and the verified sweep.

The run is followed from the initial mode through its urgent switches (the chain the nominal run
takes). In each mode the property lists, the extremum of ``q`` over the run is one of:

* ``q`` on entering the mode (the start, or the state an urgent switch lands in);
* an interior local extremum of ``q`` on the nominal run, as the event ``dq/dt = 0`` (eqs. 5-14);
* ``q`` on leaving the mode: the crossing of the urgent guard face (an event ``g(x) = 0``), or the
  horizon (the transfer map, eq. 4, in the initial mode; the event ``t = T`` on the global clock
  after a switch, since runs enter later modes at different times).

The state after a switch is the crossing map (reset applied), so the next mode's maps are maps of
the same initial deviations. The chain is followed until the horizon, or until no listed mode can
be reached any more. A switch whose time straddles the horizon (some runs of the box make it
before, some after) is followed too, and past the horizon while some runs may still switch before
it; the candidates that some runs may not reach are marked partial
(:meth:`EventProblem.candidate_steps`). The sweep does not take an exit straight back to the mode
a stretch's runs came from while its face rises (:meth:`EventProblem._returning`: closed guards on
a shared boundary), and starts the states entering through one affine face on that face
(:func:`_on_face`). Where the chain stops earlier (more than ``MAX_SWITCHES``
switches), where runs may switch before the horizon where the nominal run does not, or where the
nominal run is stationary in ``q`` and perturbed runs are not (their extrema there continue no
nominal one), the candidates say so (:class:`Candidates`). :meth:`EventProblem.sweep` is the
rigorous counterpart (:mod:`.verified`).
"""

from __future__ import annotations

import heapq
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy

from reach.backends.taylor.bound import enclose, estimated_remainder, polynomial_range
from reach.backends.taylor.da import DA, algebra
from reach.backends.taylor.deadline import NONE, Deadline
from reach.backends.taylor.event import (Picard, event_map_steps, fixed_time_map_steps, initial_state,
                                         local_extrema, refine_time_steps)
from reach.backends.taylor.flow import compile_expressions, compile_numeric
from reach.backends.taylor.interval import Jet
from reach.backends.taylor.keys import fingerprint
from reach.backends.taylor.lockstep import run_batch, run_one
from reach.backends.taylor.nominal import NominalRun, nominal
from reach.backends.taylor.tm import TM
from reach.backends.taylor.tm_flowpipe import stretch_from_box
from reach.backends.taylor.verified import (ROUNDING, at_sigma, crossing, enclose_stretch, sigma_in,
                                           variable_in)
from reach.model.constraints import affine_coefficients, lambdify_margins, opposite_pairs
from reach.model.lint import enabling_rows, fixed_ranges
from reach.spec.properties import BoundEvent

MAX_SWITCHES = 8
# enclosures kept per process: the properties of one model check the same subdomains, and
# refine's halves of two levels (root, 2 halves, 4 quarters: 14 stretches on SRNA01) must stay
# cached from one property to the next (8 let each level evict the previous; a rendezvous
# stretch of SRNA01 holds about 4 MB)
KEEP_ENCLOSURES = 32
LOOSEST_STEP_TOL = 1e-3      # the step tolerance is loosened up to this when a stretch's time series does not converge
FLOWPIPE_TOL = 1e-5          # flowpipe stretches: error added per unit time, relative to the state's size
FLOWPIPE_SECONDS = 120.0     # flowpipe stretches: time budget of one stretch
_ENCLOSURES: OrderedDict = OrderedDict()


@dataclass
class Exit:
    transition: object
    margins: object          # numpy margins of the guard, (N, n) -> (N, k)
    faces: list              # compiled g_j for DA / Taylor models
    reset: object | None     # compiled reset (all states) or None


class ModeCode:
    """A mode's flow, its urgent exits and (when the property lists the mode) ``q`` and ``dq/dt``,
    compiled once for floats, DAs, Taylor models and interval jets."""

    def __init__(self, model, name: str, quantity):
        mode, symbols = model.modes[name], model.symbols
        self.name, self.model, self._returns = name, model, {}
        self.f = compile_expressions(mode.flow, symbols)
        self.f_numeric = compile_numeric(mode.flow, symbols)
        self.exits = []
        for tr in model.outgoing(name):
            if not tr.urgent:
                continue
            reset = None
            if tr.reset:
                reset = compile_expressions([tr.reset.get(i, s) for i, s in enumerate(symbols)], symbols)
            faces = [_first(compile_expressions([c.g], symbols)) for c in tr.guard]
            self.exits.append(Exit(tr, lambdify_margins(tr.guard, symbols), faces, reset))
        self.q = self.qdot = self.q_numeric = None
        self.conserved = False          # the quantity's rate is 0 in this mode: it keeps its entry value
        if isinstance(quantity, tuple):           # avoid set: the margin max_j g_j (sweep only)
            parts = compile_expressions(list(quantity), symbols)
            self.q = lambda x: Largest(parts(x))
        elif quantity is not None:
            quantity = sympy.sympify(quantity)
            rate = sympy.expand(sum(sympy.diff(quantity, s) * f for s, f in zip(symbols, mode.flow)))
            self.conserved = rate == 0
            self.q = _first(compile_expressions([quantity], symbols))
            self.qdot = _first(compile_expressions([rate], symbols))
            self.q_numeric = _first(compile_numeric([quantity], symbols))

    def exit(self, grid: np.ndarray):
        """First node index where an urgent guard holds, with the exit and the face left last."""
        best = None
        for ex in self.exits:
            hits = np.flatnonzero(np.all(ex.margins(grid) <= 0, axis=1))
            if hits.size and hits[0] > 0 and (best is None or hits[0] < best[0]):
                k = hits[0]
                face = int(np.argmax(ex.margins(grid[k - 1:k])[0]))
                best = (k, ex, ex.faces[face])
        return best

    def stop(self, x0: np.ndarray):
        """The nominal run's stop function (:mod:`.nominal`), :meth:`guard_margin`, or None when
        the mode has no urgent exit or the start already lies in a guard (:meth:`exit` ignores
        guards held at the start)."""
        if not self.exits or self.guard_margin(np.asarray(x0, dtype=float)[None, :])[0] <= 0:
            return None
        return self.guard_margin

    def guard_margin(self, X: np.ndarray) -> np.ndarray:
        """For states ``X`` ``(k, n)``: the smallest over the urgent exits of the guard's largest
        margin (positive outside every guard)."""
        return np.min([np.max(ex.margins(X), axis=1) for ex in self.exits], axis=0)

    def returns(self, came) -> dict:
        """For a stretch whose runs all entered by the transition ``came``: ``{i: rate}`` for each
        exit ``i`` straight back to ``came``'s source, neither resetting a state, whose guard has a
        face ``g <= 0`` with ``-g <= 0`` a face of ``came``'s guard (so ``g >= 0`` for every run at
        its entry); ``rate`` is ``dg/dt`` along this mode's flow, compiled
        (:meth:`EventProblem._returning`)."""
        if came.name not in self._returns:
            out = {}
            symbols, flow = self.model.symbols, self.model.modes[self.name].flow
            if _keeps_state(came, symbols):
                for i, ex in enumerate(self.exits):
                    tr = ex.transition
                    if tr.target != came.source or not _keeps_state(tr, symbols):
                        continue
                    face = next((c.g for c in tr.guard if any(sympy.expand(c.g + d.g) == 0 for d in came.guard)),
                                None)
                    if face is not None:
                        rate = sum(sympy.diff(face, s) * f for s, f in zip(symbols, flow))
                        out[i] = _first(compile_expressions([rate], symbols))
            self._returns[came.name] = out
        return self._returns[came.name]

    def alive(self, box: np.ndarray) -> bool:
        """Whether no run with its states in ``box`` (``(n, 2)`` bounds, a step's enclosure) can
        stop there. A run stops only on its invariant's boundary, where the flow points out
        (``H_r x = g_r``, ``H_r f(x) >= 0``) and no transition is enabled; so for each row the box
        may break, the part of the box on that face with the flow out (an affine flow: rows of
        an LP; a nonlinear one: the part beyond the face) must lie where one urgent exit is
        enabled: its guard, and its target's invariant at the reset state (:func:`enabling_rows`).
        False where that cannot be shown: a nonlinear invariant or guard, an unbounded box."""
        mode = self.model.modes[self.name]
        if not mode.invariant:
            return True
        halves = mode.invariant_halfspaces
        if halves is None or not np.all(np.isfinite(box)):
            return False
        n = self.model.n
        H, g = np.asarray(halves[0], float).reshape(-1, n), np.asarray(halves[1], float).reshape(-1)
        box = box.copy()                        # states no flow or jump changes keep their initial range
        fixed, low, high = self._fixed
        box[fixed, 0] = np.maximum(box[fixed, 0], low)
        box[fixed, 1] = np.minimum(box[fixed, 1], high)
        center, radius = box.mean(axis=1), 0.5 * (box[:, 1] - box[:, 0])
        beyond = [r for r in range(len(g)) if H[r] @ center + np.abs(H[r]) @ radius > g[r]]
        return all(self._leaves_at(H[r], g[r], box) for r in beyond)

    @cached_property
    def _fixed(self) -> tuple:
        """``(index, low, high)`` of the states no run changes (parameters, a switch time) and
        their initial ranges (:func:`reach.model.lint.fixed_ranges`)."""
        return fixed_ranges(self.model)

    def _leaves_at(self, row, bound, box) -> bool:
        """Whether the runs of ``box`` that may stop on the face ``row x = bound`` (the flow
        pointing out) all have an urgent exit enabled there (LPs over the box)."""
        from reach import lp

        linear = self.model.modes[self.name].linear
        if linear is not None:                  # on the face, flow out: row x = bound, -row (A x + b) <= 0
            A, b = linear
            A_ub, b_ub, A_eq, b_eq = -(row @ A)[None, :], [row @ b], row[None, :], [bound]
        else:                                   # the part of the box beyond the face
            A_ub, b_ub, A_eq, b_eq = -row[None, :], [-bound], None, None
        bounds = (box[:, 0], box[:, 1])
        try:
            if lp.feasible_point(A_ub, b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds) is None:
                return True                     # no run reaches that face moving out
        except lp.LPError:
            return False
        size = np.abs(box).max(axis=1)          # a row's rounding scale: the magnitudes it combines
        for ex in self.exits:
            rows = enabling_rows(self.model, ex.transition)
            if rows is None:
                continue
            try:
                if all((res := lp.maximize(r, A_ub, b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds)).optimal
                       and res.value <= c + 1e-9 * (1.0 + abs(c) + np.abs(r) @ size) for r, c in zip(*rows)):
                    return True
            except lp.LPError:
                continue
        return False

    def may_enter(self, ex: Exit, X) -> bool:
        """Whether the guard of ``ex`` may hold for some deviation of the Taylor models ``X``."""
        return all(face(X).bound()[0] <= 0 for face in ex.faces)

    def inside(self, X, certainly: bool) -> Exit | None:
        """An exit whose guard holds for the Taylor models ``X``: for every deviation
        (``certainly``) or possibly for some."""
        for ex in self.exits:
            bounds = [face(X).bound() for face in ex.faces]
            if all((hi if certainly else lo) <= 0 for lo, hi in bounds):
                return ex
        return None


class Candidates(dict):
    """The candidate maps of one box, by name. Names are unique: a mode entered several times
    keeps a candidate per visit (each named by its nominal time), and :meth:`add` never replaces
    one.

    A candidate is *partial* (in ``partial``) when some runs of the box may not reach it before
    the horizon: an event whose estimated time reaches past the horizon, anything after a
    switch that some runs may make only after it, the value at the horizon in a mode that some
    runs may have left, ``q`` over a stretch past an exit or an entry. It holds the extremum of
    the runs that reach it, so it counts for the bound's outer end only
    (:func:`.bound.extremum_bound`).
    ``alternatives`` are pairs of candidates of which every run reaches one: the exit of a mode
    that runs leave around the horizon and the stretch before it that holds the value at the
    horizon of the runs that stay. A *stretch* (in ``stretches``) is ``q`` over a stretch of
    time next to an entry or an exit, a map of one more variable (the time) than the box's.

    ``gap`` says why they may miss the extremum of some runs (None when they follow the run to
    the horizon): the expansion stopped before the horizon, some runs may switch before it where
    the nominal run does not, or the nominal run is stationary in ``q`` where perturbed runs are
    not. Then they bound only the inner end of the extremum."""

    gap: str | None = None

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.partial: set[str] = set()
        self.stretches: set[str] = set()
        self.alternatives: list[tuple[str, str]] = []

    def add(self, name: str, poly: DA, partial: bool, stretch: bool = False) -> str:
        """Keep ``poly`` under ``name`` (primed while the name is taken); the name kept."""
        while name in self:
            name += "'"
        self[name] = poly
        if partial:
            self.partial.add(name)
        if stretch:
            self.stretches.add(name)
        return name

    def like(self, maps: dict) -> "Candidates":
        """``maps`` (the same names, e.g. truncated) with this one's gap, partial names,
        stretches and alternatives."""
        out = Candidates(maps)
        out.gap, out.partial, out.stretches = self.gap, set(self.partial), set(self.stretches)
        out.alternatives = list(self.alternatives)
        return out


class Largest:
    """``max_j g_j`` of Taylor models, enclosed by ``[max_j lo_j, max_j hi_j]``: the depth to an
    avoid set ``{g_j <= 0 for all j}`` (positive outside it)."""

    def __init__(self, parts):
        self.parts = parts

    def bound(self):
        ends = [p.bound() for p in self.parts]
        return max(float(lo) for lo, _ in ends), max(float(hi) for _, hi in ends)


def _first(fn):
    return lambda x: fn(x)[0]


def _keeps_state(transition, symbols) -> bool:
    """Whether ``transition`` resets no state (every assignment, if any, is ``x := x``)."""
    return all(sympy.sympify(e) == symbols[i] for i, e in transition.reset.items())


def unsupported_switch(model) -> str | None:
    """Why some switch of ``model`` is not a guard crossing that the candidates and the sweep can
    follow, or None. Both follow a run in a mode until it crosses into an urgent guard through a
    face: a mode where no time passes (SpaceEx ``flow false``), an urgent guard without
    constraints (it holds on entry) and a guard with no interior (an equality ``x == c``: a run
    meets it at an instant, and crosses no face into it) switch otherwise."""
    for name, mode in model.modes.items():
        if mode.timeless:
            # a mode left by an urgent transition without guard is read as one too (the loader)
            at_once = next((tr.name for tr in model.transitions if tr.source == name and tr.urgent and not tr.guard),
                           None)
            why = "flow false" if at_once is None else f"flow false, or left at once by '{at_once}', an urgent " \
                                                       "transition without guard"
            return (f"no time passes in mode '{name}' ({why}): taylor follows runs that leave a mode "
                    "by crossing into a guard, not instantaneous switches (star and montecarlo do)")
    for tr in model.transitions:
        if not tr.urgent:
            continue
        pair = _equality(tr.guard, model.symbols)
        if pair is not None:
            return (f"the guard of '{tr.name}' is an equality ({pair[0].text} and {pair[1].text}): a run meets "
                    "it at an instant without crossing into it, which taylor does not detect; write the "
                    "inequality the flow crosses (e.g. x >= c where the invariant keeps x <= c)")
    return None


def _equality(guard, symbols):
    """Two constraints of ``guard`` that leave it no interior (``a.x <= c`` and ``a.x >= c``, or
    a tighter pair; ``p <= c`` and ``p >= c`` for any expression ``p``, as ``x^2 == 1``), or
    None."""
    for i, j, total, _ in opposite_pairs(guard):        # total = c_lo - c_hi
        if total >= -1e-12:
            return guard[i], guard[j]
    rows = [(c, affine_coefficients(c.g, symbols)) for c in guard]
    rows = [(c, a, b) for c, coeffs in rows if coeffs is not None for a, b in [coeffs] if np.any(a)]
    for i, (c1, a1, b1) in enumerate(rows):
        for c2, a2, b2 in rows[i + 1:]:
            k = int(np.argmax(np.abs(a1)))
            lam = -a2[k] / a1[k]                      # a2 = -lam a1 with lam > 0: opposite sides
            if lam > 0 and np.allclose(a2, -lam * a1, rtol=1e-12, atol=0.0):
                width = -b1 - b2 / lam                # a1.x lies in [b2 / lam, -b1]
                if width <= 1e-12 * (1.0 + abs(b1)):
                    return c1, c2
    return None


def global_clock(model) -> int | None:
    """A state with rate 1 in every mode, starting at 0 and never reset: the global time."""
    for i in model.clocks:
        if model.initial.low[i] == 0 == model.initial.high[i] and \
                not any(i in tr.reset for tr in model.transitions):
            return i
    return None


class EventProblem:
    """One event property of a model, compiled per mode along the chain of urgent switches."""

    def __init__(self, model, prop: BoundEvent):
        self.model, self.prop = model, prop
        self.low, self.high = model.initial.low, model.initial.high
        self.uncertain = [i for i in range(model.n) if self.high[i] > self.low[i]]
        self.clock = global_clock(model)
        self._codes: dict[str, ModeCode] = {}
        self.code(model.initial.mode)
        for name in prop.modes:
            self.code(name)

    def at_horizon(self, x):
        """The event ``t = T`` on the global clock (one function for every subdomain, so that
        their event maps are answered as one batch, :mod:`.lockstep`)."""
        return x[self.clock] - self.model.horizon

    def code(self, name: str) -> ModeCode:
        if name not in self._codes:
            quantity = self.prop.quantity.get(name) if name in self.prop.modes else None
            self._codes[name] = ModeCode(self.model, name, quantity)
        return self._codes[name]

    # ------------------------------------------------------------ estimated (event maps)
    def candidates(self, center: np.ndarray, half_width: np.ndarray, order: int, tol: float) -> Candidates:
        """Taylor maps (in the subdomain's scaled deviations) of the extremum candidates."""
        return run_one(self.candidate_steps(center, half_width, order, tol))

    def candidates_batch(self, boxes: list, order: int, tol: float) -> list[Candidates]:
        """:meth:`candidates` of many boxes ``(center, half_width)``, their DA propagations run
        together as one batch (:mod:`.lockstep`)."""
        return run_batch([self.candidate_steps(c, h, order, tol) for c, h in boxes])

    def candidate_steps(self, center: np.ndarray, half_width: np.ndarray, order: int, tol: float):
        """:meth:`candidates` as a generator that yields its DA propagations.

        The nominal run is followed from mode to mode. Around the horizon the runs of a box may
        differ in whether they switch before it, so the chain is followed on past the horizon
        while some runs may switch before it (the estimated enclosure of the switch time,
        eqs. 27-28, reaches below the horizon):

        * where the nominal run stays in a mode to the horizon, it is continued past it to its
          next crossing (:meth:`_continued`); a switch that every run makes after the horizon
          ends the chain;
        * a switch that some runs may make after the horizon (its time reaches past it) makes
          everything after it partial (:class:`Candidates`). The runs that stay in the mode are
          there at the horizon, at most ``L`` (the time's upper end minus the horizon) before
          their exit: ``q`` over the stretch of length ``L`` before the exit
          (:meth:`_stretch_steps`) holds their value at the horizon, and the exit and that
          stretch are alternatives;
        * a mode the nominal run enters after the horizon holds the runs that enter before it,
          for at most ``L`` (the horizon minus the entry time's lower end): its entry and ``q``
          over the stretch of length ``L`` after the entry are partial candidates;
        * where the continued run does not cross but some runs may be inside a guard that
          matters at the horizon (:meth:`_switch_by_horizon`), they switched before it in a way
          the nominal run does not show: a gap.
        """
        T = self.model.horizon
        X = initial_state(algebra(order, len(self.uncertain)), center, half_width, self.uncertain)
        mode, t0, out = self.model.initial.mode, 0.0, Candidates()
        sign = 1.0 if self.prop.sense == "max" else -1.0
        partial = False             # whether some runs of the box may enter this mode only after the horizon
        for hop in range(MAX_SWITCHES + 1):
            code = self.code(mode)
            entry = f"{mode}:entry@{t0:.6g}" if hop else "start"
            if abs(T - t0) <= 1e-12 * max(1.0, T):       # entered at the horizon: one instant
                if code.q is not None:
                    out.add(entry, code.q(X), partial)
                return out
            if t0 > T:                                  # entered after the horizon by the nominal run
                if code.q is not None:
                    out.add(entry, code.q(X), True)
                    stay = T - self._time_range(X[self.clock])[0]
                    q = yield from self._stretch_steps(code, X, 0.0, stay, order)
                    out.add(f"{mode}:after-entry@{t0:.6g}", q, True, stretch=True)
                leave, run = yield from self._continued(code, X, t0, tol)
                if leave is None:
                    return out
            else:
                x_nominal = np.array([x.cons for x in X])
                run = yield NominalRun(code.f_numeric, x_nominal, T - t0, tol, code.stop(x_nominal))
                grid = run.grid()
                leave = code.exit(grid)
                if leave is None and run.nodes[-1] < T - t0:     # grazed the guard: run to the horizon
                    run = yield NominalRun(code.f_numeric, x_nominal, T - t0, tol)
                    grid = run.grid()
                    leave = code.exit(grid)
                last = len(run.nodes) - 1 if leave is None else leave[0]
                to_horizon = run            # the nominal run in the mode, up to its switch or the horizon
                if code.q is not None:
                    out.add(entry, code.q(X), partial)
                if code.q is not None and not code.conserved:      # conserved: every value is the entry's
                    values = np.asarray(code.q_numeric(list(grid[: last + 1].T)))
                    turning = list(local_extrema(values, self.prop.sense))
                    if _turns_at_entry(code.qdot(X)):
                        turning.insert(0, None)
                    for k in turning:
                        tk = 0.0 if k is None else run.sharpen(k, lambda Y: sign * np.asarray(code.q_numeric(list(Y))))
                        try:
                            t_e, _ = yield from refine_time_steps(code.f, code.qdot, run.solution, tk, order)
                        except ArithmeticError:
                            if k is not None:
                                raise
                            continue        # the rate does not change with time at the entry: no turn
                        span = float(run.nodes[last])
                        if not -1e-9 * max(1.0, span) <= t_e <= span * (1 + 1e-9):
                            # Newton went to a root off the run (t = 166 of a 2 s run): no candidate;
                            # from a turn the grid saw, the bound is then open (no silent miss)
                            if k is not None and out.gap is None:
                                out.gap = (f"the turning point near t = {t0 + tk:.6g} in mode '{mode}' "
                                           "could not be located")
                            continue
                        em = yield from event_map_steps(code.f, code.qdot, X, run.nodes, t_e, order)
                        late = self._time_range(self._event_time(em, t0))[1] > T
                        out.add(f"{mode}:extremum@{t0 + t_e:.6g}", code.q(em.state), partial or late)
                    flat = _plateau(values)
                    if flat is not None and out.gap is None:
                        em = yield from fixed_time_map_steps(code.f, X, run.nodes, float(run.nodes[flat]))
                        if _varies(code.qdot(em.state)):
                            out.gap = (f"the nominal run is stationary in the quantity at t = "
                                       f"{t0 + run.nodes[flat]:.6g} in mode '{mode}' and perturbed runs are not: "
                                       "their extrema there continue no nominal one")
                if leave is None:
                    leave, run = yield from self._continued(code, X, t0, tol)
                    if leave is None:                   # the nominal run does not switch
                        at_T = yield from self._at_horizon(code, X, to_horizon.nodes, t0, hop, order)
                        early = self._switch_by_horizon(code, at_T.state)
                        if early is not None:
                            out.gap = (f"some runs may be inside the guard to '{early.transition.target}' at the "
                                       f"horizon in mode '{mode}', where the nominal run continued does not switch")
                        if code.q is not None:
                            out.add(f"{mode}:horizon", code.q(at_T.state), partial or early is not None)
                        return out
            k, ex, face = leave
            tk = run.sharpen(k, lambda Y: np.where(np.all(ex.margins(Y.T) <= 0, axis=1),
                                                   -np.arange(Y.shape[1]), -np.inf))
            t_e, _ = yield from refine_time_steps(code.f, face, run.solution, tk, order)
            em = yield from event_map_steps(code.f, face, X, run.nodes, t_e, order)
            first, final = self._time_range(self._event_time(em, t0))
            if first > T:           # every run switches after the horizon (only a continued run does)
                if code.q is not None and t0 < T:
                    at_T = yield from self._at_horizon(code, X, to_horizon.nodes, t0, hop, order)
                    out.add(f"{mode}:horizon", code.q(at_T.state), partial)
                return out
            late = final > T                            # some runs may switch after the horizon
            if code.q is not None:
                leaving = out.add(f"{mode}:exit@{t0 + t_e:.6g}", code.q(em.state), partial or late)
                if late and t0 < T:                     # those runs are in the mode at the horizon
                    q = yield from self._stretch_steps(code, em.state, T - final, 0.0, order)
                    staying = out.add(f"{mode}:before-exit@{t0 + t_e:.6g}", q, True, stretch=True)
                    if not partial:
                        out.alternatives.append((leaving, staying))
            if not self._leads_to_property(ex.transition.target):
                return out
            X = ex.reset(em.state) if ex.reset else em.state
            t0, mode, partial = t0 + t_e, ex.transition.target, partial or late
            if self.clock is None:
                raise ValueError("events after a mode switch need a global clock state")
        out.gap = f"the expansion stopped at t = {t0:.6g}: more than {MAX_SWITCHES} mode switches"
        return out

    def _stretch_steps(self, code: ModeCode, x_e: list[DA], start: float, end: float, order: int):
        """``q`` along the runs through the states ``x_e`` (a map of the box's deviations) over
        the times ``start`` to ``end`` from there (a generator, :mod:`.lockstep`): the Picard
        expansion (eq. 6) in the time deviation ``dt``, with ``dt = (start + end)/2 + s (end -
        start)/2``, a map of the deviations and a last variable ``s`` in ``[-1, 1]``."""
        m = x_e[0].alg.nvars
        alg = algebra(order, m + 1)
        _, q = yield Picard(code.f, code.q, [x.embed(alg) for x in x_e], m, order)
        times = DA.var(alg, m, 0.5 * (start + end), 0.5 * (end - start))
        return q.compose([DA.var(alg, j) for j in range(m)] + [times])

    def _continued(self, code: ModeCode, X: list[DA], t0: float, tol: float):
        """The nominal run of a mode entered at ``t0`` (state ``X``) continued past the horizon
        to its next crossing into a guard that matters (:meth:`_matters`), a generator:
        ``(leave, run)`` as from :meth:`ModeCode.exit`, or ``(None, None)`` when it crosses none.
        It runs until the horizon plus the longest time a run of the box can have spent in the
        mode before the horizon plus the spread of the entry times (the estimated enclosure of
        the entry time, eqs. 27-28): time for the runs that enter first to switch again before
        the horizon, for the nominal one to switch after it."""
        if not any(self._matters(code, ex) for ex in code.exits):
            return None, None
        T = self.model.horizon
        entered_lo, entered_hi = self._time_range(X[self.clock]) if self.clock is not None else (t0, t0)
        duration = max(T - t0, 0.0) + (T - entered_lo) + (entered_hi - entered_lo)
        x_nominal = np.array([x.cons for x in X])
        run = yield NominalRun(code.f_numeric, x_nominal, duration, tol, code.stop(x_nominal))
        leave = code.exit(run.grid())
        if leave is None or not self._matters(code, leave[1]):
            return None, None
        return leave, run

    def _matters(self, code: ModeCode, ex: Exit) -> bool:
        """Whether a switch through ``ex`` changes the candidates: it ends a listed mode's stretch
        (``q`` at the exit and no value at the horizon), or leads towards a listed mode."""
        return code.q is not None or self._leads_to_property(ex.transition.target)

    def _at_horizon(self, code: ModeCode, X: list[DA], nodes: np.ndarray, t0: float, hop: int, order: int):
        """The map of the state at the horizon of a run that stays in ``code``'s mode, entered
        at the nominal time ``t0`` in the state ``X`` (a generator, :mod:`.lockstep`): the
        transfer map (eq. 4) in the initial mode, the event ``t = T`` on the global clock after
        a switch (runs enter at different times). ``nodes``: the nominal run's step nodes."""
        if hop == 0:
            return (yield from fixed_time_map_steps(code.f, X, nodes, self.model.horizon))
        return (yield from event_map_steps(code.f, self.at_horizon, X, nodes, self.model.horizon - t0, order))

    def _event_time(self, em, t0: float) -> DA:
        """The time of the event of the map ``em``: the global clock's, or, without one (in the
        initial mode), counted from ``t0``."""
        return em.state[self.clock] if self.clock is not None else em.time + t0

    @staticmethod
    def _time_range(time: DA) -> tuple[float, float]:
        """The estimated enclosure (eqs. 27-28) of a time over the box."""
        lo, hi = enclose(time, estimated_remainder(time))
        return float(lo), float(hi)

    def _switch_by_horizon(self, code: ModeCode, X_T: list[DA]) -> Exit | None:
        """An urgent exit of ``code``'s mode that matters (:meth:`_matters`) whose guard some runs
        of the box may be inside at the horizon had they stayed in the mode (the state map
        ``X_T``): the estimated enclosure (eqs. 27-28) of every face of the guard reaches zero.
        Such runs crossed into the guard, and switched, before the horizon."""
        for ex in code.exits:
            if not self._matters(code, ex):
                continue
            margins = [face(X_T) for face in ex.faces]
            if all(float(enclose(g, estimated_remainder(g))[0]) <= 0 for g in margins):
                return ex
        return None

    # ------------------------------------------------------------ rigorous (verified sweep)
    def _enclosure(self, code: ModeCode, x0: list[DA], error: np.ndarray, duration: float, rel_tol: float,
                   tol: float, deadline: Deadline = NONE):
        """The verified enclosure of one mode's stretch from ``x0 + [-error, error]``, shared by the
        properties of a model (it does not depend on the quantity): kept for the last few
        subdomains (a flowpipe cut short by the ``deadline`` is not kept)."""
        key = fingerprint(self.model, code.name, [x.c for x in x0], error, duration, rel_tol, tol)
        if key in _ENCLOSURES:
            _ENCLOSURES.move_to_end(key)
        else:
            start = np.array([x.cons for x in x0])
            run = nominal(code.f_numeric, start, duration, tol, stop=code.stop(start))
            stop = lambda step: code.inside([TM(at_sigma(p, 1.0)) for p in step.poly], True) is not None
            # the sweep takes its first step from the nominal run and runs on (past the nominal
            # crossing) until every run is inside the guard, or to the horizon
            # a tolerance the time series cannot meet is loosened (a looser step defect widens the
            # bound but keeps it sound) before the flowpipe is tried
            enc, why = None, ""
            for loosened in _loosened(rel_tol):
                try:
                    enc = enclose_stretch(code.f, x0, np.r_[run.nodes[:2], duration], stop, loosened, error)
                except ArithmeticError as err:
                    why = str(err)
                    continue
                if enc is not None:
                    break
                why = "the logarithmic-norm error bound does not close"
            if enc is None:
                if deadline.left() <= 0:
                    raise ArithmeticError(deadline.text)
                try:
                    enc = self._flowpipe(code, x0, error, duration, float(run.nodes[1] - run.nodes[0]),
                                         min(FLOWPIPE_SECONDS, deadline.left()))
                except ArithmeticError as err:    # kept too: the next property need not try again
                    if deadline.passed():
                        raise ArithmeticError(f"mode '{code.name}': {deadline.text}") from None
                    enc = ArithmeticError(f"mode '{code.name}': {why}; {err}")
            _ENCLOSURES[key] = (enc, self.model)      # the model stays alive with its entry
            while len(_ENCLOSURES) > KEEP_ENCLOSURES:
                _ENCLOSURES.popitem(last=False)
        enc = _ENCLOSURES[key][0]
        if isinstance(enc, ArithmeticError):
            raise enc
        return enc

    def _flowpipe(self, code: ModeCode, x0: list[DA], error: np.ndarray, duration: float, h0: float,
                  budget: float = FLOWPIPE_SECONDS):
        """The stretch by a Taylor-model flowpipe (:mod:`.tm_flowpipe`: validated Picard steps,
        QR-preconditioned symbolic remainders), where the logarithmic-norm bound of
        :func:`.verified.enclose_stretch` does not close (an expanding flow such as Van der Pol's).
        It starts from the interval hull of ``x0 + [-error, error]`` (the subdomain's box itself
        for an initial box), carries states of constant rate (clocks) exactly, and sets its steps
        for an error growth of ``FLOWPIPE_TOL`` times the state's size per unit time. Raises
        ArithmeticError (the sweep's reason) when a step cannot be validated or the time budget
        (``FLOWPIPE_SECONDS``, or what is left of the check's) is spent."""
        box = np.array([TM(at_sigma(x, -1.0), -e, e).bound() for x, e in zip(x0, error)], dtype=float)
        if not np.all(np.isfinite(box)):
            raise ArithmeticError(f"no verified enclosure in mode '{code.name}' (unbounded start)")
        flow = self.model.modes[code.name].flow
        exact = [i for i, rate in enumerate(flow) if sympy.sympify(rate).is_number]
        tol = FLOWPIPE_TOL * np.maximum(1.0, np.abs(box).max(axis=1))
        inside = lambda end: code.inside(end, True) is not None
        return stretch_from_box(code.f, box[:, 0], box[:, 1], x0[0].alg.order, exact, tol, duration,
                                h0, inside, budget)

    def sweep(self, center: np.ndarray, half_width: np.ndarray, order: int, rel_tol: float,
              tol: float, keep_sets: bool = False, deadline: Deadline = NONE) -> dict:
        """Rigorous bounds of the extremum of ``q`` over the listed modes' stretches.

        In each mode the verified enclosure (:mod:`.verified`) runs until the step whose end lies
        inside one urgent guard for every deviation (every run has switched by then) or the
        horizon; runs that switched earlier are followed on with the mode's flow, which only
        enlarges the set. The upper end (for a maximum) is the largest Taylor-model bound of ``q``
        over those steps, refined by branch and bound over the steps' variables where that may
        raise it (:func:`_stretch_top`). For every exit whose guard some step may meet, the states entering
        its target lie in the Taylor models of :func:`.verified.crossing` (a polytope guard crossed
        through one face) and in the hull of those step boxes, clipped to the guard's
        single-variable bounds; the models are taken unless they are wider than the hull
        (:func:`_no_wider`). Mapped by the reset, they start the target mode's sweep (up to the
        horizon counted from their earliest entry, which is no earlier than the stretch's earliest
        start plus the first step that may meet the guard), so a mode with several exits (a dock and an
        abort) branches. Exits from which no listed mode can be reached are not followed. The
        lower end is the best bound of ``q`` at the initial mode's step nodes that no run can
        have left the mode before, or on an entry box that every run passes through (a chain
        of exits, each the only one possible in its mode). With ``keep_sets`` the result's
        ``"sets"`` lists every step's enclosure box (:func:`_step_box`). Past the ``deadline`` no
        branch starts: the bound is unbounded, its reason the budget."""
        T = self.model.horizon
        m = len(self.uncertain)
        sign = 1.0 if self.prop.sense == "max" else -1.0
        outer, inner, steps, error, stretches = -np.inf, -np.inf, 0, 0.0, 0
        kept = [] if keep_sets else None
        x0 = initial_state(algebra(order, m + 1), center, half_width, self.uncertain)
        branches = [(self.model.initial.mode, x0, np.zeros(len(x0)), 0.0, 0, True, None)]
        while branches:
            mode, x0, x0_error, t_earliest, hop, sure, came = branches.pop()
            if deadline.passed():
                return _unbounded(deadline.text)
            if hop > MAX_SWITCHES:
                return _unbounded(f"more than {MAX_SWITCHES} mode switches")
            code = self.code(mode)
            start = [TM(at_sigma(x, -1.0), -e, e) for x, e in zip(x0, x0_error)]
            if T - t_earliest <= 1e-12 * max(1.0, T):       # entered at the horizon: one instant
                if code.q is not None:
                    lo, hi = code.q(start).bound()
                    outer = max(outer, hi if sign > 0 else -lo)
                    if sure:
                        inner = max(inner, lo if sign > 0 else -hi)
                continue
            try:
                enc = self._enclosure(code, x0, x0_error, T - t_earliest, rel_tol, tol, deadline)
            except ArithmeticError as err:
                return _unbounded(str(err))
            stretches += 1
            steps, error = steps + len(enc.steps), max(error, float(np.max(enc.error_box)))
            # the start counts for the inner end only if no run can switch at t = 0; a run
            # may stop where the invariant ends it with no urgent exit enabled (ModeCode.alive):
            # the inner end then stops where that may first happen, and no branch after is sure
            certified = hop == 0 and code.inside(start, False) is None
            blocked = not sure
            if code.q is not None and hop > 0 and sure:
                lo, hi = code.q(start).bound()
                inner = max(inner, lo if sign > 0 else -hi)
            entry = {i: [] for i in range(len(code.exits))}
            steps_in = {i: [] for i in range(len(code.exits))}   # the steps that may meet each exit's guard
            first = {}                  # the first step that may meet each exit's guard
            exit_taken = None
            returning = dict(code.returns(came)) if came is not None else {}
            tops = []                   # per step: the upper end of sign * q, the index, q
            for k in range(len(enc.steps)):
                X = enc.tm(k)
                if not blocked and not code.alive(np.array([x.bound() for x in X], dtype=float)):
                    blocked, certified = True, False
                returning = self._returning(returning, X)
                if kept is not None:
                    kept.append(_step_box(mode, X, enc.steps[k], t_earliest, self.clock))
                if code.q is not None:
                    value = code.q(X)
                    lo, hi = value.bound()
                    tops.append((hi if sign > 0 else -lo, k, value))
                    if certified:
                        lo0, hi0 = code.q([TM(at_sigma(x.poly, -1.0), x.lo, x.hi) for x in X]).bound()
                        inner = max(inner, lo0 if sign > 0 else -hi0)
                box = None
                for i, ex in enumerate(code.exits):
                    if i in returning:          # met only at the entry instant: a return
                        continue
                    if code.may_enter(ex, X):
                        certified = False
                        box = np.array([x.bound() for x in X]) if box is None else box
                        entry[i].append(box)
                        steps_in[i].append(k)
                        first.setdefault(i, k)
                exit_taken = code.inside(enc.tm_at_end(k), True)
                if exit_taken is not None:
                    break
            outer = _stretch_top(tops, sign, outer)
            end = enc.steps[k].t0 + enc.steps[k].h
            if exit_taken is None and end < (T - t_earliest) * (1 - 1e-12):
                return _unbounded(f"could not prove that every run leaves '{mode}' (to t = {end:g})")
            possible = [i for i, boxes in entry.items() if boxes]
            for i in possible:
                ex = code.exits[i]
                if not self._leads_to_property(ex.transition.target):
                    continue
                if self.clock is None:
                    return _unbounded("events after a mode switch need a global clock state")
                hull = _entry_box(ex, entry[i], self.model)
                states = _no_wider(self._crossing(code, ex, enc, first[i], end), hull)
                if states is None:
                    box = _entry_box(ex, _sliced(code, ex, enc, steps_in[i], entry[i]), self.model)
                    tie = None if ex.reset is not None or first[i] == 0 or not np.all(np.isfinite(box)) \
                        else self._face(ex)
                    if ex.reset is not None:
                        out = ex.reset(Jet.seed(box[:, 0], box[:, 1]))
                        box = np.array([[o.lo, o.hi] if isinstance(o, Jet) else [o, o] for o in out], dtype=float)
                    if tie is not None:
                        box, tied = _on_face(box, *tie)
                    wide = [j for j in range(self.model.n) if box[j, 1] > box[j, 0] and (tie is None or j != tied)]
                    start_box = initial_state(algebra(order, len(wide) + 1), box.mean(axis=1),
                                              0.5 * (box[:, 1] - box[:, 0]), wide)
                    start_error = np.zeros(self.model.n)
                    if tie is not None:
                        start_box[tied], start_error[tied] = _tied(start_box, box, tied, *tie)
                else:
                    if ex.reset is not None:
                        states = ex.reset(states)
                    start_box = [x.poly + 0.5 * (x.lo + x.hi) for x in states]
                    start_error = np.array([0.5 * (x.hi - x.lo) for x in states])
                    box = np.array([x.bound() for x in states])
                # no run enters before this stretch's earliest start plus the window's start
                earliest = max(box[self.clock, 0], t_earliest + enc.steps[first[i]].t0)
                branches.append((ex.transition.target, start_box, start_error, earliest, hop + 1,
                                 not blocked and len(possible) == 1 and ex is exit_taken, ex.transition))
        bound = (inner, outer) if sign > 0 else (-outer, -inner)
        out = {"bound": tuple(float(v) for v in bound), "steps": steps, "error": error,
               "stretches": stretches}
        if kept is not None:
            out["sets"] = kept
        return out

    def _face(self, ex: Exit):
        """``(a, b)`` where the guard of ``ex`` is the one affine face ``a . x + b <= 0`` (not
        strict, not reading the clock), else None: a run outside it at a window's start enters it
        on ``a . x + b = 0`` (:func:`_on_face`)."""
        guard = ex.transition.guard
        if len(guard) != 1 or guard[0].strict:
            return None
        coeffs = affine_coefficients(guard[0].g, self.model.symbols)
        if coeffs is None or coeffs[0][self.clock] != 0 or not np.any(coeffs[0]):
            return None
        return coeffs

    @staticmethod
    def _returning(returning: dict, X) -> dict:
        """The exits of ``returning`` (:meth:`ModeCode.returns`) still not met after the entry
        instant, one step further: those whose face's rate stays positive over the step's
        enclosure ``X`` (a Taylor-model bound).

        Every run of the stretch entered by a transition ``J1`` from mode ``P`` without a reset,
        so with ``g >= 0`` for a face ``g <= 0`` of the exit ``J2`` back to ``P``. While
        ``dg/dt > 0`` over every step so far, ``g > 0`` for every run after it has flowed any time,
        so ``J2``'s guard has held only at the entry instant. A run that takes ``J2`` then is back
        in ``P`` at the state and instant it left, which ``P``'s stretch already holds (the
        simulator does not take such a jump: ``Simulator._urgent_now``). From the first step
        where the rate may not be positive on, ``J2`` is taken as any exit; at that step's start
        every run is strictly outside its guard, as the crossing models assume (:meth:`_crossing`).
        A saturated loop written as three modes with closed guards on the shared boundaries
        (``lin``, ``satp``, ``satn``) would otherwise switch back and forth at its entry until the
        switch limit, and the entry states' hull, a box wider than the boundary they lie on, would
        meet the guard after the entry too."""
        return {i: rate for i, rate in returning.items() if rate(X).bound()[0] > 0}

    def _crossing(self, code: ModeCode, ex: Exit, enc, k: int, end: float):
        """The entry states of ``ex`` as Taylor models (:func:`.verified.crossing`) over the window
        from step ``k``'s start to ``end``, or None (a guard that is not a polytope, a window from
        the stretch's start, where runs may already be inside the guard without crossing a face,
        or the argument does not apply). Step ``k - 1`` cannot meet the guard, so every run is
        outside it at the window's start."""
        faces = [affine_coefficients(c.g, self.model.symbols) for c in ex.transition.guard]
        if k == 0 or any(face is None for face in faces) or not enc.crossing_models:
            return None
        step = enc.steps[k]
        x_start = [at_sigma(p, -1.0) for p in step.poly]
        return crossing(code.f, x_start, enc.error_box[k], end - step.t0, faces)

    def _leads_to_property(self, mode: str) -> bool:
        """Whether a listed mode can be reached from ``mode`` through urgent switches."""
        seen, todo = set(), [mode]
        while todo:
            name = todo.pop()
            if name in self.prop.modes:
                return True
            if name not in seen:
                seen.add(name)
                todo += [tr.target for tr in self.model.outgoing(name) if tr.urgent]
        return False


def _plateau(values: np.ndarray) -> int | None:
    """The first node at which ``values`` stays put (equal to the next within rounding), or None."""
    steps = np.abs(np.diff(values))
    still = np.flatnonzero(steps <= 1e-12 * (1.0 + np.abs(values[:-1])))
    return int(still[0]) if still.size else None


def _turns_at_entry(rate: DA) -> bool:
    """Whether the quantity's rate at the mode's entry, a polynomial over the subdomain, may
    take both signs (its range, eq. (27), holds 0): some runs then start moving against the
    nominal run's way and reach an extremum just after the entry that no extremum of the nominal
    run continues (a pendulum released at rest, nominally at its maximum). Such an extremum is
    one more candidate, from the time the rate vanishes (the event map of ``qdot = 0`` taken
    from t = 0; runs whose root lies before the entry add the value of their run continued
    backwards, which only widens the bound)."""
    lo, hi = polynomial_range(rate)
    return bool(np.all(np.isfinite([lo, hi])) and lo <= 0.0 <= hi and _varies(rate))


def _varies(p: DA) -> bool:
    """Whether ``p`` depends on the deviations beyond rounding."""
    coeffs = np.abs(p.c.reshape(-1))
    return bool(np.max(coeffs[1:], initial=0.0) > 1e-12 * (1.0 + coeffs[0]))


def _step_box(mode: str, X, step, t_earliest: float, clock: int | None) -> tuple:
    """``(mode, t0, t1, low, high)``: the interval hull of a step's Taylor-model enclosure (every
    run of the subdomain lies in it over the whole step); the times from the clock's bounds, or
    the step's span after the earliest entry without a clock."""
    box = np.array([x.bound() for x in X], dtype=float)
    if clock is not None:
        t0, t1 = box[clock]
    else:
        t0, t1 = t_earliest + step.t0, t_earliest + step.t0 + step.h
    return mode, float(t0), float(t1), box[:, 0], box[:, 1]


def _loosened(rel_tol: float) -> list[float]:
    """The step tolerances to try, tightest first: ``rel_tol``, then ten times it and
    ``LOOSEST_STEP_TOL`` where they are looser (never a tighter one than asked for)."""
    return sorted({rel_tol, *(t for t in (min(10 * rel_tol, LOOSEST_STEP_TOL), LOOSEST_STEP_TOL) if t > rel_tol)})


def _unbounded(why: str) -> dict:
    return {"bound": (-np.inf, np.inf), "steps": 0, "error": np.inf, "why": why}


#: sub-boxes of a step's variables bounded in refining the quantity's upper end on it
#: (:func:`_refined_top`)
REFINE_BOXES = 64


def _stretch_top(tops: list, sign: float, floor: float) -> float:
    """The larger of ``floor`` and an upper end of ``sign * q`` over a stretch's steps, from
    ``tops``: per step ``(top, k, value)``, the step's upper end, its index and ``q`` on it (a
    Taylor model, or :class:`Largest` of several).

    A step's upper end, the range bound (eq. 27) of ``q`` over all the model's variables at
    once (the deviations and the step time ``sigma``), is loose where ``q`` is far from linear in
    them: a monomial ``c xi sigma`` counts ``|c|`` though the run turns inside the step (the
    bouncing ball's apex step, 0.53 s long: 7.19 m against 6.72 m), and the polynomial of an
    undamped Duffing oscillator's box, sheared round its orbit, is bounded at 1.264 for a
    largest ``x`` of 1.108. The steps are refined (:func:`_refined_top`) in decreasing order of
    their upper ends while one may still raise the bound."""
    best = floor
    for top, _, value in sorted(tops, key=lambda item: (item[0], item[1]), reverse=True):
        if top <= best:
            break
        best = max(best, _refined_top(value, sign, best))
    return best


def _refined_top(value, sign: float, floor: float) -> float:
    """The larger of ``floor`` and an upper end of ``sign * value`` (a Taylor model ``P + I``
    of ``q`` over a step, or :class:`Largest` of several), by branch and bound over the cube
    ``[-1, 1]^d`` of its variables.

    The model holds ``q`` for every value of its variables, so the largest upper end over
    sub-boxes that cover the cube bounds ``sign * q``. A sub-box is the polynomial with one
    variable restricted to half its range (:func:`.verified.variable_in`, an exact change of
    variable in the same algebra; the remainder ``I`` holds on the whole cube), bounded by
    eq. (27). The sub-box with the largest upper end is halved (best first) in the variable
    whose monomials weigh most (the sum of their ``|c|``), up to ``REFINE_BOXES`` sub-boxes or
    until none can raise ``floor``; the result is the largest upper end left. Each upper end is
    padded by ``ROUNDING`` times the halvings behind it and the cube's coefficient sizes (the
    coefficients of a restricted polynomial are rounded)."""
    parts = value.parts if isinstance(value, Largest) else [value]
    alg = parts[0].poly.alg
    size = 1.0 + max(float(np.abs(t.poly.c).sum()) for t in parts)
    weighs = [alg.exps[:, j] > 0 for j in range(alg.nvars)]

    def upper(polys, level):
        ends = [polynomial_range(p) for p in polys]
        lo = max(float(a) + float(t.lo) for (a, _), t in zip(ends, parts))
        hi = max(float(b) + float(t.hi) for (_, b), t in zip(ends, parts))
        top = (hi if sign > 0 else -lo) + ROUNDING * (1 + level) * size
        return np.inf if np.isnan(top) else top         # NaN bounds nothing (max() would drop it)

    root = [t.poly for t in parts]
    frontier, count = [(-upper(root, 0), 0, root, 0)], 1
    while count + 2 <= REFINE_BOXES and -frontier[0][0] > floor:
        _, _, polys, level = heapq.heappop(frontier)
        weight = [sum(float(np.abs(p.c[..., mask]).sum()) for p in polys) for mask in weighs]
        var = int(np.argmax(weight))
        for centre in (-0.5, 0.5):
            half = [variable_in(p, var, centre, 0.5) for p in polys]
            heapq.heappush(frontier, (-upper(half, level + 1), count, half, level + 1))
            count += 1
    return max(floor, -frontier[0][0])


#: time slices of a step in which the states entering a guard are bounded (:func:`_entry_slices`)
ENTRY_SLICES = 16
#: the most steps meeting a guard whose entry states are bounded slice by slice (:func:`_sliced`)
SLICED_STEPS = 8


def _sliced(code: ModeCode, ex: Exit, enc, steps: list, boxes: list) -> list:
    """The boxes of the steps ``steps`` that may meet the guard of ``ex`` (``boxes``, the steps'
    own), each cut to its time slices that may (:func:`_entry_slices`; a step none of whose
    slices may is dropped), where there are at most ``SLICED_STEPS`` of them: a crossing that
    takes a few long steps (a slow flowpipe) is where a step's box is loose; many short steps
    already slice the crossing, and slicing each would cost more than it gains."""
    if len(steps) > SLICED_STEPS:
        return boxes
    out = []
    for k, box in zip(steps, boxes):
        cut = _entry_slices(code, ex, enc.tm(k))
        if cut is not None:
            out.append(np.stack([np.maximum(box[:, 0], cut[:, 0]), np.minimum(box[:, 1], cut[:, 1])], axis=1))
    return out or boxes


def _entry_slices(code: ModeCode, ex: Exit, X) -> np.ndarray | None:
    """The hull of the states of a step's Taylor models ``X`` in the slices of its time ``sigma``
    (``ENTRY_SLICES`` equal parts of ``[-1, 1]``, the models' last variable substituted) in which
    the guard of ``ex`` may hold, padded by ``ROUNDING``; None where it holds in none. A run
    entering the guard during the step is inside it then, so in one of those slices: the hull
    holds every entry state of the step, without the states of the step's other instants (a step
    of a slow flowpipe is long against a crossing)."""
    kept = []
    for s in range(ENTRY_SLICES):
        centre = -1.0 + (2 * s + 1) / ENTRY_SLICES
        part = [TM(sigma_in(x.poly, centre, 1.0 / ENTRY_SLICES), x.lo, x.hi) for x in X]
        if code.may_enter(ex, part):
            kept.append(np.array([x.bound() for x in part], dtype=float))
    if not kept:
        return None
    low, high = np.min([k[:, 0] for k in kept], axis=0), np.max([k[:, 1] for k in kept], axis=0)
    pad = ROUNDING * (1.0 + np.maximum(np.abs(low), np.abs(high)))
    return np.stack([low - pad, high + pad], axis=1)


def _on_face(box: np.ndarray, a: np.ndarray, b: float):
    """``(box, j)``: the entry states' hull ``box`` cut to the states it holds on the face
    ``a . x + b = 0`` and the coordinate ``j`` the face ties to the others.

    Where no run is inside a guard of one face at a window's start (no earlier step may meet
    it), each run that enters it does so on the face: the guard's margin is continuous, positive
    before and at most 0 at the first instant the guard holds. So the entry states lie in
    ``box`` and on the face. Each coordinate ``i`` is cut to ``-(b + sum_{k != i} a_k x_k) / a_i``
    over the box (interval arithmetic, twice round, padded outward by ``ROUNDING``), and the
    entry states are written with ``x_j`` the face's function of the others
    (:func:`_tied`), ``j`` the coordinate with the widest ``|a_j| (hi_j - lo_j)``: the next
    mode starts from a set one dimension thinner than the box, tied as the runs are. A
    saturated loop entering ``lin`` at ``x + v = 1`` from ``x`` in ``[1.06, 2.54]`` otherwise
    starts from every ``v`` of the box with every ``x``, and its rigorous bound from runs that
    never reach the boundary."""
    low, high = box[:, 0].copy(), box[:, 1].copy()
    nz = np.flatnonzero(np.abs(a) > 1e-9 * np.abs(a).max())      # coefficients that can tie
    for _ in range(2):
        for i in nz:
            terms = [(a[k] * low[k], a[k] * high[k]) for k in np.flatnonzero(a) if k != i]
            rest_lo = -b - sum(max(p, q) for p, q in terms)
            rest_hi = -b - sum(min(p, q) for p, q in terms)
            lo, hi = sorted((rest_lo / a[i], rest_hi / a[i]))
            pad = ROUNDING * (abs(b) + np.abs(a) @ np.maximum(np.abs(low), np.abs(high))) / abs(a[i])
            low[i], high[i] = max(low[i], lo - pad), min(high[i], hi + pad)
    if np.any(low > high):                   # no state of the hull on the face (rounding): as it was
        low, high = box[:, 0].copy(), box[:, 1].copy()
    j = int(nz[np.argmax(np.abs(a[nz]) * (high[nz] - low[nz]))])
    return np.stack([low, high], axis=1), j


def _tied(start: list, box: np.ndarray, j: int, a: np.ndarray, b: float):
    """``(x_j, e_j)``: the coordinate ``j`` of the entry states on the face ``a . x + b = 0`` as a
    polynomial of the others' (``start``, over ``box``), with its rounding ``e_j`` (a relative
    ``ROUNDING`` of the magnitudes summed: the face holds exactly, its floating-point sum up to
    that)."""
    others = [k for k in range(len(start)) if k != j]
    weights = np.array([-a[k] / a[j] for k in others] + [-b / a[j]])
    poly = DA.weighted_sum(weights, [start[k] for k in others] + [1.0])
    size = (abs(b) + np.abs(a[others]) @ np.abs(box[others]).max(axis=1)) / abs(a[j])
    return poly, 4 * ROUNDING * size


def _no_wider(states, hull: np.ndarray):
    """The crossing's entry states, or None where their bounds are wider than the hull of the
    window's step boxes in some component (both enclose every entry state, so either is sound;
    a window that is long against a stiff mode's time scale makes one polynomial step over it,
    and its entry models, useless: SRA03's abort window of 28 min in the rendezvous mode gave
    clock bounds of +-2e7 min)."""
    if states is None:
        return None
    box = np.array([x.bound() for x in states])
    slack = 1e-9 * (1.0 + np.abs(hull).max(axis=1))
    return states if np.all(box[:, 1] - box[:, 0] <= hull[:, 1] - hull[:, 0] + slack) else None


def _entry_box(ex: Exit, boxes: list[np.ndarray], model) -> np.ndarray:
    """Hull of the step boxes that may meet the guard, clipped to its single-variable bounds."""
    stacked = np.stack(boxes)                        # (k, n, 2)
    box = np.stack([stacked[:, :, 0].min(axis=0), stacked[:, :, 1].max(axis=0)], axis=1)
    for c in ex.transition.guard:
        coeffs = affine_coefficients(c.g, model.symbols)
        if coeffs is None:
            continue
        a, b = coeffs                                 # a . x + b <= 0
        nz = np.flatnonzero(a)
        if len(nz) == 1:
            i = nz[0]
            limit = -b / a[i]
            if a[i] > 0:
                box[i, 1] = min(box[i, 1], limit)
            else:
                box[i, 0] = max(box[i, 0], limit)
    box[:, 1] = np.maximum(box[:, 1], box[:, 0])
    return box
