"""Arbitrary switching between affine modes as one differential inclusion.

A *switching group* is a set of at least two modes ``p_1 .. p_k`` of a linear hybrid automaton
that a run may leave for one another at any instant: every ordered pair is joined by a
transition with no guard, no reset, no abort window and no urgency, and all members have the same
invariant. Explored mode by mode, such a group branches at every cell of every chain (each
step may switch), and the successors multiply without end (ARCH-COMP's Platoon PLAA01, where
communication is lost and restored at arbitrary times).

Inclusion. With the members' flows ``x' = A_i x + b_i + B_i (u - u_c)`` (time-varying inputs
``|u - u_c| <= u_r``, :meth:`.transitions._LinearModel._flow`) and their means ``A_m, b_m, B_m``,
a run that stays in the group with switching signal ``sigma(t)`` solves

    x' = A_m x + b_m + B_m (u - u_c) + w(t),
    w = (A_sigma - A_m) x + (b_sigma - b_m) + (B_sigma - B_m)(u - u_c),

and for ``x`` in a region ``X`` every such ``w`` lies in the box ``W(X)``. ``X`` is a box (centre
``c``, radius ``r``) cut by slabs ``l_k <= D_i[j] x <= u_k``, one per row ``j`` of each
``D_i = A_i - A_m`` that is not zero (:meth:`SwitchingModel.directions`): the slabs keep the
correlations between the states a row reads (on PLAA01 they halve the bound of ``w``). Per
component ``j``, ``W`` runs from the least lower to the largest upper end over the members of
``[D_i[j] x] + d_i[j] +- |E_i[j]| u_r`` (``d_i = b_i - b_m``, ``E_i = B_i - B_m``), where
``[D_i[j] x]`` is the slab ``[l_k, u_k]`` intersected with the box's exact range
``D_i[j] c +- |D_i[j]| r``; every end is pushed out by a relative 1e-9 of the magnitudes
involved against rounding. ``w`` is measurable (``sigma`` is piecewise constant and
``x`` continuous), so it is a bounded time-varying input, and the exploration treats it as the
remainder of a linearisation (:mod:`.linearise`): a chain in a group mode is explored block by
block (:data:`SWITCHING_CELLS` cells each), each block with the affine flow ``A_m x + b_m`` and
the input ``W(X)`` over a region ``X`` its cover stays strictly inside, box and slabs (inflate
and check). Every run that stays in the group is then
a run of that affine flow with a bounded input, block by block, whatever its switching.

The exploration in turn (``_Explorer``, with ``data`` a :class:`SwitchingModel`): a group
member's chain stands for the whole group. Its transitions within the group are not fired
when they change no state (their successors are runs of the same inclusion, already covered);
it fires every member's transitions leaving the group and every transition within it that
resets a state (a run may take them from any member), and it is checked against the unsafe
pieces of every member (:func:`group_pieces`). Any run of the automaton, up to the instant it
leaves the group, is a run of that chain, so a SAFE holds for the automaton. An UNSAFE needs a
counterexample replayed on the automaton itself (the simulator chooses its own switching).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reach.backends.star.flowpipe import AffineFlow
from reach.backends.star.transitions import _cached, _LinearModel, _unsubsumed
from reach.sets import Box

#: relative allowance for the rounding of ``W(X)`` (a handful of products and sums per entry)
ROUNDING = 1e-9

#: cells per block of a group's chain unless ``linearise_cells`` says otherwise: ``W(X)`` grows
#: with the region a block sweeps, so short blocks keep the inclusion tight (on PLAA01-BND50 the
#: lower bound of e2 over the widest block is -34.1 with 1 cell, -36.4 with 2, -38.5 with 3,
#: -42.8 with 5; SAFE in 2.5, 1.1, 0.7, 0.3 s)
SWITCHING_CELLS = 2


def switching_groups(model) -> list[tuple[str, ...]]:
    """The switching groups of ``model`` (module doc), disjoint: sets of at least two modes of
    which every ordered pair is joined directly by an unguarded, reset-free, window-free
    may-transition, kept when the members' invariants, flows' linearity and timelessness allow
    it."""
    free: dict[str, set[str]] = {name: set() for name in model.modes}
    for tr in model.transitions:
        guard = model.guard_halfspaces(tr)
        if tr.source != tr.target and not tr.urgent and not tr.reset and tr.window is None \
                and guard is not None and guard[0].shape[0] == 0:
            free[tr.source].add(tr.target)
    groups, seen = [], set()
    for name in model.modes:
        if name in seen:
            continue
        members = [name] + sorted(m for m in free[name] if name in free[m] and m not in seen)
        members = [m for m in members if all(o == m or o in free[m] for o in members)]
        if len(members) < 2 or not _compatible(model, members):
            continue
        seen.update(members)
        groups.append(tuple(members))
    return groups


def _compatible(model, members) -> bool:
    modes = [model.modes[m] for m in members]
    if any(m.linear is None or m.invariant_halfspaces is None or m.timeless for m in modes):
        return False
    H0, g0 = modes[0].invariant_halfspaces
    return all(np.array_equal(H0, m.invariant_halfspaces[0]) and np.array_equal(g0, m.invariant_halfspaces[1])
               for m in modes[1:])


@dataclass
class SwitchingInput:
    """``w(t) in [low, high]`` for every run in the box (the record :mod:`.linearise` keeps)."""

    point: np.ndarray
    low: np.ndarray
    high: np.ndarray


class SwitchingModel(_LinearModel):
    """The matrices of a linear hybrid automaton whose switching groups are explored as one
    inclusion each (module doc): ``curved`` holds every group member, :meth:`flow_over` gives
    the group's affine flow and input box over a region of states, ``fired`` a member's
    transitions leaving its group or resetting a state (those of every member), and ``flows`` of a member stays its own flow (a
    placeholder that every block replaces; counterexample signals are built from it)."""

    def __init__(self, model):
        super().__init__(model)
        self.groups = switching_groups(model) if self.linear else []
        self.group_of = {m: group for group in self.groups for m in group}
        self.curved = set(self.group_of)
        self._means = {group: self._mean(group) for group in self.groups}
        for group in self.groups:
            fired = [j for m in group for j in self.jumps[m] if j.target not in group or _resets(j)]
            kept = _unsubsumed(fired, *self.invariants[group[0]])
            for m in group:
                self.fired[m] = kept

    @classmethod
    def of(cls, model) -> "SwitchingModel":
        return _cached(model, cls)

    def _mean(self, group):
        flows = [self.flows[m] for m in group]
        A = np.mean([f.A for f in flows], axis=0)
        b = np.mean([f.b for f in flows], axis=0)
        inputs = [f for f in flows if f.B is not None]
        if inputs:
            B, u_r = np.mean([f.B for f in inputs], axis=0), inputs[0].u_radius
        else:
            B, u_r = np.zeros((self.n, 0)), np.zeros(0)
        parts = [(f.A - A, f.b - b, (f.B if f.B is not None else np.zeros_like(B)) - B) for f in flows]
        rows = np.vstack([np.zeros((0, self.n))] + [D[np.any(D != 0, axis=1)] for D, _, _ in parts])
        return A, b, B, u_r, parts, rows

    def directions(self, mode: str) -> np.ndarray:
        """The rows ``D_i[j]`` (every member ``i``, every row ``j`` that is not zero) whose
        bounds, with the box, make a block's region ``X`` (:class:`.linearise.Blocks`)."""
        return self._means[self.group_of[mode]][5]

    def flow_over(self, mode: str, region: Box):
        """``(flow, w)``: the affine flow of the group of ``mode`` with its bounded inputs and
        the switching input ``W(X)`` (module doc) as one more time-varying input. ``region``:
        the bounds of ``M x`` over ``X`` for ``M`` the identity stacked on :meth:`directions`
        (the first ``n`` entries are the box of ``X``)."""
        A, b, B, u_r, parts, rows = self._means[self.group_of[mode]]
        n = self.n
        c, r = region.center[:n], region.radius[:n]
        slab_low, slab_high = region.low[n:], region.high[n:]
        low, high = np.full(n, np.inf), np.full(n, -np.inf)
        k = 0                                           # the first of member i's rows in ``rows``
        for D, d, E in parts:
            lo, hi = D @ c - np.abs(D) @ r, D @ c + np.abs(D) @ r    # D x over the box
            used = np.flatnonzero(np.any(D != 0, axis=1))
            lo[used] = np.maximum(lo[used], slab_low[k:k + used.size])   # ... and over the slabs
            hi[used] = np.minimum(hi[used], slab_high[k:k + used.size])
            k += used.size
            spread = np.abs(E) @ u_r
            pad = ROUNDING * (np.abs(D) @ (np.abs(c) + r) + np.abs(d) + spread)
            low = np.minimum(low, lo + d - spread - pad)
            high = np.maximum(high, hi + d + spread + pad)
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise ValueError(f"the switching input of mode '{mode}' is unbounded over the box")
        w = SwitchingInput(c, low, high)
        active = np.flatnonzero(high > low)
        centre = (low + high) / 2
        columns = np.hstack([B, np.eye(self.n)[:, active]])
        radius = np.concatenate([u_r, (high - low)[active] / 2])
        if not columns.shape[1]:
            return AffineFlow(A, b + centre), w
        return AffineFlow(A, b + centre, columns, radius), w


def _resets(jump) -> bool:
    """Whether the jump changes a state (a reset other than the identity)."""
    return not (np.array_equal(jump.R, np.eye(jump.R.shape[0])) and not np.any(jump.r))


def group_pieces(pieces: dict, groups) -> dict:
    """The unsafe pieces per mode with every group member given those of all its group (a
    member's chain stands for runs in any member), duplicates dropped."""
    out = dict(pieces)
    for group in groups:
        union = []
        for m in group:
            for p in pieces.get(m, []):
                if not any(np.array_equal(p.H, q.H) and np.array_equal(p.g, q.g) and p.strict == q.strict
                           for q in union):
                    union.append(p)
        if union:
            for m in group:
                out[m] = union
    return out


def argument(data: SwitchingModel) -> str:
    """The sentence a SAFE verdict adds to its semantics."""
    groups = "; ".join("{" + ", ".join(g) + "}" for g in data.groups)
    return ("; modes that switch to one another at any instant (" + groups + ") explored as one "
            "differential inclusion each: x' = A_m x + b_m + w with A_m, b_m the members' means and "
            "w = (A_i - A_m) x + (b_i - b_m) (+ the inputs' differences) bounded over a box X the "
            "block's cover stays strictly inside (inflate and check, as for a linearisation), "
            "taken as a time-varying input; transitions within a group are covered by it, those "
            "leaving it fire from every member, and every member is checked against the pieces "
            "of all")


def check_switching(model, prop, opt, explore):
    """One exploration with every switching group explored as its inclusion, block by block
    (:func:`.linearise.explore_in_blocks` over :class:`SwitchingModel`); the inclusion's argument
    joins its semantics."""
    from reach.backends.star.linearise import Blocks, explore_in_blocks

    data = SwitchingModel.of(model)

    def details(blocks):
        summary = blocks.summary()
        return {"groups": [list(g) for g in data.groups], "blocks": summary["blocks"],
                "inflations": summary["inflations"], "largest_input": summary["largest_remainder"]}

    return explore_in_blocks(Blocks(data, opt, SWITCHING_CELLS), explore, "switching", details,
                             lambda _: argument(data),
                             "; the counterexample was replayed on the automaton (the simulator's own switching)")
