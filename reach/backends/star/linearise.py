"""Star on nonlinear flows by conservative linearisation (Althoff, Stursberg & Buss, CDC 2008).

In each mode with a nonlinear flow ``f``, over a box ``X`` of that mode,

    x' = f(x) = A x + b + L(x),     L(x) in [l_lo, l_hi] for every x in X

(:mod:`.remainder`: ``A, b`` from ``f`` and its Jacobian at the centre of ``X``, ``L`` the
Lagrange remainder enclosed by interval Hessians over ``X``). The remainder is a bounded
time-varying input, added by the exact-support input machinery of
:class:`.flowpipe.AffineFlow` (``deviation``). The linear automaton with that input is explored
as usual, and every chain the exploration computes in a mode -- its cover: grid stars of
the coefficient box, interpolation error and input effect, cell by cell up to the invariant's
exit -- is checked to lie strictly inside that mode's box (:class:`Cover`).

Argument. Let a run of the nonlinear automaton leave the boxes for the first time at ``tau``
(``x(tau) in X`` of its mode, or a jump at ``tau`` lands outside the target's box). Up to
``tau`` it is a run of the linear automaton with the input ``L(x(t))`` inside
``[l_lo, l_hi]``, so its states up to ``tau``, and the state a jump at ``tau`` lands in, lie in
explored chains, hence strictly inside the boxes; by continuity of the flow the run stays in
its box a little longer -- no such ``tau`` before the horizon. So every run is a run of the
linear automaton with bounded input, and a SAFE of the exploration holds for the nonlinear
automaton.

Boxes. Round 0 linearises every nonlinear mode at the centre of the initial box with no box
at all: it proves nothing and yields each mode's reachable hull. Round ``k`` takes the hull of
round ``k - 1`` together with its box, grown by ``linearise_margin`` of its half-width, as the
new box, encloses the remainder over it and explores again; the first round whose chains all
stay inside their boxes gives the answer (Althoff's inflate-and-check, per mode over the whole
horizon). After ``linearise_rounds`` rounds without closing: UNKNOWN. An UNSAFE needs a replayed
counterexample on the nonlinear simulator, so it stands in any round.
"""

from __future__ import annotations

import time
import weakref

import numpy as np

from reach.backends.star.flowpipe import AffineFlow, _chain_bounds
from reach.backends.star.remainder import Linearisation, unsupported
from reach.backends.star.transitions import _LinearModel, _normalised, _unsubsumed
from reach.result import Result, Status
from reach.sets import Box


#: a grown box adds at least this much, relative to ``1 + |centre|`` (a flat hull still gets room)
FLOOR = 1e-9


class LinearisedModel(_LinearModel):
    """The matrices of a hybrid automaton whose invariants, guards and resets are linear but
    whose flows need not be: the nonlinear flows compiled for :class:`.remainder.Linearisation`,
    the affine ones as in :class:`_LinearModel`. :meth:`linearise` sets ``flows`` for given boxes."""

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
        self.affine = {name: self._flow(*self._with_clock(*mode.linear))
                       for name, mode in model.modes.items() if mode.linear is not None}
        self.start = (model.initial.low + model.initial.high) / 2
        self.flows: dict[str, AffineFlow] = {}

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
        key = id(model)
        ref, value = _CACHE.get(key, (None, None))
        if ref is None or ref() is not model:
            value = cls(model)
            _CACHE[key] = (weakref.ref(model, lambda _: _CACHE.pop(key, None)), value)
        return value

    def linearise(self, boxes: dict[str, Box]) -> dict[str, dict]:
        """Set ``flows``: each nonlinear mode linearised over its box (explored states), or at the
        initial centre without a remainder where it has none yet. Returns per boxed mode the
        linearisation point and the remainder interval; raises ValueError if a remainder is
        unbounded (a singularity in the box)."""
        flows, info = dict(self.affine), {}
        m = self.n - self.added_clock
        for name, lin in self.curved.items():
            box = boxes.get(name)
            if box is None:
                rem = lin.over(self.start, self.start)
                A, b = self._with_clock(rem.A, rem.b)
                flows[name] = AffineFlow(A, b)
                continue
            rem = lin.over(box.low[:m], box.high[:m])
            if not rem.finite:
                raise ValueError(f"the remainder of mode '{name}' is unbounded over its box "
                                 f"{_text(box)} (a singularity of the flow)")
            shifted, active, radius = rem.as_input()
            A, b = self._with_clock(rem.A, shifted)
            B = np.eye(self.n)[:, active]
            flows[name] = AffineFlow(A, b, B, radius) if active.size else AffineFlow(A, b)
            info[name] = {"box": [box.low.tolist(), box.high.tolist()], "point": rem.point.tolist(),
                          "remainder": [rem.low.tolist(), rem.high.tolist()]}
        self.flows = flows
        return info


_CACHE: dict[int, tuple[weakref.ref, LinearisedModel]] = {}


def chain_hull(centers, bases, box, error, cells: int, discrete: bool):
    """``(low, high)``: a box holding the cover of the first ``cells`` cells of a chain, grid
    stars ``j = 0..cells`` (centres, bases, one coefficient box) and per-cell error (the
    interpolation error plus the input effect, or in discrete time the input effect on grid
    star ``j``). A cell's segment lies in the box hull of its two grid stars plus its error."""
    eye = np.eye(centers.shape[1])
    upper = _chain_bounds(centers, bases, box, eye)
    lower = -_chain_bounds(centers, bases, box, -eye)
    if discrete:
        upper, lower = upper[:cells], lower[:cells]
    else:
        upper = np.maximum(upper[:cells], upper[1:cells + 1])
        lower = np.minimum(lower[:cells], lower[1:cells + 1])
    return (lower - error[:cells]).min(axis=0), (upper + error[:cells]).max(axis=0)


class Cover:
    """Called by the exploration with every chain of a linearised mode: keeps each mode's hull
    and counts the chains that are not strictly inside their mode's box (``escaped``)."""

    def __init__(self, boxes: dict[str, Box], curved, discrete: bool):
        self.boxes, self.curved, self.discrete = boxes, set(curved), discrete
        self.hulls: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.escaped = 0

    def __call__(self, mode: str, centers, bases, box, error, cells: int):
        if mode not in self.curved or not cells:
            return
        low, high = chain_hull(centers, bases, box, error, cells, self.discrete)
        if mode in self.hulls:
            low, high = np.minimum(low, self.hulls[mode][0]), np.maximum(high, self.hulls[mode][1])
        self.hulls[mode] = (low, high)
        X = self.boxes.get(mode)
        if X is None or not (np.all(low > X.low) and np.all(high < X.high)):
            self.escaped += 1


def grown(hull, box: Box | None, margin: float) -> Box:
    """The box of ``hull`` (and ``box``), its half-width grown by ``margin`` plus a floor."""
    low, high = hull
    if box is not None:
        low, high = np.minimum(low, box.low), np.maximum(high, box.high)
    centre, radius = (low + high) / 2, (high - low) / 2
    radius = radius * (1 + margin) + FLOOR * (1 + np.abs(centre))
    return Box(centre - radius, centre + radius)


def _text(box: Box) -> str:
    return "[" + ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(box.low, box.high)) + "]"


def check_linearised(model, prop, opt, explore) -> Result:
    """The rounds of the module doc. ``explore(data, cover)`` runs one exploration with the
    flows in ``data`` and returns its Result."""
    start = time.perf_counter()
    data = LinearisedModel.of(model)
    boxes: dict[str, Box] = {}
    rounds = []
    result = None
    for k in range(opt.linearise_rounds + 1):
        try:
            info = data.linearise(boxes)
        except ValueError as failure:
            result = Result(result.backend if result else "star", model.name, prop.id, Status.UNKNOWN,
                            details={"reason": str(failure)})
            break
        cover = Cover(boxes, data.curved, opt.discrete_time)
        result = explore(data, cover)
        rounds.append({"round": k, "status": result.status.value, "escaped_chains": cover.escaped,
                       "modes": info})
        if result.status is Status.UNSAFE or (k and not cover.escaped):
            break
        boxes = {m: grown(hull, boxes.get(m), opt.linearise_margin) for m, hull in cover.hulls.items()}
    else:
        result.status, result.counterexample = Status.UNKNOWN, None
        result.details["reason"] = (f"the reachable set did not close inside its linearisation boxes "
                                    f"in {opt.linearise_rounds} rounds (last: {rounds[-1]['escaped_chains']} "
                                    f"chain(s) outside)")
    result.seconds = time.perf_counter() - start
    result.details["linearisation"] = rounds
    last = rounds[-1] if rounds else None
    if last is not None and last["round"] and not last["escaped_chains"]:
        result.details["semantics"] = result.details.get("semantics", "") + _argument(last)
    elif result.status is Status.UNSAFE:
        result.details["semantics"] = result.details.get("semantics", "") + (
            "; the counterexample was replayed on the nonlinear flow (the simulator)")
    return result


def _argument(last: dict) -> str:
    modes = "; ".join(
        f"{m}: |L| <= {max(np.max(np.abs(v['remainder'][0])), np.max(np.abs(v['remainder'][1]))):.3g} "
        f"over the box {_text(Box(*v['box']))}" for m, v in last["modes"].items())
    return ("; nonlinear flows by conservative linearisation (Althoff, Stursberg & Buss 2008): in each "
            "nonlinear mode f(x) = A x + b + L(x), A, b at the centre of a box X of the mode, the "
            "Lagrange remainder L enclosed over X by interval Hessians (mpmath iv, outward rounding) "
            "and taken as a time-varying input (exact support, as for inputs); every run is a run of "
            "the linear automaton with such an input while it stays in X, and every explored chain "
            f"of the mode lies strictly inside X (checked per chain), so no run leaves X before the "
            f"horizon (boxes of round {last['round']}; {modes})")
