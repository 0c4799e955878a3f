"""Runs that stop: where the explored sets reach an invariant face with no transition enabled.

A run ends where it would leave its mode's invariant and no outgoing transition is enabled
(the automaton's semantics): what it would have done after is not part of any answer. The lint
(:func:`reach.model.lint.stop_faces`) finds the parts of each invariant face where that can
happen, without reachability: ``P = {A x <= b (some rows strict), E x = f}`` -- on the face
``H_i x = g_i``, the flow pointing out, outside every enabled set. Here the reachable sets
decide it: a cell's segment ``S = {c + V a : C a <= d, lo <= a <= hi}`` (which holds every
state of its runs over the cell) meets ``P`` iff

    A V a <= b - A c  (strict rows strictly),  E V a = f - E c,  C a <= d,  lo <= a <= hi

has a point (one LP, :func:`reach.lp.strictly_feasible`), the strict rows (the flow pointing
out, the enabled sets failing) held by more than the cell's interpolation error reaches along
them. Segments over-approximate (an aggregate's interval hull holds states no run reaches), so
a meeting says only that runs *may* stop there. A SAFE whose sets met such a face samples runs (:func:`sampled_stops`: the initial
set's corners, face centres and centre, then uniform states, each abort instant's ends and
middle, simulated by :class:`reach.model.simulate.Simulator`) and names the faces where a
sampled run stopped, with how many and the earliest instant: the SAFE holds for every run for
as long as the run exists. Faces met but where no sampled run stopped are kept in the details
(``stop_faces_met``), not in the verdict's line.
"""

from __future__ import annotations

import time

import numpy as np

from reach import lp
from reach.errors import InputError
from reach.sets import Star


def stop_rows(model, widen) -> dict[str, list[tuple]]:
    """Per mode, ``(face, E, f)`` for each invariant row where runs may stop
    (:attr:`HybridAutomaton.stop_faces`), the face's row ``E x = f`` over the explored states
    (``widen`` adds the added clock's zero column to rows over the model's states)."""
    out: dict[str, list[tuple]] = {}
    for face in model.stop_faces:
        out.setdefault(face.mode, []).append((face, *widen(*face.face[3:])))
    return out


def stop_pieces(face, widen) -> list[tuple]:
    """The parts of ``face`` where no transition is enabled (its ``pieces``, found on first
    use), each ``(A, b, strict, E, f)`` over the explored states."""
    return [(*widen(A, b), strict, *widen(E, f)) for A, b, strict, E, f in face.pieces]


def meets(seg: Star, A, b, strict, E, f, error=None) -> bool:
    """Whether ``seg`` has a point in ``{A x <= b (rows strict strictly), E x = f}`` (module
    docstring); False where the solver gives no answer (a note, not a verdict, rests on it).
    ``error``: the segment's interpolation error box (radius per state): the strict rows (the
    flow pointing out, the guards failing) must then hold by more than the error's reach along
    them, which the segment's bloat alone cannot give (a run entering across the face it is
    moving away from)."""
    if error is not None:
        b = np.where(strict, b - np.abs(A) @ np.asarray(error, float), b)
    low, high = seg.box.low, seg.box.high
    lo, hi = np.isfinite(low), np.isfinite(high)
    m = seg.nvars
    rows = np.vstack([A @ seg.basis, seg.predicate.A.reshape(-1, m), -np.eye(m)[lo], np.eye(m)[hi]])
    rhs = np.concatenate([b - A @ seg.center, seg.predicate.b, -low[lo], high[hi]])
    marks = np.concatenate([strict, np.zeros(len(rhs) - len(b), bool)])
    return bool(lp.strictly_feasible(rows, rhs, marks, A_eq=E @ seg.basis, b_eq=f - E @ seg.center))


def sampled_stops(model, stopped: dict, seconds: float, count: int = 48, seed: int = 0) -> dict:
    """``details`` entries for the faces the sets met (``stopped``: ``(mode, row text)`` to the
    earliest clock of a segment meeting it): ``stopped_runs``, the faces where sampled runs
    stopped (module docstring), and ``stop_faces_met``, those the sets met; the sampling stops
    after ``seconds`` (none is drawn when that is not positive: the faces met are named alone)."""
    from reach.backends.montecarlo.sampling import random_plan, structured_plan, switch_window
    from reach.model.simulate import Simulator

    met = "; ".join(f"mode '{mode}' at the boundary of {text} (from t = {t:.4g})"
                    for (mode, text), t in sorted(stopped.items(), key=lambda item: item[1]))
    out = {"stop_faces_met": met}
    if seconds <= 0:
        return out
    rng = np.random.default_rng(seed)
    try:
        window = switch_window(model)
        X, tau = structured_plan(model, window, 16, rng)
        Xr, taur = random_plan(model, window, count, rng)
        X = np.vstack([X, Xr])
        tau = None if tau is None else np.concatenate([tau, taur])
        runs = Simulator(model).run(X, tau, deadline=time.time() + seconds)
    except (InputError, ValueError, ArithmeticError, MemoryError, np.linalg.LinAlgError):
        return out                  # no sample (a grid too fine to simulate): the sets' faces stand
    found: dict[tuple[str, str], list[float]] = {}
    names = list(model.modes)
    stopped_here = np.isfinite(runs.blocked_at) & (runs.blocked_at < model.horizon)
    stopped_here[runs.cut_rows] = False         # cut by the time budget, not stopped by the model
    for k in np.flatnonzero(stopped_here):
        mode = names[int(runs.final_mode[k])]
        for text in _faces_at(model, mode, runs.final_state[k]):
            if (mode, text) in stopped:
                found.setdefault((mode, text), []).append(float(runs.blocked_at[k]))
    if found:
        where = "; ".join(f"{len(times)} in mode '{mode}' at the boundary of {text} (the first at t = {min(times):.4g})"
                          for (mode, text), times in sorted(found.items(), key=lambda item: min(item[1])))
        out["stopped_runs"] = (f"of {len(X)} sampled runs, some stop where no transition is enabled: {where}; "
                               f"the answer holds for every run while it lasts, not for what it would do after "
                               f"(see reach lint)")
    return out


def _faces_at(model, mode: str, x) -> list[str]:
    """The invariant rows of ``mode`` that ``x`` lies on (within a relative 1e-6)."""
    halves = model.modes[mode].invariant_halfspaces
    if halves is None or not len(halves[1]):
        return []
    H, g = np.asarray(halves[0], float).reshape(-1, model.n), np.asarray(halves[1], float).reshape(-1)
    gap = np.abs(H @ x - g) <= 1e-6 * (1.0 + np.abs(H) @ np.abs(x) + np.abs(g))
    return list(dict.fromkeys(c.text for c, on in zip(model.modes[mode].invariant, gap) if on))
