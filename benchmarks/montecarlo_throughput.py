"""Monte Carlo throughput: runs per second against a plain numpy loop, in the same run.

    python benchmarks/montecarlo_throughput.py [--runs N] [--repeat R] [--out results/montecarlo_throughput]

Instances: SRA01 (linear, passive abort at 120 min) and SRNA01 (nonlinear orbital dynamics) with
the four rendezvous properties of properties/rendezvous.yaml, and the thermostat with
properties/thermostat.yaml. For each, the median over ``repeat`` repetitions of

* the simulator with every property of the file monitored (:class:`reach.model.simulate.
  Simulator` and one :class:`reach.backends.montecarlo.SafetyMonitor` per property, all sharing
  one simulation);
* the plain numpy reference: one loop over the grid steps advancing every run by the exact
  one-step map of its mode (``expm`` of the augmented generator; RK4 with the simulator's two
  substeps on SRNA01), urgent guards tested at the grid points and taken there (no event
  location), the abort at the first grid point at or after the run's instant, every property
  tested at every step with its own vectorised test;
* both again timed by this process's CPU seconds (median of ``repeat``): on a shared machine
  the wall seconds carry the other processes' load, the CPU seconds much less of it;
* ``reach check --backend montecarlo`` on the thermostat, end to end (wall and CPU seconds,
  once: on a shared machine the CPU seconds are the process's own cost).

Writes ``OUT.md`` and ``OUT.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg

from reach.backends.montecarlo import SafetyMonitor, random_plan, switch_window
from reach.model import load_model
from reach.model.constraints import lambdify_margins
from reach.model.simulate import Simulator, single_threaded
from reach.spec import bind, load_properties

INSTANCES = [("SRA01", "models/SRA01.yaml", "properties/rendezvous.yaml"),
             ("SRNA01", "models/SRNA01.yaml", "properties/rendezvous.yaml"),
             ("thermostat", "models/thermostat.yaml", "properties/thermostat.yaml")]


def reference_loop(model, props, X0, tau, dt):
    """The plain loop (see the module docstring); returns each property's smallest depth per run."""
    names = list(model.modes)
    n, N = model.n, X0.shape[0]
    X = X0.copy()
    mode = np.full(N, names.index(model.initial.mode))
    steps = int(np.ceil(model.horizon / dt - 1e-9))
    maps = {}
    for m_index, name in enumerate(names):
        lin = model.modes[name].linear
        if lin is not None:
            M = np.zeros((n + 1, n + 1))
            M[:n, :n], M[:n, n] = lin
            E = scipy.linalg.expm(M * dt)
            maps[m_index] = (E[:n, :n].T.copy(), E[:n, n].copy())
    urgent = [(names.index(tr.source), names.index(tr.target), lambdify_margins(tr.guard, model.symbols))
              for tr in model.transitions if tr.urgent]
    window = [(names.index(tr.source), names.index(tr.target)) for tr in model.transitions if tr.window]
    tests = [{names.index(m): p.violation(m) for m in p.modes if p.violation(m) is not None} for p in props]
    depth = [np.full(N, np.inf) for _ in props]

    def monitor():
        for test, d in zip(tests, depth):
            for m_index, fn in test.items():
                sel = np.flatnonzero(mode == m_index)
                if sel.size:
                    d[sel] = np.minimum(d[sel], fn(X[sel])[1])

    def jumps(t):
        for source, target, guard in urgent:
            sel = np.flatnonzero(mode == source)
            if sel.size:
                mode[sel[np.all(guard(X[sel]) <= 0, axis=1)]] = target
        if tau is not None:
            for source, target in window:
                mode[(mode == source) & (tau <= t + 1e-9)] = target

    jumps(0.0)
    monitor()
    for k in range(steps):
        for m_index, name in enumerate(names):
            sel = np.flatnonzero(mode == m_index)
            if not sel.size:
                continue
            if m_index in maps:
                Phi, phi = maps[m_index]
                X[sel] = X[sel] @ Phi + phi
            else:
                rhs, Y, h = model.modes[name].rhs, X[sel], dt / 2
                for _ in range(2):
                    k1 = rhs(Y)
                    k2 = rhs(Y + 0.5 * h * k1)
                    k3 = rhs(Y + 0.5 * h * k2)
                    k4 = rhs(Y + h * k3)
                    Y = Y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
                X[sel] = Y
        jumps((k + 1) * dt)
        monitor()
    return depth


def simulate(model, props, X0, tau, sim):
    monitors = [SafetyMonitor(model, p, X0.shape[0]) for p in props]
    sim.run(X0, tau, observers=monitors)
    return [m.min_depth for m in monitors]


def timed(fn, repeat, cpu=False):
    """Median wall seconds of ``repeat`` calls (CPU seconds of this process with ``cpu``) and the
    last call's value."""
    clock = time.process_time if cpu else time.perf_counter
    times, value = [], None
    for _ in range(repeat):
        start = clock()
        value = fn()
        times.append(clock() - start)
    return statistics.median(times), value


def measure(label, model_file, prop_file, runs, repeat):
    model = load_model(model_file)
    props = [p for p in (bind(q, model) for q in load_properties(prop_file)) if p.modes]
    X0, tau = random_plan(model, switch_window(model), runs, np.random.default_rng(0))
    sim = Simulator(model)
    ours, depths = timed(lambda: simulate(model, props, X0, tau, sim), repeat)
    plain, ref_depths = timed(lambda: reference_loop(model, props, X0, tau, sim.dt), repeat)
    ours_cpu, _ = timed(lambda: simulate(model, props, X0, tau, sim), repeat, cpu=True)
    plain_cpu, _ = timed(lambda: reference_loop(model, props, X0, tau, sim.dt), repeat, cpu=True)
    gap = max(float(np.max(np.abs(a - b) / (1 + np.abs(b)), initial=0.0)) for a, b in zip(depths, ref_depths))
    return {"instance": label, "runs": runs, "steps": sim.steps, "properties": [p.id for p in props],
            "seconds": ours, "runs_per_s": runs / ours, "reference_seconds": plain,
            "reference_runs_per_s": runs / plain, "ratio": plain / ours,
            "cpu_runs_per_s": runs / ours_cpu, "reference_cpu_runs_per_s": runs / plain_cpu,
            "largest_relative_depth_gap": gap}


def thermostat_check():
    cmd = [sys.executable, "-m", "reach.cli", "check", "models/thermostat.yaml", "properties/thermostat.yaml",
           "--backend", "montecarlo"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    seconds, proc = timed(lambda: subprocess.run(cmd, capture_output=True, text=True), 1)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    reported = {line.split()[0]: line.split()[2] for line in proc.stdout.splitlines()[1:]
                if len(line.split()) > 3 and line.split()[2].replace(".", "").isdigit()}
    return {"command": " ".join(["reach"] + cmd[3:]), "seconds_end_to_end": seconds, "cpu_seconds": cpu,
            "exit": proc.returncode,
            "seconds_per_property": reported}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", default="results/montecarlo_throughput")
    args = parser.parse_args()
    rows = []
    started, load_before = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), os.getloadavg()[0]
    for label, model_file, prop_file in INSTANCES:
        with single_threaded():         # both sides: one BLAS thread (see Simulator)
            rows.append(measure(label, model_file, prop_file, args.runs, args.repeat))
        r = rows[-1]
        print(f"{label}: {r['runs_per_s']:,.0f} runs/s, reference {r['reference_runs_per_s']:,.0f} runs/s, "
              f"ratio {r['ratio']:.2f} (depth gap {r['largest_relative_depth_gap']:.1e})", flush=True)
    check = thermostat_check()
    load_after = os.getloadavg()[0]
    print(f"thermostat check: {check['seconds_end_to_end']:.2f} s end to end ({check['cpu_seconds']:.2f} s CPU), "
          f"exit {check['exit']}")
    out = Path(args.out)
    out.with_suffix(".json").write_text(json.dumps({"started": started, "load_average": [load_before, load_after],
                                                    "instances": rows, "thermostat_check": check}, indent=2))
    lines = ["# Monte Carlo throughput", "",
             f"`python benchmarks/montecarlo_throughput.py --runs {args.runs} --repeat {args.repeat}` ({started}, "
             f"load average {load_before:.1f} before, {load_after:.1f} after): median of {args.repeat}; every "
             "property of the file monitored; the reference is the plain numpy loop of the benchmark's docstring, "
             "measured in the same run. Wall seconds, and CPU seconds of the process (less sensitive to other "
             "processes on a shared machine).", "",
             "| instance | runs x steps | runs/s | reference runs/s | ratio | runs/s (CPU) | reference runs/s (CPU) "
             "| largest depth gap to the reference |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r['instance']} | {r['runs']} x {r['steps']} | {r['runs_per_s']:,.0f} | "
                     f"{r['reference_runs_per_s']:,.0f} | {r['ratio']:.2f} | {r['cpu_runs_per_s']:,.0f} | "
                     f"{r['reference_cpu_runs_per_s']:,.0f} | {r['largest_relative_depth_gap']:.1e} |")
    per = ", ".join(f"{k} {v} s" for k, v in check["seconds_per_property"].items())
    lines += ["", f"`{check['command']}`: {check['seconds_end_to_end']:.2f} s end to end, "
              f"{check['cpu_seconds']:.2f} s CPU (user + system), once "
              f"(exit {check['exit']}; reported per property: {per}).", ""]
    out.with_suffix(".md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
