"""VTXO mission supervisor: star verdicts and times, the Zeno lint, and a mission timeline.

    python benchmarks/vtxo_supervisor.py

Prints a table (property, verdict, seconds) of the star back-end on
models/vtxo_supervisor.yaml with properties/vtxo_supervisor.yaml, the lint findings of the
deliberately Zeno variant, and writes results/plots/vtxo_supervisor_timeline.png: mode
against time for the runs with every transient at its shortest (t_min) and longest (t_max)
duration, with a zoom on the first orbits after commissioning.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from reach.backends.star import BACKEND  # noqa: E402
from reach.bench.plots import plot_timeline  # noqa: E402
from reach.model import load_model  # noqa: E402
from reach.model.simulate import Simulator  # noqa: E402
from reach.spec import bind, load_properties  # noqa: E402

MODEL = ROOT / "models" / "vtxo_supervisor.yaml"
PROPS = ROOT / "properties" / "vtxo_supervisor.yaml"
ZENO = ROOT / "models" / "vtxo_supervisor_zeno.yaml"
TMIN = ROOT / "models" / "vtxo_supervisor_tmin.yaml"
OUT = ROOT / "results" / "plots" / "vtxo_supervisor_timeline.png"


def one_run(model, dt: float = 10.0):
    """The model's single deterministic run from its initial state: (t, mode names)."""
    traj = Simulator(model, dt).run(model.initial.low[None], None, record=True)
    t, modes, _ = traj.path[0]
    names = list(model.modes)
    return t, [names[int(m)] for m in modes]


def main() -> int:
    import os
    os.chdir(ROOT)                       # file names in findings relative to the project
    model = load_model(MODEL.relative_to(ROOT))
    props = [bind(p, model) for p in load_properties(PROPS)]
    print(f"star back-end on {model.name} ({len(model.modes)} modes, {len(model.transitions)} transitions, "
          f"horizon {model.horizon:g} {model.units.time})")
    print("| property | verdict | seconds | stars | LPs |")
    print("|---|---|---|---|---|")
    for prop in props:
        start = time.perf_counter()
        result = BACKEND.check(model, prop)
        seconds = time.perf_counter() - start
        d = result.details
        print(f"| {prop.id} | {result.status.value} | {seconds:.2f} | {d.get('stars')} | {d.get('lps')} |")

    print(f"\nlint {ZENO.relative_to(ROOT)}:")
    for line in load_model(ZENO.relative_to(ROOT)).lints or ["no findings"]:
        print(f"  {line}")

    runs = []
    for label, m in (("transients at t_min = 9 s", load_model(TMIN)), ("transients at t_max = 3 min", model)):
        t, names = one_run(m)
        end = t[names.index("end")]
        runs.append((f"{label}: end at {end:.2f} h", t, names))
        print(f"{label}: mode 'end' reached at t = {end:.4f} h")
    commissioning = model.constants["T_com"]
    plot_timeline(runs, list(model.modes), OUT, title=f"{model.name}: mission timeline (simulated)",
                  time_unit=model.units.time, zoom=(commissioning - 5, commissioning + 3 * 32.5 + 5))
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
