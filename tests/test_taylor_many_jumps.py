"""taylor's estimated event bounds on runs with many jumps and on switches around the horizon,
against runs integrated by solve_ivp with event detection (and the closed form).

A 1-D docking against a bumper: ``x' = v, v' = -a`` (a pull towards the dock), and the urgent
switch ``x <= 0, v <= 0`` resets ``v`` to ``-e v`` (restitution ``e = 0.5``) into mode
``rebound``, again on every later contact. From ``x0`` in [1, 1.2], ``v0`` in [-0.2, -0.1] the
first contact is at ``t1 = (sqrt(v0^2 + 2 a x0) - |v0|) / a`` (4.49 to 8.44 s) with speed
``vi = sqrt(v0^2 + 2 a x0)``; each bounce then lasts ``2 e^k vi / a``, halving, so some runs
bounce five times before t = 40 and their jumps accumulate (Zeno) from t = 41.96. The horizons
put the first contact (6 s), the second (28 s) and a run of fast bounces (40 s) across the
horizon.
"""

from __future__ import annotations

from functools import lru_cache
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import reach.backends.taylor as taylor
from reach.backends.taylor import BACKEND, Options
from reach.backends.taylor import deadline as deadline_module
from reach.result import Status
from model_files import load_files

A, E = 0.01, 0.5

DOCK = """
name: dock
state: [x, v, t]
constants: {{a: 0.01, e: 0.5}}
modes:
  inbound:
    flow: {{x: v, v: "-a", t: 1}}
    invariant: ["x >= 0"]
  rebound:
    flow: {{x: v, v: "-a", t: 1}}
    invariant: ["x >= 0"]
transitions:
  - {{from: inbound, to: rebound, guard: ["x <= 0", "v <= 0"], urgent: true, reset: {{v: "-e*v"}}}}
  - {{from: rebound, to: rebound, guard: ["x <= 0", "v <= 0"], urgent: true, reset: {{v: "-e*v"}}}}
initial: {{mode: inbound, box: {{x: [1.0, 1.2], v: [-0.2, -0.1], t: 0}}}}
horizon: {horizon}
"""

# (mode, sense, quantity): the first contact, the rebound speeds, the apex, the last time in
# each mode
EVENTS = {
    "first_contact": ("rebound", "min", "t"),
    "rebound_v_max": ("rebound", "max", "v"),
    "rebound_v_min": ("rebound", "min", "v"),
    "apex": ("rebound", "max", "x"),
    "last_inbound": ("inbound", "max", "t"),
    "last_rebound": ("rebound", "max", "t"),
}
PROPS = "properties:\n" + "".join(
    f"  - {{id: {name}, kind: event, modes: [{mode}], {'maximize' if sense == 'max' else 'minimize'}: {q}, "
    f"require: \"{'<=' if sense == 'max' else '>='} 0\"}}\n" for name, (mode, sense, q) in EVENTS.items())


def _run(x0: float, v0: float, horizon: float) -> list[tuple]:
    """One run up to the horizon as pieces ``(mode, t, x, v)`` (arrays), integrated contact by
    contact by solve_ivp with a terminal event at ``x = 0`` falling; the state entering a mode
    (after the reset) is a piece of its own."""
    def contact(t, z):
        return z[0]
    contact.terminal, contact.direction = True, -1
    t, z, mode, pieces = 0.0, [x0, v0], "inbound", []
    while t < horizon:
        sol = solve_ivp(lambda _, y: [y[1], -A], (t, horizon), z, events=contact, dense_output=True,
                        rtol=1e-12, atol=1e-14)
        ts = np.linspace(t, sol.t[-1], 4001)
        x, v = sol.sol(ts)
        pieces.append((mode, ts, x, v))
        if sol.status != 1:                     # reached the horizon
            break
        t, z, mode = float(sol.t[-1]), [0.0, -E * sol.y[1, -1]], "rebound"
        pieces.append((mode, np.array([t]), np.array([0.0]), np.array([z[1]])))
    return pieces


@lru_cache(maxsize=None)
def _truth(horizon: float) -> dict:
    """For each event: the least and the greatest over the runs from a 9 x 9 grid of the initial
    box (corners included) of the run's extremum (``-inf`` for a maximum over no stretch of the
    mode, ``inf`` for a minimum)."""
    per_event = {name: [] for name in EVENTS}
    for x0 in np.linspace(1.0, 1.2, 9):
        for v0 in np.linspace(-0.2, -0.1, 9):
            pieces = _run(x0, v0, horizon)
            for name, (mode, sense, q) in EVENTS.items():
                values = [{"t": t, "x": x, "v": v}[q] for m, t, x, v in pieces if m == mode]
                pick = np.max if sense == "max" else np.min
                empty = -np.inf if sense == "max" else np.inf
                per_event[name].append(pick(np.concatenate(values)) if values else empty)
    return {name: (min(values), max(values)) for name, values in per_event.items()}


def test_the_simulated_runs_follow_the_closed_form():
    """The solve_ivp runs against the closed form: first contact times, the largest rebound
    speed ``e vi`` and apex ``(e vi)^2 / (2 a)``, at the horizon of the reported case."""
    x0, v0 = np.meshgrid(np.linspace(1.0, 1.2, 9), np.linspace(-0.2, -0.1, 9))
    vi = np.sqrt(v0 ** 2 + 2 * A * x0)
    t1 = (vi - np.abs(v0)) / A
    truth = _truth(40.0)
    assert truth["first_contact"] == pytest.approx((t1.min(), t1.max()), abs=1e-9)
    assert truth["rebound_v_max"][1] == pytest.approx(E * vi.max(), abs=1e-9)
    assert truth["apex"][1] == pytest.approx((E * vi.max()) ** 2 / (2 * A), abs=1e-6)
    assert truth["rebound_v_min"][0] == pytest.approx(-E * vi.max(), abs=1e-9)   # just before the second contact


@pytest.mark.parametrize("horizon", [6.0, 20.0, 28.0, 40.0])
def test_estimated_bounds_contain_every_run(tmp_path, horizon):
    """Each event's estimated bound holds the extremum of every simulated run, its outer end
    finite: before, a mode entered again replaced the candidate of its first entry (at 40 s the
    first contact was bounded by the third, [24.4, 30.8] s), and a mode left before the horizon
    by some runs only was taken as left by none."""
    model, props = load_files(tmp_path, DOCK.format(horizon=horizon), PROPS)
    truth = _truth(horizon)
    for name, (_, sense, _) in EVENTS.items():
        result = BACKEND.check(model, props[name], {})
        lo, hi = result.bound
        least, greatest = truth[name]
        assert lo <= least + 1e-6 and greatest - 1e-6 <= hi, (name, result.bound, truth[name])
        assert np.isfinite(hi if sense == "max" else lo), (name, result.bound)
        assert "note" not in result.details, (name, result.details["note"])


def test_rebound_speed_violation_is_found_at_forty_seconds(tmp_path):
    """``v <= 0.124`` in rebound fails by 0.0025 (the fastest rebound, ``e vi = 0.1265``): the
    estimated margin reaches below zero and a replayed subdomain point shows it (before, the
    margin was estimated at [0.053, 0.103])."""
    model, props = load_files(tmp_path, DOCK.format(horizon=40), """
        properties:
          - {id: v_rebound, kind: safety, modes: [rebound], require: ["v <= 0.124"]}
    """)
    result = BACKEND.check(model, props["v_rebound"], {})
    lo, hi = result.details["margin_bound"]
    assert lo <= 0.124 - _truth(40.0)["rebound_v_max"][1] <= hi
    assert result.status is Status.UNSAFE


def test_past_the_switch_limit_the_outer_end_is_open_and_says_why(tmp_path):
    """At 45 s some runs have bounced without end (Zeno from 41.96 s): the expansion stops after
    eight switches, so the first contact's lower end is open, with the reason; the upper end
    still holds the latest first contact (closed form)."""
    model, props = load_files(tmp_path, DOCK.format(horizon=45), PROPS)
    result = BACKEND.check(model, props["first_contact"], {})
    lo, hi = result.bound
    latest = (np.sqrt(0.1 ** 2 + 2 * A * 1.0) - 0.1) / A
    assert lo == -np.inf and hi >= latest
    assert "mode switches" in result.details["note"]
    assert result.status is Status.UNKNOWN


def test_the_time_budget_defaults_to_two_minutes():
    assert Options.from_dict({}).max_seconds == 120.0
    assert Options.from_dict({"max_seconds": None}).max_seconds is None


def test_sweeps_cut_short_by_the_budget_name_it(tmp_path, monkeypatch):
    """Rigorous, on two subdomains, with a clock that passes the budget once the first sweep is
    done: the second is cut short, and the note names the budget before the first's own reason
    (its bound is open past eight switches too)."""
    clock = [0.0]
    monkeypatch.setattr(deadline_module, "time", SimpleNamespace(time=lambda: clock[0]))
    real_sweep = taylor.sweep_box

    def sweep_then_late(*args):
        out = real_sweep(*args)
        clock[0] += 100.0
        return out

    monkeypatch.setattr(taylor, "sweep_box", sweep_then_late)
    model, props = load_files(tmp_path, DOCK.format(horizon=20), PROPS)
    result = BACKEND.check(model, props["first_contact"], {"remainder": "rigorous", "max_splits": 1,
                                                            "max_seconds": 50})
    assert result.details["subdomain_count"] == 2
    reasons = [row["verified"].get("why", "") for row in result.details["subdomains"]]
    assert sum("time budget of 50 s" in why for why in reasons) == 1
    assert result.status is Status.UNKNOWN
    assert "(time budget of 50 s (option max_seconds) exhausted" in result.details["note"]


def test_a_clockless_model_that_switches_back_into_the_property_mode_gets_a_clock(tmp_path):
    """A bouncing ball of one mode (a self-loop with an affine reset) and no clock state: events
    after the bounce need elapsed time, which taylor adds itself, so the event property and a
    safety property of that mode are checked (not an internal error). Their apex: h0 + v0^2 / (2 g)
    = 1.2 + 0.04 / 19.62 at the box's top corner, inside the estimated bound."""
    from reach.checking import check_files
    (tmp_path / "m.yaml").write_text(
        "name: ball\nstate: [h, v]\nmodes:\n  fall: {flow: {h: v, v: -9.81}, invariant: [\"h >= 0\"]}\n"
        "transitions:\n  - {from: fall, to: fall, guard: [\"h <= 0\", \"v <= 0\"], urgent: true, "
        "reset: {v: \"-0.8*v + 0.5\"}}\n"
        "initial: {mode: fall, box: {h: [1, 1.2], v: [0, 0.2]}}\nhorizon: 4\n")
    (tmp_path / "p.yaml").write_text(
        "properties:\n  - {id: apex, kind: event, modes: [fall], maximize: h, require: \"<= 1.3\"}\n"
        "  - {id: low, kind: safety, modes: [fall], require: [\"h <= 1.2015\"]}\n")
    apex, low = check_files(tmp_path / "m.yaml", tmp_path / "p.yaml", "taylor")
    assert apex.status is Status.UNKNOWN and apex.bound[0] <= 1.2 + 0.04 / 19.62 <= apex.bound[1] + 1e-6
    assert low.status is Status.UNSAFE
