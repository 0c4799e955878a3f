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
any bounded horizon. It suffices to check *simple* cycles: every cycle's transitions contain
those of a simple cycle, and with them its reset and its bound.

A lower bound is read from single-variable guard rows ``-a x <= -b`` (``a > 0``), i.e.
``x >= b / a``; a reset counts when it sets ``x`` to a constant expression. Parallel
transitions (same source and target) are alternatives: a mode cycle is reported when some
choice of one transition per step leaves no clock both reset and bounded on it.

Each finding is one line naming the file, the field and the mode cycle (the shortest
:data:`MAX_REPORTED` cycles, then a count)::

    models/x.yaml: transitions: possible zero-dwell cycle transient -> science -> transient
    (no clock reset on it is bounded below by a positive guard)
"""

from __future__ import annotations

import itertools

import numpy as np
import sympy

from reach.model.constraints import affine_coefficients

#: stop enumerating simple cycles beyond this many (the lint then says it is incomplete)
MAX_CYCLES = 20_000

#: report at most this many offending cycles per model (the shortest), then a count
MAX_REPORTED = 10


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


def strongly_connected(nodes: list, successors: dict) -> list[list]:
    """Strongly connected components (Tarjan), each in ``nodes`` order."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    order = {n: i for i, n in enumerate(nodes)}

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(successors.get(v, ()), key=order.get):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            out.append(sorted(component, key=order.get))

    for v in nodes:
        if v not in index:
            visit(v)
    return out


def simple_cycles(nodes: list, successors: dict, limit: int = MAX_CYCLES) -> list[list]:
    """Simple cycles of a directed graph (each once, starting at its smallest node in
    ``nodes`` order); ``successors[n]`` is the set of successors of ``n``. Depth-first search
    from each node through larger nodes only; stops after ``limit`` cycles."""
    order = {n: i for i, n in enumerate(nodes)}
    cycles = []
    for start in nodes:
        stack = [(start, iter(sorted(successors.get(start, ()), key=order.get)))]
        path, on_path = [start], {start}
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                stack.pop()
                on_path.discard(path.pop())
                continue
            if nxt == start:
                cycles.append(list(path))
                if len(cycles) >= limit:
                    return cycles
            elif nxt in order and order[nxt] > order[start] and nxt not in on_path:
                path.append(nxt)
                on_path.add(nxt)
                stack.append((nxt, iter(sorted(successors.get(nxt, ()), key=order.get))))
    return cycles


def zero_dwell_cycles(model) -> tuple[list[list[str]], bool]:
    """``(cycles, complete)``: mode cycles (``[m0, m1, ..., m0]``) on which some choice of
    transitions has no clock that is reset and bounded below by a larger constant (see the
    module doc), and whether every offending cycle is in the list.

    Per strongly connected component: when no clock is both reset and bounded (above its
    reset value) on the component's own transitions, every cycle in it offends and only the
    first :data:`MAX_REPORTED` + 1 are enumerated; otherwise its simple cycles are checked
    one by one (up to :data:`MAX_CYCLES`)."""
    names = list(model.modes)
    edges: dict[tuple[str, str], set] = {}
    for tr in model.transitions:
        reset, bound = edge_signature(model, tr)
        key = (frozenset(reset.items()), frozenset(bound.items()))
        edges.setdefault((tr.source, tr.target), set()).add(key)
    successors: dict[str, set] = {}
    for source, target in edges:
        successors.setdefault(source, set()).add(target)
    found, complete = [], True
    for component in strongly_connected(names, successors):
        members = set(component)
        inner = {k: v for k, v in edges.items() if k[0] in members and k[1] in members}
        if not inner:
            continue
        local = {m: successors.get(m, set()) & members for m in component}
        signatures = [(dict(r), dict(b)) for keys in inner.values() for r, b in keys]
        if not cycle_is_safe(signatures):       # no cycle of the component can be safe
            cycles = simple_cycles(component, local, MAX_REPORTED + 1)
            complete = complete and len(cycles) <= MAX_REPORTED
            found.extend(c + [c[0]] for c in cycles)
            continue
        cycles = simple_cycles(component, local)
        complete = complete and len(cycles) < MAX_CYCLES
        for cycle in cycles:
            steps = list(zip(cycle, cycle[1:] + cycle[:1]))
            choices = [sorted(inner[s], key=repr) for s in steps]
            for choice in itertools.product(*choices):
                if not cycle_is_safe([(dict(r), dict(b)) for r, b in choice]):
                    found.append(cycle + [cycle[0]])
                    break
    return found, complete


def lint(model) -> list[str]:
    """All findings for ``model``, one line each (empty when the model is clean)."""
    cycles, complete = zero_dwell_cycles(model)
    cycles = sorted(cycles, key=len)
    findings = [f"{model.file}: transitions: possible zero-dwell cycle {' -> '.join(c)} "
                f"(no clock reset on it is bounded below by a positive guard)"
                for c in cycles[:MAX_REPORTED]]
    if len(cycles) > MAX_REPORTED or not complete:
        findings.append(f"{model.file}: transitions: more possible zero-dwell cycles not listed")
    return findings
