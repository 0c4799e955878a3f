"""Flow* 2.1.0 against reach's taylor back-end on SRNA01, in the same run.

Flow* (Chen, Abraham & Sankaranarayanan; Taylor-model flowpipes, C++) is not a dependency of
reach. Build it from its public source (repository chenxin415/flowstar, the archive
``flowstar-2.1.0/flowstar-2.1.0.zip`` in it) outside this repository::

    apt-get install libgmp-dev libmpfr-dev libgsl-dev libglpk-dev bison flex g++ make
    unzip flowstar-2.1.0.zip && cd flowstar-2.1.0 && make flowstar      # about 3 minutes
    FLOWSTAR=$PWD/flowstar python benchmarks/flowstar_srna01.py

Without ``FLOWSTAR`` naming an executable, the script prints these steps and exits with 0.

The Flow* model is generated from ``models/SRNA01.yaml`` as reach loads it (closed-loop
flows with the LQR laws substituted, mode invariants, the docking guard, the initial box),
so both tools check the same automaton:

* Flows are Flow*'s ``nonpoly ode`` (the gravity term has a square root). Each fractional
  power ``b**e`` whose base has a positive constant part ``c`` is written ``c**e (b/c)**e``
  (an identity): for SRNA01 this is the scaled gravity ``mu/rc**3 = n**2 (r/rc)**3``, without
  which Flow*'s flowpipe does not start (``(r + x)**2 ~ 1.8e15`` swamps the remainder).
* The urgent docking transition becomes a Flow* jump (may-semantics, taken anywhere in the
  guard while the approach invariant ``x <= -100`` holds). Every urgent run is also a
  may-run, so a SAFE under Flow*'s semantics is a SAFE of the model.
* A property's unsafe set is a union of conjunctions per mode (``BoundSafety.pieces``; an
  event ``max q <= v`` is the piece ``q >= v`` in each of its modes). Flow* checks one
  conjunction per mode per run, so the reachability run checks the first piece of each mode
  and dumps its flowpipes; each further piece is checked on those saved Taylor models by a
  Flow* run on the dump file. A property is SAFE for Flow* when its flowpipe was completed to
  the horizon and every one of its pieces was SAFE.

Settings (those of the anchor in shared/ANCHORS.md): adaptive steps 0.01-1 min, QR
preconditioning, cutoff 1e-10, precision 53, remainder estimate 1e-2, interval aggregation
at the jump; TM order 5 to 200 min and order 7 to 240 min. reach's taylor back-end checks the
same model with the rigorous remainder through both property files
(properties/rendezvous.yaml and properties/rendezvous_events.yaml) to the same horizons. If
``benchmarks/taylor_vs_daceypy.py`` and ``daceypy`` (``--daceypy-path``) are present, that
comparison runs in the same run too. Times are wall-clock and CPU seconds (user + system of
the Flow* processes; of this process and its children for reach); ratios are Flow* / reach.
Results go to results/flowstar.json and results/flowstar.md (``--render`` rewrites the .md
from the .json; ``--write-model FILE`` only writes the order-5 Flow* model).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import sympy

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models" / "SRNA01.yaml"
PROPERTY_FILES = [ROOT / "properties" / "rendezvous.yaml", ROOT / "properties" / "rendezvous_events.yaml"]
SETTINGS = [  # (TM order, horizon in model minutes): the anchor's two runs
    (5, 200.0),
    (7, 240.0),
]
ANSI = re.compile(r"\x1b\[[0-9;]*m")


# ---------------------------------------------------------------- expressions in Flow* syntax

def number(value: float) -> str:
    """A non-negative float in a form Flow*'s lexer reads (it has no ``e+``)."""
    text = repr(float(value))
    if text in ("inf", "nan"):
        raise ValueError(f"cannot write {text} for Flow*")
    return text.replace("e+", "e")


def scale_powers(expr: sympy.Expr, symbols) -> sympy.Expr:
    """Rewrite ``b**e`` (``e`` not an integer, ``b`` with constant part ``c > 0``) as
    ``c**e * (b/c)**e``: the same function, with a base of order one."""

    def scaled(power):
        base, exponent = power.args
        c = base.subs({s: 0 for s in symbols})
        if not c.is_number or float(c) <= 0.0:
            return power
        c = sympy.Float(float(c))
        return sympy.Pow(c, exponent) * sympy.Pow(sympy.expand(base / c), exponent)

    return expr.replace(lambda e: e.is_Pow and not e.exp.is_integer and e.exp.is_Rational, scaled)


def flowstar_text(expr: sympy.Expr) -> str:
    """``expr`` in Flow*'s expression syntax (``^`` for integer powers, ``sqrt``, ``/``)."""
    expr = sympy.sympify(expr)
    if expr.is_Number:
        v = float(expr)
        return number(v) if v >= 0 else f"(-{number(-v)})"
    if expr.is_Symbol:
        return expr.name
    if expr.is_Add:
        terms = sympy.Add.make_args(expr)
        out = ""
        for k, term in enumerate(terms):
            coeff = term.as_coeff_Mul()[0]
            negative = coeff.is_Number and float(coeff) < 0
            body = flowstar_text(-term) if negative else flowstar_text(term)
            if k == 0:
                out = f"-({body})" if negative else body
            else:
                out += f" - {body}" if negative else f" + {body}"
        return f"({out})"
    if expr.is_Mul:
        numer, denom = [], []
        for factor in sympy.Mul.make_args(expr):
            if factor.is_Pow and factor.exp.is_number and float(factor.exp) < 0:
                denom.append(flowstar_text(sympy.Pow(factor.base, -factor.exp)))
            elif factor.is_Number and float(factor) < 0:
                return f"(-({flowstar_text(-expr)}))"
            else:
                numer.append(flowstar_text(factor))
        text = "*".join(numer) if numer else "1"
        return f"({text}/({'*'.join(denom)}))" if denom else text
    if expr.is_Pow and expr.exp.is_number:
        base, e = expr.base, float(expr.exp)
        if e < 0:
            return f"(1/{flowstar_text(sympy.Pow(base, -expr.exp))})"
        if e.is_integer():
            return f"({flowstar_text(base)})^{int(e)}"
        if (2 * e).is_integer():
            root = f"sqrt({flowstar_text(base)})"
            return root if e == 0.5 else f"{root}^{int(2 * e)}"
    if isinstance(expr, (sympy.exp, sympy.sin, sympy.cos, sympy.log)):
        return f"{type(expr).__name__}({flowstar_text(expr.args[0])})"
    raise ValueError(f"no Flow* form for {expr}")


def constraint_text(c) -> str:
    """A constraint ``g <= 0`` (a strict one is written closed: a larger unsafe set)."""
    return f"{flowstar_text(sympy.expand(sympy.N(c.g, 17)))} <= 0"


# ---------------------------------------------------------------- the model

def unsafe_pieces(model, props) -> dict[str, list[tuple[str, list]]]:
    """Per property id: ``[(mode, conjunction of Constraints)]``, the union of its unsafe set."""
    from reach.model.constraints import Constraint
    out = {}
    for prop in props:
        if prop.kind == "safety":
            out[prop.id] = [(m, piece) for m in prop.modes for piece in prop.pieces.get(m, [])]
        elif prop.kind == "event":
            pieces = []
            for m in prop.modes:
                q = prop.quantity[m]
                # unsafe: the requirement fails, q > v for "<= v", q < v for ">= v" (closed here)
                g = (prop.value - q) if prop.op == "<=" else (q - prop.value)
                pieces.append((m, [Constraint(g, False, f"{prop.id} violated", None)]))
            out[prop.id] = pieces
    return out


def outside_invariant(mode, piece) -> bool:
    """True when the piece cannot meet the mode's invariant: a single strict linear constraint
    ``a.x + c < 0`` with ``a.x + c >= 0`` on the whole invariant polytope ``H x <= g`` (LP).

    Flow* has closed constraints only, so ``x < -100`` would be checked as ``x <= -100``, which
    the entry set of the rendezvous mode touches (``x = -100`` on the guard); the open piece
    itself is empty inside the invariant, so no state of the mode is in it."""
    from scipy.optimize import linprog

    from reach.model.constraints import affine_coefficients
    hs = mode.invariant_halfspaces
    if len(piece) != 1 or not piece[0].strict or hs is None:
        return False
    coeffs = affine_coefficients(piece[0].g, mode.symbols)
    if coeffs is None:
        return False
    a, c = coeffs
    H, g = hs
    lp = linprog(a, A_ub=H, b_ub=g, bounds=[(None, None)] * len(a), method="highs")
    return lp.status == 0 and lp.fun + c >= 0.0


def flowstar_model(model, order: int, horizon: float, unsafe: dict[str, list],
                   aggregation: str = "interval", output: str = "srna01") -> str:
    """The Flow* ``hybrid reachability`` text of ``model`` with one unsafe conjunction per mode."""
    names = model.state
    lines = ["hybrid reachability", "{", f" state var {', '.join(names)}", "", " setting", " {",
             "  adaptive steps { min 0.01, max 1 }",
             f"  time {number(horizon)}",
             "  remainder estimation 1e-2",
             "  QR precondition",
             f"  gnuplot octagon {names[0]}, {names[1]}",
             f"  fixed orders {order}",
             "  cutoff 1e-10",
             "  precision 53",
             f"  tm output {output}",
             f"  max jumps {len(model.transitions)}",
             "  print off",
             " }", "", " modes", " {"]
    for mode in model.modes.values():
        lines += [f"  {mode.name}", "  {", "   nonpoly ode", "   {"]
        for name, f in zip(names, mode.flow):
            lines.append(f"    {name}' = {flowstar_text(sympy.N(scale_powers(f, mode.symbols), 17))}")
        lines += ["   }", "   inv", "   {"]
        lines += [f"    {constraint_text(c)}" for c in mode.invariant]
        lines += ["   }", "  }"]
    lines += [" }", "", " jumps", " {"]
    for tr in model.transitions:
        if tr.reset:
            raise ValueError("resets are not written for Flow* here")
        lines += [f"  {tr.source} -> {tr.target}", "  guard {"]
        lines += [f"   {constraint_text(c)}" for c in tr.guard]
        lines += ["  }", "  reset { }",
                  "  interval aggregation" if aggregation == "interval" else "  parallelotope aggregation { }"]
    lines += [" }", "", " init", " {", f"  {model.initial.mode}", "  {"]
    if not model.initial.is_box:
        raise ValueError("only box initial sets are written for Flow* here")
    for name, lo, hi in zip(names, model.initial.low, model.initial.high):
        lines.append(f"   {name} in [{number_signed(lo)}, {number_signed(hi)}]")
    lines += ["  }", " }", "}", ""]
    return "\n".join(lines) + unsafe_block(unsafe)


def number_signed(v: float) -> str:
    return number(v) if v >= 0 else "-" + number(-v)


def unsafe_block(unsafe: dict[str, list]) -> str:
    """``unsafe { mode { g <= 0 ... } }`` with one conjunction per mode."""
    if not unsafe:
        return ""
    lines = ["unsafe", "{"]
    for mode, piece in unsafe.items():
        lines += [f" {mode}", " {"] + [f"  {constraint_text(c)}" for c in piece] + [" }"]
    return "\n".join(lines + ["}", ""])


# ---------------------------------------------------------------- running Flow*

@dataclass
class FlowstarRun:
    """What one Flow* invocation printed: verdict word, completion, Flow*'s own CPU seconds."""

    seconds: float
    verdict: str                    # SAFE | UNSAFE | UNKNOWN | FAILED
    completed: bool
    flowpipes: int | None = None
    cpu_seconds: float | None = None
    output: str = ""
    process_cpu_seconds: float = 0.0   # user + system time of the flowstar process


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_flowstar(binary: str, text: str, workdir: Path, timeout: float) -> FlowstarRun:
    """Feed ``text`` to ``flowstar`` on standard input in ``workdir`` (it writes outputs/ there)."""
    start, cpu0 = time.perf_counter(), children_cpu()
    try:
        proc = subprocess.run([binary], input=text, capture_output=True, text=True, cwd=workdir,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return FlowstarRun(time.perf_counter() - start, "FAILED", False, output=f"timed out after {timeout:g} s")
    seconds = time.perf_counter() - start
    cpu = children_cpu() - cpu0
    out = ANSI.sub("", proc.stdout)
    verdict = re.search(r"Result of (?:the )?safety verification[^:]*:\s*(SAFE|UNSAFE|UNKNOWN)", out)
    pipes = re.search(r"(\d+) flowpipe\(s\) computed", out)
    own = re.search(r"(?:Total time cost|Time cost of safety verification):\s*([0-9.]+)", out)
    tail = "\n".join(line for line in out.splitlines() if "%" not in line)[-2000:]
    if proc.returncode != 0 or verdict is None:
        tail += ANSI.sub("", proc.stderr)[-1000:]
        return FlowstarRun(seconds, "FAILED", False, output=tail, process_cpu_seconds=cpu)
    return FlowstarRun(seconds, verdict.group(1), "Computation not completed" not in out,
                       int(pipes.group(1)) if pipes else None,
                       float(own.group(1)) if own else None, tail, cpu)


def check_on_dump(dump: str, unsafe: dict[str, list]) -> str:
    """The dumped flowpipes with ``unsafe`` in place of the run's own unsafe block (the dump
    writes constraints with six decimals only) and no plot or dump output."""
    head = dump[:dump.index("\nunsafe\n{")]
    head = re.sub(r"\noutput \S+\n", "\nno output\n", head)
    return head + "\n" + unsafe_block(unsafe) + dump[dump.index("\nhybrid flowpipes\n"):]


def flowstar_setting(binary: str, model, pieces: dict[str, list], order: int, horizon: float,
                     timeout: float) -> dict:
    """One anchor setting: the reachability run, then every further unsafe piece on its dump."""
    by_mode: dict[str, list[list]] = {}          # mode -> unique pieces, each [text, piece, users]
    outside: set[tuple[str, int]] = set()
    for pid, plist in pieces.items():
        for k, (mode, piece) in enumerate(plist):
            if outside_invariant(model.modes[mode], piece):
                outside.add((pid, k))
                continue
            key = "\n".join(constraint_text(c) for c in piece)
            slot = next((u for u in by_mode.setdefault(mode, []) if u[0] == key), None)
            if slot is None:
                by_mode[mode].append([key, piece, []])
                slot = by_mode[mode][-1]
            slot[2].append((pid, k))
    rounds = max((len(v) for v in by_mode.values()), default=0)
    piece_verdict: dict[tuple[str, int], str] = {}
    with tempfile.TemporaryDirectory(prefix="flowstar-") as tmp:
        work = Path(tmp)
        first = {m: v[0][1] for m, v in by_mode.items()}
        main = run_flowstar(binary, flowstar_model(model, order, horizon, first), work, timeout)
        record = {"order": order, "horizon_min": horizon, "flowpipe_seconds": round(main.seconds, 2),
                  "flowstar_cpu_seconds": main.cpu_seconds, "flowpipes": main.flowpipes,
                  "completed": main.completed, "verdict_first_pieces": main.verdict}
        for m, v in by_mode.items():
            for user in v[0][2]:
                piece_verdict[user] = main.verdict if main.completed else "UNKNOWN"
        dump_file = work / "outputs" / "srna01.flow"
        check_seconds, check_cpu = 0.0, 0.0
        if main.verdict != "FAILED" and dump_file.exists():
            dump = dump_file.read_text()
            for r in range(1, rounds):
                unsafe = {m: v[r][1] for m, v in by_mode.items() if r < len(v)}
                chk = run_flowstar(binary, check_on_dump(dump, unsafe), work, timeout)
                check_seconds += chk.seconds
                check_cpu += chk.process_cpu_seconds
                for m, v in by_mode.items():
                    if r < len(v):
                        for user in v[r][2]:
                            piece_verdict[user] = chk.verdict
        else:
            record["output"] = main.output
    record["check_seconds"] = round(check_seconds, 2)
    record["flowpipe_cpu_seconds"] = round(main.process_cpu_seconds, 2)
    record["cpu_seconds"] = round(main.process_cpu_seconds + check_cpu, 2)
    record["check_runs"] = max(rounds - 1, 0)
    record["unique_pieces_checked"] = {m: len(v) for m, v in by_mode.items()}
    record["pieces_outside_invariant"] = sorted(f"{pid}[{k}]" for pid, k in outside)
    piece_verdict.update({user: "SAFE" for user in outside})
    record["seconds"] = round(main.seconds + check_seconds, 2)
    verdicts = {}
    for pid, plist in pieces.items():
        words = [piece_verdict.get((pid, k), "FAILED") for k in range(len(plist))]
        if not plist:
            verdicts[pid] = "n/a"
        elif main.completed and all(w == "SAFE" for w in words):
            verdicts[pid] = "SAFE"
        else:
            verdicts[pid] = "UNKNOWN (" + ", ".join(sorted(set(words))) + ")"
    record["verdicts"] = verdicts
    return record


# ---------------------------------------------------------------- reach and daceypy, same run

def reach_setting(model, horizon: float) -> dict:
    """reach's taylor back-end (rigorous remainder) on both property files to ``horizon``."""
    from dataclasses import replace

    from reach.checking import check_model, not_applicable, resolve_backend
    from reach.spec import bind, load_properties
    backend = resolve_backend("taylor")
    short = replace(model, horizon=horizon)
    out = {}
    for path in PROPERTY_FILES:
        props = [bind(p, short) for p in load_properties(path)]
        start, cpu0 = time.perf_counter(), time.process_time() + children_cpu()
        results = check_model(backend, short, props, {"remainder": "rigorous"})
        seconds = time.perf_counter() - start
        cpu = time.process_time() + children_cpu() - cpu0
        out[path.name] = {"seconds": round(seconds, 2), "cpu_seconds": round(cpu, 2),
                          "verdicts": {r.property: "n/a" if not_applicable(r) else r.status.value
                                       for r in results}}
    return out


def daceypy_run(path: str | None) -> dict | None:
    """benchmarks/taylor_vs_daceypy.py in this run, if it and daceypy are present."""
    script = ROOT / "benchmarks" / "taylor_vs_daceypy.py"
    if not script.exists():
        return None
    env = dict(os.environ)
    if path:
        env["PYTHONPATH"] = path + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, str(script), "--order", "4", "--time", "30"], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=900)
    if proc.returncode != 0:
        return {"error": (proc.stderr.strip().splitlines() or ["failed"])[-1]}
    numbers = {}
    for key, label in (("reach_seconds", "reach DA, vectorised stages"), ("daceypy_seconds", "daceypy (DACE)"),
                       ("ratio_daceypy_over_reach", "ratio daceypy / reach"),
                       ("max_rel_coefficient_difference", "largest relative coefficient difference")):
        m = re.search(re.escape(label) + r"[^:]*:\s*([-+0-9.eE]+)", proc.stdout)
        numbers[key] = float(m.group(1)) if m else None
    numbers["case"] = "SRNA01 approach flow, order 4, 30 min"
    return numbers


# ---------------------------------------------------------------- report

def ratios_of(fs: dict, rs: dict) -> dict:
    """Flow* seconds / reach seconds per property file that reach decided (none UNSUPPORTED):
    ``total`` with every piece checked, ``flowpipes`` for the reachability run alone."""
    out = {}
    for name, r in rs.items():
        if r["seconds"] > 0 and "UNSUPPORTED" not in r["verdicts"].values():
            out[name] = {"total": round(fs["seconds"] / r["seconds"], 3),
                         "flowpipes": round(fs["flowpipe_seconds"] / r["seconds"], 3)}
            if r.get("cpu_seconds") and fs.get("cpu_seconds"):
                out[name]["total_cpu"] = round(fs["cpu_seconds"] / r["cpu_seconds"], 3)
                out[name]["flowpipes_cpu"] = round(fs["flowpipe_cpu_seconds"] / r["cpu_seconds"], 3)
    return out


def summary(verdicts: dict) -> str:
    """``11 SAFE`` or ``3 SAFE; UNKNOWN: a, b``: counts of SAFE and n/a, the rest by name."""
    safe = sum(v == "SAFE" for v in verdicts.values())
    skipped = sum(v == "n/a" for v in verdicts.values())
    rest = {}
    for pid, v in verdicts.items():
        if v not in ("SAFE", "n/a"):
            rest.setdefault(v, []).append(pid)
    parts = [f"{safe} SAFE"] + ([f"{skipped} n/a"] if skipped else [])
    parts += [f"{v}: {', '.join(ids)}" for v, ids in rest.items()]
    return "; ".join(parts)


def markdown(report: dict) -> str:
    """results/flowstar.md from the JSON record of one run."""
    m = report["machine"]
    lines = ["# Flow* 2.1.0 against reach's taylor back-end on SRNA01 (`benchmarks/flowstar_srna01.py`)", "",
             f"Measured {report.get('date', '')} on this machine ({m['cores']} cores, shared: load average "
             f"{m['load_average_at_start'][0]:.1f} at the start, {m['load_average_at_end'][0]:.1f} at the end), "
             "Flow* and reach in the same run. Seconds are wall-clock; ratios are Flow* / reach.", "",
             f"Model `{report['model']}` (Flow* model generated from it: `--write-model FILE`), properties "
             + ", ".join(f"`{p}`" for p in report["property_files"]) + ".", "",
             f"Flow* settings: {report['flowstar_settings']}. Flow* checks one unsafe conjunction per mode "
             "and run: the reachability run checks the first piece of each mode and dumps its Taylor-model "
             "flowpipes, every further piece is checked on the dump by one more Flow* run (`checks`). "
             "A piece that cannot meet the mode invariant (LP) is not sent to Flow*.", "",
             "| TM order, horizon | Flow* flowpipe run s (CPU; Flow*'s clock) | checks: runs, s (CPU) | "
             "Flow* total s (CPU) | Flow* verdicts | property file | reach taylor s (CPU) | reach verdicts | "
             "ratio Flow*/reach total, wall (CPU) | flowpipe run only, wall (CPU) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for st in report["settings"]:
        fs, rs = st["flowstar"], st["reach_taylor"]
        found = ratios_of(fs, rs)
        check_cpu = fs.get("cpu_seconds", 0) - fs.get("flowpipe_cpu_seconds", 0)
        for name, r in rs.items():
            left = (f"| {fs['order']}, {fs['horizon_min']:g} min | {fs['flowpipe_seconds']:.1f} "
                    f"({fs.get('flowpipe_cpu_seconds', '-')}; {fs['flowstar_cpu_seconds']:.1f}) | "
                    f"{fs['check_runs']}, {fs['check_seconds']:.1f} ({check_cpu:.1f}) | "
                    f"{fs['seconds']:.1f} ({fs.get('cpu_seconds', '-')}) | "
                    f"{summary({p: v for p, v in fs['verdicts'].items() if p in r['verdicts']})} |")
            q = found.get(name)
            ratio = (f"{q['total']:.2f} ({q.get('total_cpu', float('nan')):.2f}) | "
                     f"{q['flowpipes']:.2f} ({q.get('flowpipes_cpu', float('nan')):.2f})") if q else "- | -"
            lines.append(f"{left} {name} | {r['seconds']:.1f} ({r.get('cpu_seconds', '-')}) | "
                         f"{summary(r['verdicts'])} | {ratio} |")
    lines += ["", "How to read it: CPU is user + system seconds of the flowstar processes (for reach: of "
              "its process); Flow*'s clock is the time it prints for the reachability computation alone "
              "(the run's CPU also covers preparing and writing the dump). With the machine shared, the CPU "
              "ratios are the steadier ones. Flow*'s jump is a may-transition inside the docking guard "
              "while the approach invariant holds; the model's urgent runs are among those runs, so Flow*'s "
              "SAFE is a SAFE of the model. The checks re-read the dumped Taylor models, whose coefficients "
              "Flow* prints with 15 significant digits. Pieces outside the invariant: "
              + (", ".join(report["settings"][0]["flowstar"]["pieces_outside_invariant"]) or "none")
              + " (the open `x < -100` cannot hold where the invariant says `x >= -100`; Flow* would check it "
              "closed and meet the entry edge `x = -100`). reach runs `check_model` with the taylor back-end "
              "and `remainder: rigorous` on the same model with its horizon set to the Flow* time; "
              "a property file that reach's taylor does not support on this branch has no ratio.", "",
              "Anchor (shared/ANCHORS.md, a quieter machine): Flow* SAFE to 200 min in 42 s (order 5) and "
              "to 240 min in 89 s (order 7), one unsafe conjunction per run; all 14 pieces add about 80 s.", ""]
    dace = report.get("daceypy")
    if dace:
        lines += ["## daceypy in the same run (`benchmarks/taylor_vs_daceypy.py`)", ""]
        if "error" in dace:
            lines.append(f"Not run: {dace['error']}")
        else:
            lines += ["| case | reach s | daceypy s | ratio daceypy/reach | largest coefficient difference |",
                      "|---|---|---|---|---|",
                      f"| {dace['case']} | {dace['reach_seconds']} | {dace['daceypy_seconds']} | "
                      f"{dace['ratio_daceypy_over_reach']} | {dace['max_rel_coefficient_difference']:.1e} |"]
        lines.append("")
    lines += ["## Build recipe", "", BUILD_HELP.strip(), ""]
    return "\n".join(lines)


# ---------------------------------------------------------------- driver

BUILD_HELP = __doc__[__doc__.index("Build it"):__doc__.index("Without")]


def write(report: dict, json_path: Path, md_path: Path) -> None:
    report["machine"]["load_average_at_end"] = list(os.getloadavg())
    json_path.write_text(json.dumps(report, indent=2) + "\n")
    md_path.write_text(markdown(report))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per Flow* call")
    parser.add_argument("--daceypy-path", default=os.environ.get("DACEYPY_PATH"),
                        help="directory with daceypy installed (pip install --target DIR daceypy)")
    parser.add_argument("--write-model", metavar="FILE", help="only write the order-5 Flow* model and stop")
    parser.add_argument("--json", default=str(ROOT / "results" / "flowstar.json"))
    parser.add_argument("--render", action="store_true", help="only rewrite the .md from the .json")
    args = parser.parse_args(argv)
    md_path = Path(args.json).with_suffix(".md")
    if args.render:
        md_path.write_text(markdown(json.loads(Path(args.json).read_text())))
        return 0

    from reach.model import load_model
    from reach.spec import bind, load_properties
    model = load_model(MODEL)
    props = [bind(p, model) for path in PROPERTY_FILES for p in load_properties(path)]
    pieces = unsafe_pieces(model, props)
    if args.write_model:
        first = {}
        for plist in pieces.values():
            for mode, piece in plist:
                first.setdefault(mode, piece)
        Path(args.write_model).write_text(flowstar_model(model, *SETTINGS[0], first))
        return 0
    binary = os.environ.get("FLOWSTAR")
    if not binary or shutil.which(binary) is None:
        print("FLOWSTAR does not name a flowstar executable; nothing run.\n" + BUILD_HELP)
        return 0

    report = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "machine": {"cores": os.cpu_count(), "platform": platform.platform(),
                          "load_average_at_start": list(os.getloadavg())},
              "model": str(MODEL.relative_to(ROOT)),
              "property_files": [str(p.relative_to(ROOT)) for p in PROPERTY_FILES],
              "unsafe_pieces": {pid: len(v) for pid, v in pieces.items()},
              "flowstar_settings": "nonpoly ode, adaptive steps 0.01-1 min, QR precondition, cutoff 1e-10, "
                                   "precision 53, remainder estimation 1e-2, interval aggregation",
              "settings": []}
    for order, horizon in SETTINGS:
        print(f"Flow* order {order} to {horizon:g} min ...", flush=True)
        fs = flowstar_setting(binary, model, pieces, order, horizon, args.timeout)
        print(f"  {fs['seconds']} s ({fs['flowpipe_seconds']} s flowpipes, {fs['check_runs']} checks "
              f"{fs['check_seconds']} s): {fs['verdicts']}", flush=True)
        print(f"reach taylor (rigorous) to {horizon:g} min ...", flush=True)
        rs = reach_setting(model, horizon)
        for name, r in rs.items():
            print(f"  {name}: {r['seconds']} s {r['verdicts']}", flush=True)
        ratios = ratios_of(fs, rs)
        report["settings"].append({"flowstar": fs, "reach_taylor": rs, "ratio_flowstar_over_reach": ratios})
        print(f"  ratio Flow*/reach: {ratios}", flush=True)
        write(report, Path(args.json), md_path)        # each finished setting survives a cut run
    dace = daceypy_run(args.daceypy_path)
    if dace is not None:
        report["daceypy"] = dace
        print(f"daceypy: {dace}")
    write(report, Path(args.json), md_path)
    print(f"wrote {args.json} and {md_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
