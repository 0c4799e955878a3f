"""Hylaa against the star back-end on the same rendezvous instances, in the same run.

Hylaa (PyPI ``hylaa``, generalized star sets, discrete time) is not a dependency of reach:
install it into a separate virtual environment and point ``--hylaa-python`` at it::

    python3 -m venv /work/hylaa-venv && /work/hylaa-venv/bin/pip install hylaa "swiglpk==5.0.10"
    python benchmarks/hylaa_vs_star.py                       # SRA01, SRA08, SRU02
    python benchmarks/hylaa_vs_star.py SRA02 --hylaa-repeat 3

(swiglpk 5.0.12 and 5.0.13 break Hylaa 2.0.2: GLPK aborts in ``glp_set_mat_row`` with "column
index out of range"; 5.0.10 works.)

The Hylaa side follows its ``examples/rendezvous`` encoding (modes P2, P3, passive and an
error mode; step 0.1 min; deaggregation; error guards for the LOS cone, the velocity
octagon and the passive-mode box of half-width 0.2 m), instantiated with the closed-loop
matrices, abort window, initial box and horizon read from our model file, so both tools
check the same instance. The star side checks the same three requirements (``los`` and
``velocity`` of properties/rendezvous.yaml, ``collision_0p2`` of
properties/collision_box_0p2.yaml), one property per call, in continuous time. Times are
wall-clock seconds of the verification calls only (model loading and imports excluded),
the median over ``--hylaa-repeat`` / ``--star-repeat`` runs (the first star run on a model
also extracts its matrices from the symbolic model; later runs reuse them, as Hylaa is
handed matrices directly); the ratio is Hylaa / star.

This file has two roles: run with the project's Python it is the driver; run by the Hylaa
interpreter with ``--hylaa-worker SPEC.json`` it builds and runs one Hylaa automaton and
prints a JSON line (it then imports nothing from reach).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STAR_PROPERTIES = [("properties/rendezvous.yaml", "los"), ("properties/rendezvous.yaml", "velocity"),
                   ("properties/collision_box_0p2.yaml", "collision_0p2")]


# ---------------------------------------------------------------------- Hylaa worker

def hylaa_worker(spec_file: str) -> None:
    """Build the Hylaa automaton of examples/rendezvous for ``spec`` and run it."""
    from hylaa import aggstrat, lputil
    from hylaa.core import Core
    from hylaa.hybrid_automaton import HybridAutomaton
    from hylaa.settings import HylaaSettings, PlotSettings
    from hylaa.stateset import StateSet

    spec = json.loads(Path(spec_file).read_text())
    lo, hi = spec["window"]
    if lo == hi:
        lo = hi = hi + 1e-4        # as the example: switch at a single step, not at two
    ha = HybridAutomaton(f"rendezvous {spec['name']}")

    def dynamics(mode):
        A, b = spec["A"][mode], spec["b"][mode]
        return [row + [bi] for row, bi in zip(A, b)] + [[0.0] * (len(b) + 1)]

    clock = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    octagon = [[-1, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0], [0, -1, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0],
               [-1, -1, 0, 0, 0, 0], [1, 1, 0, 0, 0, 0], [-1, 1, 0, 0, 0, 0], [1, -1, 0, 0, 0, 0]]
    octagon_rhs = [100, 100, 100, 100, 141.1, 141.1, 141.1, 141.1]

    p2 = ha.new_mode("P2")
    p2.set_dynamics(dynamics("approach"))
    p2.set_invariant([[1.0, 0, 0, 0, 0, 0], clock], [-100.0, hi])
    p3 = ha.new_mode("P3")
    p3.set_dynamics(dynamics("rendezvous"))
    p3.set_invariant(octagon + [clock], octagon_rhs + [hi])
    passive = ha.new_mode("passive")
    passive.set_dynamics(dynamics("passive"))
    error = ha.new_mode("error")

    ha.new_transition(p2, p3).set_guard(octagon, octagon_rhs)
    for source in (p2, p3):
        ha.new_transition(source, passive).set_guard([[0, 0, 0, 0, -1.0, 0]], [-lo])

    rad = 0.2
    ha.new_transition(passive, error).set_guard(
        [[1, 0, 0, 0, 0, 0], [-1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, -1, 0, 0, 0, 0]], [rad] * 4)
    ha.new_transition(p3, error, "los1").set_guard([[1, 0, 0, 0, 0, 0]], [-100])
    ha.new_transition(p3, error, "los2").set_guard([[-0.57735, 1, 0, 0, 0, 0]], [0])
    ha.new_transition(p3, error, "los3").set_guard([[-0.57735, -1, 0, 0, 0, 0]], [0])
    limit = 0.055 * 60
    h, w = limit * math.cos(math.pi / 8), limit * math.sin(math.pi / 8)
    for k, (row, rhs) in enumerate([([0, 0, 1, 0], -h), ([0, 0, -1, 0], -h), ([0, 0, 0, 1], -h),
                                    ([0, 0, 0, -1], -h), ([0, 0, 1, 1], -(w + h)),
                                    ([0, 0, -1, 1], -(w + h)), ([0, 0, -1, -1], -(w + h)),
                                    ([0, 0, 1, -1], -(w + h))]):
        ha.new_transition(p3, error, f"v{k}").set_guard([row + [0, 0]], [rhs])

    box = [tuple(b) for b in spec["initial"]] + [(1.0, 1.0)]
    init = [StateSet(lputil.from_box(box, p2), p2)]
    settings = HylaaSettings(spec["step"], spec["horizon"])
    settings.plot.plot_mode = PlotSettings.PLOT_NONE
    settings.stdout = HylaaSettings.STDOUT_NONE
    settings.stop_on_aggregated_error = False
    settings.aggstrat.deaggregate = True
    settings.aggstrat.deagg_preference = aggstrat.Aggregated.DEAGG_LEAVES_FIRST

    start = time.perf_counter()
    result = Core(ha, settings).run(init)
    seconds = time.perf_counter() - start
    print(json.dumps({"seconds": seconds, "concrete_error": bool(result.has_concrete_error),
                      "aggregated_error": bool(result.has_aggregated_error)}))


# ---------------------------------------------------------------------- driver

def hylaa_spec(model, step: float) -> dict:
    """The instance as plain numbers for the worker (closed loops, window, box, horizon)."""
    window = next(tr.window for tr in model.transitions if tr.window is not None)
    A = {name: mode.linear[0].tolist() for name, mode in model.modes.items()}
    b = {name: mode.linear[1].tolist() for name, mode in model.modes.items()}
    return {"name": model.name, "A": A, "b": b, "window": [window[1], window[2]],
            "initial": [[float(lo), float(hi)] for lo, hi in zip(model.initial.low, model.initial.high)],
            "horizon": float(model.horizon), "step": step}


def run_hylaa(python: str, spec: dict, timeout: float) -> dict:
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(spec, f)
    try:
        out = subprocess.run([python, __file__, "--hylaa-worker", f.name], capture_output=True,
                             text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:g} s"}
    finally:
        Path(f.name).unlink()
    if out.returncode != 0:
        return {"error": (out.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_star(model, props, options: dict) -> dict:
    from reach.backends.star import BACKEND
    verdicts, seconds = {}, 0.0
    for prop in props:
        start = time.perf_counter()
        result = BACKEND.check(model, prop, options)
        seconds += time.perf_counter() - start
        verdicts[prop.id] = result.status.value
    return {"seconds": seconds, "verdicts": verdicts}


def hylaa_verdict(result: dict) -> str:
    if "error" in result:
        return f"did not run ({result['error']})"
    if result["concrete_error"]:
        return "UNSAFE (concrete error)"
    if result["aggregated_error"]:
        return "error reachable, no concrete violation"
    return "SAFE"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("instances", nargs="*", default=["SRA01", "SRA08", "SRU02"])
    parser.add_argument("--hylaa-python", default="/work/hylaa-venv/bin/python")
    parser.add_argument("--hylaa-step", type=float, default=0.1)
    parser.add_argument("--hylaa-repeat", type=int, default=1, help="Hylaa runs (median reported)")
    parser.add_argument("--star-repeat", type=int, default=3, help="star runs (median reported)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per Hylaa run")
    args = parser.parse_args(argv)

    sys.path.insert(0, str(ROOT))
    import reach.backends.montecarlo  # noqa: F401  (imported before timing: replays use it)
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties

    def median(values):
        values = sorted(values)
        return values[len(values) // 2]

    print(f"{'instance':9} {'hylaa s':>9} {'star s':>8} {'ratio':>7}  hylaa verdict | star verdicts")
    for name in args.instances:
        model = load_model(ROOT / "models" / f"{name}.yaml")
        props = [bind(p, model) for file, pid in STAR_PROPERTIES
                 for p in load_properties(ROOT / file) if p.id == pid]
        hylaa_runs = [run_hylaa(args.hylaa_python, hylaa_spec(model, args.hylaa_step), args.timeout)
                      for _ in range(args.hylaa_repeat)]
        star_runs = [run_star(model, props, {}) for _ in range(args.star_repeat)]
        star_s = median([r["seconds"] for r in star_runs])
        verdicts = " ".join(f"{k}={v}" for k, v in star_runs[0]["verdicts"].items())
        ok = [r for r in hylaa_runs if "error" not in r]
        if ok:
            hylaa_s = median([r["seconds"] for r in ok])
            print(f"{name:9} {hylaa_s:9.2f} {star_s:8.2f} {hylaa_s / star_s:7.1f}  "
                  f"{hylaa_verdict(ok[0])} | {verdicts}", flush=True)
        else:
            print(f"{name:9} {'-':>9} {star_s:8.2f} {'-':>7}  {hylaa_verdict(hylaa_runs[0])} | {verdicts}",
                  flush=True)
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--hylaa-worker":
        hylaa_worker(sys.argv[2])
    else:
        sys.exit(main())
