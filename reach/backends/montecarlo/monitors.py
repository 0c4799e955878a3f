"""Monitoring sampled runs of a safety property: per run, the smallest depth into its unsafe set
and the first violation.

Every visited state is checked against every unsafe piece of the property, one monitor per
property sharing a simulation. Whole blocks of grid states are tested at once, every unsafe piece
of a mode stacked in one matrix whose rows the simulator's block product evaluates with the
guards and invariants (:mod:`reach.model.batch`); a mode with a nonlinear piece (or an equality,
an instant) takes the state-by-state test (:func:`reach.model.constraints.violation_test`). A
state violates a piece when every row of it is beyond rounding, ``g < -1e-9 (1 + m)`` with ``m``
the magnitude the row combines, its states counted with those the simulator computes them from
(:func:`reach.model.simulate.value_sources`): the invariants' tolerance per row, a hundredth
of this one, uses the same scale.
"""

from __future__ import annotations

import numpy as np

from reach.model.automaton import HybridAutomaton
from reach.model.constraints import NUMERICAL_TOLERANCE, affine_magnitudes, equality_rows
from reach.model.simulate import value_sources
from reach.spec.properties import BoundSafety

_COMPILED: dict = {}


def _compiled_tests(model: HybridAutomaton, prop: BoundSafety):
    """``(tests, stacked)`` of ``prop`` in ``model``'s modes, compiled once per (model, property):
    ``tests[mode index]`` the state-by-state violation test, ``stacked[mode index] = (L, c,
    starts, magnitudes)`` every unsafe piece's ``H x <= g`` stacked (pieces starting at rows
    ``starts``; ``magnitudes`` of their rows, :func:`reach.model.constraints.affine_magnitudes`)
    where all pieces are linear and the property uses the standard test."""
    key = (id(model), id(prop))
    if key in _COMPILED and _COMPILED[key][0] is model and _COMPILED[key][1] is prop:
        return _COMPILED[key][2]
    names = list(model.modes)
    sources = value_sources(model)
    standard = type(prop).violation is BoundSafety.violation          # not a subclass's own test
    tests = {names.index(m): test for m in prop.modes
             if (test := prop.violation(m, sources) if standard else prop.violation(m)) is not None}
    stacked = {}
    for m_index, m in enumerate(names):
        hs = prop.halfspace_pieces(m) if m_index in tests and standard else None
        if any(equality_rows(piece) for piece in prop.pieces.get(m, [])):
            hs = None                   # an equality (an instant) takes the state-by-state test
        if hs:
            L, c = np.vstack([H for H, _ in hs]), np.concatenate([g for _, g in hs])
            stacked[m_index] = (L, c, np.cumsum([0] + [H.shape[0] for H, _ in hs[:-1]]),
                                affine_magnitudes(L, c, sources))
    if len(_COMPILED) > 256:
        _COMPILED.clear()
    _COMPILED[key] = (model, prop, (tests, stacked))
    return tests, stacked


class SafetyMonitor:
    """Tracks, per run, the smallest depth into the unsafe set and the first violation."""

    def __init__(self, model: HybridAutomaton, prop: BoundSafety, n_runs: int):
        self.tests, self.stacked = _compiled_tests(model, prop)
        self.min_depth = np.full(n_runs, np.inf)
        self.violation_time = np.full(n_runs, np.nan)
        self.violation_state = np.full((n_runs, model.n), np.nan)
        self.violation_mode = np.full(n_runs, -1)

    def margin_rows(self, m_index: int):
        """``(H, g)``: every unsafe piece of the property in mode ``m_index`` stacked, whose
        margins ``H x - g`` :meth:`block` reads; None where it tests state by state."""
        stacked = self.stacked.get(m_index)
        return None if stacked is None else stacked[:2]

    def block(self, t, X, seen, m_index, rows, margins=None):
        """A whole block of grid states of one mode at once: ``X`` (B, n, R) at times ``t``
        (B, R), ``seen`` (B, R) the states the runs ``rows`` (distinct) visit, ``margins`` (B,
        k, R) the values of :meth:`margin_rows` there if the simulator computed them. The same
        test as :meth:`__call__`: a piece's depth is the largest of its margins ``H x - g``, the
        depth the smallest over the pieces, a violation a piece whose every margin is below
        ``-NUMERICAL_TOLERANCE (1 + m)``, ``m`` its row's magnitude. That bound is at most
        ``-NUMERICAL_TOLERANCE``, so only the runs whose smallest depth in the block is below
        it are searched for their first violation."""
        if m_index not in self.tests or not seen.any():
            return
        if m_index not in self.stacked:            # a nonlinear piece: the state-by-state test
            j, r = np.nonzero(seen)
            self(t[j, r], np.moveaxis(X, 1, 2)[j, r], np.full(j.size, m_index), rows[r])
            return
        L, c, starts, magnitudes = self.stacked[m_index]
        if margins is None:
            margins = np.matmul(L, X)
            margins -= c[:, None]
        if seen.all() and starts.size == margins.shape[1]:        # one constraint per piece
            depth = margins.min(axis=1)
        else:
            depth = np.where(seen, _piece_depth(margins, starts), np.inf)
        # a run that leaves the real numbers within the block (NaN states) keeps NaN as its
        # depth (counted as undefined), but a violation at its real states before is still found
        undefined = np.isnan(depth).any(axis=0)
        low = np.fmin.reduce(depth, axis=0)             # the least over the real states
        self.min_depth[rows] = np.where(undefined, np.nan, np.minimum(self.min_depth[rows], low))
        r = np.flatnonzero((low < -NUMERICAL_TOLERANCE) & np.isnan(self.violation_time[rows]))
        if r.size:
            B, k = margins.shape[:2]
            size = magnitudes(X[:, :, r].transpose(0, 2, 1).reshape(-1, X.shape[1]))
            size = size.reshape(B, r.size, k).transpose(0, 2, 1)
            violated = seen[:, r] & _beyond(margins[:, :, r], size, starts)
            first = violated.any(axis=0)
            r, j = r[first], violated[:, first].argmax(axis=0)
            self.violation_time[rows[r]] = t[j, r]
            self.violation_state[rows[r]] = X[j, :, r]
            self.violation_mode[rows[r]] = m_index

    def __call__(self, t, X, mode, rows):
        """States one by one (``t``, ``X`` (N, n), ``mode``, ``rows`` per state; a run may appear
        several times, in time order): the property's own test, or where its pieces are
        stacked the same test from their rows (as :meth:`block`)."""
        for m_index, test in self.tests.items():
            sel = np.flatnonzero(mode == m_index)
            if sel.size == 0:
                continue
            if m_index in self.stacked:
                L, c, starts, magnitudes = self.stacked[m_index]
                Y = X[sel]
                G = (L @ Y.T - c[:, None])[None]
                d = _piece_depth(G, starts)[0]
                violated = np.zeros(sel.size, dtype=bool)
                near = np.flatnonzero(d < -NUMERICAL_TOLERANCE)      # every tolerance is at least that
                if near.size:
                    violated[near] = _beyond(G[:, :, near], magnitudes(Y[near]).T[None], starts)[0]
            else:
                violated, d = test(X[sel])
            r = rows[sel]                      # a run may appear many times, in time order
            np.minimum.at(self.min_depth, r, d)
            hits = np.flatnonzero(violated & np.isnan(self.violation_time[r]))
            if hits.size:
                _, first = np.unique(r[hits], return_index=True)
                k = sel[hits[first]]
                self.violation_time[rows[k]] = t[k]
                self.violation_state[rows[k]] = X[k]
                self.violation_mode[rows[k]] = m_index

    ARRAYS = ("min_depth", "violation_time", "violation_state", "violation_mode")

    def arrays(self) -> tuple:
        """What the monitor found, per run (to send back from a worker and merge)."""
        return tuple(getattr(self, a) for a in self.ARRAYS)

    @classmethod
    def merged(cls, model: HybridAutomaton, prop: BoundSafety, parts: list) -> "SafetyMonitor":
        """One monitor over the runs of several (``arrays()`` of each, in run order)."""
        out = cls(model, prop, 0)
        for i, name in enumerate(cls.ARRAYS):
            setattr(out, name, np.concatenate([q[i] for q in parts]))
        return out

    def first_violation(self) -> int | None:
        """The violating run that went deepest into the unsafe set, if any."""
        hit = np.flatnonzero(np.isfinite(self.violation_time))
        if hit.size == 0:
            return None
        depth = self.min_depth[hit]         # NaN: the run left the real numbers after its violation
        return int(hit[np.argmin(np.where(np.isnan(depth), np.inf, depth))])


def _beyond(G: np.ndarray, size: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``(B, R)``: whether some piece (starting at rows ``starts`` of the margins ``G`` (B, k,
    R)) has every margin below ``-NUMERICAL_TOLERANCE (1 + size)`` (``size`` (B, k, R), the
    rows' magnitudes)."""
    below = G < -NUMERICAL_TOLERANCE * (1.0 + size)
    return np.logical_and.reduceat(below, starts, axis=1).any(axis=1)


def _piece_depth(G: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``(B, R)``: the smallest over the pieces (starting at rows ``starts`` of ``G`` (B, k,
    R)) of the largest of their margins."""
    if starts.size == G.shape[1]:
        return G.min(axis=1)
    bounds = list(starts) + [G.shape[1]]
    depth = G[:, bounds[0]:bounds[1]].max(axis=1)
    for a, b in zip(bounds[1:-1], bounds[2:]):
        np.minimum(depth, G[:, a:b].max(axis=1), out=depth)
    return depth
