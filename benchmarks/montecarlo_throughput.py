"""Monte Carlo throughput: simulated runs per second on an ARCH rendezvous instance.

    python benchmarks/montecarlo_throughput.py [MODEL] [--runs N]

Reports runs/s for the bare simulator (every grid state visited, no property) and with the
four rendezvous properties monitored, median of three repetitions.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from reach.backends.montecarlo import SafetyMonitor, random_plan, switch_window
from reach.model import load_model
from reach.model.simulate import Simulator
from reach.spec import bind, load_properties


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("model", nargs="?", default="models/SRA01.yaml")
    parser.add_argument("--runs", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    model = load_model(args.model)
    props = [p for p in (bind(q, model) for q in load_properties("properties/rendezvous.yaml")) if p.modes]
    X, tau = random_plan(model, switch_window(model), args.runs, np.random.default_rng(0))
    sim = Simulator(model)
    for label, with_props in [("simulator only", False), ("with 4 properties monitored", True)]:
        times = []
        for _ in range(args.repeat):
            monitors = [SafetyMonitor(model, p, args.runs) for p in props] if with_props else []
            start = time.perf_counter()
            sim.run(X, tau, observers=monitors)
            times.append(time.perf_counter() - start)
        median = statistics.median(times)
        steps = int(np.ceil(model.horizon / sim.dt))
        print(f"{model.name} {label}: {args.runs} runs x {steps} steps in {median:.2f} s "
              f"-> {args.runs / median:,.0f} runs/s ({args.runs * steps / median:,.3g} states/s)")


if __name__ == "__main__":
    main()
