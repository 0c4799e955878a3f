"""The ``star`` back-end: generalized-star-set reachability of linear hybrid automata (and of
nonlinear flows by conservative linearisation).

Method
------
Each mode has affine dynamics ``x' = A x + b``. A star ``S`` advances by one step ``h`` as
``e^{Ah} S + psi(h)`` (``[Phi psi; 0 1] = expm([A b; 0 0] h)``: the affine term by state
augmentation), so a whole chain of grid stars ``Y_0, Y_1, ...`` is a stack of matrix
products. Between grid points every run is covered by the **segment** of its cell
``[t_j, t_j + h]``: the exact convex hull of ``Y_j`` and ``Y_{j+1}`` with a shared
predicate (:func:`reach.sets.star.chord_hull`) plus the linear-interpolation error

    |x_i(t_j + lam h) - chord_i(lam)| <= lam (1 - lam) h^2 / 2 * M_i,   M_i >= sup |x_i''|

on the cell. ``x'' = A^2 x + A b`` is an affine function of the state; ``M`` comes from
``q + 1`` sub-samples at spacing ``delta = h / q`` (support bounds of ``Y_j`` in the
directions of ``A^2 e^{A s}``) and the closure argument ``y := x''``, ``y'' = A^2 y``:

    sup |y| <= max_samples |y| + delta^2/8 |A^2| sup |y|
    =>  M = (I - delta^2/8 |A^2|)^{-1} max_samples |y|,

valid because ``q`` is chosen so that the spectral radius of ``delta^2/8 |A^2|`` is at
most 1/4 (the inverse is then a non-negative Neumann series).

Transitions -- urgent ones (the octagon entry) and may-transitions over a clock window
(the abort) alike -- fire from a segment intersected with the guard and the source
invariant: that set contains the state at every switching instant inside the cell, so the
continuum of switching times is covered without aggregation; each such set starts a
successor star that carries the global clock, so no alignment of time grids is assumed.
Where the guard leaves a single instant (a switch at ``t == 5``, and a start star whose
clock is one value up to rounding), the successor is instead the image of the cell's start
star at that instant, bloated by the instant's width times a bound on ``|x'|``
(:meth:`_Explorer._at_instant`): no chord, no interpolation error and no second copy of the
coefficients, so a schedule of switches keeps its stars small.
Urgent guards. A guard of one row (or a slab) ends the flow of its mode: its negation is a
row every run keeps while it flows there, and it cuts the chain like an invariant. The outside
of a guard of several rows is a union of half-spaces, so each segment is split by them instead,
and the chain itself flows on; but a row ``h x >= c`` of such a guard (its far side) is kept
where no run can cross it outside the guard -- on its face, wherever another row of the guard
is not met, the flow enters it strictly, whatever the inputs (one LP per other row,
:func:`.explorer._barrier_rows`) -- and the entry star lies on its side. The deadband's coast
mode (``th >= 0.1 & w >= 0``, ``th' = w``) keeps ``th <= 0.1``: without it the chain flowed on
to the horizon and fired from every cell, a cover of ``th`` up to 1.05 for a true 0.11.
Invariants are intersected exactly (predicate rows). Every unsafe convex piece of the
property is checked per segment: cheap support bounds first (vectorised over the chain),
an LP on the segment only where they do not exclude the piece. The chain's screening takes
``M`` first over each grid star's interval hull (``|D_l| |V_j| r``: ``n^2`` operations per
sample instead of ``n^2 m``, 273 states in a few milliseconds) and the exact support above
only for the cells that bound does not clear, so every cell checked further has the same
error as before.

Refinement. Each cell's segment adds a block of coefficients (hull weights, chord weight,
error terms) to its star, and successors keep their ancestors' blocks. When a piece is
met, the block with the largest spread along the piece is blamed and only the cell that
owns it is bisected (halved step, a quarter of the error), with everything downstream of
it; up to ``max_refinements`` times per cell. A witness -- an LP point of a segment inside a
piece -- maps back through the coefficients (the original ones are kept in every derived
star) to an initial state and abort time; it is replayed with the Monte Carlo simulator
when nothing is left to refine or when it lies deeper in the piece than all refinable
spread. UNSAFE only if the replay violates; otherwise UNKNOWN.

Timed modes. In a mode whose flow is a constant (``A = 0``: clocks, counters, stopwatches
of a timed or linear hybrid automaton) every run is the ray ``x + s b``; the cell
``[0, h]`` from ``S`` is then exactly ``S + [0, h] b`` -- one new coefficient ``s in [0, 1]``
instead of a chord hull, no interpolation error, nothing to refine -- so coefficient counts
grow by one per mode visit and hundreds of jumps stay cheap. A transition whose guard,
within the source invariant, lies inside the guard of another transition with the same
target and reset is *subsumed* (its successors are contained in the other's) and is not
fired separately (an urgent time-out at the end of a window, for example).

Timeless modes. Where no time may pass (SpaceEx ``flow false``, e.g. the ``start`` mode an
import adds for several initial locations) the entry star is the whole of what the mode holds:
it is checked once and its jumps fire from it at once, one successor per transition instead of
one per cell of a chain (:meth:`_Explorer._instant`).

Switching groups. Modes a run may leave for one another at any instant (unguarded, reset-free
may-transitions both ways, one invariant: communication lost and restored at arbitrary times)
are explored as one differential inclusion per group, ``x' = A_m x + b_m + w`` with ``w`` the
members' differences bounded over a box the block stays in (:mod:`.switching`), instead of a
possible switch at every cell of every chain (option ``switching``).

Jumps. ``max_jumps`` bounds the jumps along a path (none by default): a path past it is not
followed, the others are (a violation within the bound is UNSAFE; otherwise UNKNOWN). When the model may
have a zero-dwell cycle (:mod:`reach.model.lint`), a path may take at most ``STALL_JUMPS``
jumps while its earliest clock advances by less than one time step; beyond, UNKNOWN (a
Zeno-like run cannot be followed to the horizon). Any other model may take ``CHATTER_JUMPS``
such jumps: more mean switching faster than the step resolves (a hysteresis band crossed
back and forth within one cell), and the UNKNOWN asks for a finer step. Paths too deep for the recursion end
in UNKNOWN too. A witness whose path takes more
than one window switch, or a window on a clock other than the global one, is replayed
without a switch time (the simulator takes one switch at a global time): if that run does
not violate, the answer stays UNKNOWN.

Clock. The horizon and the switch times are read off a global clock (rate 1 everywhere,
0 initially, never reset). A model without one gets its own, an extra explored state that
no guard, invariant, reset or property mentions (:class:`_LinearModel`).

Aggregation. Each segment of a non-constant flow doubles a star's coefficients (the chord
hull keeps ``a`` and ``lam a``), so a path with many jumps -- a thermostat switching every
few minutes -- would need LPs of exponential size. Past the first ``aggregate_after`` jumps
of a path, the successors one chain sends through one transition (the stars entering a
mode in that chain's time window) are replaced by their interval hull, a box star with
fresh coefficients intersected with the target invariant and with the rows every successor
of the transition meets (:func:`.transitions.kept_rows`: the rows of its guard and of the
source's invariant and kept urgent rows whose normal lies in the reset's row space, ``h = a
R``, as ``a y <= g + a r``; ``v := 0.8 v`` keeps the switching line ``x + v = -0.2`` as ``x +
1.25 v = -0.2``); it contains every member, so a proof under it covers them. When a check under an aggregate fails, its witness is traced
back through the nearest point of a member (one LP per member, per aggregate level) to an
initial state and replayed; if that run does not violate, the aggregate is refined into
its members, explored with their exact histories. A constant flow's segments are exact and
add one coefficient, so its successors are aggregated only on a model without a clock, where
the hulls let the fixpoint check close the cycle. Star, coefficient and memory budgets end
a check in UNKNOWN with the reason, and progress goes to the ``reach.star`` logger.

Strict and non-strict bounds. With piece rows of unit norm, the depth LP (HiGHS, primal
feasibility 1e-10, its value the weak-duality bound) is trusted to ``tol = touch_tolerance *
scale``: a piece of strict inequalities (the negation of ``x >= -100``) counts as entered only
above ``tol`` (a set that meets ``x = -100`` only touches it), with the scale ``max(1, |g|,
|h . c|)``, or the size of the rows' terms over the segment, ``max(|g|, |h| |c| + |h V| r)``,
where that is smaller (a quantity of 1e-6 is read at its own scale); a piece with a non-strict
row as met from ``-tol``, with the scale ``max(1, |g|, |h . c|)``; the details state the
largest ``tol`` used. An LP failure answers UNKNOWN.

Inputs. A time-varying bounded input (``model.bounded_inputs`` with ``varying``) is taken out
of the flow: the run is the input-free run (input at the box centre) plus a deviation ``d``
bounded per cell by a box, added to every segment; invariants are relaxed by it on the
input-free grid stars and applied exactly to the segments. The box is the exact support of
``d(t)`` over all measurable signals, ``int_0^t |e^{A s} B| u_r ds`` per component, bounded
from above on sub-cells by the chord of ``e^{A s} B`` plus a closure bound on its curvature
(:class:`.flowpipe.AffineFlow`; sound between grid points, within ``O(delta^2)`` of exact).
The box grows with the time since its start, and the relaxed invariant cannot remove runs
that left the mode long ago; so in a mode whose invariant reads a state an input moves, a
chain is explored a few cells at a time, each block restarting ``d`` from the last block's end
star (grid star plus box, cut by the exact invariant), which holds every run still in the
mode (:meth:`_Explorer._rebase_cells`). The first half of a bisected cell takes the box at its
own end, so the box shrinks with the cell near a start. The box is exact per component but
not jointly: a successor that carries it through a jump starts from its corners, which no
signal reaches together. Along the rows of the mode's unsafe pieces and guards that mix
components (at most 16), the cell's box is cut by ``|c^T d| <= int_0^t |c^T e^{A s} B| u_r ds``
bounded the same way (Le Guernic and Girard's support functions: the support of a sum is the
sum of the supports), so a requirement such as ``x - 0.5 v <= 3.17`` reads the input's exact
support, not the box's ``|x| + 0.5 |v|`` (:func:`.flowpipe._plus_box`). With ``input_cells = L > 0`` a chain is cut into blocks of ``L``
cells and each completed block's effect enters the grid stars as generators, two per input
(the block's mean input and its first Legendre moment, coupled by ``|x| + |y| <= 1``), plus a
residual box of order ``T^3`` (:class:`.flowpipe.ChainInputs`); only the block in progress
is a box. A polytopic initial set (``initial.polytope``) cuts the initial star. A witness is replayed
with the inputs held at its initial values and then with the extremal signal of the piece:
for the piece row ``h x <= g`` the inputs move most, the LP point of the segment deepest
along ``-h`` (the other rows kept, so an instant ``t == 20`` stays one) gives the initial
state and the instant ``t`` (the latest instant of that depth: the input's support grows with
time, the cell's bound is that of its end), and the input is the bang-bang signal
``u = u_c + u_r sign(int_piece -h e^{A (t - s)} B)`` on a fine grid
(:func:`.witnesses.extremal_signal`), which attains the input's exact support at ``t``;
the simulator replays it on a grid that contains the pieces' starts. UNSAFE only if a
replay violates (an equality of the piece is met up to rounding there, the other rows
beyond it: :func:`reach.model.constraints.violation_test`).

Forbidden locations. A piece with no rows (SpaceEx ``loc() == error``) makes its whole mode
unsafe: any point of a segment there before the horizon is a witness, replayed at once; if
the replay does not reach the mode, the cell that fired the latest refinable jump on the
path is bisected, and UNKNOWN follows when nothing is left to refine.

Nonlinear flows (:mod:`.linearise`, Althoff, Stursberg & Buss, CDC 2008). A mode whose flow
``f`` is not affine is explored in blocks of cells; for each block ``f(x) = A x + b + L(x)``
with ``A, b`` the linearisation at the centre of a box ``X`` and the Lagrange remainder ``L``
enclosed over ``X`` by interval Hessians in outward rounding (:mod:`.remainder`); ``L`` is a
time-varying input in that enclosure, bounded by its exact support as above. ``X`` is grown
until the block's cover under that input lies strictly inside it (else the block is halved;
UNKNOWN when a single cell does not close). SAFE then holds for the nonlinear automaton: a run
cannot leave ``X`` within the block (at its first exit it would still be a run of the affine
flow with such an input, so inside the cover, strictly inside ``X``), so it is a run of the
affine automaton with a bounded input. Invariants, guards and resets must stay linear; UNSAFE
needs a counterexample replayed on the nonlinear simulator.

Several properties (:meth:`StarBackend.check_many`). The reachable sets do not depend on the
property, only their refinement does: the properties of one model are explored once against the
union of their unsafe sets, whose SAFE is each one's SAFE; where the union is violated or
undecided, each is checked on its own.

Layout: :mod:`.options` (settings, constants), :mod:`.flowpipe` (flows, segments, bounds),
:mod:`.transitions` (the automaton as matrices), :mod:`.explorer` (the exploration),
:mod:`.aggregation`, :mod:`.witnesses` (witnesses back to initial states), :mod:`.linearise`
and :mod:`.remainder` (nonlinear flows), this module (the back-end, its Result and the safe-abort
sweep).

``discrete_time=True`` checks and switches at grid points only (Hylaa's semantics): no
segments, no error terms -- not a proof for continuous time, so it answers UNSAFE (replayed)
or UNKNOWN ("no violation at the grid points"), never SAFE.

:func:`safe_abort_time` / :func:`safe_abort_map` sweep initial cells for the latest abort
time up to which every abort is proven safe (Fig. 5 of the rendezvous benchmark).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from reach import lp
from reach.deep import call_deep
from reach.backends.star.explorer import BARRIER_SLOPE, LOG, OUT_OF_TIME, _Explorer, _Stop, budget_text
from reach.backends.star.flowpipe import AffineFlow, flowpipe
from reach.backends.star.hull import check_hull
from reach.backends.star.linearise import LinearisedModel, check_linearised
from reach.backends.star.options import (DEFAULT_PASS_SHARE, DEPTH_LP_TOLERANCE, FINER_FACTOR,
                                         FINER_MAX_SECONDS, FINER_PASSES, FINER_SECONDS, NAME, StarOptions,
                                         aggregating_retry, finer_retry, first_share, inputs_retry)
from reach.backends.star.polygons import SIDES
from reach.backends.star.stops import sampled_stops
from reach.backends.star.switching import SwitchingModel, check_switching
from reach.backends.star.transitions import _LinearModel, _unsafe_pieces
from reach.backends.star.witnesses import witness_details
from reach.model.simulate import check_size, single_threaded
from reach.result import Result, Status
from reach.sets import Star
from reach.spec.properties import BoundSafety

__all__ = ["AffineFlow", "BACKEND", "StarBackend", "StarOptions", "arc_cells", "flowpipe",
           "safe_abort_map", "safe_abort_time"]


_SOUNDNESS = (
    "continuous time: each cell [t, t+h] is covered by the exact convex hull of its two grid "
    "stars (shared predicate) plus the interpolation error lam(1-lam) h^2/2 M, "
    "M >= sup|x''| from {q} sub-samples per cell and the closure (I - delta^2/8 |A^2|)^-1; "
    "transitions (urgent and window) fire from segment-and-guard sets, so every switching "
    "instant is covered; invariants and guards are exact LP rows; depth LPs by HiGHS with primal "
    "feasibility tolerance {lp_tol:g} (100 times that, then HiGHS's default 1e-7, where it fails; "
    "other LPs ~1e-7); a piece of strict inequalities counts as entered at a depth above "
    "max({rel:g}, 10 x the LP's tolerance) x min(max(1, |g|, |h.c|), max(|g|, |h| |c| + |h V| r)) (at "
    "most the size of its rows' terms over the segment), a piece with a non-strict row as met at a depth "
    "of at least minus that tolerance x max(1, |g|, |h.c|) (largest used: {tol:g}); matrix exponentials in floating "
    "point (rounding not enclosed)")


_DISCRETE = ("discrete time: states checked and switched at grid points t = k*h only "
             "(Hylaa's semantics); behaviour between grid points is not covered")


def _with_budget(options, opt: StarOptions, share: float):
    """``options`` (a dict of options or StarOptions, ``opt`` read from them) with ``share`` of
    their time budget."""
    if opt.max_seconds is None:
        return options
    if isinstance(options, StarOptions):
        return replace(options, max_seconds=opt.max_seconds * share)
    return {**(options or {}), "max_seconds": opt.max_seconds * share}


#: the share of ``max_seconds`` the joint exploration of several properties may take
#: (:meth:`StarBackend.check_many`): each property may still need its own whole budget after it
JOINT_SHARE = 0.25


#: the least time the mode-by-mode pass after an undecided switching inclusion has (seconds)
MODE_BY_MODE_SECONDS = 5.0

#: why a check whose matrices hold inf or NaN cannot go on
OVERFLOW = ("numbers beyond double precision: a flow or its linearisation overflows (terms such as "
            "1e300*h*h or exp(700*h))")


class StarBackend:
    name = NAME
    varying_inputs = True           # time-varying bounded inputs: the input set per step

    def supports(self, model, prop) -> str | None:
        if getattr(prop, "kind", None) != "safety":
            return f"the star back-end checks safety properties only (got '{getattr(prop, 'kind', '?')}')"
        try:
            if not _LinearModel.of(model).linear:
                reason = LinearisedModel.of(model).reason
                if reason is not None:
                    return reason
        except np.linalg.LinAlgError as failure:        # inf or NaN in a flow's matrices
            return f"{OVERFLOW} ({failure})"
        if model.disturbance is not None:
            return "stochastic disturbance: the star back-end is deterministic (use fsr or montecarlo)"
        for mode in prop.modes:
            if _unsafe_pieces(prop).get(mode) is None:
                return (f"nonlinear unsafe set in mode '{mode}': star takes linear requirements and quadratics in "
                        f"two states (as polygons); this one is for taylor and montecarlo")
        return None

    def check(self, model, prop, options=None) -> Result:
        # star's products are many and small (50 x 50 at most on the suite): BLAS threads only
        # contend for the cores (BLDF01-BDU01: 0.18 s with them, 0.035 s with one)
        start = time.perf_counter()
        with single_threaded():
            try:
                return self._check_with_retry(model, prop, options)
            except MemoryError:         # past the memory guard (an allocation larger than its margin)
                pass
            except np.linalg.LinAlgError as failure:    # inf or NaN in a matrix: an overflowing flow
                return Result(NAME, model.name, prop.id, Status.UNKNOWN, time.perf_counter() - start,
                              details={"reason": f"{OVERFLOW} ({failure}); nothing concluded"})
        # out of the handler, the failed search's frames are freed: the next property has them
        return Result(NAME, model.name, prop.id, Status.UNKNOWN, time.perf_counter() - start,
                      details={"reason": "out of memory: an allocation failed (nothing concluded; a coarser "
                                         "step, fewer coefficients or sooner aggregation)"})

    def check_many(self, model, props, options=None) -> list[Result]:
        """Several safety properties of one model, explored together first: one exploration
        against the union of their unsafe sets (:func:`_together`). Every run avoiding the
        union avoids each set, so a SAFE of the union is a SAFE of each, with the shared time
        split between them. Anything else (a violation of one of them, UNKNOWN) says nothing
        about the others: each property is then checked on its own, as :meth:`check` does,
        and the time of the joint attempt is added to theirs. The joint attempt has
        ``JOINT_SHARE`` of the time budget ``max_seconds``. With ``keep_sets`` (pictures) each
        property keeps its own exploration."""
        opt = options if isinstance(options, StarOptions) else StarOptions.from_dict(options)
        if len(props) < 2 or opt.keep_sets:
            return [self.check(model, p, options) for p in props]
        start = time.perf_counter()
        joint = self.check(model, _together(props), _with_budget(options, opt, JOINT_SHARE))
        shared = time.perf_counter() - start
        if joint.status is Status.SAFE:
            names = ", ".join(p.id for p in props)
            results = []
            for p in props:
                details = {**joint.details, "together": f"proved in one exploration of the union of the "
                                                        f"unsafe sets of {names} ({shared:.3g} s shared)"}
                results.append(Result(NAME, model.name, p.id, Status.SAFE, shared / len(props),
                                      details=details))
            return results
        results = [self.check(model, p, options) for p in props]
        for r in results:
            r.seconds += shared / len(props)
            r.details["together"] = (f"the joint exploration of all {len(props)} properties was "
                                     f"{joint.status.value} after {shared:.3g} s; checked one by one")
        return results

    def _check_with_retry(self, model, prop, options) -> Result:
        start = time.perf_counter()
        reason = self.supports(model, prop)
        if reason is not None:
            return Result(NAME, model.name, prop.id, Status.UNSUPPORTED, details={"reason": reason})
        opt = StarOptions.from_dict(options)
        if opt.replay_dt is not None:           # bad input now, not a replay that fails later
            check_size(model, opt.replay_dt, option="replay_dt")
        shared = first_share(model, options, opt)
        first = self._check_aggregating(model, prop, options, shared, start)
        spent = time.perf_counter() - start
        share = min(max(FINER_FACTOR * spent, FINER_SECONDS), FINER_MAX_SECONDS)
        left = math.inf if opt.max_seconds is None else opt.max_seconds - spent
        budget = min(share, left)
        deadline, finer, result, tried = time.perf_counter() + budget, opt, first, []
        latest = first                                  # the last pass run
        spent_share = shared is not opt and OUT_OF_TIME in first.details.get("reason", "")
        correlated = inputs_retry(model, options, first, opt, left if spent_share else budget, spent_share)
        if correlated is not None:
            latest = self._check_aggregating(model, prop, options, correlated, start)
            tried.append(f"{first.details['step']:.3g} with the input effect as generators")
            if latest.status is not Status.UNKNOWN:
                latest.details["semantics"] += (f"; with the input effect carried as generators (blocks of "
                                                f"{correlated.input_cells} cells): its box left it undecided "
                                                f"({first.details.get('reason', '')})")
                return latest
        # the plain exploration only: the switching inclusion and the linearisation explore in
        # blocks over cover boxes and fall back to the switching hull; their finer passes are not
        # yet validated against references (tests/test_star_rounding.py runs them at fine steps)
        plain = _LinearModel.of(model).linear and not (opt.switching and SwitchingModel.of(model).groups)
        for _ in range(FINER_PASSES if plain else 0):
            finer = finer_retry(result, finer, model.horizon, deadline - time.perf_counter())
            if finer is None:
                break
            result = latest = self._check_aggregating(model, prop, options, finer, start)
            tried.append(f"{finer.step:.3g}")
            if result.status is not Status.UNKNOWN:
                result.details["semantics"] += (f"; at step {finer.step:.3g}: the default step "
                                                f"{first.details['step']:.3g} left it undecided "
                                                f"({first.details.get('reason', '')})")
                return result
        if not tried:
            if OUT_OF_TIME in first.details.get("reason", ""):
                first.details["reason"] += " (option max_seconds)"
            return first
        first.seconds = latest.seconds
        reason = latest.details.get("reason", "")
        if spent_share and OUT_OF_TIME in reason:        # the two passes shared the user's budget
            first.details["reason"] = (f"{budget_text(opt.max_seconds)} (option max_seconds): a quarter of it "
                                       f"with the input effect as a box, the rest with it as generators "
                                       f"(step {first.details['step']:.3g})")
            return first
        if OUT_OF_TIME in reason:                       # whose budget (:meth:`_Explorer.out_of_time`)
            reason += (" (option max_seconds)" if left <= share else
                       f" (the finer passes share {FINER_FACTOR:g} times the first pass's time, "
                       f"{FINER_SECONDS:g} to {FINER_MAX_SECONDS:g} s, within -o max_seconds)")
        first.details["reason"] += f"; checked again at step {' and '.join(tried)}, still undecided: {reason}"
        return first

    def _check_aggregating(self, model, prop, options, opt, start) -> Result:
        """One check with ``opt``: first with the default aggregation, then, past a number of
        stars (on a clocked model also past half the time budget ``opt.max_seconds``, or
        undecided for want of precision), aggregating from the first jump
        (:func:`.options.aggregating_retry`) with what the first pass left of the budget (after
        an undecided pass, at most as much as a finer pass would have)."""
        began = time.perf_counter()
        retry = None if isinstance(options, StarOptions) else aggregating_retry(model, options, opt)
        if retry is None:
            return self._check(model, prop, opt, start)
        retry, stars, clocked = retry
        budget = min(opt.max_stars, stars)
        first_budget = opt.max_seconds
        if clocked and first_budget is not None:
            first_budget *= DEFAULT_PASS_SHARE
        first = self._check(model, prop, replace(opt, max_stars=budget, max_seconds=first_budget), start)
        many = first.details.get("stars", 0) > budget
        slow = clocked and OUT_OF_TIME in first.details.get("reason", "")
        vague = clocked and bool(first.details.get("finer_step_may_decide"))
        if first.status is not Status.UNKNOWN or not (many or slow or vague):
            return first
        if opt.max_seconds is not None:         # the second pass has what the first left of the budget
            spent = time.perf_counter() - began
            left = opt.max_seconds - spent
            if vague and not (many or slow):    # a try, not the rest of the budget (as a finer pass)
                left = min(left, max(FINER_FACTOR * spent, FINER_SECONDS))
            if left <= 0:
                return _whole_budget(first, first_budget, opt.max_seconds)
            retry = replace(retry, max_seconds=left)
        result = _whole_budget(self._check(model, prop, retry, start), retry.max_seconds, opt.max_seconds)
        why = (f"took more than {budget} stars" if many else "ran out of half the time budget" if slow
               else "left cells undecided")
        result.details["semantics"] += (f"; the default aggregation {why}, so the check started over "
                                        f"aggregating from the first jump")
        return result

    def _check(self, model, prop, opt, start) -> Result:
        if not _LinearModel.of(model).linear:
            return check_linearised(model, prop, opt, lambda data, blocks: self._explore(
                model, prop, opt, start, data, blocks))
        if opt.switching and SwitchingModel.of(model).groups:
            result = check_switching(model, prop, opt, lambda data, blocks: self._explore(
                model, prop, opt, start, data, blocks))
            if result.status is Status.UNKNOWN and opt.switching_hull and not opt.discrete_time:
                result = _with_hull(model, prop, opt, result, start)
            if result.status is Status.UNKNOWN:
                return self._mode_by_mode(model, prop, opt, result, start)
            return result
        return self._explore(model, prop, opt, start)

    def _mode_by_mode(self, model, prop, opt, undecided: Result, start) -> Result:
        """After the switching inclusion (and its hull) left ``undecided``: the group's modes
        explored one by one, as ``-o switching=false`` does, with what is left of the time
        budget. The inclusion's witnesses replay only runs that never switch; mode by mode, a
        witness names its switches (a group whose other member violates at once: UNSAFE,
        replayed). A verdict of this pass is returned; otherwise ``undecided``. The pass is a
        try: it has as long as the inclusion took, at least :data:`MODE_BY_MODE_SECONDS`, within
        ``max_seconds`` (mode by mode, a group over a long horizon is a switch per cell)."""
        spent = time.perf_counter() - start
        limit = spent + max(MODE_BY_MODE_SECONDS, spent)
        if opt.max_seconds is not None:
            if spent >= opt.max_seconds:
                return undecided
            limit = min(limit, opt.max_seconds)
        result = self._explore(model, prop, replace(opt, switching=False, max_seconds=limit), start)
        if result.status is Status.UNKNOWN:
            undecided.seconds = result.seconds
            undecided.details["mode_by_mode"] = result.details.get("reason", "")
            return undecided
        result.details["semantics"] += (f"; explored mode by mode: the switching inclusion was undecided "
                                        f"({undecided.details.get('reason', '')})")
        return result

    def _explore(self, model, prop, opt, start, data=None, linearise=None) -> Result:
        """One exploration and its Result (``data``, ``linearise``: see :class:`_Explorer`)."""
        explorer = _Explorer(model, prop, opt, data=data, linearise=linearise)
        status, counterexample = Status.SAFE, None
        details = {}
        try:
            call_deep(explorer.run, explorer.cancel)     # paths of thousands of jumps (reach.deep)
            if explorer.unresolved:
                raise _Stop(Status.UNKNOWN, f"{len(explorer.unresolved)} cell(s) still meet an unsafe "
                                            f"piece after refinement; no witness replayed (a smaller "
                                            f"step, -o step={explorer.h / 10:.3g}, may decide it)",
                            witness=explorer.unresolved[0], imprecise=True)
            if explorer.too_deep:                   # no violation within the bound, none proved past it
                raise _Stop(Status.UNKNOWN, explorer.too_deep)
            if opt.discrete_time:
                raise _Stop(Status.UNKNOWN, "no violation at the grid points (discrete time: "
                                            "behaviour between grid points is not checked)")
        except _Stop as stop:
            status, counterexample = _stopped(explorer, stop, details)
        except lp.LPError as failure:
            status = Status.UNKNOWN
            details["reason"] = explorer.out_of_time() or f"LP solver failure, nothing concluded: {failure}"
        except ArithmeticError as failure:         # overflow, or a cell far too long for the flow
            status = Status.UNKNOWN
            details["reason"] = f"nothing concluded: {failure}"
            if linearise is not None:               # the flow is the linearisation over a box of states
                details["reason"] += (" (of the linearisation over the box of states explored: a wide box of "
                                      "a strongly nonlinear flow makes that time scale short, whatever the step)")
        except RecursionError:
            status = Status.UNKNOWN
            details["reason"] = (f"a path of more than {explorer.stats.jumps} jumps is too deep to "
                                 f"follow (set max_jumps to bound it)")
        if status is Status.UNKNOWN and explorer.unresolved:
            try:
                explorer.replay_finer()                 # a witness may violate on a finer grid
            except _Stop as stop:
                details.clear()
                status, counterexample = _stopped(explorer, stop, details)
            except lp.LPError:
                pass
        if status is Status.UNKNOWN and explorer.uncut_urgent:
            details["reason"] = details.get("reason", "") + (
                f" (the urgent guards of several rows of {', '.join(explorer.uncut_urgent[:3])} did not end "
                f"the flow of their mode on a chain whose entry set reaches inside them: its runs are also "
                f"followed past them, which only adds behaviour; an invariant saying where the mode is "
                f"left is always cut)")
        details.update(_run_details(explorer))
        if explorer.stopped and status is Status.SAFE:
            spent = time.perf_counter() - start
            left = math.inf if opt.max_seconds is None else opt.max_seconds - spent
            details.update(sampled_stops(model, explorer.stopped, min(max(1.0, 0.25 * spent), left)))
        LOG.info("%s / %s: %s after %d stars, %d cells, %d LPs, %d aggregates", model.name, prop.id,
                 status.value, explorer.stats.chains,
                 explorer.stats.cells, explorer.stats.lps, explorer.stats.aggregated)
        return Result(NAME, model.name, prop.id, status, time.perf_counter() - start,
                      counterexample=counterexample, details=details, sets=explorer.sets)


def _stopped(explorer: _Explorer, stop: _Stop, details: dict):
    """``(status, counterexample)`` of a search ended by ``stop``, its reason and witness put in
    ``details``."""
    details["reason"] = stop.reason
    if stop.imprecise:
        details["finer_step_may_decide"] = True
    if stop.witness is not None:
        try:
            details["witness"] = witness_details(explorer, stop.witness)
        except (_Stop, lp.LPError):        # tracing it back needs LPs the budget lacks
            w = stop.witness
            details["witness"] = {"mode": w.mode, "piece": w.piece, "depth": w.depth}
    return stop.status, stop.counterexample


def _with_hull(model, prop, opt, result: Result, start: float) -> Result:
    """``result`` (UNKNOWN from the switching inclusion) decided by the closed group's hull
    (:mod:`.hull`) where it proves every piece excluded: SAFE, its argument as the semantics
    and its report under ``details.hull``; otherwise ``result`` with that report added."""
    try:
        report = check_hull(model, prop, opt)
    except (ArithmeticError, lp.LPError) as failure:
        report = {"proved": False, "reason": f"nothing concluded: {failure}"}
    if report is None:
        return result
    result.seconds = time.perf_counter() - start
    if not report["proved"]:
        result.details["hull"] = report
        return result
    details = {k: v for k, v in result.details.items() if k not in ("reason", "witness")}
    details["inclusion"] = result.details.get("reason", "")
    details["hull"] = report
    details["semantics"] = (f"continuous time, closed switching group {{{', '.join(report['group'])}}} "
                            f"bounded around its mean flow on {report['steps']} steps of "
                            f"{report['step']:.6g} (the inclusion explored first was undecided): "
                            f"{report['argument']}; matrix exponentials in floating point (rounding "
                            f"not enclosed)")
    return Result(NAME, model.name, prop.id, Status.SAFE, result.seconds, details=details)


def _together(props) -> BoundSafety:
    """One safety property whose unsafe set is the union of those of ``props`` (bound to the
    same model): per mode, every piece of every property."""
    modes = list(dict.fromkeys(m for p in props for m in p.modes))
    pieces = {m: [piece for p in props for piece in p.pieces.get(m, [])] for m in modes}
    return BoundSafety("+".join(p.id for p in props), modes, pieces, props[0].symbols, props[0].file,
                       "; ".join(p.description for p in props))


def _substeps(flow, h: float) -> str:
    """Sub-samples per cell of the curvature bound, as the soundness text states them."""
    try:
        return str(flow.curvature(h)[3] + 1)
    except ArithmeticError:
        return "none (the cell is too long for the flow)"


def _run_details(explorer: _Explorer) -> dict:
    s, opt = explorer.stats, explorer.opt
    substeps = {m: _substeps(f, explorer.h) for m, f in explorer.flows.items()}
    soundness = _DISCRETE if opt.discrete_time else _SOUNDNESS.format(
        q=", ".join(f"{m}: {q}" for m, q in substeps.items()), lp_tol=DEPTH_LP_TOLERANCE,
        rel=opt.touch_tolerance, tol=s.tolerance)
    if explorer.data.varying:
        soundness += ("; time-varying inputs " + ", ".join(u.name for u in explorer.data.varying)
                      + ": their effect up to the end of a cell bounded by the box R(t) = int_0^t "
                        "|e^{A s} B| u_r ds (t since the chain or block started; chords of e^{A s} B plus "
                        "a curvature bound), for any measurable signal in the input box"
                      + ("" if not opt.input_cells else
                         f"; completed blocks of {opt.input_cells} cells carried as "
                         "generators (mean and first moment of the input, |x| + |y| <= 1) plus "
                         "their residual box, moved with the flow")
                      + ("" if opt.input_cells or not (opt.rebase_generators and s.rebased) else
                         "; in chains explored a few cells at a time, each completed cell carried as "
                         "generators (mean and first moment of the input, |x| + |y| <= 1) plus its "
                         "residual box, moved with the flow"))
    if s.instants:
        soundness += (f"; {s.instants} jumps at a single instant taken from the image of their cell's start "
                      f"star at that instant, bloated by the instant's width times a bound on |x'|")
    if explorer.barrier_guards:
        soundness += (f"; urgent guards of several rows cut by one of their rows ("
                      f"{', '.join(sorted(explorer.barrier_guards)[:3])}): a row h x >= c every state of the "
                      f"entry star meets and on whose face the flow enters strictly wherever another row of the "
                      f"guard is not met (an LP per other row over the face, the invariant and the inputs' "
                      f"ranges: the rate of h x is at least {BARRIER_SLOPE:g} |h A| times that row's excess), "
                      f"so a run reaches the guard, and leaves, before it could cross the row")
    if s.returns:
        soundness += (f"; {s.returns} jumps back to the mode a chain's runs had just left not taken from "
                      f"its first cell: the guard's row rises strictly there, so only runs that had not "
                      f"moved could take them, at the state and instant they left (runs the earlier mode "
                      f"follows on)")
    if s.rebased:
        soundness += (f"; {s.rebased} chain blocks restarted the input effect from the previous block's "
                      f"end star (grid star plus R, cut by the invariant), which holds every run still "
                      f"in the mode")
    if s.memory_blocks:
        soundness += (f"; chains too long to hold at once explored in blocks ({s.memory_blocks} block ends), "
                      f"each from the grid star ending the block before, cut by the invariant")
    if s.aggregated:
        soundness += (f"; {s.aggregated} aggregates: interval hulls of the successor stars they "
                      f"replace ({s.deaggregated} refined back into their members)")
    if explorer.data.added_clock:
        soundness += "; the model has no global clock: one was added (rate 1, 0 initially, never reset)"
    if any("as polygons of" in p.label for pieces in explorer.pieces.values() for p in pieces or ()):
        soundness += (f"; each quadratic requirement's unsafe set replaced by polygons of {SIDES} sides that "
                      f"hold it (within 3e-4 of its radius), witnesses replayed on the exact requirement")
    if explorer.covered is not None and explorer.covered.pruned and explorer.covered.shift:
        soundness += (f"; {explorer.covered.pruned} aggregates not explored: their states lie in an earlier "
                      "aggregate of the same mode entered no later, and the automaton does not depend "
                      "on time (the added clock), so their runs are time-shifted runs of that one's")
    elif explorer.covered is not None and explorer.covered.pruned:
        soundness += (f"; {explorer.covered.pruned} aggregates not explored: their states, the clock "
                      "included, lie in an earlier aggregate of the same mode, so their runs are among "
                      "that one's")
    if explorer.data.timeless:
        soundness += (f"; modes where no time passes ({', '.join(sorted(explorer.data.timeless))}): "
                      f"each entry star is checked once and jumps out at once (every state has rate 0 "
                      f"there; waiting only delays the same state on the added clock, which nothing reads)")
    return {"method": "generalized star sets", "semantics": soundness, "step": explorer.h,
            "touch_tolerance": {"relative": opt.touch_tolerance, "largest": s.tolerance},
            "stars": s.chains, "cells": s.cells, "refined_cells": s.refined,
            "deepest_refinement": s.deepest, "lps": s.lps, "replays": explorer.replayed,
            "jumps": s.jumps, "latest_chain_start": s.reached, "aggregates": s.aggregated,
            "aggregated_stars": s.members, "refined_aggregates": s.deaggregated,
            "nested_refinements": s.nested,
            "covered_aggregates": 0 if explorer.covered is None else explorer.covered.pruned,
            "rebased_blocks": s.rebased, "instant_jumps": s.instants, "zero_dwell_returns": s.returns}


BACKEND = StarBackend()


def _whole_budget(result: Result, part: float | None, whole: float | None) -> Result:
    """``result`` of a pass that had ``part`` of the time budget ``whole``, its reason naming the
    whole budget (the user's option, not the share of it)."""
    if part is not None and whole is not None and "reason" in result.details:
        result.details["reason"] = result.details["reason"].replace(budget_text(part), budget_text(whole))
    return result


def safe_abort_time(model, props, low, high, options=None) -> float:
    """The latest ``T`` such that, from every initial state in the box ``[low, high]``, every
    run that aborts in ``[lo, T]`` (``lo, hi`` the model's abort window) is proven to satisfy
    every property of ``props`` (bound safety properties); ``hi`` if all aborts are safe; NaN
    if no abort is proven safe (not even one at ``lo``).

    One exploration per property with the whole window: the first segment that cannot be
    cleared after refinement bounds ``T`` by its earliest abort time (or, before any abort,
    by its earliest clock); later aborts are skipped. No replays: a value below ``hi`` means
    "not proven beyond", not "unsafe".
    """
    windows = [tr.window for tr in model.transitions if tr.window is not None]
    if not windows:
        raise ValueError(f"model '{model.name}' has no abort window to sweep")
    if not _LinearModel.of(model).linear:
        raise ValueError(f"model '{model.name}': the safe-abort sweep needs affine flows")
    opt = StarOptions.from_dict({"max_seconds": None, **dict(options or {}), "replay": False})
    initial = Star.from_box(_LinearModel.of(model).initial_box(low, high))
    earliest, latest = min(w[1] for w in windows), max(w[2] for w in windows)
    whole = latest
    for prop in props:
        reason = BACKEND.supports(model, prop)
        if reason is not None:
            raise ValueError(f"{prop.id}: {reason}")
        explorer = _Explorer(model, prop, opt, initial=initial, cutoff=latest)
        explorer.run()
        latest = min(latest, explorer.cutoff)
    if latest < whole and latest <= earliest:   # cut at the window's start: no abort is proven safe
        return float("nan")
    return float(latest)


def arc_cells(model, radius: float, count: int, start_deg: float = 180.0, end_deg: float = 270.0,
              x: str = "x", y: str = "y"):
    """Initial cells along an arc of ``radius`` (angles in degrees, counter-clockwise):
    ``count`` boxes, each the bounding box of its stretch of arc in ``(x, y)``, the other
    states as in the model's initial box. Returns ``[(low, high, angle_mid)]``."""
    ix, iy = model.index(x), model.index(y)
    edges = np.radians(np.linspace(start_deg, end_deg, count + 1))
    cells = []
    for a, b in zip(edges[:-1], edges[1:]):
        angles = np.concatenate([[a, b], [k * np.pi / 2 for k in range(-4, 9) if a < k * np.pi / 2 < b]])
        low, high = model.initial.low.copy(), model.initial.high.copy()
        low[ix], high[ix] = radius * np.cos(angles).min(), radius * np.cos(angles).max()
        low[iy], high[iy] = radius * np.sin(angles).min(), radius * np.sin(angles).max()
        cells.append((low, high, float(np.degrees((a + b) / 2))))
    return cells


def _sweep_unit(model_file: str, property_files: tuple[str, ...], property_ids, low, high, options):
    """One cell of a sweep, loading its inputs itself (picklable for any executor)."""
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties
    model = load_model(model_file)
    props = [bind(p, model) for f in property_files for p in load_properties(f)
             if property_ids is None or p.id in property_ids]
    props = [p for p in props if BACKEND.supports(model, p) is None]
    return safe_abort_time(model, props, low, high, options)


def safe_abort_map(model_file: str, property_files, cells, property_ids=None, options=None,
                   executor=None) -> list[float]:
    """:func:`safe_abort_time` for every cell ``(low, high, ...)`` of ``cells`` (e.g. from
    :func:`arc_cells`), through ``executor`` (``map_unordered(fn, arg_list)`` yielding
    ``(index, ("ok", value))``, as :mod:`reach.executors`; in-process if None).
    Properties the back-end does not support are left out. Returns one time per cell."""
    args = [(str(model_file), tuple(map(str, property_files)), property_ids, cell[0], cell[1], options)
            for cell in cells]
    if executor is None:
        return [_sweep_unit(*a) for a in args]
    out = [float("nan")] * len(args)
    for index, (status, value) in executor.map_unordered(_sweep_unit, args):
        if status == "ok":
            out[index] = value
    return out
