"""Taylor event bounds against Monte Carlo: every sampled run's extremum inside its subdomain's bound.

For each event property the taylor back-end is run twice on the same ADS subdomains, with the
estimated remainder (eq. 28) and with the rigorous one (verified enclosure). ``--samples``
i.i.d. initial states (default 10,000) are simulated once (reach.model.simulate, grid ``--dt``);
for every run the sampled extremum of the quantity must lie in the bound of the subdomain that
holds its initial state — exactly above a maximum's lower end / below a minimum's upper end up to
the grid slack, strictly on the outer side. Prints per property: subdomains, runs outside
(estimated, rigorous), bound widths and their ratio, seconds.

    python benchmarks/taylor_vs_montecarlo.py                      # SRNA01 events
    python benchmarks/taylor_vs_montecarlo.py --model models/cw_siren.yaml \\
        --properties properties/cw_siren.yaml --samples 10000
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np

from reach.backends.montecarlo.event_sampling import outside_bounds, sample_extrema
from reach.backends.taylor import BACKEND
from reach.model.loader import load_model
from reach.spec.properties import bind, load_properties


def main(argv=None) -> int:
    warnings.simplefilter("ignore", RuntimeWarning)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="models/SRNA01.yaml")
    ap.add_argument("--properties", default="properties/rendezvous_events.yaml")
    ap.add_argument("--only", nargs="*", default=["thrust_x_min", "thrust_y_max", "los_upper_margin"])
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--dt", type=float, default=None)
    ap.add_argument("--e-tol", type=float, default=None)
    ap.add_argument("--max-splits", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", default=None, help="write the table to this file")
    args = ap.parse_args(argv)

    model = load_model(args.model)
    props = [bind(p, model) for p in load_properties(args.properties) if not args.only or p.id in args.only]
    rng = np.random.default_rng(2026)
    low, high = model.initial.low, model.initial.high
    x0 = low + (high - low) * rng.random((args.samples, model.n))
    uncertain = np.flatnonzero(high > low)
    rows = []
    for prop in props:
        options = {"max_splits": args.max_splits, "jobs": args.jobs}
        if args.e_tol is not None:
            options["e_tol"] = args.e_tol
        start = time.perf_counter()
        est = BACKEND.check(model, prop, {**options, "remainder": "estimated"})
        t_est = time.perf_counter() - start
        start = time.perf_counter()
        rig = BACKEND.check(model, prop, {**options, "remainder": "rigorous"})
        t_rig = time.perf_counter() - start
        start = time.perf_counter()
        monitor, _, dt = sample_extrema(model, prop, x0, args.dt)
        t_mc = time.perf_counter() - start
        values = monitor.extrema()
        subs_e, subs_r = est.details["subdomains"], rig.details["subdomains"]
        width_e = np.array([r["bound"][1] - r["bound"][0] for r in subs_e])
        width_r = np.array([r["bound"][1] - r["bound"][0] for r in subs_r])
        row = {
            "property": prop.id, "subdomains": len(subs_r), "samples": args.samples, "dt": dt,
            "grid_slack": monitor.slack,
            "sampled_range": [float(np.min(values)), float(np.max(values))],
            "estimated_bound": est.bound, "rigorous_bound": rig.bound, "rigorous_status": rig.status.value,
            "outside_estimated": outside_bounds(subs_e, x0, values, uncertain, prop.sense, monitor.slack),
            "outside_rigorous": outside_bounds(subs_r, x0, values, uncertain, prop.sense, monitor.slack),
            "width_ratio_median": float(np.median(width_r / np.maximum(width_e, 1e-300))),
            "width_ratio_max": float(np.max(width_r / np.maximum(width_e, 1e-300))),
            "seconds": {"estimated": t_est, "rigorous": t_rig, "montecarlo": t_mc},
        }
        rows.append(row)
        print(f"{prop.id:24s} subdomains {row['subdomains']:3d}  outside est {row['outside_estimated']}"
              f" rig {row['outside_rigorous']} of {args.samples}  sampled [{row['sampled_range'][0]:.6g},"
              f" {row['sampled_range'][1]:.6g}]  est [{est.bound[0]:.6g}, {est.bound[1]:.6g}]"
              f"  rig [{rig.bound[0]:.6g}, {rig.bound[1]:.6g}] {rig.status.value}  width rig/est median"
              f" {row['width_ratio_median']:.3g} max {row['width_ratio_max']:.3g}  s est {t_est:.1f}"
              f" rig {t_rig:.1f} mc {t_mc:.1f}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1, default=float)
    return 1 if any(r["outside_estimated"] or r["outside_rigorous"] for r in rows) else 0


if __name__ == "__main__":
    raise SystemExit(main())
