"""CW SIREN closest approach proved by Taylor-model flowpipes (reach/backends/taylor/tm_flowpipe.py).

For each subdomain of the initial position box, the transfer mode's closed loop (CW dynamics and
the SIREN thrust direction) is integrated by the validated Taylor-model flowpipe, and the
subdomain (or a part of it, split up to ``--depth`` times) is proved when a step end shows
``L <= 1`` for every run of the part (properties/cw_siren.yaml, L of eq. 30). The flowpipe follows
the transfer flow only; that suffices: a run whose transfer-flow state has ``L <= 1`` at a time
``t`` either switched to ``arrived`` before ``t`` (the switch happens at ``L = 0.9``) or is still in
the transfer mode at ``t``; either way its minimum of L is at most 1.

Subdomains: ``--boxes ads`` (the estimated map's 288 subdomains from results/cw_siren.json,
smallest first), ``--boxes spread`` (the map's subdomains holding the box's corners, edge midpoints
and centre), ``--grid N`` (a uniform N x N grid) or ``--box CX CY RX RY`` (centre and half-widths in
m, repeatable); ``--limit K`` keeps the first K (0: no run, e.g. to redraw the map). Each gets at
most ``--budget`` seconds; ``--deadline`` caps the whole run (subdomains not started by then count
as not proved). Prints the share of the box's area proved, each subdomain's outcome (where its
flowpipe failed or stopped: step, time, step size, carried error, the proved sub-boxes) and the
seconds. ``--json`` adds the run to the file's ``runs`` (earlier runs kept); ``--md`` appends it to
the results page as "### Run N: NOTE" (``--note``).

``--map PNG`` (with ``--json``): Fig. 4 with proved colours, from every run in the ``--json`` file.
Each subdomain of the estimated map is "proved safe" when proved boxes cover it entirely,
"proved unsafe" on a proof that a run keeps L > 1 over the horizon (none is attempted here), else
"undecided" (reach/bench/proved_map.py); the proved boxes are drawn as patches, and the attempted
subdomains left undecided are outlined with the flight time their flowpipe reached. The map's
figures go to the ``fig4_proved_map`` key of the json (proved area by union, colour counts, every
attempt's outcome) and, with ``--md``, to the page's section "Fig. 4 with proved colours".

    python benchmarks/cw_siren_proof.py --jobs 2 --box 500 -500 1 1 --box 550 -640 0.5 0.5 \
        --budget 1500 --deadline 1600 --json results/cw_siren_proof.json --md results/cw_siren_proof.md
    python benchmarks/cw_siren_proof.py --jobs 1 --boxes spread --budget 300 --deadline 1200 \
        --json results/cw_siren_proof.json --md results/cw_siren_proof.md --note "..."
    python benchmarks/cw_siren_proof.py --limit 0 --json results/cw_siren_proof.json \
        --md results/cw_siren_proof.md --map results/plots/cw_siren_fig4_proved.png

(results/cw_siren_proof.md: the two boxes of the first command are proved in about 10 minutes; the
estimated map's subdomains, 0.4-27 m wide, are not.)
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from reach.backends.taylor.flow import compile_expressions
from reach.backends.taylor.problem import global_clock
from reach.backends.taylor.tm_flowpipe import TMFlow, prove_minimum_at_most
from reach.bench.plots import plot_proved_map
from reach.bench.proved_map import (COLOURS, PROVED_SAFE, PROVED_UNSAFE, UNDECIDED, colour_map, covers, meets,
                                    union_area)
from reach.executors import LocalExecutor
from reach.model.loader import load_model
from reach.spec.properties import bind, load_properties

MODEL, PROPERTIES = "models/cw_siren.yaml", "properties/cw_siren.yaml"
ESTIMATED = "results/cw_siren.json"          # the estimated map (benchmarks/cw_siren.py)
MAP_SECTION = "## Fig. 4 with proved colours"
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
    # the proved sub-boxes xi_c +- xi_r of [-1, 1]^2 in m (x = centre + half * xi)
    parts = [[list(map(float, np.add(center, np.multiply(half, xi_c - xi_r)))),
              list(map(float, np.add(center, np.multiply(half, xi_c + xi_r))))] for xi_c, xi_r, _ in proof.proved]
    return {
        "center": list(center), "half": list(half), "status": proof.status, "fraction": proof.fraction,
        "proved_parts": parts,
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
    rows = estimated_rows()
    if args.boxes == "spread":
        model = problem()["model"]
        u = np.flatnonzero(model.initial.high > model.initial.low)
        low, high = model.initial.low[u], model.initial.high[u]
        points = [low + np.multiply(f, high - low) for f in
                  [(0, 0), (1, 0), (0, 1), (1, 1), (0.5, 0), (0.5, 1), (0, 0.5), (1, 0.5), (0.5, 0.5)]]
        chosen = []
        for point in points:
            row = next(r for r in rows if np.all(np.greater_equal(point, r["low"])) and
                       np.all(np.less_equal(point, r["high"])))
            if row not in chosen:
                chosen.append(row)
        rows = chosen
    else:
        rows = sorted(rows, key=lambda r: np.prod(np.subtract(r["high"], r["low"])))
    return [([0.5 * (a + b) for a, b in zip(r["low"], r["high"])], [0.5 * (b - a) for a, b in zip(r["low"], r["high"])])
            for r in rows]


def estimated_rows() -> list[dict]:
    """The estimated map's subdomains (``low``, ``high``, ``bound``) from results/cw_siren.json."""
    return json.loads(Path(ESTIMATED).read_text())["subdomain_rows"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--boxes", choices=["ads", "spread"], default="ads")
    ap.add_argument("--grid", type=int, default=0)
    ap.add_argument("--box", type=float, nargs=4, action="append", metavar=("CX", "CY", "RX", "RY"))
    ap.add_argument("--limit", type=int, default=None, help="at most this many subdomains (0: no run)")
    ap.add_argument("--order", type=int, default=4)
    ap.add_argument("--depth", type=int, default=3, help="splits of a subdomain at the event")
    ap.add_argument("--budget", type=float, default=280.0, help="seconds per subdomain")
    ap.add_argument("--deadline", type=float, default=600.0, help="seconds for the whole run")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", default=None, help="add the run to this file's runs")
    ap.add_argument("--md", default=None, help="add the run (and the map's section) to this page")
    ap.add_argument("--note", default="", help="the run's title in the --md page")
    ap.add_argument("--map", default=None, metavar="PNG",
                    help="draw the estimated map with proved colours from every run of --json")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    if args.map and not args.json:
        ap.error("--map reads the runs of --json")
    command = "python benchmarks/cw_siren_proof.py " + shlex.join(argv if argv is not None else sys.argv[1:])
    record = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).exists() else {"runs": []}
    boxes = subdomains(args)[: args.limit]
    run = prove_boxes(args, boxes, command) if boxes else None
    if run is not None:
        record["runs"].append(run)
    if args.map:
        record["fig4_proved_map"] = proved_map(record["runs"], Path(args.map), command)
        record.update(proved_summary(record["fig4_proved_map"]))
    if args.json:
        Path(args.json).write_text(json.dumps(record, indent=1, default=float))
    if args.md:
        page = (Path(args.md).read_text() if Path(args.md).exists()
                else "# CW SIREN: closest approach by Taylor-model flowpipes\n")
        if run is not None:
            page = page.rstrip("\n") + "\n\n" + run_markdown(run, len(record["runs"])) + "\n"
        if args.map:
            page = with_section(page, map_markdown(record["fig4_proved_map"], Path(args.md).parent))
        Path(args.md).write_text(page)
    return 0


def prove_boxes(args, boxes: list, command: str) -> dict:
    """Try every box (at most ``--budget`` s each, ``--deadline`` s in all): the run's record."""
    model = problem()["model"]
    u = np.flatnonzero(model.initial.high > model.initial.low)
    box_area = float(np.prod(model.initial.high[u] - model.initial.low[u]))
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
    print(f"proved {proved_area:.4g} m^2 of {box_area:.4g} m^2 ({100 * proved_area / box_area:.4f} % of the box) "
          f"in {seconds:.0f} s ({cpu_seconds:.0f} CPU s)", flush=True)
    return {
        "command": command, "note": args.note,
        "order": args.order, "depth": args.depth, "budget": args.budget, "deadline": args.deadline,
        "jobs": args.jobs, "tolerance_per_second": TOL, "box_area_m2": box_area,
        "subdomains": len(boxes), "finished": len(done), "proved_area_m2": proved_area,
        "fraction_of_box_proved": proved_area / box_area,
        "attempted_area_m2": sum(4 * r["half"][0] * r["half"][1] for r in done),
        "seconds": seconds, "cpu_seconds": cpu_seconds, "results": done,
    }


def _box(r: dict) -> tuple[list, list]:
    """``(low, high)`` of a result's box."""
    return ([c - h for c, h in zip(r["center"], r["half"])], [c + h for c, h in zip(r["center"], r["half"])])


def proved_safe_boxes(r: dict) -> list:
    """The boxes of a result proved to reach L <= 1: the whole box when proved, else its proved
    sub-boxes (results recorded before sub-boxes were kept count only when wholly proved)."""
    if r["status"] == "proved":
        return [_box(r)]
    return [tuple(part) for part in r.get("proved_parts", [])]


def proved_map(runs: list, png: Path, command: str) -> dict:
    """Colour the estimated map's subdomains by what the runs prove (reach/bench/proved_map.py),
    draw it to ``png`` and return its record: area proved, colour counts, every attempt's outcome.

    Proved safe: results proved wholly, or their proved sub-boxes. Proved unsafe: results of status
    ``"unsafe"`` (a proof that every run of the box keeps L > 1 over the horizon); ``prove_box``
    attempts no such proof, so none are recorded."""
    rows = estimated_rows()
    results = [(k, r) for k, run in enumerate(runs, start=1) for r in run["results"]]
    safe = []
    for box in sorted((b for _, r in results for b in proved_safe_boxes(r)),   # largest first: a box
                      key=lambda b: -np.prod(np.subtract(b[1], b[0]))):        # inside a kept one adds nothing
        if not any(covers([kept], *box) for kept in safe):
            safe.append(box)
    unsafe = [_box(r) for _, r in results if r["status"] == "unsafe"]
    subs = [(r["low"], r["high"]) for r in rows]
    coloured = colour_map(subs, safe, unsafe)
    low, high = np.min([s[0] for s in subs], axis=0), np.max([s[1] for s in subs], axis=0)
    box_area = float(np.prod(high - low))
    proved_area = union_area(safe)
    attempts, other = _outcomes(results, rows, coloured)
    colours = [c["colour"] for c in coloured]
    counts = {name: colours.count(name) for name in COLOURS}
    partly = [i for i, c in enumerate(coloured) if c["colour"] == UNDECIDED and c["proved_safe_area"] > 0]
    outlines = _attempt_outlines(attempts, other, safe)
    plot_proved_map(subs, colours, safe, outlines, png,
                    f"CW SIREN closest approach (min L <= 1), {len(subs)} subdomains of the estimated map: "
                    f"{counts[PROVED_SAFE]} proved safe, {counts[PROVED_UNSAFE]} proved unsafe, "
                    f"{counts[UNDECIDED]} undecided;\nproved-safe boxes {proved_area:.4g} m^2 of {box_area:.4g} m^2 "
                    f"({100 * proved_area / box_area:.4f} %); blue: proof attempted, flight time reached",
                    zooms=_zoom_windows(safe, outlines, subs)[:3])
    print(f"map: {counts}, proved {proved_area:.4g} m^2 ({100 * proved_area / box_area:.4f} % of the box); "
          f"wrote {png}", flush=True)
    return {"png": str(png), "command": command, "box_area_m2": box_area, "proved_area_m2": proved_area,
            "fraction_of_box_proved": proved_area / box_area, "counts": counts,
            "proved_safe_boxes": [[list(lo), list(hi)] for lo, hi in safe],
            "subdomains_partly_proved": partly, "attempted_subdomains": attempts, "other_boxes": other,
            "runs_on_subdomains": [{"run": k, "command": runs[k - 1]["command"], "seconds": runs[k - 1]["seconds"],
                                    "cpu_seconds": runs[k - 1]["cpu_seconds"]}
                                   for k in sorted({a["run"] for a in attempts})],
            "montecarlo": json.loads(Path(ESTIMATED).read_text()).get("montecarlo")}


def _outcomes(results: list, rows: list, coloured: list) -> tuple[list, list]:
    """Every result's outcome (``results``: ``(run number, result)``), split into those of the
    map's subdomains (with the subdomain's index, estimated bound and proved colour) and the
    other boxes."""
    attempts, other = [], []
    for k, r in results:
        outcome = {"run": k, "center": r["center"], "half": r["half"], "status": r["status"],
                   "fraction": r["fraction"], "t_reached": r.get("t_reached"), "steps": r.get("steps"),
                   "last_h": r.get("last_h"), "error_at_end": r.get("error_at_end"), "seconds": r["seconds"],
                   "why": r["why"]}
        lo, hi = _box(r)
        index = next((i for i, row in enumerate(rows)
                      if np.allclose(row["low"], lo, atol=1e-9) and np.allclose(row["high"], hi, atol=1e-9)), None)
        if index is None:
            other.append(outcome)
        else:
            attempts.append({"subdomain": index, "low": rows[index]["low"], "high": rows[index]["high"],
                             "estimated_bound": rows[index]["bound"], "colour": coloured[index]["colour"],
                             "proved_area_m2": coloured[index]["proved_safe_area"], **outcome})
    return attempts, other


def _attempt_outlines(attempts: list, other: list, safe: list) -> list:
    """The attempted boxes proved neither safe (covered by proved boxes) nor unsafe, one outline
    each, labelled with the furthest flight time any attempt on it reached: the map's subdomains
    (solid) and the other boxes (dashed)."""
    furthest = {}
    for a in attempts + other:
        lo, hi = _box(a)
        if not covers(safe, lo, hi) and a["status"] != "unsafe":
            key = (tuple(lo), tuple(hi), "subdomain" not in a)
            furthest[key] = max(furthest.get(key, 0.0), a["t_reached"] or 0.0)
    return [{"low": list(lo), "high": list(hi), "dashed": dashed, "label": f"{_time_text(t)} s"}
            for (lo, hi, dashed), t in furthest.items()]


def _zoom_windows(boxes: list, outlines: list, subs: list) -> list:
    """Windows of the side panels: per proved box, the subdomains it meets (1 m wider); and one
    around the attempted subdomains too narrow for their label on the main panel (at least 6 m wide)."""
    zooms = []
    for box in boxes:
        near = [s for s in subs if meets(box, *s)]
        window = ([float(v) for v in np.min([s[0] for s in near], axis=0) - 1.0],
                  [float(v) for v in np.max([s[1] for s in near], axis=0) + 1.0])
        if window not in zooms:
            zooms.append(window)
    map_width = max(s[1][0] for s in subs) - min(s[0][0] for s in subs)
    narrow = [o for o in outlines if not o["dashed"] and o["high"][0] - o["low"][0] < 0.04 * map_width]
    if narrow:
        low = np.min([o["low"] for o in narrow], axis=0) - 1.0
        high = np.max([o["high"] for o in narrow], axis=0) + 1.0
        grow = max(0.0, 6.0 - (high[0] - low[0])) / 2
        zooms.append(([float(low[0] - grow), float(low[1])], [float(high[0] + grow), float(high[1])]))
    return zooms


def proved_summary(m: dict) -> dict:
    """The record's top-level figures, from the map: the proved boxes (none inside another), the
    area of their union (overlaps counted once) and its share of the box."""
    boxes = [{"center": [0.5 * (a + b) for a, b in zip(lo, hi)], "half": [0.5 * (b - a) for a, b in zip(lo, hi)]}
             for lo, hi in m["proved_safe_boxes"]]
    return {"proved_boxes": boxes, "proved_area_m2": m["proved_area_m2"], "box_area_m2": m["box_area_m2"],
            "fraction_of_box_proved": m["fraction_of_box_proved"]}


def run_markdown(s: dict, number: int) -> str:
    """One run as a section of the results page: the share proved, then one row per subdomain."""
    lines = [f"### Run {number}: {s['note']}" if s["note"] else f"### Run {number}", "",
             f"`{s['command']}` (order {s['order']}, {s['jobs']} processes, {s['budget']:g} s per subdomain, "
             f"split depth {s['depth']} at the event).", "",
             f"Proved: **{s['proved_area_m2']:.4g} m^2 of {s['box_area_m2']:.4g} m^2 "
             f"({100 * s['fraction_of_box_proved']:.4f} % of the box)**; attempted {s['attempted_area_m2']:.4g} m^2 "
             f"in {s['finished']} subdomains; {s['seconds']:.0f} s wall, {s['cpu_seconds']:.0f} CPU s.", "",
             "| subdomain (centre, half-widths, m) | outcome | proved | t reached (s) | steps | last h (s) | "
             "carried error at the end (x, y m; vx, vy m/s) | seconds |", "|---|---|---|---|---|---|---|---|"]
    for r in s["results"]:
        lines.append(f"| ({r['center'][0]:.4g}, {r['center'][1]:.4g}) +- ({r['half'][0]:.3g}, {r['half'][1]:.3g}) | "
                     f"{r['status']} | {100 * r['fraction']:.1f} % | {r.get('t_reached', 0):.0f} | {r.get('steps', 0)} | "
                     f"{(r.get('last_h') or 0):.3g} | {_error_text(r)} | {(r['seconds'] or 0):.0f} |")
    lines.append("")
    for r in s["results"]:
        if r.get("why"):
            lines.append(f"- ({r['center'][0]:.4g}, {r['center'][1]:.4g}): {r['why']}")
    return "\n".join(lines)


def map_markdown(m: dict, folder: Path) -> str:
    """The map's section of the results page in ``folder``: what is proved, what is only estimated
    and sampled."""
    c, mc = m["counts"], m["montecarlo"] or {}
    n = sum(c.values())
    lines = [MAP_SECTION, "",
             f"![map]({os.path.relpath(m['png'], folder)}) (`{m['command']}`)", "",
             f"The estimated map's {n} subdomains (results/cw_siren.json, benchmarks/cw_siren.py: estimated "
             f"remainder, not a proof) coloured by what the flowpipes of every run above prove "
             f"(reach/bench/proved_map.py): **{c[PROVED_SAFE]} proved safe, {c[PROVED_UNSAFE]} proved unsafe, "
             f"{c[UNDECIDED]} undecided**. A subdomain is proved safe only when proved boxes cover it entirely, "
             f"proved unsafe only on a proof that a run keeps L > 1 over the whole horizon (no such proof is "
             f"attempted; with the estimated largest min L at 0.77 none is expected). Proved-safe boxes: "
             f"**{m['proved_area_m2']:.4g} m^2 of {m['box_area_m2']:.4g} m^2 "
             f"({100 * m['fraction_of_box_proved']:.4f} % of the box)**, drawn as filled patches (ringed); "
             f"{len(m['subdomains_partly_proved'])} subdomains hold a proved part and stay undecided.", "",
             f"Only estimated and sampled: the other {100 * (1 - m['fraction_of_box_proved']):.3f} % of the box. "
             f"The estimated bounds of min L lie in [0.658, 0.769] (all <= 1), and the {mc.get('samples', 0):,} "
             f"Monte Carlo runs of results/cw_siren.json (`montecarlo`) have {mc.get('outside', '?')} sampled "
             f"minima outside their subdomain's bound ({mc.get('outside_without_slack', '?')} without the grid "
             f"slack), sampled min L in [{mc.get('sampled_range', [np.nan] * 2)[0]:.4f}, "
             f"{mc.get('sampled_range', [np.nan] * 2)[1]:.4f}], {mc.get('runs_meeting_requirement', '?'):,} "
             f"runs with min L <= 1: evidence, not a proof.", "",
             "Attempted subdomains of the map (blue outlines in the figure, labelled with the flight time "
             "the flowpipe reached):", "",
             "| subdomain (index: x, y in m) | size (m) | estimated min L | run | outcome | proved | t reached (s) | "
             "steps | last h (s) | carried error at the end (x, y m; vx, vy m/s) | seconds |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for a in m["attempted_subdomains"]:
        lo, hi = a["low"], a["high"]
        lines.append(f"| {a['subdomain']}: [{lo[0]:.6g}, {hi[0]:.6g}] x [{lo[1]:.6g}, {hi[1]:.6g}] | "
                     f"{hi[0] - lo[0]:.4g} x {hi[1] - lo[1]:.4g} | [{a['estimated_bound'][0]:.3f}, "
                     f"{a['estimated_bound'][1]:.3f}] | {a['run']} | {a['status']} | {100 * a['fraction']:.1f} % | "
                     f"{_time_text(a['t_reached'] or 0)} | {a['steps'] or 0} | "
                     f"{_step_text(a['last_h'])} | {_error_text(a)} | "
                     f"{(a['seconds'] or 0):.0f} |")
    lines += ["", "Runs on the map's subdomains: " + "; ".join(
        f"run {r['run']}: `{r['command']}`, {r['seconds']:.0f} s wall ({r['cpu_seconds']:.0f} CPU s)"
        for r in m["runs_on_subdomains"]) + ".",
        "", "Other boxes (not subdomains of the map) and their outcomes: " + "; ".join(
        f"({o['center'][0]:.4g}, {o['center'][1]:.4g}) +- ({o['half'][0]:.3g}, {o['half'][1]:.3g}) run {o['run']}: "
        f"{o['status']}" + (f" (t reached {_time_text(o['t_reached'])} s)" if o["status"] != "proved" else "")
        for o in m["other_boxes"]) + ".", ""]
    return "\n".join(lines)


def with_section(page: str, section: str) -> str:
    """``page`` with its map section replaced by ``section`` (added before "## The runs" if absent)."""
    if MAP_SECTION in page:
        start = page.index(MAP_SECTION)
        end = page.find("\n## ", start + len(MAP_SECTION))
        return page[:start] + section + ("\n" + page[end + 1:] if end >= 0 else "")
    anchor = page.find("## The runs")
    if anchor < 0:
        return page.rstrip("\n") + "\n\n" + section
    return page[:anchor] + section + "\n" + page[anchor:]


def _time_text(t: float) -> str:
    """A flight time in s: whole seconds, or two digits below 1 s."""
    return f"{t:.0f}" if t >= 1 or t == 0 else f"{t:.2g}"


def _step_text(h) -> str:
    """The last accepted step size in s (``-``: no step accepted)."""
    return f"{h:.3g}" if h else "-"


def _error_text(r: dict) -> str:
    return ", ".join(f"{v:.2g}" for v in r["error_at_end"]) if r.get("error_at_end") else "-"


def _cpu_seconds() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


if __name__ == "__main__":
    raise SystemExit(main())
