"""Structural lints of a hybrid automaton: findings that are not errors but deserve a look.

Zero-dwell cycles (strong non-Zenoness, Tripakis 1999; Asarin et al.)
---------------------------------------------------------------------
A run is *Zeno* when it takes infinitely many jumps in finite time. A sufficient, purely
structural condition that excludes it: every cycle ``m_0 -e_0-> m_1 -> ... -> m_0`` of the
transition graph has a clock ``x`` (rate 1 in every mode of the model) that is

* reset to a constant ``r`` by some transition of the cycle, and
* bounded from below by ``x >= L`` with ``L > r`` in the guard of some transition of the
  cycle (an urgent guard is a guard too).

Then between two passes through that guard the run passes the reset, so ``x`` grows from
``r`` to at least ``L``: every traversal of the cycle takes at least ``L - r > 0`` time, a
run of ``k * |modes|`` jumps lasts at least ``k * min(L - r)`` and jumps are finitely many on
any bounded horizon. It suffices to check *simple* cycles of the transition graph: every
cycle's transitions contain those of a simple cycle, and with them its reset and its bound.

A lower bound is read from single-variable guard rows ``-a x <= -b`` (``a > 0``), i.e.
``x >= b / a``; a reset counts when it sets ``x`` to a constant expression. Parallel
transitions (same source and target) are alternatives: a mode cycle is reported when some
choice of one transition per step leaves no clock both reset and bounded on it.

A second sufficient condition covers hysteresis without clocks (a thermostat that switches off
at ``T >= 21`` and on at ``T <= 19``): the cycle cannot be traversed at one instant. With its
guards, the invariants of the modes it leaves and its resets all linear (affine resets
``x+ = R x + r``), a zero-time traversal ``x_0 -> x_1 -> ... -> x_k`` is the polyhedron

    G_j x_j <= g_j,  I_j x_j <= i_j,  x_{j+1} = R_j x_j + r_j      (j = 0 .. k-1)

in the stacked states (strict inequalities relaxed to non-strict ones, which only makes it
larger), here for the cycle taken twice (``k`` = twice its length: a relaxation oscillator's
reset ``x := 0.5`` off its guard ``x >= 1.5`` is taken once at an instant, never twice). If it
is empty by more than the LP tolerance, consecutive double passes through the cycle are
separated by a positive distance that a continuous flow crosses only in positive time on any
bounded region: no zero-dwell run goes round it. When it is not empty, the finding names a state
where every jump of the cycle, twice over, can happen at once, so a reader can check it.

Invariant faces where no transition is enabled
----------------------------------------------
A run ends where it would leave its mode's invariant with no transition enabled (the
automaton's semantics): what happens after is not checked, and a SAFE says nothing about it.
A model rarely means that. For a mode with a linear invariant ``H x <= g`` and each row ``i``,
the *exit face* is where a run can reach that row's boundary from inside, the flow pointing
out (for an affine flow ``x' = A x + b``; the whole face for a nonlinear one):

    H x <= g,  H_i x = g_i,  H_i (A x + b) > 0,   bounded inputs within their ranges

The face is covered when the outgoing transitions are enabled on all of it together (a
transition without guard into a mode without invariant covers everything). A transition is
enabled where its guard holds and its target's invariant holds at the reset state
(:func:`enabling_rows`: ``H (R x + r) <= h`` for an affine reset; a nonlinear reset or target
invariant leaves the guard alone, a nonlinear guard counts as covering): a hand-over into a
mode whose invariant fails after it does not happen. Only the target's rows that read a state
the mode's flow moves or the jump resets count: a row on states the mode keeps (a budget
``rem >= 0`` spent elsewhere) held or failed since the mode was entered, which reachability,
not the face, decides. The face minus an enabled set is the union
of the pieces where one of its rows fails strictly, each searched against the remaining sets,
and a piece left with a point (a positive slack in its strict rows) is a part no transition
leaves from. Such a face is reported, with whether some enabled set meets it at all (a run
there may still leave).
(A run that only touches the boundary, its flow along it, goes on: hence the strict ``>``.)
A row that bounds the global clock from above, alone or with constants (``t <= 20``, SpaceEx's
``t <= stoptime``), is an end of time the model sets itself and is not reported.

Each finding is one line naming the file, the field and the mode cycle (the shortest
:data:`MAX_REPORTED` cycles, then a count)::

    models/x.yaml: transitions: possible zero-dwell cycle transient -> science -> transient
    (no clock reset on it is bounded below by a positive guard)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy

from reach.model.constraints import affine_coefficients

#: stop enumerating simple cycles beyond this many (the lint then says it is incomplete)
MAX_CYCLES = 20_000

#: report at most this many offending cycles per model (the shortest), then a count
MAX_REPORTED = 10

#: LPs per invariant face in the search for a part of it that no guard covers
MAX_PIECES = 200


def edge_signature(model, transition) -> tuple[dict, dict]:
    """``(reset, bound)`` of a transition: ``reset[clock] = value`` for clocks reset to a
    constant, ``bound[clock] = L`` for the largest lower bound ``clock >= L`` in its guard."""
    clocks = set(model.clocks)
    reset = {}
    for index, expr in transition.reset.items():
        if index in clocks:
            value = sympy.sympify(expr)
            if value.is_number:
                reset[index] = float(value)
    bound = {}
    for con in transition.guard:
        coeffs = affine_coefficients(con.g, model.symbols)
        if coeffs is None:
            continue
        a, const = coeffs
        nz = np.flatnonzero(a)
        if len(nz) == 1 and nz[0] in clocks and a[nz[0]] < 0:
            i = int(nz[0])
            low = const / -a[i]                 # a_i x + const <= 0, a_i < 0  =>  x >= const/(-a_i)
            bound[i] = max(bound.get(i, -np.inf), float(low))
    return reset, bound


def cycle_is_safe(signatures) -> bool:
    """Whether a cycle, given as the ``(reset, bound)`` of its transitions, has a clock that
    is reset on it and bounded below on it by more than every value it is reset to."""
    resets: dict[int, float] = {}
    bounds: dict[int, float] = {}
    for reset, bound in signatures:
        for x, r in reset.items():
            resets[x] = max(resets.get(x, -np.inf), r)
        for x, low in bound.items():
            bounds[x] = max(bounds.get(x, -np.inf), low)
    return any(x in bounds and bounds[x] > r for x, r in resets.items())


def _halfspaces(constraints, symbols):
    """``(H, h)`` with ``H x <= h`` for linear constraints; None if any is nonlinear."""
    rows, rhs = [], []
    for con in constraints:
        coeffs = affine_coefficients(con.g, symbols)
        if coeffs is None:
            return None
        a, c = coeffs
        rows.append(a)
        rhs.append(-c)
    n = len(symbols)
    return np.array(rows, dtype=float).reshape(-1, n), np.array(rhs, dtype=float)


def linear_jump(model, transition):
    """``(H, h, R, r)`` of a transition: the jump is possible from ``x`` with ``H x <= h`` (its
    guard and its source's invariant) and lands at ``R x + r``; None if any part is nonlinear."""
    symbols = model.symbols
    hs = _halfspaces(list(transition.guard) + list(model.modes[transition.source].invariant), symbols)
    if hs is None:
        return None
    reset = affine_reset(model, transition)
    return None if reset is None else (hs[0], hs[1], *reset)


def affine_reset(model, transition):
    """``(R, r)`` with the transition's reset ``x+ = R x + r``; None if it is not affine."""
    R, r = np.eye(model.n), np.zeros(model.n)
    for i, expr in transition.reset.items():
        coeffs = affine_coefficients(expr, model.symbols)
        if coeffs is None:
            return None
        R[i], r[i] = coeffs
    return R, r


def enabling_rows(model, transition, reading=None):
    """``(G, c)``: where ``transition`` is enabled, ``G x <= c``: its guard, and its target's
    invariant at the reset state (``H (R x + r) <= h`` for an affine reset ``x+ = R x + r``);
    None if either is not linear. ``reading``: keep only the target's rows that read one of
    these states (all rows when None)."""
    n = model.n
    guard = model.guard_halfspaces(transition)
    target = model.modes[transition.target].invariant_halfspaces
    if guard is None or target is None:
        return None
    G, c = np.asarray(guard[0], float).reshape(-1, n), np.asarray(guard[1], float).reshape(-1)
    H, h = np.asarray(target[0], float).reshape(-1, n), np.asarray(target[1], float).reshape(-1)
    if reading is not None:
        keep = np.any(H[:, sorted(reading)] != 0, axis=1) if reading else np.zeros(len(h), bool)
        H, h = H[keep], h[keep]
    if not len(h):
        return G, c
    reset = affine_reset(model, transition)
    if reset is None:
        return None
    R, r = reset
    return np.vstack([G, H @ R]), np.concatenate([c, h - H @ r])


def fixed_ranges(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(index, low, high)`` of the states no run changes -- flow 0 in every mode, never reset:
    constants (SpaceEx ``const`` params, ``tmax == 20`` in a cfg) and bounded inputs -- with the
    range the initial set gives them (its bounding box), which every reachable state keeps."""
    reset = {i for tr in model.transitions for i in tr.reset}
    fixed = [i for i in range(model.n) if i not in reset
             and all(m.timeless or m.flow[i] == 0 for m in model.modes.values())]
    index = np.array(fixed, dtype=int)
    low, high = np.asarray(model.initial.low, float)[index], np.asarray(model.initial.high, float)[index]
    keep = np.isfinite(low) | np.isfinite(high)
    return index[keep], low[keep], high[keep]


def zero_time_witness(n: int, jumps, fixed=None) -> tuple[bool, np.ndarray | None]:
    """``(possible, state)``: whether a chain of jumps (each a :func:`linear_jump`, or None for
    a nonlinear one) can be taken at one instant (the polyhedron of the module doc is not empty),
    with a start state where it can; ``fixed``: :func:`fixed_ranges`, the ranges the start
    state keeps. A nonlinear jump counts as possible (no witness)."""
    from reach.lp import LPError, feasible_point

    if any(j is None for j in jumps):
        return True, None
    k = len(jumps)
    blocks_A, blocks_b, eq_A, eq_b = [], [], [], []
    if fixed is not None and fixed[0].size:
        index, low, high = fixed
        for sign, bound in ((1.0, high), (-1.0, -low)):
            finite = np.isfinite(bound)
            row = np.zeros((int(finite.sum()), n * (k + 1)))
            row[np.arange(row.shape[0]), index[finite]] = sign
            blocks_A.append(row)
            blocks_b.append(bound[finite])
    for j, (H, h, R, r) in enumerate(jumps):
        row = np.zeros((H.shape[0], n * (k + 1)))
        row[:, j * n:(j + 1) * n] = H
        blocks_A.append(row)
        blocks_b.append(h)
        link = np.zeros((n, n * (k + 1)))
        link[:, j * n:(j + 1) * n] = R
        link[:, (j + 1) * n:(j + 2) * n] = -np.eye(n)
        eq_A.append(link)
        eq_b.append(-r)
    A_ub, b_ub = np.vstack(blocks_A), np.concatenate(blocks_b)
    try:
        x = feasible_point(A_ub if A_ub.size else None, b_ub if A_ub.size else None,
                           A_eq=np.vstack(eq_A), b_eq=np.concatenate(eq_b), n=n * (k + 1))
    except LPError:
        return True, None
    return (x is not None), (None if x is None else x[:n])


def on_cycles(model) -> set[int]:
    """The transitions that lie on some cycle of modes: those whose source and target are in
    one strongly connected component of the mode graph (every cycle stays in one), so that the
    search below never starts on a chain of modes that no run can close (a mission's phases in a
    line: no LP at all)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    index = {name: i for i, name in enumerate(model.modes)}
    edges = [(index[tr.source], index[tr.target]) for tr in model.transitions]
    if not edges:
        return set()
    rows, cols = zip(*edges)
    graph = coo_matrix((np.ones(len(edges)), (rows, cols)), shape=(len(index), len(index)))
    _, component = connected_components(graph, directed=True, connection="strong")
    return {k for k, (a, b) in enumerate(edges) if component[a] == component[b]}


def zero_dwell_cycles(model) -> tuple[list, bool]:
    """``(found, complete)``: ``found`` lists ``(modes, transition names, state)`` for simple
    mode cycles (``modes``: ``[m0, m1, ..., m0]``), one choice of transition per step, on which
    no clock is reset and bounded below by a larger constant and whose jumps can be taken twice
    round at one instant (``state``: a start state where they can, None when a nonlinear
    constraint left that open); ``complete``: whether every offending cycle is in the list.

    Depth-first search over chains of transitions that can be taken at one instant: a chain
    that cannot be is never extended, since no cycle through it can be traversed in zero time
    (so nothing offending is pruned). A cycle is found once, from its transition of smallest
    index. At most :data:`MAX_CYCLES` chains are tried and :data:`MAX_REPORTED` + 1 findings
    kept. A chain that cannot be taken once at one instant is pruned; a cycle is reported when
    it can be taken twice (see the module doc)."""
    transitions = model.transitions
    cyclic = on_cycles(model)
    signature = {k: edge_signature(model, transitions[k]) for k in cyclic}
    jumps = {k: linear_jump(model, transitions[k]) for k in cyclic}
    leaving: dict[str, list[int]] = {}
    for k in sorted(cyclic):
        leaving.setdefault(transitions[k].source, []).append(k)
    order = {name: i for i, name in enumerate(model.modes)}
    fixed = fixed_ranges(model)
    found, tried = [], 0
    for first in sorted(cyclic):
        home = transitions[first].source
        stack = [iter([first])]
        chain: list[int] = []
        while stack:
            k = next(stack[-1], None)
            if k is None:
                stack.pop()
                if chain:
                    chain.pop()
                continue
            visited = {transitions[j].source for j in chain}
            target = transitions[k].target
            if (k < first or (target != home and target in visited)
                    or transitions[k].source in visited):
                continue
            tried += 1
            if tried > MAX_CYCLES:
                return found, False
            possible, state = zero_time_witness(model.n, [jumps[j] for j in chain + [k]], fixed)
            if not possible:
                continue
            if target == home:
                cycle = chain + [k]
                if not cycle_is_safe([signature[j] for j in cycle]):
                    shift = min(range(len(cycle)), key=lambda i: order[transitions[cycle[i]].source])
                    cycle = cycle[shift:] + cycle[:shift]
                    possible, state = zero_time_witness(model.n, [jumps[j] for j in cycle] * 2, fixed)
                    if not possible:
                        continue
                    modes = [transitions[j].source for j in cycle] + [transitions[cycle[0]].source]
                    found.append((modes, [transitions[j].name for j in cycle], state))
                    if len(found) > MAX_REPORTED:
                        return found, False
                continue
            chain.append(k)
            stack.append(iter(leaving.get(target, [])))
    return found, True


def initial_outside(model) -> str | None:
    """A finding where part of the initial set lies outside its mode's (linear) invariant: the
    rows some initial state breaks (the largest ``h x - g`` over the set, by LP, beyond 1e-9 of
    the row's scale). Those states start no run (the simulator blocks them at 0, star cuts the
    set by the invariant), which a model rarely means; none of them lying inside is bad input
    (:meth:`reach.model.loader._Builder.check_initial_invariant`)."""
    from reach import lp
    from reach.model.loader import initial_and_invariant

    rows = initial_and_invariant(model)
    if rows is None:
        return None
    A, b, E, f = rows
    mode = model.modes[model.initial.mode]
    H, g = (np.asarray(a, float) for a in mode.invariant_halfspaces)
    A_set, b_set = A[len(g):], b[len(g):]
    broken = []
    for row, bound, constraint in zip(H.reshape(len(g), -1), g.reshape(-1), mode.invariant):
        try:
            res = lp.maximize(row, A_set, b_set, A_eq=E if E.shape[0] else None, b_eq=f if E.shape[0] else None)
        except lp.LPError:
            continue
        if res.optimal and res.value - bound > 1e-9 * (1.0 + abs(bound) + np.abs(row).sum()):
            broken.append(constraint.text)
    if not broken:
        return None
    return (f"{model.file}: initial: part of the initial set lies outside the invariant of mode "
            f"'{mode.name}' ({', '.join(broken)[:100]} fails there): those states start no run")


def _exit_face(mode, row: int, H, g, low, high):
    """``(A, b, E, f, strict)``: the exit face ``A x <= b, E x = f`` of invariant row ``row`` of
    ``mode`` (module docstring) with the states' ``low <= x <= high`` where finite; ``strict``
    marks the row of the flow pointing out, which must hold strictly (a run that only touches
    the boundary, the flow along it, goes on)."""
    n = H.shape[1]
    finite_low, finite_high = np.isfinite(low), np.isfinite(high)
    A = np.vstack([H, -np.eye(n)[finite_low], np.eye(n)[finite_high]])
    b = np.concatenate([g, -low[finite_low], high[finite_high]])
    strict = np.zeros(len(b), bool)
    if mode.linear is not None:                 # the flow points out of the row: -H_i (A x + b) < 0
        flow, drift = mode.linear
        A = np.vstack([A, -(H[row] @ flow)])
        b = np.append(b, H[row] @ drift)
        strict = np.append(strict, True)
    return A, b, H[row:row + 1], g[row:row + 1], strict


@dataclass
class StopFace:
    """An invariant row ``text`` of ``mode`` whose exit face the outgoing transitions' enabled
    sets do not cover (module docstring). ``partly``: some enabled set meets the face;
    ``targets``: where the guards alone cover the face, the target invariant rows that refuse
    the jumps there; ``face``: ``(A, b, strict, E, f)``, the exit face (``A x <= b`` with the
    rows ``strict`` held strictly, ``E x = f``), and ``guards`` the enabled sets."""

    mode: str
    text: str
    partly: bool
    targets: list[str]
    face: tuple
    guards: list

    @cached_property
    def pieces(self) -> list:
        """The parts of the face no transition leaves from, each ``(A, b, strict, E, f)``, all
        of them unless the LP budget runs out (found on first use: the lint needs only one)."""
        found: list = []
        _open_pieces(*self.face, self.guards, [MAX_PIECES], found)
        return found


def stop_faces(model) -> list[StopFace]:
    """Every invariant row whose exit face the outgoing transitions' enabled sets do not cover:
    runs that reach it stop there (module docstring). Modes with a nonlinear invariant or where
    no time passes are passed over; a nonlinear guard counts as covering (it cannot be told)."""
    from reach import lp

    n, faces = model.n, []
    low, high = np.full(n, -np.inf), np.full(n, np.inf)
    for u in model.bounded_inputs:
        low[u.index], high[u.index] = u.low, u.high
    clock = model.global_clock
    fixed = set(fixed_ranges(model)[0].tolist())
    for name, mode in model.modes.items():
        halves = mode.invariant_halfspaces
        if mode.timeless or halves is None or not len(halves[1]):
            continue
        H, g = np.asarray(halves[0], float).reshape(-1, n), np.asarray(halves[1], float).reshape(-1)
        guards, plain, targets = [], [], []
        for tr in model.outgoing(name):
            moved = {i for i, rate in enumerate(mode.flow) if rate != 0} | set(tr.reset)
            found, guard = enabling_rows(model, tr, moved), model.guard_halfspaces(tr)
            guards.append(_rows(found or guard, n))
            plain.append(_rows(guard, n))
            if found is not None and guard is not None and len(found[1]) > len(guard[1]):
                read = {model.symbols[i] for i in moved}
                after = {model.symbols[i]: e for i, e in tr.reset.items()}
                texts = [c.text for c in model.modes[tr.target].invariant
                         if sympy.sympify(c.g).subs(after, simultaneous=True).free_symbols & read]
                if texts:
                    targets.append(f"'{tr.target}': {', '.join(dict.fromkeys(texts))}")
        if any(guard is None or not len(guard[1]) for guard in guards):
            continue                            # a transition always enabled, or one not told
        shadowed = _shadowed(H, g)
        if H.shape[0] - len(shadowed) > MAX_FACE_ROWS:
            continue                            # too many faces to examine (LPs of that many rows each)
        for i, constraint in enumerate(mode.invariant):   # each row (abs(x) <= 1 has two faces)
            if i in shadowed:
                continue
            nz = set(np.flatnonzero(H[i]).tolist())
            if clock in nz and H[i, clock] > 0 and nz - {clock} <= fixed:
                continue                        # an end of time the model sets itself
            A, b, E, f, strict = _exit_face(mode, i, H, g, low, high)
            try:
                if not _uncovered(A, b, strict, E, f, guards, [MAX_PIECES]):
                    continue
                meets = any(lp.feasible_point(np.vstack([A, G]), np.concatenate([b, c]), A_eq=E, b_eq=f) is not None
                            for G, c in guards)
                by_target = bool(targets) and all(G is not None for G in plain) and \
                    not _uncovered(A, b, strict, E, f, plain, [MAX_PIECES])
            except lp.LPError:
                continue
            faces.append(StopFace(name, constraint.text, meets, targets if by_target else [], (A, b, strict, E, f),
                                  guards))
    return faces


#: a mode whose invariant has more distinct rows is not examined for faces that stop runs
MAX_FACE_ROWS = 200


def _shadowed(H, g) -> set[int]:
    """The rows of ``H x <= g`` whose face lies outside another row with the same normal and a
    smaller bound (or the same bound, earlier): their exit face is empty or another row's."""
    out = set()
    for i in range(H.shape[0]):
        same = np.flatnonzero(np.all(H == H[i], axis=1))
        if np.any((g[same] < g[i]) | ((g[same] == g[i]) & (same < i))):
            out.add(i)
    return out


def blocking_faces(model) -> list[tuple[str, bool]]:
    """Findings for invariant rows whose exit face the outgoing transitions' enabled sets do not
    cover (:func:`stop_faces`, the model's ``stop_faces``), each with whether some enabled set
    meets the face (``partly``). One finding per mode and kind, naming the rows."""
    findings = []
    for name in model.modes:
        for meets in (False, True):
            group = [face for face in model.stop_faces if face.mode == name and face.partly == meets]
            if not group:
                continue
            where = ("no transition out of it is enabled on part of that boundary" if meets else
                     "no transition out of it is enabled there")
            targets = list(dict.fromkeys(t for face in group for t in face.targets))
            if targets:
                where += f": the guards hold there, but a jump needs its target's invariant after it, {'; '.join(targets)}"
            listed = ", ".join(dict.fromkeys(face.text for face in group))
            findings.append((f"{model.file}: modes.{name}.invariant: runs of mode '{name}' that reach "
                             f"the boundary of {listed if len(listed) < 160 else listed[:157] + '...'} "
                             f"stop there ({where}): nothing after is checked", meets))
    return findings


def _rows(found, n: int):
    """``(G, c)`` of half-spaces as float arrays of ``n`` columns; None stays None."""
    if found is None:
        return None
    return np.asarray(found[0], float).reshape(-1, n), np.asarray(found[1], float).reshape(-1)


def _uncovered(A, b, strict, E, f, guards, budget: list[int]) -> bool:
    """Whether ``{A x <= b (rows marked strict held strictly), E x = f}`` has a point in none of
    the linear ``guards`` (:func:`_open_pieces`, stopping at the first part found)."""
    pieces = []
    _open_pieces(A, b, strict, E, f, guards, budget, pieces, first=True)
    return bool(pieces)


def _open_pieces(A, b, strict, E, f, guards, budget: list[int], pieces: list, first: bool = False) -> None:
    """The parts of ``{A x <= b (rows marked strict held strictly), E x = f}`` in none of the
    linear ``guards``, appended to ``pieces`` as ``(A, b, strict, E, f)``: the set minus the
    first guard is the union of the pieces where one of its rows fails strictly, each searched
    against the rest (an LP per piece, :func:`reach.lp.strictly_feasible`). ``budget`` (one
    count, shared) caps the LPs; past it, or where the solver gives no answer, a piece counts
    as covered. ``first``: stop at the first part found."""
    from reach import lp

    if budget[0] <= 0 or (first and pieces):
        return
    budget[0] -= 1
    if not lp.strictly_feasible(A, b, strict, A_eq=E, b_eq=f):
        return
    if not guards:
        pieces.append((A, b, strict, E, f))
        return
    (G, c), rest = guards[0], guards[1:]
    for row, bound in zip(G, c):
        _open_pieces(np.vstack([A, -row]), np.append(b, -bound), np.append(strict, True), E, f, rest, budget,
                     pieces, first)


def lint(model, check: bool = False) -> list[str]:
    """All findings for ``model``, one line each (empty when the model is clean). ``check``:
    those worth a warning before a check, where invariant faces that a guard meets in part (a
    rendezvous mode left only through its entry window) are left to ``reach lint``."""
    findings = [found] if (found := initial_outside(model)) else []
    findings += [text for text, partly in blocking_faces(model) if not (check and partly)]
    cycles, complete = zero_dwell_cycles(model)
    cycles = sorted(cycles, key=lambda found: len(found[0]))
    for cycle, names, state in cycles[:MAX_REPORTED]:
        at = ("" if state is None else ", and its jumps " + ", ".join(names)
              + " can all be taken twice round at one instant from "
              + ", ".join(f"{v}={x + 0.0:.6g}" for v, x in zip(model.state, state)))
        findings.append(f"{model.file}: transitions: possible zero-dwell cycle {' -> '.join(cycle)} "
                        f"(no clock reset on it is bounded below by a positive guard{at})")
    if len(cycles) > MAX_REPORTED or not complete:
        findings.append(f"{model.file}: transitions: more possible zero-dwell cycles not listed")
    return findings
