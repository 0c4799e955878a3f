"""Star on nonlinear flows by conservative linearisation (Althoff, Stursberg & Buss, CDC 2008).

A chain in a mode with a nonlinear flow ``f`` is explored in blocks of ``linearise_cells`` cells
(option; default: one block to the horizon), a block halved while its box does not close (below).
For each block, from its start star ``S`` and a box ``X``,

    x' = f(x) = A x + b + L(x),     L(x) in [l_lo, l_hi] for every x in X

(:mod:`.remainder`: ``A, b`` from ``f`` and its Jacobian at the centre of ``X``, ``L`` the
Lagrange remainder enclosed by interval Hessians over ``X``). The remainder is a bounded
time-varying input, added by the exact-support input machinery of
:class:`.flowpipe.AffineFlow` (``deviation``), and the block is explored as a chain of that
affine flow. Its end -- the grid star at the block's last time plus the input effect ``R``
there, cut by the invariant -- starts the next block.

The box. ``X`` starts as the start star's interval hull, grown by ``linearise_margin`` of its
half-width; the block's cover (grid stars over the coefficient box, interpolation error and
input effect, cell by cell up to the first grid star outside the invariant: what the
exploration's screening rests on) is computed under the remainder over ``X``; if it is not
strictly inside ``X``, ``X`` becomes the cover's hull together with ``X``, grown by the margin,
and the remainder is enclosed again (Althoff's inflate-and-check); after ``linearise_inflations``
inflations without closing the block is halved, and a single cell that does not close ends the
check in UNKNOWN.

Argument. Take a run that starts the block in ``S`` and suppose it leaves ``X`` within the
block, first at ``tau`` (``x(tau) in X``). Up to ``tau`` it is a run of ``A x + b + u`` with the
input ``u(t) = L(x(t))`` inside ``[l_lo, l_hi]``, so its states up to ``tau`` lie in the cover,
strictly inside ``X``, and by continuity it stays in ``X`` a little longer -- no such ``tau``
while it flows in the mode within the block. So every run of the nonlinear automaton is, block
by block, a run of the affine one with bounded input; the checks, jumps and refinements of the
exploration are then those of the affine case, and a SAFE holds for the nonlinear automaton.
An UNSAFE needs a counterexample replayed on the nonlinear simulator.
"""

from __future__ import annotations

import numpy as np

from reach.backends.star.explorer import _Stop
from reach.backends.star.flowpipe import AffineFlow, _chain_abs_bounds, _chain_bounds
from reach.backends.star.remainder import Linearisation, unsupported
from reach.backends.star.transitions import _cached, _LinearModel, _normalised, _unsubsumed
from reach.result import Result, Status
from reach.sets import Box, Star


#: a grown box adds at least this much, relative to ``1 + |centre|`` (a flat hull still gets room)
FLOOR = 1e-9

#: a box side narrower than this, relative to ``1 + |centre|``, is still near the floor (a point
#: start): its cover may outgrow it many times without the block diverging
SETTLED = 1e-6

#: a cover this many times wider than its box: the remainder drives the inflation apart, so the
#: block is halved at once (its linearisation would only get worse, and costlier)
BLOWUP = 10.0


class LinearisedModel(_LinearModel):
    """The matrices of a hybrid automaton whose invariants, guards and resets are linear but
    whose flows need not be: the nonlinear flows compiled for :class:`.remainder.Linearisation`
    (:meth:`flow_over` linearises one over a box), the affine ones as in :class:`_LinearModel`.
    ``flows`` holds, for a nonlinear mode, its linearisation at the initial centre (no
    remainder): a placeholder that every block replaces."""

    def __init__(self, model):
        super().__init__(model)
        self.reason = self._reason(model)
        if self.reason is not None:
            return
        self.invariants = {name: _normalised(*self.widen(*mode.invariant_halfspaces))
                           for name, mode in model.modes.items()}
        self.fired = {name: _unsubsumed(js, *self.invariants[name]) for name, js in self.jumps.items()}
        self.curved = {name: Linearisation(mode.flow, model.symbols)
                       for name, mode in model.modes.items() if mode.linear is None}
        self.flows = {name: self._flow(*self._with_clock(*mode.linear))
                      for name, mode in model.modes.items() if mode.linear is not None}
        centre = (model.initial.low + model.initial.high) / 2
        for name, lin in self.curved.items():
            try:
                rem = lin.over(centre, centre)
            except (ArithmeticError, ValueError):       # mpmath: a real function at a point outside its domain
                rem = None
            if rem is None or not (np.all(np.isfinite(rem.A)) and np.all(np.isfinite(rem.b))):
                self.reason = (f"mode '{name}': the flow or its derivative is not finite and real at the centre of the "
                               f"initial set, where the linearisation starts")
                return
            self.flows[name] = AffineFlow(*self._with_clock(rem.A, rem.b))

    def _reason(self, model) -> str | None:
        """Why this automaton is out of reach of the linearisation, or None."""
        if any(m.invariant_halfspaces is None for m in model.modes.values()) or \
                any(j is None for js in self.jumps.values() for j in js):
            return "nonlinear invariants, guards or resets: star needs them linear"
        if self.varying:
            return "time-varying inputs in a nonlinear flow: not supported by the linearisation"
        for mode in model.modes.values():
            if mode.linear is None:
                why = unsupported(mode.flow, model.symbols)
                if why is not None:
                    return f"mode '{mode.name}': {why}"
        return None

    @classmethod
    def of(cls, model) -> "LinearisedModel":
        return _cached(model, cls)

    def flow_over(self, mode: str, box: Box):
        """``(flow, remainder)``: the mode's flow linearised over ``box`` (explored states), the
        remainder as a bounded input. ValueError if the remainder is unbounded over the box."""
        m = self.n - self.added_clock
        try:
            rem = self.curved[mode].over(box.low[:m], box.high[:m])
        except (ArithmeticError, ValueError) as failure:    # sqrt of a negative level, log of 0
            raise ValueError(f"the flow of mode '{mode}' is not real everywhere on the box {_text(box)} its "
                             f"runs may reach ({failure}): an invariant that keeps the states in the flow's "
                             f"domain (a level >= 0 under a square root) lets the linearisation stay there") from None
        if not rem.finite:
            raise ValueError(f"the remainder of mode '{mode}' is unbounded over the box {_text(box)} "
                             f"(a singularity of the flow, or states outside its domain: an invariant that "
                             f"keeps them in it lets the linearisation stay there)")
        shifted, active, radius = rem.as_input()
        A, b = self._with_clock(rem.A, shifted)
        if not active.size:
            return AffineFlow(A, b), rem
        return AffineFlow(A, b, np.eye(self.n)[:, active], radius), rem




def chain_hull(centers, bases, box, error, cells: int, M=None):
    """``(low, high)``: bounds of ``M x`` (``M`` the identity if None: a box) over the cover of
    the first ``cells`` cells of a chain, grid stars ``j = 0..cells`` (centres, bases, one
    coefficient box) plus per-cell ``error`` (the interpolation error and the input effect).
    A cell's segment lies in the hull of its two grid stars plus its error box."""
    M = np.eye(centers.shape[1]) if M is None else M
    upper = _chain_bounds(centers[:cells + 1], bases[:cells + 1], box, M)
    lower = -_chain_bounds(centers[:cells + 1], bases[:cells + 1], box, -M)
    if not cells:
        return lower[0], upper[0]
    spread = error[:cells] @ np.abs(M).T
    upper = np.maximum(upper[:-1], upper[1:]) + spread
    lower = np.minimum(lower[:-1], lower[1:]) - spread
    return lower.min(axis=0), upper.max(axis=0)


def block_cover(flow: AffineFlow, star: Star, h: float, cells: int, Hi, gi, M=None):
    """The bounds of ``M x`` (default: the box) over the cover of ``cells`` cells of length ``h``
    from ``star`` under ``flow``, up to the first grid star outside the invariant
    ``Hi x <= gi`` (relaxed by the input effect), computed as the exploration's chain does
    (:meth:`_Explorer._flow_chain`)."""
    Phis, psis = flow.powers(h, cells)
    dev = flow.deviation(h, cells)
    centers = star.center @ np.swapaxes(Phis, 1, 2) + psis
    bases = np.einsum("jab,bm->jam", Phis, star.basis)
    last = cells
    if Hi.shape[0]:
        lower = -_chain_bounds(centers, bases, star.box, -Hi)
        relaxed = np.broadcast_to(gi, lower.shape) + (0.0 if dev is None else dev @ np.abs(Hi).T)
        outside = np.flatnonzero(np.any(lower > relaxed + 1e-12 * (1 + np.abs(relaxed)), axis=1))
        if outside.size:
            last = min(last, int(outside[0]))
    D, d, F, _ = flow.curvature(h)
    samples = _chain_abs_bounds(centers[:last], bases[:last], star.box, D, d).max(axis=1)
    error = h * h / 8 * samples @ F.T
    if dev is not None:
        error = error + dev[1:last + 1]
    return chain_hull(centers, bases, star.box, error, last, M)


def grown(hull, box: Box | None, margin: float) -> Box:
    """The box of ``hull`` (and ``box``), its half-width grown by ``margin`` plus a floor."""
    low, high = hull
    if box is not None:
        low, high = np.minimum(low, box.low), np.maximum(high, box.high)
    centre, radius = (low + high) / 2, (high - low) / 2
    radius = radius * (1 + margin) + FLOOR * (1 + np.abs(centre))
    return Box(centre - radius, centre + radius)


class Blocks:
    """The chains of the nonlinear modes, block by block (module doc), for one exploration;
    counts blocks and inflations and keeps the largest remainder and box per mode."""

    def __init__(self, data: LinearisedModel, opt, cells: int | None = None):
        """``cells``: cells per block where the option ``linearise_cells`` is not set (None:
        one block to the horizon)."""
        self.data, self.opt = data, opt
        self.cells = cells if opt.linearise_cells is None else opt.linearise_cells
        self.curved = set(data.curved)
        self.blocks, self.inflations = 0, 0
        self.failure = ""
        self.largest: dict[str, dict] = {}

    def chain(self, explorer, mode: str, star: Star, path, guess=None, direction=None):
        """Explore ``star`` in ``mode`` to the horizon, one linearisation per block; the explorer's
        flow of the mode is the block's while the block is explored (and restored after)."""
        clock = np.eye(explorer.n)[explorer.clock]
        inherited = None                                # the rounding a block hands on
        while star is not None and mode in explorer.relevant:
            t0 = -star.support_bounds(-clock)[0]
            if t0 > explorer.horizon:
                return
            count = max(1, int(np.ceil((explorer.horizon - t0) / explorer.h - 1e-9)))
            block = count if self.cells is None else min(count, self.cells)
            flow = self.block_flow(explorer, mode, star, block)
            while flow is None and block > 1:           # halve a block whose box does not close
                block = (block + 1) // 2
                flow = self.block_flow(explorer, mode, star, block)
            if flow is None:
                raise _Stop(Status.UNKNOWN, self.failure)
            saved = explorer.flows[mode]
            explorer.flows[mode] = flow
            try:
                handed = explorer._flow_chain(mode, star, path, guess, direction, block, inherited=inherited)
            finally:
                explorer.flows[mode] = saved
            star, guess, inherited = handed if handed is not None else (None, None, None)
            direction = None

    def block_flow(self, explorer, mode: str, star: Star, cells: int) -> AffineFlow | None:
        """The linearised flow of a block whose cover stays strictly inside its box; None (and
        the reason in ``failure``) if the box does not close."""
        Hi, gi = explorer.invariants[mode]
        M = self._template(mode, explorer.n)
        box = grown((-star.support_bounds(-M), star.support_bounds(M)), None, self.opt.linearise_margin)
        for k in range(self.opt.linearise_inflations):
            try:
                flow, rem = self.data.flow_over(mode, box)
            except ValueError as failure:
                raise _Stop(Status.UNKNOWN, str(failure))
            low, high = block_cover(flow, star, explorer.h, cells, Hi, gi, M)
            if np.all(low > box.low) and np.all(high < box.high):
                self._record(mode, Box(box.low[:explorer.n], box.high[:explorer.n]), rem)
                return flow
            width = box.high - box.low          # a side still near the floor (a point start) may grow
            settled = width > SETTLED * (1 + np.abs(box.center))
            if k and (not np.all(np.isfinite(high - low))
                      or not np.all((high - low <= BLOWUP * width) | ~settled)):   # diverging
                break
            self.inflations += 1
            box = grown((low, high), box, self.opt.linearise_margin)
        self.failure = (f"mode '{mode}': the reachable set of a block of {cells} cell(s) did not stay "
                        f"inside its linearisation box after {self.opt.linearise_inflations} inflations "
                        f"(last box {_text(Box(box.low[:explorer.n], box.high[:explorer.n]))})")
        return None

    def _template(self, mode: str, n: int):
        """The rows ``M`` whose bounds make a block's region ``X = {x : low <= M x <= high}``:
        the states (a box), then the extra directions the data asks for (``directions``: the
        rows a switching input reads, so that its bound keeps the correlations of the states)."""
        extra = getattr(self.data, "directions", None)
        rows = None if extra is None else extra(mode)
        return np.eye(n) if rows is None or not len(rows) else np.vstack([np.eye(n), rows])

    def _record(self, mode: str, box: Box, rem):
        self.blocks += 1
        size = float(max(np.max(np.abs(rem.low)), np.max(np.abs(rem.high))))
        top = self.largest.get(mode)
        if top is None or size > top["remainder"]:
            self.largest[mode] = {"remainder": size, "box": [box.low.tolist(), box.high.tolist()],
                                  "point": rem.point.tolist()}

    def summary(self) -> dict:
        return {"blocks": self.blocks, "inflations": self.inflations, "largest_remainder": self.largest}


def _text(box: Box) -> str:
    return "[" + ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(box.low, box.high)) + "]"


def explore_in_blocks(blocks: Blocks, explore, key: str, details, argument, replayed: str) -> Result:
    """One exploration whose curved modes go block by block: ``explore(data, blocks)`` runs it and
    returns its Result, which gets ``details`` under ``key`` (computed by ``details(blocks)``
    after the run), ``argument(blocks)`` joined to the semantics of a SAFE and ``replayed`` to
    those of an UNSAFE."""
    result = explore(blocks.data, blocks)
    result.details[key] = details(blocks)
    if result.status is Status.SAFE:
        result.details["semantics"] = result.details.get("semantics", "") + argument(blocks)
    elif result.status is Status.UNSAFE:
        result.details["semantics"] = result.details.get("semantics", "") + replayed
    return result


def check_linearised(model, prop, opt, explore) -> Result:
    """One exploration with the nonlinear modes linearised block by block (see
    :func:`explore_in_blocks`); the linearisation's argument joins its semantics."""
    return explore_in_blocks(Blocks(LinearisedModel.of(model), opt), explore, "linearisation", Blocks.summary,
                             _argument, "; the counterexample was replayed on the nonlinear flow (the simulator)")


def _argument(blocks: Blocks) -> str:
    modes = "; ".join(f"{m}: |L| <= {v['remainder']:.3g} over the widest box {_text(Box(*v['box']))}"
                      for m, v in blocks.largest.items())
    cells = "to the horizon" if blocks.cells is None else f"of {blocks.cells} cells"
    return ("; nonlinear flows by conservative linearisation (Althoff, Stursberg & Buss 2008), "
            f"{blocks.blocks} blocks {cells}: per block f(x) = A x + b + L(x), A, b at the centre "
            "of a box X, the Lagrange remainder L enclosed over X by interval Hessians (mpmath iv, "
            "outward rounding) and taken as a time-varying input (exact support, as for inputs); "
            "the block's cover under that input lies strictly inside X, so every run stays in X "
            "over the block and is a run of the affine flow with such an input; sub-samples per cell "
            f"as stated for the initial linearisation ({modes})")
