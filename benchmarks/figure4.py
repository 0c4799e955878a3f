"""The panels of Fig. 4 of the rendezvous benchmark paper (004_6079856ecf6fcec7.txt), from reach's
own sets, into results/plots/fig4_*.png, with their size and drawing time in
results/plots/figure4.json:

* positions without Passive: star on the linear model (SRA02's approach and rendezvous modes) and
  taylor (rigorous step enclosures) on the nonlinear SRNA01 with Monte Carlo runs overlaid;
* velocity in mode 2 (rendezvous) with the octagon of the velocity requirement;
* thrust Fx and Fy against time with the 10 N limits;
* positions after a Passive transition in [120, 125] min with the collision box.

    .venv/bin/python benchmarks/figure4.py            (about two minutes on one core)
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from reach.checking import check_model, resolve_backend  # noqa: E402
from reach.model import load_model  # noqa: E402
from reach.plotting.axes import parse_vars  # noqa: E402
from reach.plotting.reach_sets import plot_reach_sets  # noqa: E402
from reach.spec import bind, load_properties  # noqa: E402

OUT = ROOT / "results" / "plots"
RENDEZVOUS = ROOT / "properties" / "rendezvous.yaml"
STAR = {"keep_sets": True, "step": 1.0}                 # 1 min cells: thin segments
MONTECARLO = {"keep_sets": True, "samples": 200, "search_rounds": 0, "optimise": False}


def checked(model_file, property_file, backend, options, only=None):
    model = load_model(ROOT / model_file)
    bound = [bind(p, model) for p in load_properties(property_file) if only is None or p.id in only]
    start = time.perf_counter()
    results = check_model(resolve_backend(backend), model, bound, options)
    seconds = time.perf_counter() - start
    print(f"{model.name} {backend}: " + ", ".join(f"{r.property} {r.status.value}" for r in results)
          + f" ({seconds:.1f} s)", flush=True)
    return model, bound, results, seconds


def panel(name, model, results, bound, variables, modes, title, rows):
    out = OUT / f"fig4_{name}.png"
    axes = parse_vars(model, variables, bound)
    start = time.perf_counter()
    summary = plot_reach_sets(model, results, bound, axes, out, modes=modes, title=title)
    seconds = time.perf_counter() - start
    rows.append({"panel": name, "file": str(out.relative_to(ROOT)), "kb": round(out.stat().st_size / 1024, 1),
                 "draw_seconds": round(seconds, 2), "drawn": summary})
    print(f"  {out.name}: {rows[-1]['kb']} KB, {seconds:.1f} s", flush=True)


def main() -> int:
    rows, checks = [], {}
    linear, bound, star, checks["SRA02 star"] = checked("models/SRA02.yaml", RENDEZVOUS, "star", STAR)
    nonlinear, events, taylor, checks["SRNA01 taylor"] = checked(
        "models/SRNA01.yaml", ROOT / "properties" / "rendezvous_events.yaml", "taylor",
        {"keep_sets": True, "remainder": "rigorous"}, only={"speed"})
    _, nl_bound, sampled, checks["SRNA01 montecarlo"] = checked("models/SRNA01.yaml", RENDEZVOUS, "montecarlo",
                                                                MONTECARLO)
    modes12 = ["approach", "rendezvous"]
    panel("positions_star_linear", linear, {"star": star}, bound, "x,y", modes12,
          "SRA02 (linear): positions in approach and rendezvous, star segments", rows)
    panel("positions_taylor_nonlinear", nonlinear, {"taylor": taylor, "montecarlo": sampled}, nl_bound,
          "x,y", modes12, "SRNA01 (nonlinear): taylor step enclosures with Monte Carlo runs", rows)
    panel("velocity_mode2", linear, {"star": star}, bound, "vx,vy", ["rendezvous"],
          "SRA02: velocity in rendezvous (mode 2) against the octagon", rows)
    panel("thrust_x", linear, {"star": star}, bound, "t,Fx", modes12, "SRA02: thrust Fx against time", rows)
    panel("thrust_y", linear, {"star": star}, bound, "t,Fy", modes12, "SRA02: thrust Fy against time", rows)
    panel("positions_passive", linear, {"star": star}, bound, "x,y", ["passive"],
          "SRA02: positions after a Passive transition in [120, 125] min", rows)
    (OUT / "figure4.json").write_text(json.dumps({"check_seconds": checks, "panels": rows}, indent=1))
    print(f"wrote {OUT / 'figure4.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
