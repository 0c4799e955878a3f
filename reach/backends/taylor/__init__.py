"""taylor — event-map bounds by differential algebra and automatic domain splitting
(Evans & Armellin, "Sample-free safety assessment of neural network controllers via Taylor
methods").

For an event property (extremum of a quantity ``q`` over the run in some modes) the initial box is
covered by ADS subdomains (:mod:`.ads`). On each, the run is followed from the initial mode
through its urgent switches (:mod:`.problem`) and the candidates for the extremum — ``q`` on
entering a mode, at every interior local extremum (the event ``dq/dt = 0``, :mod:`.event`,
eqs. 5-14), and on leaving (guard crossing or horizon) — are expanded as Taylor maps of the scaled
initial deviations. The ADS splitting criterion is the truncation estimate of those maps that
can hold the extremum (:func:`.bound.contenders`). The boxes of one ADS level are expanded in
lockstep, one batch per worker (:mod:`.lockstep`): their DA propagations run as one array
computation, which gives each box the maps it would get on its own.

Bounds, by the ``remainder`` option:

* ``estimated`` (the paper's eq. 28) and ``next-order``: each candidate is enclosed by eq. (27)
  plus an estimated remainder (:mod:`.bound`). They assume that perturbed runs have no other local
  extremum than the continuations of the nominal ones and switch through the same guard face, and
  that the remainder estimate holds: the verdict is UNKNOWN with the bound. Around the horizon
  the runs of a subdomain may differ in whether they switch before it: the switches are followed
  past the horizon while some runs may still make them before it, and the candidates that some
  runs may not reach count for the bound's outer end only (:func:`.bound.extremum_bound`).
  Where the candidates miss part of the run (more than ``MAX_SWITCHES`` switches before the
  horizon, runs that may switch where the nominal run does not, a nominal run stationary in
  ``q``: :class:`.problem.Candidates`) the bound's outer end is open and ``details["note"]``
  says why.
* ``rigorous``: a verified enclosure of every run on the subdomain (:mod:`.verified`: Taylor-model
  defect bound, logarithmic-norm Gronwall estimate; where that bound does not close, as on an
  expanding flow, a Taylor-model flowpipe with QR-preconditioned symbolic remainders,
  :mod:`.tm_flowpipe`), swept step by step for the extremum
  (:meth:`.problem.EventProblem.sweep`). It needs none of those assumptions, so a bound meeting
  the requirement on every subdomain is a proof: SAFE.

Safety properties are read as the extremum of each unsafe piece's margin (:mod:`.safety`): a
required constraint is an event, an ``avoid`` set is excluded step by step by the verified sweep;
UNSAFE comes only with a subdomain point that the simulator replays. A may-transition window
makes the switch time one more expansion variable (:mod:`.window`).

Each property has a time budget, ``max_seconds`` (120 s by default, :mod:`.deadline`); under
``-v`` the ADS levels and each subdomain's rigorous sweep are logged as they end.
"""


from __future__ import annotations

import logging
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from reach.backends.options import option_error, parse_options, ranged
from reach.backends.taylor.ads import Subdomain, split_domain, truncation_estimate
from reach.backends.taylor.bound import (contenders, enclose, estimated_remainder, extremum_bound,
                                         next_order_remainder, overflows)
from reach.backends.taylor.da import DA, algebra, stack
from reach.backends.taylor.deadline import Deadline, OutOfTime
from reach.backends.taylor.flow import Unsmooth
from reach.backends.taylor.keys import picklable
from reach.backends.taylor.nominal import NominalFailure
from reach.backends.taylor import units
from reach.backends.taylor.problem import EventProblem, global_clock, unsupported_switch
from reach.model.lint import blocking_faces
from reach.backends.taylor.units import expand_boxes, sweep_box
from reach.result import Result, Status
from reach.backends.taylor.safety import check_safety, margins, witness
from reach.backends.taylor.window import unsupported_window, with_switch_time
from reach.executors import _worker_start, guarded
from reach.spec.properties import BoundEvent, BoundSafety


log = logging.getLogger(__name__)

# the fewest boxes of an ADS level given to one worker. A batch costs a fixed part, the Python
# overhead of its sequence of array operations, plus a part per box (CW SIREN, one process: 1 box
# 1.05 CPU s, 2: 1.39, 4: 1.64, 8: 2.00, 16: 2.75; deep subdomains 1.49, 1.62, 1.80, 2.37 for
# 1, 2, 4, 8): halving a level of 8 boxes over two workers saves 0.4-0.6 s of wall time and costs
# a whole fixed part (1-1.5 CPU s)
MIN_SHARE = 8


@dataclass
class Options:
    """The taylor options (``-o name=value``); each field's comment says what it sets.

    ``max_seconds`` is the time budget of one property (all its margins for a safety
    property), 120 s by default like star's, ``None`` (``-o max_seconds=null``) for none. Past it
    no ADS level, refinement level, rigorous sweep branch or flowpipe step starts
    (:mod:`.deadline`): what was cut short is unbounded and the result is UNKNOWN, its note
    naming the budget; what was finished stands.
    """

    order: int = ranged(4, 1, 12)                 # Taylor order n
    e_tol: float | None = None      # ADS tolerance on the event value; default 1e-4 (1 + |value|)
    max_splits: int = ranged(6, 0, 30)            # N_max: halvings on the way to one subdomain
    remainder: str = "estimated"    # "estimated" (eq. 28), "next-order" or "rigorous"
    integration_tol: float = ranged(1e-9, 1e-13, 0.1)   # step doubling tolerance on the nominal run (above rounding)
    step_tol: float = ranged(1e-5, 1e-12, 0.1)    # rigorous mode: largest step defect relative to the rates
    refine: int = ranged(0, 0, 12)                # extra halvings of the subdomains that hold the bound open (below)
    jobs: int = ranged(1, 1, 256)                  # local worker processes for ADS boxes and sweeps
    scheduler: object = None        # or a Dask scheduler address (or Client) to run them on
    keep_sets: bool = False         # rigorous mode: the step enclosures in Result.sets (pictures)
    max_seconds: float | None = ranged(120.0, 0.0, open_low=True)  # time budget per property (above)

    @classmethod
    def from_dict(cls, options: dict | None) -> "Options":
        out = cls(**parse_options(cls, options, "taylor"))
        if out.remainder not in ("estimated", "next-order", "rigorous"):
            raise option_error("taylor", "remainder", "must be 'estimated', 'next-order' or 'rigorous'")
        return out


def _clocked(model, prop: BoundEvent):
    """``model`` and ``prop`` with a global clock when an event after a mode switch may need one
    (the horizon is the event ``t = T`` on it; a switch may lead back into the initial mode):
    the model's own, else a state ``_time`` added (rate 1 everywhere, 0 initially, never reset;
    :meth:`HybridAutomaton.with_global_clock`)."""
    if not model.transitions or global_clock(model) is not None:
        return model, prop
    clocked, _ = model.with_global_clock()
    return clocked, replace(prop, symbols=clocked.symbols)


#: the estimate's assumption where runs may stop at an invariant (shown in the verdict's line)
PAST_STOPS = ("the estimate follows the runs on past an invariant boundary where no transition is enabled "
              "(reach lint names it), though the automaton stops them there: it may hold values no run reaches")


class TaylorBackend:
    name = "taylor"

    def supports(self, model, prop) -> str | None:
        if not isinstance(prop, (BoundSafety, BoundEvent)):
            return "taylor checks safety and event properties only"
        if model.disturbance is not None:
            return "stochastic models are not handled (the flow must be deterministic)"
        reason = unsupported_window(model) or unsupported_switch(model)
        if reason is not None:
            return reason
        if isinstance(prop, BoundSafety):
            for part in margins(model, prop):
                if part.event is not None:
                    reason = self.supports(model, part.event)
                    if reason is not None:
                        return f"{part.text}: {reason}"
            return None
        model, _ = with_switch_time(model)
        model, prop = _clocked(model, prop)
        try:
            EventProblem(model, prop)
        except Unsmooth as err:
            return f"not smooth: {err}"
        return None

    def check(self, model, prop, options=None) -> Result:
        opts = Options.from_dict(options)
        deadline = Deadline.start(opts.max_seconds)
        if isinstance(prop, BoundSafety):
            return check_safety(self, model, prop, opts, deadline)
        result = self.check_event(model, prop, opts, deadline)
        if result.status is not Status.SAFE and not deadline.passed():
            found = witness(model, prop, result, prop.op, prop.value)
            if found is not None:
                result.status, result.counterexample = Status.UNSAFE, found
                result.details["argument"] = (
                    "a point of a subdomain whose bound reaches past the requirement (its centre or a corner), "
                    "mapped back to an initial state and replayed by the simulator: its extremum breaks it")
                result.details.pop("note", None)
        return result

    def check_event(self, model, prop: BoundEvent, opts: Options, deadline: Deadline) -> Result:
        """An event property's bound, nothing started past the ``deadline``."""
        opts = replace(opts)            # _check_event may set the remainder
        model, _ = with_switch_time(model)
        model, prop = _clocked(model, prop)
        try:
            with _unit_runner(opts, picklable(model, prop)) as run_units:
                return self._check_event(model, prop, opts, run_units, deadline)
        except (NominalFailure, OutOfTime) as err:
            return Result(self.name, model.name, prop.id, Status.UNKNOWN, bound=(-np.inf, np.inf),
                          details={"reason": f"{err}: nothing was bounded", "remainder": opts.remainder,
                                   "subdomain_count": 0, "share_meeting_requirement": 0.0})

    def _check_event(self, model, prop, opts: Options, run_units, deadline: Deadline) -> Result:
        """:meth:`check` of an event property, its work units run by ``run_units(fn, arg_list)``
        (:func:`_unit_runner`). Past the ``deadline`` no ADS level starts (OutOfTime: nothing is
        bounded), no sweep branch (its subdomain is unbounded) and no refinement level (the
        bound so far stands: refining only narrows it)."""
        avoid = isinstance(next(iter(prop.quantity.values())), tuple)
        if avoid:       # a non-smooth margin: bounded by the verified sweep only
            opts.remainder = "rigorous"
        problem = units.problem(model, prop)
        e_tol = opts.e_tol if opts.e_tol is not None else 1e-4 * (1.0 + abs(prop.value))
        u = problem.uncertain
        rigorous = opts.remainder == "rigorous"
        expand_order = opts.order + (1 if opts.remainder == "next-order" else 0)

        def full_box(center_u, half_u):
            center = problem.low + 0.5 * (problem.high - problem.low)
            half = np.zeros(model.n)
            center[u], half[u] = center_u, half_u
            return center, half

        def expand_level(boxes):
            """A level's boxes in batches (:mod:`.lockstep`), one per worker, on as many of the
            ``jobs`` workers as give each at least :data:`MIN_SHARE` boxes."""
            if deadline.passed():
                raise OutOfTime(deadline.text)
            full = [full_box(c, h) for c, h in boxes]
            workers = max(1, min(opts.jobs, len(full) // MIN_SHARE))
            chunks = [list(part) for part in np.array_split(np.arange(len(full)), workers)]
            parts = run_units(expand_boxes, [(model, prop, opts.order, expand_order, opts.integration_tol,
                                              [full[i] for i in chunk], deadline) for chunk in chunks])
            return [result for part in parts for result in part]

        def measure(result):
            """The ADS measure of a box: its candidates that can hold the extremum, stacked (zero
            when the nominal run visits none of the listed modes: nothing to split for). Stretches
            are left out: each continues an entry or exit map, in one more variable (the time)."""
            maps = result[0]
            held = [p for name, p in contenders(maps, prop.sense, maps.partial, maps.alternatives).items()
                    if name not in maps.stretches]
            return stack(held) if held else DA.const(algebra(opts.order, len(u)), 0.0)

        kept_sets: list = []            # step enclosures of the rigorous sweeps (keep_sets)
        if avoid:
            subdomains = [Subdomain(problem.low[u], problem.high[u], None, 0.0, 0, True)]
        else:
            subdomains = split_domain(None, problem.low[u], problem.high[u], e_tol, opts.max_splits,
                                      measure=measure, map_boxes=expand_level)

        def evaluate(subs) -> list[dict]:
            """A row per subdomain: candidate bounds, the estimated bound and (rigorous) the sweep."""
            sweeps = [None] * len(subs)
            if rigorous:
                started = time.perf_counter()
                log.info("rigorous sweeps of %d subdomains", len(subs))
                sweeps = run_units(sweep_box, [(model, prop, opts.order, opts.step_tol, opts.integration_tol,
                                                *full_box(sub.center, sub.half_width), opts.keep_sets, deadline)
                                               for sub in subs])
                for sweep in sweeps:
                    kept_sets.extend(_set_pieces(model, sweep.pop("sets", [])))
                log.info("rigorous sweeps of %d subdomains in %.1f s", len(subs), time.perf_counter() - started)
            out = []
            for sub, sweep in zip(subs, sweeps):
                if sub.poly is None:       # no candidate maps (avoid set)
                    out.append({"low": sub.low, "high": sub.high, "splits": sub.splits, "truncation_estimate": None,
                                "converged": True, "candidates": {}, "bound": _no_nan(sweep["bound"]),
                                "verified": sweep})
                    continue
                polys, full = sub.poly
                bounds = {}
                for name, p in polys.items():
                    R = (next_order_remainder(full[name]) if opts.remainder == "next-order"
                         else estimated_remainder(p))
                    lo, hi = enclose(p, R)
                    bounds[name] = (float(lo), float(hi), float(R))
                estimated = extremum_bound({name: b[:2] for name, b in bounds.items()}, prop.sense,
                                           polys.partial, polys.alternatives)
                if polys.gap is not None:   # runs may reach beyond every candidate: no outer end
                    estimated = (estimated[0], np.inf) if prop.sense == "max" else (-np.inf, estimated[1])
                row = {"low": sub.low, "high": sub.high, "splits": sub.splits,
                       "truncation_estimate": sub.error, "converged": sub.converged, "candidates": bounds,
                       "bound": _no_nan(sweep["bound"] if rigorous else estimated)}
                overflowed = sorted(name for name, p in polys.items() if overflows(p))
                if overflowed:              # their enclosures are unbounded (enclose)
                    row["overflow"] = overflowed
                if polys.gap is not None:
                    row["gap"] = polys.gap
                if polys.partial:           # candidates some runs may not reach before the horizon
                    row["partial"] = sorted(polys.partial)
                if rigorous:
                    row["estimated_bound"], row["verified"] = estimated, sweep
                out.append(row)
            return out

        def decided(row) -> bool:
            lo, hi = row["bound"]
            return (hi <= prop.value or lo > prop.value) if prop.op == "<=" else (lo >= prop.value or hi < prop.value)

        sign = 1.0 if prop.sense == "max" else -1.0

        def outer(row) -> float:
            """The end of a row's bound on the side of the extremum (the upper end of a maximum)."""
            return row["bound"][1] if sign > 0 else -row["bound"][0]

        def inner(row) -> float:
            return row["bound"][0] if sign > 0 else -row["bound"][1]

        def capped(row, parent) -> dict:
            """A half's row with its outer end held to its parent's: the parent's bound holds every
            run of the half too (the inner end is the half's own: its runs are fewer)."""
            if outer(row) > outer(parent):
                lo, hi = row["bound"]
                row["bound"] = (lo, parent["bound"][1]) if sign > 0 else (parent["bound"][0], hi)
            return row

        def progress(rows) -> tuple[float, float]:
            """The bound's outer end (negated: larger is better) and the share of the box decided."""
            share = sum(np.prod(r["high"] - r["low"]) for r in rows if decided(r))
            return -max(outer(r) for r in rows), share / np.prod(problem.high[u] - problem.low[u])

        rows = evaluate(subdomains)
        # splitting on the bound: halve the subdomains whose bound is undecided or whose outer end
        # lies beyond the best inner end (the only ones that can hold the extremum, so the only
        # ones whose halving can narrow the bound); stop when a level neither narrows the bound
        # nor decides more of the box (on SRNA01 the width left after one level is error radius,
        # which halving does not reduce: refine=2 gave the bounds of refine=1 at twice the time)
        for _ in range(opts.refine if len(u) else 0):     # a point initial set has nothing to halve
            if deadline.passed():
                log.info("refinement stopped: %s", deadline.text)
                break
            reached = progress(rows)
            floor = max(inner(r) for r in rows)
            open_rows = [r for r in rows if not decided(r) or outer(r) > floor]
            if not open_rows:
                break
            log.info("refining %d subdomains", len(open_rows))
            halves = []
            for r in open_rows:
                width = (r["high"] - r["low"]) / (problem.high[u] - problem.low[u])
                k = int(np.argmax(width))
                mid = 0.5 * (r["low"][k] + r["high"][k])
                left_hi, right_lo = r["high"].copy(), r["low"].copy()
                left_hi[k], right_lo[k] = mid, mid
                halves += [(r["low"], left_hi, r["splits"] + 1, r), (right_lo, r["high"], r["splits"] + 1, r)]
            if avoid:
                children = [Subdomain(lo, hi, None, 0.0, depth, True) for lo, hi, depth, _ in halves]
            else:
                results = expand_level([(0.5 * (lo + hi), 0.5 * (hi - lo)) for lo, hi, _, _ in halves])
                children = []
                for (lo, hi, depth, _), result in zip(halves, results):
                    error, _ = truncation_estimate(measure(result))
                    children.append(Subdomain(lo, hi, result, error, depth, error <= e_tol))
            kept = [r for r in rows if not any(r is parent for *_, parent in halves)]
            rows = kept + [capped(row, parent) for row, (*_, parent) in zip(evaluate(children), halves)]
            if all(now <= before for now, before in zip(progress(rows), reached)):
                break
        rows.sort(key=lambda r: tuple(r["low"]))
        volume = np.prod(problem.high[u] - problem.low[u])
        meets = violates = 0.0
        for row in rows:
            lo, hi = row["bound"]
            share = np.prod(row["high"] - row["low"]) / volume
            meets += share * (hi <= prop.value if prop.op == "<=" else lo >= prop.value)
            violates += share * (lo > prop.value if prop.op == "<=" else hi < prop.value)
        lo, hi = min(r["bound"][0] for r in rows), max(r["bound"][1] for r in rows)
        verdict = "met" if meets >= 1 - 1e-12 else "violated" if violates >= 1 - 1e-12 else "undecided"
        details = {
            "remainder": {"estimated": "estimated", "next-order": "next-order (not rigorous)",
                          "rigorous": "rigorous (verified enclosure or flowpipe)"}[opts.remainder],
            "requirement": f"{prop.sense} {prop.op} {prop.value:g}: bound {verdict}",
            "sense": prop.sense, "op": prop.op, "value": prop.value,
            "share_meeting_requirement": meets, "share_violating_requirement": violates,
            "variables": [model.state[i] for i in u], "order": opts.order, "e_tol": e_tol,
            "max_splits": opts.max_splits, "refine": opts.refine, "subdomain_count": len(rows), "subdomains": rows,
            "integrator": f"fixed-step DOP853 tableau, steps doubled to {opts.integration_tol:g}",
        }
        if rigorous:
            details["argument"] = (
                "on every subdomain the runs lie in a verified enclosure of the flow (Taylor-model "
                "defect bound and a logarithmic-norm Gronwall estimate, reach.backends.taylor.verified; "
                "or a Taylor-model flowpipe whose steps are validated by the Picard operator, "
                "reach.backends.taylor.tm_flowpipe) and the extremum over the mode's stretch lies in the Taylor-model bound of the quantity "
                "over all its steps, up to the step where every run is inside the urgent guard")
            details["assumptions"] = [
                "floating-point rounding is covered only by a relative allowance of 1e-12 on the defect bound, "
                "not by directed rounding",
                "the initial set lies in the mode's invariant (runs are not blocked at t = 0)",
            ]
            details["max_error_radius"] = max(r["verified"]["error"] for r in rows)
            status = Status.SAFE if verdict == "met" else Status.UNKNOWN
            coverage = meets
            if verdict == "undecided":
                # the budget first where it cut a sweep short: the other reasons may not be all
                whys = sorted({r["verified"]["why"] for r in rows if r["verified"].get("why")},
                              key=lambda why: (not deadline.cut(why), why))
                # a sweep that ran to its end with an outer end at infinity: the quantity overflowed
                blown = [r for r in rows if not r["verified"].get("why") and outer(r) == np.inf]
                if blown:
                    details["overflow"] = sorted({name for r in blown for name in r.get("overflow", [])})
                    whys.insert(0, overflow_note(prop, details["overflow"]))
                details["note"] = (f"the bound is open on {1 - meets - violates:.0%} of the box"
                                   + (f" ({'; '.join(whys[:2])})" if whys else "")
                                   + ("" if deadline.passed() or not len(u) or len(blown) == len(rows) or (whys and all(
                                       "mode switches" in why for why in whys)) else
                                      f"; -o refine={opts.refine + 2} halves the subdomains that hold it open"))
        else:
            details["assumptions"] = [
                "the truncation remainder is " + ("extrapolated from the coefficient decay (eq. 28)"
                                                  if opts.remainder == "estimated" else
                                                  "the next-order terms plus a geometric tail"),
                "perturbed runs have no local extremum besides the continuations of the nominal ones",
                "perturbed runs leave the initial mode through the nominal run's guard face",
                "the integration error of the flow is negligible",
            ]
            if blocking_faces(model):
                details["assumptions"].append(PAST_STOPS)
            details["why_not_safe"] = "the remainder is estimated; remainder: rigorous proves bounds"
            gaps = sorted({r["gap"] for r in rows if "gap" in r})
            if gaps:
                details["note"] = (f"the candidates miss part of the run ({gaps[0]}): the bound's "
                                   f"{'upper' if prop.sense == 'max' else 'lower'} end is open")
            if PAST_STOPS in details["assumptions"]:
                details["note"] = "; ".join(filter(None, [details.get("note"), PAST_STOPS]))
            overflowed = sorted({name for r in rows for name in r.get("overflow", [])})
            if overflowed:
                details["overflow"] = overflowed
                details["note"] = "; ".join(filter(None, [overflow_note(prop, overflowed), details.get("note")]))
            status, coverage = Status.UNKNOWN, 0.0
        return Result(self.name, model.name, prop.id, status, bound=(lo, hi), coverage=coverage,
                      details=details, sets=kept_sets)


def _no_nan(bound) -> tuple[float, float]:
    """A bound with an end that is not a number (an overflow) made unbounded on that end."""
    lo, hi = (float(v) for v in bound)
    return (-np.inf if np.isnan(lo) else lo, np.inf if np.isnan(hi) else hi)


def overflow_note(prop, names: list[str]) -> str:
    """Why a bound is unbounded: the quantity overflows the floating-point numbers, at the
    candidates ``names`` where they are known (its value there is not finite: no number to
    report, and no end to prove)."""
    from reach.paths import few

    end = "upper" if prop.sense == "max" else "lower"
    where = f" at {few(names)}" if names else " in the enclosure of the runs"
    return (f"the {prop.text or 'quantity'} overflows (is not finite){where}: "
            f"the bound's {end} end is unbounded")


def _set_pieces(model, boxes) -> list:
    """Step enclosure boxes ``(mode, t0, t1, low, high)`` of a sweep as set pieces."""
    from reach.result import SetPiece

    names = tuple(model.state)
    return [SetPiece(mode, t0, t1, "box", names, low=low, high=high) for mode, t0, t1, low, high in boxes]


@contextmanager
def _unit_runner(opts: Options, portable: bool):
    """A context giving ``run(fn, arg_list) -> results in order``: in this process, or on worker
    processes (when the model can be sent to them). Local workers are started once for the whole
    check and serve every ADS level and the sweeps: :class:`reach.executors.LocalExecutor` starts
    a pool per call, and a pool per ADS level cost each worker a fresh start and the problem's
    compilation on every level (CW SIREN: 15 levels, about 0.35 CPU s per worker and level)."""
    if (opts.jobs <= 1 and opts.scheduler is None) or not portable:
        yield lambda fn, arg_list: [fn(*args) for args in arg_list]
        return
    if opts.scheduler is None:
        with ProcessPoolExecutor(max_workers=opts.jobs, initializer=_worker_start) as pool:
            yield _runner(_Workers(pool))
        return
    from reach.executors import make_executor

    yield _runner(make_executor(opts.jobs, opts.scheduler))


class _Workers:
    """A process pool as an executor (``map_unordered``, :mod:`reach.executors`)."""

    def __init__(self, pool: ProcessPoolExecutor):
        self.pool = pool

    def map_unordered(self, fn, arg_list):
        futures = {self.pool.submit(guarded, fn, args, None): i for i, args in enumerate(arg_list)}
        for future in as_completed(futures):
            yield futures[future], future.result()


def _runner(executor):
    """``run(fn, arg_list)`` on ``executor`` (a single unit runs in this process)."""

    def run(fn, arg_list):
        if len(arg_list) == 1:
            return [fn(*arg_list[0])]
        out = [None] * len(arg_list)
        for i, (status, value) in executor.map_unordered(fn, arg_list):
            if status != "ok":
                raise RuntimeError(f"a taylor work unit did not finish ({status})")
            out[i] = value
        return out

    return run


BACKEND = TaylorBackend()
