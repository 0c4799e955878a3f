"""taylor — event-map bounds by differential algebra and automatic domain splitting
(Evans & Armellin, "Sample-free safety assessment of neural network controllers via Taylor
methods").

For an event property (extremum of a quantity ``q`` over the run in the initial mode) the
initial box is covered by ADS subdomains (:mod:`.ads`); on each, the candidates for the
extremum are expanded as Taylor maps of the scaled initial deviations:

* the run's start, ``q(x0)``;
* every interior local extremum of ``q`` on the subdomain's nominal run, as the event
  ``dq/dt = 0`` (:mod:`.event`, eqs. 5-14);
* the end of the stretch: the crossing of the urgent guard face the nominal run leaves through
  (an event ``g(x) = 0``), or the horizon (the transfer map, eq. 4).

Each candidate is enclosed by eq. (27) plus a remainder (:mod:`.bound`); the extremum over the
run lies between the extreme candidate bounds. Assumptions (listed in ``details``): perturbed
runs have no other local extremum of ``q`` than the continuations of the nominal ones, and
leave the stretch through the same guard face; the remainder is an estimate (``estimated``,
eq. 28) or a next-order interval bound with a geometric tail (``next-order``). None of this is a
proof, so the verdict is UNKNOWN with the bound; ``details["requirement"]`` says whether every
subdomain's bound meets the requirement.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import sympy

from reach.backends.taylor.ads import split_domain
from reach.backends.taylor.bound import enclose, estimated_remainder, next_order_remainder, truncate
from reach.backends.taylor.da import DA, algebra, stack
from reach.backends.taylor.event import event_map, fixed_time_map, local_extrema, refine_time
from reach.backends.taylor.flow import Unsmooth, compile_expressions, compile_numeric, nominal
from reach.model.constraints import lambdify_margins
from reach.result import Result, Status
from reach.spec.properties import BoundEvent


@dataclass
class Options:
    order: int = 4                  # Taylor order n
    e_tol: float | None = None      # ADS tolerance on the event value; default 1e-4 (1 + |value|)
    max_splits: int = 6             # N_max: halvings on the way to one subdomain
    remainder: str = "estimated"    # "estimated" (eq. 28) or "next-order"
    integration_tol: float = 1e-9   # step doubling tolerance on the nominal run

    @classmethod
    def from_dict(cls, options: dict | None) -> "Options":
        options = dict(options or {})
        names = {f.name for f in fields(cls)}
        unknown = set(options) - names
        if unknown:
            raise ValueError(f"unknown taylor option(s): {', '.join(sorted(unknown))}")
        out = cls(**options)
        if out.remainder not in ("estimated", "next-order"):
            raise ValueError("remainder must be 'estimated' or 'next-order'")
        return out


class EventProblem:
    """One event property on the initial-mode stretch of a model, compiled for DA and floats."""

    def __init__(self, model, prop: BoundEvent):
        self.model, self.prop = model, prop
        mode = model.modes[model.initial.mode]
        symbols = model.symbols
        quantity = sympy.sympify(prop.quantity[mode.name])
        rate = sum(sympy.diff(quantity, s) * f for s, f in zip(symbols, mode.flow))
        self.f = compile_expressions(mode.flow, symbols)
        self.f_numeric = compile_numeric(mode.flow, symbols)
        q_numeric = compile_numeric([quantity], symbols)
        self.q_numeric = lambda x: q_numeric(x)[0]
        q = compile_expressions([quantity], symbols)
        qdot = compile_expressions([rate], symbols)
        self.q = lambda x: q(x)[0]
        self.qdot = lambda x: qdot(x)[0]
        self.guards = []
        for tr in model.outgoing(mode.name):
            faces = [compile_expressions([c.g], symbols) for c in tr.guard]
            self.guards.append((tr, lambdify_margins(tr.guard, symbols), faces))
        self.low, self.high = model.initial.low, model.initial.high
        self.uncertain = [i for i in range(model.n) if self.high[i] > self.low[i]]

    def exit(self, grid: np.ndarray):
        """First node index where an urgent guard holds, with the guard's margins and the face
        left last, or None."""
        best = None
        for _, margins, faces in self.guards:
            hits = np.flatnonzero(np.all(margins(grid) <= 0, axis=1))
            if hits.size and hits[0] > 0 and (best is None or hits[0] < best[0]):
                k = hits[0]
                face = int(np.argmax(margins(grid[k - 1:k])[0]))
                best = (k, margins, faces[face])
        return best

    def candidates(self, center: np.ndarray, half_width: np.ndarray, order: int, tol: float):
        """Taylor maps (in the subdomain's scaled deviations) of the extremum candidates."""
        m, T = len(self.uncertain), self.model.horizon
        run = nominal(self.f_numeric, center, T, tol)
        grid = run.grid()
        alg = algebra(order, m)
        x0 = [DA.var(alg, self.uncertain.index(i), c, half_width[i]) if i in self.uncertain
              else DA.const(alg, c) for i, c in enumerate(center)]
        out = {"start": self.q(x0)}
        leave = self.exit(grid)
        last = len(run.nodes) - 1 if leave is None else leave[0]
        values = np.asarray(self.q_numeric(list(grid[: last + 1].T)))
        sign = 1.0 if self.prop.sense == "max" else -1.0
        for k in local_extrema(values, self.prop.sense):
            t0 = run.sharpen(k, lambda X: sign * np.asarray(self.q_numeric(list(X))))
            t_e, _ = refine_time(self.f, self.qdot, run.solution, t0, order)
            em = event_map(self.f, self.qdot, center, half_width, self.uncertain, run.nodes, t_e, order)
            out[f"extremum@{t_e:.6g}"] = self.q(em.state)
        if leave is None:
            em = fixed_time_map(self.f, center, half_width, self.uncertain, run.nodes, T, order)
            out["horizon"] = self.q(em.state)
        else:
            _, margins, face = leave
            # first dense sample inside the guard: maximise "inside" then earliness
            t0 = run.sharpen(last, lambda X: np.where(np.all(margins(X.T) <= 0, axis=1),
                                                      -np.arange(X.shape[1]), -np.inf))
            crossing = lambda x: face(x)[0]
            t_e, _ = refine_time(self.f, crossing, run.solution, t0, order)
            em = event_map(self.f, crossing, center, half_width, self.uncertain, run.nodes, t_e, order)
            out[f"exit@{t_e:.6g}"] = self.q(em.state)
        return out


class TaylorBackend:
    name = "taylor"

    def supports(self, model, prop) -> str | None:
        if not isinstance(prop, BoundEvent):
            return "taylor checks event properties (extremum of a quantity along the run) only"
        if model.disturbance is not None:
            return "stochastic models are not handled (the flow must be deterministic)"
        initial = model.initial.mode
        if prop.modes != [initial]:
            return (f"only the stretch in the initial mode '{initial}' is mapped; the property "
                    f"asks for modes {prop.modes} (events after a mode switch are not handled)")
        for tr in model.outgoing(initial):
            if not tr.urgent and tr.window is not None and tr.window[1] < model.horizon:
                return (f"the may-transition '{tr.name}' leaves '{initial}' at a nondeterministic "
                        "instant inside the horizon")
            if not tr.urgent and tr.window is None:
                return f"may-transition '{tr.name}' without a clock window"
        try:
            EventProblem(model, prop)
        except Unsmooth as err:
            return f"not smooth: {err}"
        return None

    def check(self, model, prop, options=None) -> Result:
        opts = Options.from_dict(options)
        problem = EventProblem(model, prop)
        e_tol = opts.e_tol if opts.e_tol is not None else 1e-4 * (1.0 + abs(prop.value))
        u = problem.uncertain
        expand_order = opts.order + (1 if opts.remainder == "next-order" else 0)

        def expand(center_u, half_u):
            center = problem.low + 0.5 * (problem.high - problem.low)
            half = np.zeros(model.n)
            center[u], half[u] = center_u, half_u
            maps = problem.candidates(center, half, expand_order, opts.integration_tol)
            return {name: truncate(p, opts.order) if expand_order > opts.order else p
                    for name, p in maps.items()}, maps

        subdomains = split_domain(expand, problem.low[u], problem.high[u], e_tol, opts.max_splits,
                                  measure=lambda result: stack(list(result[0].values())))
        pick = max if prop.sense == "max" else min
        rows, volume = [], np.prod(problem.high[u] - problem.low[u])
        meets = violates = 0.0
        for sub in subdomains:
            polys, full = sub.poly
            bounds = {}
            for name, p in polys.items():
                R = (estimated_remainder(p) if opts.remainder == "estimated"
                     else next_order_remainder(full[name]))
                lo, hi = enclose(p, R)
                bounds[name] = (float(lo), float(hi), float(R))
            lo = pick(b[0] for b in bounds.values())
            hi = pick(b[1] for b in bounds.values())
            share = np.prod(sub.high - sub.low) / volume
            ok = hi <= prop.value if prop.op == "<=" else lo >= prop.value
            bad = lo > prop.value if prop.op == "<=" else hi < prop.value
            meets += share * ok
            violates += share * bad
            rows.append({"low": sub.low, "high": sub.high, "bound": (lo, hi), "splits": sub.splits,
                         "truncation_estimate": sub.error, "converged": sub.converged,
                         "candidates": bounds})
        lo, hi = min(r["bound"][0] for r in rows), max(r["bound"][1] for r in rows)
        verdict = "met" if meets >= 1 - 1e-12 else "violated" if violates >= 1 - 1e-12 else "undecided"
        details = {
            "remainder": "estimated" if opts.remainder == "estimated" else "next-order (not rigorous)",
            "requirement": f"{prop.sense} {prop.op} {prop.value:g}: bound {verdict}",
            "share_meeting_requirement": meets, "share_violating_requirement": violates,
            "variables": [model.state[i] for i in u], "order": opts.order, "e_tol": e_tol,
            "max_splits": opts.max_splits, "subdomain_count": len(rows), "subdomains": rows,
            "integrator": f"fixed-step DOP853 tableau, steps doubled to {opts.integration_tol:g}",
            "assumptions": [
                "the truncation remainder is " + ("extrapolated from the coefficient decay (eq. 28)"
                                                  if opts.remainder == "estimated" else
                                                  "the next-order terms plus a geometric tail"),
                "perturbed runs have no local extremum besides the continuations of the nominal ones",
                "perturbed runs leave the initial mode through the nominal run's guard face",
                "the integration error of the flow is negligible",
            ],
            "why_not_safe": "the remainder is not enclosed by a verified integration",
        }
        return Result(self.name, model.name, prop.id, Status.UNKNOWN, bound=(lo, hi), coverage=0.0,
                      details=details)


BACKEND = TaylorBackend()
