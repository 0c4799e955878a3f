"""Hylaa against the star back-end on the same automata, in the same run.

Hylaa (PyPI ``hylaa``, generalized star sets, discrete time) is not a dependency of reach:
install it into a separate virtual environment and point ``--hylaa-python`` at it::

    python3 -m venv /work/hylaa-venv && /work/hylaa-venv/bin/pip install hylaa "swiglpk==5.0.10"
    python benchmarks/hylaa_vs_star.py                       # SRA01, SRA08, SRU02
    python benchmarks/hylaa_vs_star.py SRA02 --hylaa-repeat 3

    python benchmarks/hylaa_vs_star.py BLDC01-BDS01 GRBX01-MES01  # imported SpaceEx (table AFF)

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

The imported ARCH AFF instances (``AFF``: models/spaceex/ files through
``reach.model.spaceex.load_spaceex``) reach Hylaa through :func:`automaton_spec`, which reads
only the HybridAutomaton (flows' ``A, b``, invariant and guard half-spaces, affine resets,
initial box or polytope, bounded inputs) and the cfg's forbidden set; star checks the same
automaton against the same forbidden set (one merged property, as ``reach check MODEL.xml
CFG``). Hylaa's semantics differ in two ways the table should be read with: it decides at
its time steps only (star covers the continuous time between them), and its inputs are held
constant over a step; its transitions are may-transitions.

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
    if spec.get("kind") == "automaton":
        hylaa_automaton_worker(spec)
        return
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


def hylaa_automaton_worker(spec: dict) -> None:
    """Build and run the Hylaa automaton of :func:`automaton_spec` (plain matrices)."""
    import numpy as np
    from hylaa import lputil
    from hylaa.core import Core
    from hylaa.hybrid_automaton import HybridAutomaton
    from hylaa.settings import HylaaSettings, PlotSettings
    from hylaa.stateset import StateSet

    ha = HybridAutomaton(spec["name"])
    modes = {}
    for name, m in spec["modes"].items():
        mode = modes[name] = ha.new_mode(name)
        mode.set_dynamics(np.array(m["A"], dtype=float))
        if spec["inputs"]:
            mode.set_inputs(np.array(m["B"], dtype=float), spec["inputs"]["C"], spec["inputs"]["d"])
        if m["inv_g"]:
            mode.set_invariant(np.array(m["inv_H"], dtype=float), m["inv_g"])
    error = ha.new_mode(spec["error_mode"])
    for k, t in enumerate(spec["transitions"]):
        tr = ha.new_transition(modes[t["source"]], modes[t["target"]], f"t{k}")
        tr.set_guard(np.array(t["H"], dtype=float), t["g"])
        tr.set_reset(np.array(t["R"], dtype=float))
    for k, e in enumerate(spec["errors"]):
        ha.new_transition(modes[e["source"]], error, f"e{k}").set_guard(np.array(e["H"], dtype=float), e["g"])
    init = [StateSet(lputil.from_constraints(np.array(i["H"], dtype=float), i["g"], modes[i["mode"]]),
                     modes[i["mode"]]) for i in spec["initial"]]
    settings = HylaaSettings(spec["step"], spec["horizon"])
    settings.plot.plot_mode = PlotSettings.PLOT_NONE
    settings.stdout = HylaaSettings.STDOUT_NONE
    settings.stop_on_aggregated_error = False

    start = time.perf_counter()
    result = Core(ha, settings).run(init)
    seconds = time.perf_counter() - start
    print(json.dumps({"seconds": seconds, "concrete_error": bool(result.has_concrete_error),
                      "aggregated_error": bool(result.has_aggregated_error)}))


# ---------------------------------------------------------------------- driver

class Inexpressible(Exception):
    """The automaton uses something Hylaa 2.0.2 has no counterpart for."""


def automaton_spec(model, prop, step: float) -> dict:
    """Hylaa's automaton for an imported linear ``model`` and a bound safety ``prop``.

    Coordinates: the model's states without its time-varying bounded inputs, plus a constant
    ``1`` last (Hylaa's flows are ``x' = A x``: an affine flow ``A x + b`` becomes the column
    ``b`` against that constant, as in Hylaa's examples). A varying input ``u_j in [l, h]``
    becomes a Hylaa input with ``B = A[:, j]`` and constraints ``l <= u_j <= h``; a constant
    input stays a state with zero flow (exact). Invariants and guards are the constraints'
    half-spaces (strict ones closed); resets ``x := R x + c`` are the matrix ``[[R, c], [0, 1]]``.
    The unsafe pieces become guards into one ``error`` mode (named apart from the model's modes);
    a guard without constraints gets the row ``0 <= 1``. A timeless initial mode (SpaceEx
    flow ``false``) is passed over: its successors (initial set and guard) start in the
    targets. Another timeless mode gets the flow ``0``: while Hylaa's steps pass its states stay
    the entry states, which is the set a timeless mode reaches. Raises :class:`Inexpressible`
    otherwise.
    """
    import numpy as np
    from reach.model.constraints import affine_coefficients, halfspaces

    n_all = len(model.state)
    varying = [u.index for u in model.varying_inputs]
    keep = [i for i in range(n_all) if i not in varying]
    n = len(keep) + 1

    def lift(H):                    # rows over all states -> rows over kept states and the constant
        H = np.asarray(H, dtype=float).reshape(-1, n_all)
        if varying and np.any(H[:, varying]):
            raise Inexpressible("a constraint on a time-varying input")
        return np.hstack([H[:, keep], np.zeros((len(H), 1))])

    def rows(constraints):
        hs = halfspaces(constraints, model.symbols)
        if hs is None:
            raise Inexpressible("a nonlinear constraint")
        H, g = lift(hs[0]), np.asarray(hs[1], dtype=float)
        if not len(H):                # a guard "true": Hylaa wants at least one row
            H, g = np.zeros((1, n)), np.ones(1)
        return H, g

    start = model.initial.mode
    skipped = start if model.modes[start].timeless else None
    unsafe_modes = set(prop.pieces)
    modes = {}
    for name, mode in model.modes.items():
        if name == skipped:
            continue
        lin = (np.zeros((n_all, n_all)), np.zeros(n_all)) if mode.timeless else mode.linear
        if lin is None:
            raise Inexpressible(f"mode {name}: nonlinear flow")
        A, b = lin
        full = np.zeros((n, n))
        full[:-1, :-1] = A[np.ix_(keep, keep)]
        full[:-1, -1] = b[keep]
        H, g = rows(mode.invariant)
        modes[name] = {"A": full.tolist(), "B": np.vstack([A[np.ix_(keep, varying)], np.zeros((1, len(varying)))]).tolist(),
                       "inv_H": H.tolist(), "inv_g": g.tolist()}

    def reset_matrix(tr):
        R = np.eye(n)
        for i, expr in tr.reset.items():
            coeffs = affine_coefficients(expr, model.symbols)
            if coeffs is None:
                raise Inexpressible(f"transition {tr.source} -> {tr.target}: nonlinear reset")
            R[keep.index(i)] = np.append(lift(coeffs[0])[0, :-1], coeffs[1])
        return R

    transitions = []
    for tr in model.transitions:
        if tr.source == skipped:
            continue
        if tr.target == skipped:
            raise Inexpressible(f"a transition into the timeless initial mode {skipped}")
        if tr.window is not None:
            raise Inexpressible("a switching-time window")
        H, g = rows(tr.guard)
        transitions.append({"source": tr.source, "target": tr.target, "H": H.tolist(), "g": g.tolist(),
                            "R": reset_matrix(tr).tolist()})

    errors = []
    for mode in unsafe_modes:
        pieces = prop.halfspace_pieces(mode)
        if pieces is None:
            raise Inexpressible("a nonlinear unsafe set")
        if mode == skipped:
            raise Inexpressible(f"an unsafe set in the timeless initial mode {mode}")
        errors += [{"source": mode, "H": lift(H).tolist(), "g": np.asarray(g).tolist()} for H, g in pieces]

    P = model.initial.polytope
    if P is None:
        H0 = np.vstack([np.eye(n_all), -np.eye(n_all)])
        g0 = np.concatenate([model.initial.high, -model.initial.low])
    else:
        H0 = np.vstack([P.A, P.E, -P.E])
        g0 = np.concatenate([P.b, P.f, -P.f])
    one = np.zeros((2, n))
    one[0, -1], one[1, -1] = 1.0, -1.0
    inner = np.any(H0[:, keep] != 0, axis=1)       # the rows of the varying inputs' bounds go
    H0 = np.vstack([np.hstack([H0[inner][:, keep], np.zeros((inner.sum(), 1))]), one])
    g0 = np.concatenate([g0[inner], [1.0, -1.0]])
    initial = []
    if skipped:
        for tr in model.outgoing(start):
            if tr.reset or tr.target == start:
                raise Inexpressible(f"a reset or a self-loop out of the timeless initial mode {start}")
            H, g = rows(tr.guard)
            initial.append({"mode": tr.target, "H": np.vstack([H0, H]).tolist(), "g": np.concatenate([g0, g]).tolist()})
    else:
        initial.append({"mode": start, "H": H0.tolist(), "g": g0.tolist()})
    inputs = None
    if varying:
        lo = [u.low for u in model.varying_inputs]
        hi = [u.high for u in model.varying_inputs]
        inputs = {"C": np.vstack([np.eye(len(varying)), -np.eye(len(varying))]).tolist(), "d": hi + [-v for v in lo]}
    error_mode = "error"
    while error_mode in model.modes:   # the model may have its own mode of that name
        error_mode = "_" + error_mode
    return {"kind": "automaton", "name": model.name, "modes": modes, "transitions": transitions,
            "error_mode": error_mode,
            "errors": errors, "initial": initial, "inputs": inputs, "step": step, "horizon": float(model.horizon)}


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


#: imported SpaceEx instances under models/spaceex/: (model, cfg, Hylaa time step[, star options
#: as in suite.yaml]); the cfgs give
#: no usable sampling time, so the steps are those of Hylaa's ARCH-COMP AFF runs where there is
#: one (0.01 s for Building; 5e-4 s in Hylaa's examples/drivetrain, the ARCH-COMP 2018 drivetrain
#: encoding; 0.1 min in its examples/rendezvous), 1/500 of the horizon for Gearbox, 0.01 s for
#: Platoon (no Hylaa Platoon run in the reports), the cfg's sampling-time 0.02 for the
#: filtered oscillator (no ARCH instance) and 0.01 for the ISS (2000 steps over 20).
AFF = {
    "BLDC01-BDS01": ("Building/BLDC01.xml", "Building/BLDC01-BDS01.cfg", 0.01),
    "BLDF01-BDS01": ("Building/BLDF01.xml", "Building/BLDF01-BDS01.cfg", 0.01),
    "BLDF01-BDU01": ("Building/BLDF01.xml", "Building/BLDF01-BDU01.cfg", 0.01),
    "BLDC01-BDU02": ("Building/BLDC01.xml", "Building/BLDC01-BDU02.cfg", 0.01),
    "BLDF01-BDU02": ("Building/BLDF01.xml", "Building/BLDF01-BDU02.cfg", 0.01),
    "GRBX01-MES01": ("Gearbox/GRBX01-MES01.xml", "Gearbox/GRBX01-MES01.cfg", 0.001),
    "DTN-2theta-30": ("Powertrain/drivetrain_2theta_30percent.xml",
                      "Powertrain/drivetrain_2theta_30percent-forbidden.cfg", 5e-4),
    "PLAD01-BND42": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42-forbidden.cfg", 0.01),
    "PLAD01-BND30": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND30-forbidden.cfg", 0.01),
    "PLAD01-BND42-h20": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND42-h20-forbidden.cfg", 0.01,
                         {"input_cells": 1}),
    "PLAD01-BND30-h20": ("Platoon/PLAD01-BND.xml", "Platoon/PLAD01-BND30-h20-forbidden.cfg", 0.01,
                         {"input_cells": 1}),
    "PLAA01-BND50": ("Platoon/PLAA01-BND.xml", "Platoon/PLAA01-BND50-forbidden.cfg", 0.01),
    "PLAA01-BND50-h20": ("Platoon/PLAA01-BND.xml", "Platoon/PLAA01-BND50-h20-forbidden.cfg", 0.01),
    "PLAN01-UNB50": ("Platoon/PLAN01-UNB.xml", "Platoon/PLAN01-UNB50-forbidden.cfg", 0.01),
    "SRA01-SR0-LOS": ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-LOS.cfg", 0.1),
    "SRA01-SR0-collision": ("Rendezvous_ARCH18/SRA01-SR0_.xml", "Rendezvous_ARCH18/SRA01-SR0_-collision.cfg", 0.1),
    "SRNA01-SR0-LOS": ("Rendezvous_ARCH18/SRNA01-SR0_.xml", "Rendezvous_ARCH18/SRNA01-SR0_-LOS.cfg", 0.1),
    "bball-height": ("BouncingBall/bball.xml", "BouncingBall/bball-height.cfg", 0.01),
    "bball-speed": ("BouncingBall/bball.xml", "BouncingBall/bball-speed.cfg", 0.01),
    "filtered_oscillator-x07": ("FilteredOscillator/filtered_oscillator.xml",
                                "FilteredOscillator/filtered_oscillator-x07.cfg", 0.02),
    "filtered_oscillator-x06": ("FilteredOscillator/filtered_oscillator.xml",
                                "FilteredOscillator/filtered_oscillator-x06.cfg", 0.02),
    "ISSC01-ISS02": ("SpaceStation/iss_270.xml", "SpaceStation/ISSC01-ISS02-forbidden.cfg", 0.01),
    "ISSC01-ISU02": ("SpaceStation/iss_270.xml", "SpaceStation/ISSC01-ISU02-forbidden.cfg", 0.01),
}


def load_aff(name: str):
    """The imported automaton, its cfg's forbidden set as one bound property and star's options
    from the cfg's hints (as ``reach check``)."""
    from reach.model.spaceex import load_spaceex
    from reach.spec import bind
    from reach.spec.properties import BoundSafety

    xml, cfg, *rest = AFF[name]
    xml, cfg = ROOT / "models/spaceex" / xml, ROOT / "models/spaceex" / cfg
    model, props, docs = load_spaceex(xml, cfg)
    bound = [bind(p, model) for p in props]
    modes = [m for m in model.modes if any(m in b.modes for b in bound)]
    pieces = {m: [piece for b in bound for piece in b.pieces.get(m, [])] for m in modes}
    from reach.backends.star.options import cfg_hints
    return (model, BoundSafety(docs.property_id, modes, pieces, model.symbols, str(cfg), f"forbidden set of {cfg}"),
            cfg_hints(docs.model.get("notes", {}), dict(rest[1]) if len(rest) > 1 else {}))


def compare_aff(name: str, args) -> str:
    """One table line: Hylaa and star on the imported automaton ``name``."""
    model, prop, options = load_aff(name)
    try:
        spec = automaton_spec(model, prop, args.hylaa_step or AFF[name][2])
    except Inexpressible as exc:
        hylaa_runs = [{"error": f"Hylaa cannot express it: {exc}"}]
    else:
        hylaa_runs = [run_hylaa(args.hylaa_python, spec, args.timeout) for _ in range(args.hylaa_repeat)]
    star_runs = [run_star(model, [prop], options) for _ in range(args.star_repeat)]
    return line(name, hylaa_runs, star_runs)


def median(values):
    values = sorted(values)
    return values[len(values) // 2]


def line(name, hylaa_runs, star_runs) -> str:
    star_s = median([r["seconds"] for r in star_runs])
    verdicts = " ".join(f"{k}={v}" for k, v in star_runs[0]["verdicts"].items())
    ok = [r for r in hylaa_runs if "error" not in r]
    if not ok:
        return f"{name:12} {'-':>9} {star_s:8.2f} {'-':>7}  {hylaa_verdict(hylaa_runs[0])} | {verdicts}"
    hylaa_s = median([r["seconds"] for r in ok])
    return f"{name:12} {hylaa_s:9.2f} {star_s:8.2f} {hylaa_s / star_s:7.1f}  {hylaa_verdict(ok[0])} | {verdicts}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("instances", nargs="*", default=["SRA01", "SRA08", "SRU02"])
    parser.add_argument("--hylaa-python", default="/work/hylaa-venv/bin/python")
    parser.add_argument("--hylaa-step", type=float, default=None,
                        help="Hylaa time step (default: 0.1 min for rendezvous, the table AFF for imported instances)")
    parser.add_argument("--hylaa-repeat", type=int, default=1, help="Hylaa runs (median reported)")
    parser.add_argument("--star-repeat", type=int, default=3, help="star runs (median reported)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per Hylaa run")
    args = parser.parse_args(argv)

    sys.path.insert(0, str(ROOT))
    import reach.backends.montecarlo  # noqa: F401  (imported before timing: replays use it)
    from reach.model.loader import load_model
    from reach.spec import bind, load_properties

    print(f"{'instance':12} {'hylaa s':>9} {'star s':>8} {'ratio':>7}  hylaa verdict | star verdicts")
    for name in args.instances:
        if name in AFF:
            print(compare_aff(name, args), flush=True)
            continue
        model = load_model(ROOT / "models" / f"{name}.yaml")
        props = [bind(p, model) for file, pid in STAR_PROPERTIES
                 for p in load_properties(ROOT / file) if p.id == pid]
        hylaa_runs = [run_hylaa(args.hylaa_python, hylaa_spec(model, args.hylaa_step or 0.1), args.timeout)
                      for _ in range(args.hylaa_repeat)]
        star_runs = [run_star(model, props, {}) for _ in range(args.star_repeat)]
        print(line(name, hylaa_runs, star_runs), flush=True)
    return 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--hylaa-worker":
        hylaa_worker(sys.argv[2])
    else:
        sys.exit(main())
