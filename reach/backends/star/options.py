"""Settings of the star back-end and the constants of its method."""

from __future__ import annotations

from dataclasses import dataclass, replace

from reach.backends.options import parse_options, ranged


NAME = "star"


#: a cell is bisected before any check while its interpolation error along a guard row of its
#: mode exceeds this fraction of the row's magnitude over the segment (fast transients, e.g.
#: right after a controller switch)
ERROR_RATIO = 0.25


#: primal feasibility tolerance of the depth LPs (HiGHS's default is 1e-7): a depth is
#: then exact to well below the touch tolerance of :class:`StarOptions`
DEPTH_LP_TOLERANCE = 1e-10

#: HiGHS's own primal feasibility tolerance (used where it fails at the tighter ones)
HIGHS_DEFAULT_TOLERANCE = 1e-7


#: in a model that may have a zero-dwell cycle, this many jumps on a path while its
#: earliest clock advances by less than one time step end the check (UNKNOWN)
STALL_JUMPS = 10

#: in any other model, this many: the switching is then faster than the step resolves (a
#: hysteresis band crossed within one cell, back and forth), and a finer step decides sooner
#: than the coarse one (:func:`finer_retry`)
CHATTER_JUMPS = 100
MAX_CELLS = 1_000_000             # grid cells over the horizon (horizon / step) a check may start with


#: a jump whose guard leaves its clock within this relative width, or a local timer within
#: :data:`INSTANT_STEP_FRACTION` of the step (an aggregate's timer, rounded outward), is taken
#: at one instant (:meth:`.explorer._Explorer._at_instant`; the spread ``w`` costs a box of
#: ``w |x'|``, far below the segment's sweep of a step). The global clock keeps the relative
#: width alone: a guard on the states that a set crosses in a sliver of time is no schedule,
#: and its successors are better joined by the hull the fixpoint check compares
INSTANT_WIDTH = 1e-9
INSTANT_STEP_FRACTION = 1e-6

#: the grid stacks of one chain may take at most this many bytes (memory guard)
MAX_CHAIN_BYTES = 1 << 30

#: the whole check may hold at most this fraction of the machine's memory (resident set, read
#: at chains and cells at most every MEMORY_PERIOD seconds; beyond it the answer is UNKNOWN,
#: never an out-of-memory kill)
MEMORY_FRACTION = 0.4
MEMORY_PERIOD = 0.05


#: seconds between two progress lines (logger ``reach.star``, shown under ``-v``)
PROGRESS_SECONDS = 1.0


#: a witness is replayed at once when the spread refinement could still remove is below
#: this fraction of the unsafe piece's inradius: the over-approximation is already tight
TIGHT_RATIO = 0.1


@dataclass
class StarOptions:
    """Settings of the star back-end (the problem -- model, property -- is separate).

    step: base time step in model time units (default: horizon / 60; cells that need it are
        bisected).
    discrete_time: check and switch at grid points only (Hylaa-like; not a proof).
    max_refinements: how many times a failing cell may be bisected.
    replay: replay LP witnesses with the Monte Carlo simulator.
    max_replays: at most this many replays per check.
    max_unresolved: stop (UNKNOWN) after this many cells that refinement cannot clear.
    max_lps: LP budget; when exhausted the answer is UNKNOWN.
    max_jumps: bound on discrete jumps along a path; UNKNOWN beyond. None (default): no
        bound, but at most ``STALL_JUMPS`` jumps within one time step when the model may
        have a zero-dwell cycle (:mod:`reach.model.lint`), ``CHATTER_JUMPS`` otherwise.
    aggregate_after: successors of the jumps after the first ``aggregate_after`` ones on a
        path, out of a mode whose flow is not constant or moves with a time-varying input (on a
        model without a clock out of every mode, so the fixpoint check closes cycles of
        constant rates), are aggregated: the stars one chain
        sends through one transition become one star, their interval hull (see
        :meth:`_Explorer._aggregate`); refined back into the members when a check under it
        fails. None: never aggregate.
    aggregate_fanout: successors are aggregated before ``aggregate_after`` jumps too, out of a
        chain from which a transition on a cycle of modes may fire in more than this many cells
        (a may-transition over a wide guard, taken again and again): explored one by one, each
        would start a path of its own, a fan-out that multiplies at every pass round the cycle.
        A transition that leaves the cycle for good (an abort) keeps its successors exact: its
        fan-out does not multiply. A constant flow without time-varying inputs needs no such
        rule: its consecutive cells are one exact cell with one successor per transition.
        None: no such rule.
    aggregate_drift_coefficients: out of a mode whose flow is constant, successors are
        aggregated likewise once the chain's star holds more than this many coefficients (on a
        model with a clock too). Each visit adds one coefficient to such a star, so a path of
        hundreds of jumps (a counter, a sawtooth) would hold stars of hundreds of coefficients
        at every level, memory and time quadratic in its length; below the limit the stars stay
        exact (a timed automaton's clock differences, which an interval hull would lose). None:
        only where ``aggregate_after`` says.
    max_seconds: UNKNOWN once the check of a property (finer passes included) has run this
        long (default 120 s: a check that has not ended by then is better told than waited
        for; None: no time budget).
    finer_retry: where a check ends UNKNOWN for want of precision (cells that refinement
        cannot clear, jumps piling up within one step, the LP or star budget), check again
        with the step divided by 10, up to ``FINER_PASSES`` times within a shared time budget
        (:func:`finer_retry`).
    max_stars: UNKNOWN once this many stars (chains) have been explored.
    max_coefficients: UNKNOWN when a segment needs more coefficients than this (each
        segment of a non-constant flow doubles them: LPs and grid stacks would grow without
        bound; aggregation keeps the count down).
    max_deaggregations: at most this many aggregates are refined back into their members.
    max_nested_refinements: an aggregate is refined only where fewer than this many
        refinements lie on its members' histories (an aggregate formed from the successors
        of a refined aggregate's member is one level deeper). Where the aggregates of a
        zero-dwell cycle (guards that overlap) each lose the same precision, every level
        refines again with members of twice the coefficients; past this depth the failure
        counts as unresolved (UNKNOWN, sooner) instead.
    touch_tolerance: relative LP tolerance. With piece rows of unit norm, the depth LP's
        answer counts as exact up to ``tol = touch_tolerance * max(1, |g_r|, |h_r . c|)``
        (largest over the piece's rows ``h_r x <= g_r``, ``c`` the segment's centre; at least
        10 times the feasibility tolerance the LP was solved to, see ``_depth``): a
        piece made only of strict inequalities is entered when the depth exceeds ``tol``;
        a piece with a non-strict row is met when the depth is at least ``-tol``.
    replay_dt: simulator step for replays (None: the simulator's default).
    keep_sets: keep the flowpipe segments of every explored chain in ``Result.sets`` (for
        pictures; memory grows with the exploration).
    linearise_cells: nonlinear flows (:mod:`.linearise`): cells per block of a chain, each
        block linearised over its own box (None: one block to the horizon; shorter blocks give
        smaller remainders on strongly nonlinear flows, at a few coefficients per block).
    linearise_inflations: at most this many times a block's box is grown before UNKNOWN.
    linearise_margin: a grown box adds this fraction of the hull's half-width.
    rebase_cells: in a mode with time-varying inputs whose invariant reads the states they
        move, the chain is explored this many cells at a time, each block starting from the
        interval hull of the last one's end, cut by the invariant, with the input effect
        restarted (:meth:`.explorer._Explorer._rebase_cells`); 0: one chain to the horizon.
    switching: modes that may switch to one another at any instant (unguarded, reset-free
        may-transitions both ways, one invariant) are explored as one differential inclusion
        per group (:mod:`.switching`); false: mode by mode, every cell a possible switch.
    switching_hull: when that inclusion leaves a check UNKNOWN and the initial mode's group is
        closed (no transition leaves it or resets a state), bound the group around its mean
        flow with the members' difference as a fed-back input (:mod:`.hull`); it answers SAFE
        or leaves the UNKNOWN.
    hull_steps: the most grid steps over the horizon that bound takes: it starts at an eighth
        of this and doubles while a piece is not excluded (cost quadratic in the steps).
    input_cells: a chain with time-varying inputs is cut into blocks of this many cells, each
        completed block's effect carried by generators (two coefficients per input) plus a
        small box (:class:`.flowpipe.ChainInputs`); 0: the effect since the chain's start as
        one box (exact per state, not jointly).
    rebase_generators: where ``input_cells`` is 0, a chain explored ``rebase_cells`` cells at a
        time carries each completed cell's input effect as generators, as ``input_cells = 1``
        would (at most ``2 rebase_cells`` coefficients per input and block, as many as the
        block's end box adds); other chains keep the box. Off by default; the aggregating second
        pass of a clockless model turns it on (:func:`aggregating_retry`).
    """

    step: float | None = None
    discrete_time: bool = False
    max_refinements: int = 8
    replay: bool = True
    max_replays: int = 20
    max_unresolved: int = 8
    max_lps: int = 50_000
    max_jumps: int | None = None
    aggregate_after: int | None = 2
    aggregate_fanout: int | None = ranged(16, 0)
    aggregate_drift_coefficients: int | None = ranged(256, 0)
    max_stars: int = 20_000
    max_seconds: float | None = ranged(120.0, 0.0, open_low=True)
    finer_retry: bool = True
    max_coefficients: int = 2_000
    max_deaggregations: int = 50
    max_nested_refinements: int = ranged(3, 0)
    touch_tolerance: float = ranged(1e-9, 0.0, 1e-3, open_low=True)
    replay_dt: float | None = ranged(None, 0.0, open_low=True)
    keep_sets: bool = False
    linearise_cells: int | None = ranged(None, 1)
    linearise_inflations: int = ranged(8, 1)
    linearise_margin: float = 0.1
    rebase_cells: int = ranged(2, 0)
    switching: bool = True
    switching_hull: bool = True
    hull_steps: int = ranged(2000, 1, 20_000)
    input_cells: int = ranged(0, 0)
    rebase_generators: bool = False

    @classmethod
    def from_dict(cls, options: dict | None) -> "StarOptions":
        if isinstance(options, StarOptions):
            return options
        return cls(**parse_options(cls, options, "star"))


def cfg_hints(notes: dict, options: dict | None) -> dict:
    """Star options from a SpaceEx cfg (``notes`` of the imported model) where the user set
    none: ``iter-max`` (when not -1: SpaceEx's "no bound") becomes ``max_jumps``, so a path
    with more jumps ends the check in UNKNOWN, never in SAFE. ``sampling-time`` is SpaceEx's step
    for its own discrete-time scheme and sets nothing here: star covers the time between its grid
    points, splits the cells that need it and retries finer steps when undecided, and on 14 cfgs
    of 13 third-party SpaceEx models, a tank with varying inputs and the ISS that step (1e-5 to
    0.2) was never needed and up to 70 times slower (a heater: 2.05 s against 0.03 s; the tank:
    UNKNOWN after 30 s against SAFE in 8 s; the ISS: out of its 120 s against 13 s)."""
    options = dict(options or {})
    iterations = notes.get("iter-max")
    if "max_jumps" not in options and iterations is not None and iterations >= 0:
        options["max_jumps"] = int(iterations)
    return options


#: stars the default aggregation may take before the check starts over aggregating from the
#: first jump (:func:`aggregating_retry`): on a model that does not depend on time, and on one
#: that does (a declared clock read by nothing but the horizon, a window)
CLOCKLESS_FIRST_STARS, CLOCKED_FIRST_STARS = 100, 500
#: the share of the time budget the default aggregation may take on a model that depends on
#: time before that second pass (a clockless one has the whole: the platoon PLAN01's default
#: pass needs it, and its stars end it soon enough)
DEFAULT_PASS_SHARE = 1 / 2


def aggregating_retry(model, options: dict | None, opt: StarOptions) -> tuple[StarOptions, int, bool] | None:
    """The options of a second pass where the user set no ``aggregate_after``: successors
    aggregated from the first jump, taken when the default pass runs past the returned number
    of stars or, on a model that depends on time (the returned flag), past
    :data:`DEFAULT_PASS_SHARE` of the time budget or undecided for want of precision; None
    when the user chose the aggregation. Aggregation is sound whatever the model
    (a hull holds its members; a failed check refines it into them); it costs precision, which
    is why the default pass comes first.

    On a model that does not depend on time (:mod:`.fixpoint`), runs that cycle through the same
    modes then collapse into aggregates that the fixpoint check closes, instead of one family of
    stars per cell of the first chains: the second pass comes after
    :data:`CLOCKLESS_FIRST_STARS`. On one that does (a declared global clock, even one read by
    nothing), successors per cell still multiply at each urgent jump of a cycle (a deadband
    limit cycle over a long horizon: thousands of stars), while the aggregates they would have
    formed stay a handful per jump: the second pass comes after :data:`CLOCKED_FIRST_STARS`,
    beyond the stars the suite's time-dependent models take (at most a few hundred), and also
    after a default pass that ended undecided for want of precision (a witness through an
    aggregate of a whole jump's successors may replay where the per-cell successors left only
    cells no replay confirmed; a clockless model goes on to its input-generators pass instead,
    which decides the platoon PLAN01 in seconds).
    The default comes first since an aggregate refined into its members leaves the cells
    before it unrefined.

    On a model that does not depend on time, the second pass carries time-varying inputs as
    generators in the chains explored a few cells at a time (``rebase_generators``) where the
    user set neither that nor ``input_cells`` (where time matters, the box does, at a third of
    the cost: a clocked deadband's aggregates close without the fixpoint check): the first
    chain's successors are aggregated at once, and a box of the input effect, exact per state
    but not jointly, would hand them corners no signal reaches together (a deadband whose
    disturbance both speeds the attitude rate up and moves the angle) that no refinement behind the aggregate can remove; a witness through the aggregate
    then points to an initial state and signal that do not violate. Such chains add a few
    coefficients per block either way; a chain to the horizon would gain two per cell, so it
    keeps the box."""
    from reach.backends.star.fixpoint import time_invariant

    options = options or {}
    if "aggregate_after" in options:
        return None
    invariant = time_invariant(model)
    generators = invariant and not ({"input_cells", "rebase_generators"} & set(options))
    stars = CLOCKLESS_FIRST_STARS if invariant else CLOCKED_FIRST_STARS
    return replace(opt, aggregate_after=0, rebase_generators=generators or opt.rebase_generators), stars, not invariant


#: cells per input block of the pass that keeps the input effect's correlation (:func:`inputs_retry`)
INPUT_RETRY_CELLS = 4

#: the share of ``max_seconds`` the default pass may take where :func:`inputs_retry` may follow
#: it: the rest is left for that pass (a box that misses the correlation can keep refining cells
#: the generators decide at once)
INPUT_FIRST_SHARE = 1 / 4


def first_share(model, options, opt: StarOptions) -> StarOptions:
    """The options of the default pass: with time-varying inputs, no ``input_cells`` chosen and a
    time budget, at most :data:`INPUT_FIRST_SHARE` of it (:func:`inputs_retry` may follow)."""
    chosen = set(options) if isinstance(options, dict) else set()
    if (not model.varying_inputs or isinstance(options, StarOptions) or opt.input_cells
            or {"input_cells", "rebase_generators"} & chosen or opt.max_seconds is None):
        return opt
    return replace(opt, max_seconds=opt.max_seconds * INPUT_FIRST_SHARE)


def inputs_retry(model, options: dict | StarOptions | None, result, opt: StarOptions,
                 budget: float, spent_share: bool = False) -> StarOptions | None:
    """The options of a pass that carries the effect of time-varying inputs as generators
    (``input_cells = INPUT_RETRY_CELLS``), after a pass with the default box (``input_cells =
    0``: the effect since the chain's start, exact per state but not jointly) that ended
    UNKNOWN for want of precision or with its share of the time spent (``spent_share``,
    :func:`first_share`), with ``budget`` seconds left; None where none applies (no
    time-varying input, the user chose ``input_cells`` or ``rebase_generators``, another
    outcome, no time left). The box's corners combine extremes no one signal reaches together
    (a double integrator's ``x - v``: the largest x and the smallest v need opposite inputs),
    which no refinement of the cells removes; the generators keep the correlation at a few
    coefficients per block, which on long horizons costs more than the box (the platoon
    PLAN01 takes minutes), hence a second pass, not the default."""
    from reach.result import Status

    chosen = set(options) if isinstance(options, dict) else set()
    if (not model.varying_inputs or isinstance(options, StarOptions) or opt.input_cells
            or {"input_cells", "rebase_generators"} & chosen or result.status is not Status.UNKNOWN
            or not (result.details.get("finer_step_may_decide") or spent_share) or budget <= 0):
        return None
    return replace(opt, input_cells=INPUT_RETRY_CELLS, max_seconds=budget)


#: finer passes at most, each at a tenth of the step before; their time budget together is
#: FINER_FACTOR times the first pass's, at least FINER_SECONDS and at most FINER_MAX_SECONDS
FINER_PASSES, FINER_FACTOR, FINER_SECONDS, FINER_MAX_SECONDS = 2, 4.0, 30.0, 120.0


def finer_retry(result, opt: StarOptions, horizon: float, budget: float) -> StarOptions | None:
    """The options of a next pass with the step divided by 10, after a pass (its ``result``)
    that ended UNKNOWN for want of precision (``details.finer_step_may_decide``: cells that
    refinement cannot clear, jumps piling up within one step, the LP or star budget spent),
    with ``budget`` seconds left; None
    where none applies (option ``finer_retry`` off, another outcome, too many cells, no time
    left). The default step (horizon / 60) knows nothing of the
    model's own time scales: a sawtooth of period 1 over a horizon of 400, a ball bouncing
    ever faster. A finer step costs time and never soundness; the passes share a time budget
    (see :meth:`reach.backends.star.StarBackend._check_with_retry`), so a model that stays
    undecided still ends in bounded time."""
    from reach.result import Status

    if not opt.finer_retry or result.status is not Status.UNKNOWN or "step" not in result.details \
            or not result.details.get("finer_step_may_decide") or budget <= 0:
        return None
    step = result.details["step"] / 10
    if horizon / step > MAX_CELLS:
        return None
    return replace(opt, step=step, max_seconds=budget)
