"""Executors: local processes and a real Dask LocalCluster give the same results, and the
results are right (closed-form thrust, a solve_ivp replay of the passive collision)."""

import numpy as np
import pytest

from arch import K1, NEWTON, closest_passive_approach
from reach.executors import DaskExecutor, LocalExecutor
from reach.bench.runner import run_unit

UNITS = [("models/SRA01.yaml", "properties/thrust_7N.yaml", "montecarlo", {"samples": 40, "search_rounds": 0}),
         ("models/SRU01.yaml", "properties/collision_box_0p2.yaml", "montecarlo", {"samples": 40, "search_rounds": 0}),
         ("models/SRA02.yaml", "properties/rendezvous.yaml", "montecarlo", {"samples": 40, "search_rounds": 0})]


def _essence(results):
    out = {}
    for index, (state, rows) in results:
        assert state == "ok"
        out[index] = [(r["property"], r["status"], r["details"].get("closest_depth"),
                       (r["counterexample"] or {}).get("initial_state")) for r in rows]
    return out


def test_local_processes_and_dask_local_cluster_agree():
    distributed = pytest.importorskip("distributed")
    local = _essence(LocalExecutor(jobs=2).map_unordered(run_unit, UNITS))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        dask = _essence(DaskExecutor(client).map_unordered(run_unit, UNITS))
    serial = _essence(LocalExecutor(jobs=1).map_unordered(run_unit, UNITS))
    assert local == dask == serial
    (thrust,), (collision,), safe = local[0], local[1], local[2]
    assert thrust[1] == "unsafe" and collision[1] == "unsafe"
    assert np.abs(K1 @ np.array(thrust[3][:4])).max() / NEWTON > 7.0        # 7 N at t = 0
    assert closest_passive_approach(collision[3], 260.0, 300.0) <= 0.2   # the 0.2 m box
    assert {status for _, status, _, _ in safe} == {"unknown"}   # ARCH safe: no counterexample


def test_time_limit_stops_a_unit():
    slow = [("models/SRNA01.yaml", "properties/rendezvous.yaml", "montecarlo", {"samples": 5000})]
    ((index, (state, value)),) = list(LocalExecutor(jobs=1).map_unordered(run_unit, slow, time_limit=1.0))
    assert state == "timeout" and value is None


def test_taylor_subdomains_on_processes_and_dask_match_one_process():
    """ADS levels and rigorous sweeps as executor units: same subdomains and bounds."""
    import dataclasses

    distributed = pytest.importorskip("distributed")
    from reach.backends.taylor import BACKEND
    from reach.model.loader import load_model
    from reach.spec.properties import bind, load_properties

    model = dataclasses.replace(load_model("models/SRNA01.yaml"), horizon=10.0)
    prop = {p.id: bind(p, model) for p in load_properties("properties/rendezvous_events.yaml")}["thrust_y_min"]
    base = {"e_tol": 1e-12, "max_splits": 1, "remainder": "rigorous"}

    def essence(result):
        return [(tuple(r["low"]), tuple(r["high"]), r["bound"]) for r in result.details["subdomains"]]

    serial = essence(BACKEND.check(model, prop, base))
    local = essence(BACKEND.check(model, prop, {**base, "jobs": 2}))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        dask = essence(BACKEND.check(model, prop, {**base, "scheduler": client}))
    assert len(serial) == 2 and serial == local == dask


MC_UNITS = [("models/SRA02.yaml", "properties/rendezvous.yaml"),
            ("models/SRU01.yaml", "properties/collision_box_0p2.yaml")]


def _mc_essence(model_file, prop_file, options):
    from reach.checking import check_files

    return [(r.property, r.status, r.details["closest_depth"], r.details["violation_probability_upper_95"],
             r.details["blocked_runs"], None if r.counterexample is None else r.counterexample.initial_state)
            for r in check_files(model_file, prop_file, "montecarlo", options)]


@pytest.mark.parametrize("model_file,prop_file", MC_UNITS)
def test_monte_carlo_batches_give_the_same_answer_whatever_the_split_and_the_executor(model_file, prop_file):
    """2500 i.i.d. runs: one batch in this process, three batches in this process, three
    batches on two worker processes, and on a Dask cluster: identical verdicts, closest
    approaches, bounds and counterexamples for the seed."""
    base = {"samples": 2500, "search_rounds": 1, "search_size": 50, "optimise": False, "seed": 3}
    one = _mc_essence(model_file, prop_file, base)
    split = _mc_essence(model_file, prop_file, {**base, "batch": 1000})
    processes = _mc_essence(model_file, prop_file, {**base, "batch": 1000, "jobs": 2})
    assert one == split == processes
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        dask = _mc_essence(model_file, prop_file, {**base, "batch": 700, "scheduler": client})
    assert dask == one


WORKERS_OF_A_KILLED_PARENT = """
import os, sys, time
from reach.executors import LocalExecutor
def pid_then_sleep(seconds):
    os.write(1, f"{os.getpid()}\\n".encode())  # one write: the two workers' lines never interleave
    time.sleep(seconds)
for _ in LocalExecutor(jobs=2).map_unordered(pid_then_sleep, [(60,), (60,)]):
    pass
"""


def test_local_workers_end_with_a_killed_parent():
    """A ``reach bench -j 2`` ended by SIGTERM or SIGKILL (a CI job cancelled) leaves no worker
    computing on: each worker gets SIGTERM when its parent dies."""
    import os
    import signal
    import subprocess
    import sys
    import time
    parent = subprocess.Popen([sys.executable, "-c", WORKERS_OF_A_KILLED_PARENT], stdout=subprocess.PIPE, text=True)
    workers = [int(parent.stdout.readline()) for _ in range(2)]
    parent.kill()
    parent.wait()

    def alive(pid):
        try:
            with open(f"/proc/{pid}/stat") as f:
                return f.read().split(")")[-1].split()[0] != "Z"
        except FileNotFoundError:
            return False
    for _ in range(100):
        if not any(alive(p) for p in workers):
            break
        time.sleep(0.1)
    survivors = [p for p in workers if alive(p)]
    for p in survivors:
        os.kill(p, signal.SIGKILL)
    assert not survivors


def _spin(seconds):
    """A unit that computes for ``seconds`` (a Monte Carlo batch would)."""
    import time as clock
    end = clock.time() + seconds
    while clock.time() < end:
        pass
    return seconds


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def test_an_interrupt_ends_the_workers_at_once():
    """Ctrl-C while the pool runs (a SIGALRM raising KeyboardInterrupt after 1 s, in wait())
    ends its workers at once: the pool does not wait for the units under way (60 s each)."""
    import signal
    import time as clock

    executor = LocalExecutor(jobs=2)
    previous = signal.signal(signal.SIGALRM, _interrupt)
    begin = clock.time()
    try:
        signal.setitimer(signal.ITIMER_REAL, 1.0)
        with pytest.raises(KeyboardInterrupt):
            list(executor.map_unordered(_spin, [(60.0,), (60.0,), (60.0,)]))
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert clock.time() - begin < 30
