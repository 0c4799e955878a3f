"""CW SIREN closest approach proved by Taylor-model flowpipes (reach/backends/taylor/tm_flowpipe.py).

For each subdomain of the initial position box, the transfer mode's closed loop (CW dynamics and
the SIREN thrust direction) is integrated by the validated Taylor-model flowpipe, and the
subdomain (or a part of it, split up to ``--depth`` times) is proved when a step end shows
``L <= 1`` for every run of the part (properties/cw_siren.yaml, L of eq. 30). The flowpipe follows
the transfer flow only; that suffices: a run whose transfer-flow state has ``L <= 1`` at a time
``t`` either switched to ``arrived`` before ``t`` (the switch happens at ``L = 0.9``) or is still in
the transfer mode at ``t``; either way its minimum of L is at most 1.

Subdomains: ``--boxes ads`` (the estimated map's 288 subdomains from results/cw_siren.json,
smallest first), ``--grid N`` (a uniform N x N grid) or ``--box CX CY RX RY`` (centre and
half-widths in m, repeatable). Each gets at most ``--budget`` seconds; ``--deadline`` caps the whole
run (subdomains not started by then count as not proved). Prints and records the share of the
box's area proved, each subdomain's outcome (where its flowpipe failed or stopped: step, time, step
size, carried error) and the seconds.

    python benchmarks/cw_siren_proof.py --jobs 2 --box 500 -500 1 1 --box 550 -640 0.5 0.5 \
        --budget 1500 --deadline 1600 --json results/cw_siren_proof.json --md results/cw_siren_proof.md

(results/cw_siren_proof.md: those two boxes are proved in about 10 minutes; the estimated map's
subdomains, 5-7 m wide, are not.)
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from pathlib import Path

import numpy as np

from reach.backends.taylor.flow import compile_expressions
from reach.backends.taylor.problem import global_clock
from reach.backends.taylor.tm_flowpipe import TMFlow, prove_minimum_at_most
from reach.executors import LocalExecutor
from reach.model.loader import load_model
from reach.spec.properties import bind, load_properties

MODEL, PROPERTIES = "models/cw_siren.yaml", "properties/cw_siren.yaml"
# error per unit time a step may add (m/s for positions, m/s^2 for velocities): step-size control
TOL = {"x": 1e-7, "y": 1e-7, "vx": 1e-10, "vy": 1e-10}
TRACE_EVERY = 250.0          # seconds of flight between trace records

_PROBLEM = {}


def problem():
    """The transfer field, L and the requirement (compiled once per process)."""
    if not _PROBLEM:
        model = load_model(MODEL)
        prop = bind(load_properties(PROPERTIES)[0], model)
        f = compile_expressions(model.modes["transfer"].flow, model.symbols)
        q = compile_expressions([prop.quantity["transfer"]], model.symbols)
        _PROBLEM.update(model=model, prop=prop, f=f, q=lambda x: q(x)[0])
    return _PROBLEM


def prove_box(center: list, half: list, order: int, depth: int, budget: float) -> dict:
    """Try to prove one subdomain (centre and half-widths of ``(x, y)`` in m)."""
    warnings.simplefilter("ignore", RuntimeWarning)
    p = problem()
    model, prop = p["model"], p["prop"]
    c, r = model.initial.low.copy(), np.zeros(model.n)
    u = np.flatnonzero(model.initial.high > model.initial.low)
    c[u], r[u] = center, half
    names = [str(s) for s in model.symbols]
    tol = np.array([TOL.get(name, 1.0) for name in names])
    clock = global_clock(model)
    flow = TMFlow(p["f"], c, r, order=order, exact=[clock] if clock is not None else [], tol=tol)
    trace, next_record = [], [0.0]

    def q(x):
        value = p["q"](x)
        t = float(x[clock].poly.cons) if clock is not None else np.nan
        if t >= next_record[0]:
            lo, hi = value.bound()
            trace.append({"t": t, "L": [float(lo), float(hi)]})
            next_record[0] = t + TRACE_EVERY
        return value

    proof = prove_minimum_at_most(flow, q, prop.value, model.horizon, 10.0, max_depth=depth, budget=budget)
    pipe = proof.pipe
    segs = pipe.segments
    radius = pipe.error_radius
    for rec in trace:                      # the error carried at the node nearest each record
        k = int(np.searchsorted([s.t0 + s.h for s in segs], rec["t"]))
        rec["error"] = [float(v) for v in radius[min(k, len(radius) - 1)][:4]] if radius else None
    last = segs[-1] if segs else None
    return {
        "center": list(center), "half": list(half), "status": proof.status, "fraction": proof.fraction,
        "why": proof.why, "seconds": proof.seconds, "steps": len(segs),
        "t_reached": pipe.t_end, "last_h": last.h if last else None,
        "error_at_end": [float(v) for v in radius[-1][:4]] if radius else None,
        "witness_times": [float(t) for *_, t in proof.proved],
        "pending_parts": len(proof.pending), "trace": trace,
    }


def subdomains(args) -> list[tuple[list, list]]:
    """``(centre, half-widths)`` of the chosen subdomains."""
    if args.box:
        return [([b[0], b[1]], [b[2], b[3]]) for b in args.box]
    if args.grid:
        model = problem()["model"]
        u = np.flatnonzero(model.initial.high > model.initial.low)
        low, high = model.initial.low[u], model.initial.high[u]
        step = (high - low) / args.grid
        return [([float(low[0] + (i + 0.5) * step[0]), float(low[1] + (j + 0.5) * step[1])], [float(s / 2) for s in step])
                for i in range(args.grid) for j in range(args.grid)]
    rows = json.loads(Path("results/cw_siren.json").read_text())["subdomain_rows"]
    rows.sort(key=lambda r: np.prod(np.subtract(r["high"], r["low"])))
    return [([0.5 * (a + b) for a, b in zip(r["low"], r["high"])], [0.5 * (b - a) for a, b in zip(r["low"], r["high"])])
            for r in rows]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--boxes", choices=["ads"], default="ads")
    ap.add_argument("--grid", type=int, default=0)
    ap.add_argument("--box", type=float, nargs=4, action="append", metavar=("CX", "CY", "RX", "RY"))
    ap.add_argument("--limit", type=int, default=None, help="at most this many subdomains")
    ap.add_argument("--order", type=int, default=4)
    ap.add_argument("--depth", type=int, default=3, help="splits of a subdomain at the event")
    ap.add_argument("--budget", type=float, default=280.0, help="seconds per subdomain")
    ap.add_argument("--deadline", type=float, default=600.0, help="seconds for the whole run")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", default=None)
    ap.add_argument("--md", default=None)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)

    model = problem()["model"]
    u = np.flatnonzero(model.initial.high > model.initial.low)
    box_area = float(np.prod(model.initial.high[u] - model.initial.low[u]))
    boxes = subdomains(args)[: args.limit]
    print(f"CW SIREN proof: {len(boxes)} subdomains, order {args.order}, {args.jobs} processes, "
          f"{args.budget:g} s each, deadline {args.deadline:g} s", flush=True)
    started, cpu = time.perf_counter(), _cpu_seconds()
    results = [None] * len(boxes)
    units = [(c, h, args.order, args.depth, min(args.budget, args.deadline)) for c, h in boxes]
    executor = LocalExecutor(args.jobs)
    for i, (status, value) in executor.map_unordered(prove_box, units, time_limit=args.deadline + 60):
        if status != "ok":
            value = {"center": boxes[i][0], "half": boxes[i][1], "status": status, "fraction": 0.0,
                     "why": f"the unit ended with {status}", "seconds": None}
        results[i] = value
        print(f"  [{boxes[i][0][0]:.3f}, {boxes[i][0][1]:.3f}] +- [{boxes[i][1][0]:.3g}, {boxes[i][1][1]:.3g}] m: "
              f"{value['status']}, {100 * value['fraction']:.1f} % proved, t reached {value.get('t_reached', 0):.0f} s, "
              f"{value.get('steps', 0)} steps, {value['seconds'] or 0:.0f} s. {value['why']}", flush=True)
        if time.perf_counter() - started > args.deadline:
            break
    seconds, cpu_seconds = time.perf_counter() - started, _cpu_seconds() - cpu
    done = [r for r in results if r is not None]
    proved_area = sum(r["fraction"] * 4 * r["half"][0] * r["half"][1] for r in done)
    summary = {
        "command": "python benchmarks/cw_siren_proof.py " + " ".join(argv if argv is not None else os.sys.argv[1:]),
        "order": args.order, "depth": args.depth, "budget": args.budget, "deadline": args.deadline,
        "jobs": args.jobs, "tolerance_per_second": TOL, "box_area_m2": box_area,
        "subdomains": len(boxes), "finished": len(done), "proved_area_m2": proved_area,
        "fraction_of_box_proved": proved_area / box_area,
        "attempted_area_m2": sum(4 * r["half"][0] * r["half"][1] for r in done),
        "seconds": seconds, "cpu_seconds": cpu_seconds, "results": done,
    }
    print(f"proved {proved_area:.4g} m^2 of {box_area:.4g} m^2 ({100 * proved_area / box_area:.4f} % of the box) "
          f"in {seconds:.0f} s ({cpu_seconds:.0f} CPU s)", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1, default=float))
    if args.md:
        Path(args.md).write_text(markdown(summary))
    return 0


def markdown(s: dict) -> str:
    """The run as a results page: the share proved, then one row per subdomain."""
    lines = ["# CW SIREN: closest approach by Taylor-model flowpipes", "",
             f"`{s['command']}` (order {s['order']}, {s['jobs']} processes, {s['budget']:g} s per subdomain, "
             f"split depth {s['depth']} at the event). Figures in the .json next to this file.", "",
             f"Proved: **{s['proved_area_m2']:.4g} m^2 of {s['box_area_m2']:.4g} m^2 "
             f"({100 * s['fraction_of_box_proved']:.4f} % of the box)**; attempted {s['attempted_area_m2']:.4g} m^2 "
             f"in {s['finished']} subdomains; {s['seconds']:.0f} s wall, {s['cpu_seconds']:.0f} CPU s.", "",
             "| subdomain (centre, half-widths, m) | outcome | proved | t reached (s) | steps | last h (s) | "
             "carried error at the end (x, y m; vx, vy m/s) | seconds |", "|---|---|---|---|---|---|---|---|"]
    for r in s["results"]:
        err = ", ".join(f"{v:.2g}" for v in r["error_at_end"]) if r.get("error_at_end") else "-"
        lines.append(f"| ({r['center'][0]:.4g}, {r['center'][1]:.4g}) +- ({r['half'][0]:.3g}, {r['half'][1]:.3g}) | "
                     f"{r['status']} | {100 * r['fraction']:.1f} % | {r.get('t_reached', 0):.0f} | {r.get('steps', 0)} | "
                     f"{(r.get('last_h') or 0):.3g} | {err} | {(r['seconds'] or 0):.0f} |")
    lines.append("")
    for r in s["results"]:
        if r.get("why"):
            lines.append(f"- ({r['center'][0]:.4g}, {r['center'][1]:.4g}): {r['why']}")
    lines.append("")
    return "\n".join(lines)


def _cpu_seconds() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


if __name__ == "__main__":
    raise SystemExit(main())
