"""Executors: local processes and a real Dask LocalCluster give the same results, and the
results are right (closed-form thrust, a solve_ivp replay of the passive collision)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reach.bench.executors import DaskExecutor, LocalExecutor
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
    assert np.abs(K1 @ np.array(thrust[3][:4])).max() / 3600.0 > 7.0            # 7 N, t = 0
    assert closest_passive_approach(collision[3][:4], 260.0) <= 0.2               # the 0.2 m box
    assert {status for _, status, _, _ in safe} == {"unknown"}   # ARCH safe: no counterexample


N, MC = 0.00438138, 500.0
K1 = np.array([[-28.82867767694, 0.1004799482599, -1449.975419853, 0.004624472318875],
               [-0.08701567868523, -33.25619924505, 0.004624472318875, -1451.501346434]])
K2 = np.array([[-288.0287662715, 0.1312430397158, -9614.989795432, -3.41199964983e-07],
               [-0.1312430403689, -287.9999700959, -3.41199964983e-07, -9614.988297970]])


def cwh(K):
    def f(t, s):
        x, y, vx, vy = s
        F = K @ s
        return [vx, vy, 3 * N * N * x + 2 * N * vy + F[0] / MC, -2 * N * vx + F[1] / MC]
    return f


def closest_passive_approach(x0, abort):
    """Max-norm distance to the target after the abort at ``abort`` min (SRU01: horizon 300),
    by solve_ivp through approach (to the docking face x = -100), rendezvous and passive."""
    dock = lambda t, s: s[0] + 100.0
    dock.terminal, dock.direction = True, 1
    first = solve_ivp(cwh(K1), [0, abort], x0, events=dock, rtol=1e-10, atol=1e-9)
    second = solve_ivp(cwh(K2), [first.t[-1], abort], first.y[:, -1], rtol=1e-10, atol=1e-9)
    passive = solve_ivp(cwh(np.zeros((2, 4))), [abort, 300.0], second.y[:, -1], rtol=1e-10, atol=1e-9,
                        dense_output=True)
    t = np.linspace(abort, 300.0, 60001)
    return float(np.min(np.max(np.abs(passive.sol(t)[:2]), axis=0)))


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
