"""``reach bench``: run a suite, print progress, cross-check the back-ends, write results/."""

from __future__ import annotations

import fcntl
import json
import platform
import sys
import time
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path

from reach.bench.crosscheck import cross_check
from reach.executors import make_executor
from reach.bench.suite import load_suite
from reach.bench.tables import markdown_table
from reach.errors import InputError
from reach.paths import few, printable, writable_folder


def run_unit(model_path: str, property_path: str, backend: str, options: dict) -> list[dict]:
    """One work unit: every property of one instance with one back-end (plain dicts back)."""
    from reach.checking import check_files

    try:
        return [r.to_dict() for r in check_files(model_path, property_path, backend, options)]
    except InputError as exc:
        return [{"backend": backend, "property": "*", "status": "error", "seconds": 0.0,
                 "details": {"error": str(exc)}}]


def _read_inputs(instances) -> None:
    """Load every chosen instance's model and bind its property file, before any unit runs: a
    malformed one is bad input (exit 2, its file, line and field), not a unit error that the
    cross-checks would count as a failure (exit 1); so is an expected verdict of a property the
    file does not have (it would never be checked)."""
    from reach.checking import load_bound
    ids: dict[tuple, set] = {}
    for inst in instances:
        key = (str(inst.model), str(inst.properties))
        if key not in ids:
            ids[key] = {p.id for p in load_bound(*key)[1]}
        unknown = sorted(set(inst.expect) - ids[key])
        if unknown:                             # an expectation that would never be checked
            raise InputError(f"instance '{inst.id}' expects a verdict of '{unknown[0]}', which is no property "
                             f"of {printable(inst.properties)} (it has {', '.join(sorted(ids[key]))[:200]})",
                             field=f"instances.{inst.id}.expect")


def plot_models(instances, folder: Path, stream, executor) -> list[str]:
    """Sample runs of every model of the suite, coloured by mode, with the requirements of the
    property files it is checked against (one PNG per model), drawn by ``executor``'s
    workers with a progress line per model."""
    files: dict[str, list[str]] = {}
    for inst in instances:
        files.setdefault(str(inst.model), []).append(str(inst.properties))
    args = [(path, sorted(set(files[path])), str(folder)) for path in sorted(files)]
    if args:
        print(f"  drawing sample runs of {len(args)} models in {folder}", file=stream, flush=True)
    written = []
    for done, (i, (state, value)) in enumerate(executor.map_unordered(plot_unit, args), start=1):
        if state == "ok" and value.endswith(".png"):
            written.append(value)
            print(f"  [{done:>3}/{len(args)}] {Path(value).name}", file=stream, flush=True)
        else:
            print(f"  [{done:>3}/{len(args)}] no plot for {args[i][0]}: {value or state}", file=stream, flush=True)
    return sorted(written)


def plot_unit(model_path: str, property_paths: list[str], folder: str) -> str:
    """One model's sample-run plot: the PNG's path, or why there is none."""
    from reach.bench.plots import plot_model_runs
    from reach.model import load_model
    from reach.spec import bind, load_properties

    try:
        model = load_model(model_path)
        bound = [bind(p, model) for f in property_paths if f.endswith((".yaml", ".yml"))
                 for p in load_properties(f)]
    except InputError as exc:
        return str(exc)
    target = Path(folder) / f"{model.name}_runs.png"
    plot_model_runs(model, target, runs=12, bound_props=bound)
    return str(target)


def plot_subdomains(rows, folder: Path) -> list[str]:
    """The ADS subdomain map of every taylor result split over two variables (one PNG each)."""
    from reach.bench.plots import plot_subdomain_map

    written = []
    for r in rows:
        d = r.get("details") or {}
        if r.get("backend") != "taylor" or d.get("subdomain_count", 0) < 2 or len(d.get("variables", [])) != 2:
            continue
        target = folder / f"{r['instance']}_{r['property']}_subdomains.png"
        requirement = {"op": d["op"], "value": d["value"], "label": r["property"]}
        plot_subdomain_map(d["subdomains"], d["variables"], requirement, target,
                           f"{r['instance']} {r['property']}: {d['subdomain_count']} subdomains, "
                           f"{100 * d['share_meeting_requirement']:.1f} % safe ({d['remainder']})")
        written.append(str(target))
    return written


def previous_rows(path: Path, suite_path, rerun: set, instances: set, stream) -> tuple[list, list]:
    """Rows and runs of an earlier report of the same suite that this (filtered) run keeps: every
    row whose (instance, back-end) is not run again and whose instance is still in the suite."""
    if not path.is_file():
        return [], []
    try:
        old = read_report(path)
    except InputError as exc:
        print(f"  earlier results not kept: {exc}", file=stream)
        return [], []
    if old.get("suite") != str(suite_path):
        print(f"  earlier results in {path} are of another suite ({old.get('suite')}); not kept", file=stream)
        return [], []
    runs = old.get("runs") or [{"run": old.get("started", "earlier"), "filter": "",
                                "wall_seconds": old.get("wall_seconds", 0.0)}]
    kept = []
    for r in old["rows"]:
        r.setdefault("run", runs[-1]["run"])
        if (r.get("instance"), r.get("backend")) not in rerun and r.get("instance") in instances:
            kept.append(r)
    return kept, runs


def read_report(path) -> dict:
    """A results.json (size-capped read); InputError if it is not one."""
    from reach.paths import read_text

    try:
        report = json.loads(read_text(path, (".json",), "results file", max_bytes=200_000_000))
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise InputError(f"not a results file: invalid JSON ({exc.__class__.__name__})", str(path)) from None
    if not isinstance(report, dict) or not isinstance(report.get("rows"), list) or not all(
            isinstance(r, dict) and {"instance", "property", "backend", "status"} <= set(r)
            and all(isinstance(r[k], str) for k in ("instance", "property", "backend", "status"))
            for r in report["rows"]):
        raise InputError("not a results file (expected rows with instance, property, backend, status)",
                         str(path))
    return report


@contextmanager
def _results_lock(out: Path):
    """An exclusive lock on ``out``'s results while a run merges its rows into them and writes
    them (another run writing the same folder waits, then keeps these rows)."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".results.lock", "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def run_suite(suite_path, backends=None, instances=None, out="results", jobs=None, scheduler=None,
              time_limit=None, stream=sys.stdout) -> int:
    """Run (a filtered part of) a suite; exit code 1 if a cross-check fails, else 3 if one
    leaves a note (an expected verdict no back-end reached: undecided), else 0 (bad input, a
    malformed suite, model or property file, or a filter that selects no unit, raises
    InputError before any unit runs).

    A filtered run (``backends`` or ``instances``) replaces only its own rows of an existing
    ``results.json`` of the same suite and keeps the others; every row says which run it came
    from (``run``), and the report lists the runs."""
    suite = load_suite(suite_path)
    writable_folder(Path(out) / "plots", "--out")
    from reach.backends import available
    names = list(suite.backends)
    if backends:
        unknown = set(backends) - set(names)
        if unknown:
            raise InputError(f"back-end '{sorted(unknown)[0]}' is not in the suite ({', '.join(names)})",
                             field="--backend")
        names = [b for b in names if b in backends]
    missing = [b for b in names if b not in available()]
    chosen = suite.instances
    if instances:
        unknown = set(instances) - {i.id for i in chosen}
        if unknown:
            raise InputError(f"no instance '{sorted(unknown)[0]}' in {suite.file}", field="--instance")
        chosen = [i for i in chosen if i.id in instances]
    units = [(inst, b) for inst in chosen for b in names
             if b not in missing and (inst.backends is None or b in inst.backends)]
    if not units:
        raise InputError(f"no unit to run: {', '.join(names) or 'no back-end'} runs on none of the chosen "
                         f"instances ({few([i.id for i in chosen])})", field="--backend" if backends else "--instance")
    _read_inputs(chosen)
    executor = make_executor(jobs, scheduler)
    run_id = datetime.now(timezone.utc).isoformat(timespec="seconds")
    flags = [f"--backend {b}" for b in backends or []] + [f"--instance {i}" for i in instances or []]
    print(f"reach bench: {len(units)} units ({len(chosen)} instances, {len({b for _, b in units})} back-ends) "
          f"on {executor.name} executor", file=stream)
    for b in missing:
        print(f"  back-end '{b}' is not available in this installation; skipped", file=stream)
    start = time.perf_counter()
    rows = []
    args = [(str(inst.model), str(inst.properties), b, suite.options(inst, b)) for inst, b in units]
    for done, (i, (state, value)) in enumerate(executor.map_unordered(run_unit, args, time_limit), start=1):
        inst, backend = units[i]
        if state == "timeout":
            value = [{"backend": backend, "property": "*", "status": "timeout", "seconds": time_limit,
                      "details": {"error": f"stopped after {time_limit} s"}}]
        for r in value:
            r["run"] = run_id
            r["instance"] = inst.id
            r["expected"] = inst.expect.get(r["property"])
            r["source"] = inst.source
            rows.append(r)
        verdicts = " ".join(f"{r['property']}={r['status']}" for r in value)
        unit_seconds = sum(float(r.get("seconds") or 0) for r in value)
        print(f"  [{done:>3}/{len(units)}] {inst.id:<14} {backend:<11} {unit_seconds:7.2f} s  {verdicts}",
              file=stream, flush=True)
    wall = time.perf_counter() - start
    out = Path(out)
    with _results_lock(out):        # two runs writing one folder merge their rows in turn
        runs = []
        if flags:
            kept, runs = previous_rows(out / "results.json", suite_path, {(inst.id, b) for inst, b in units},
                                       {i.id for i in suite.instances}, stream)
            if kept:
                print(f"  kept {len(kept)} rows of earlier runs in {out / 'results.json'}", file=stream)
            rows = kept + rows
        runs = [r for r in runs if any(row.get("run") == r["run"] for row in rows)]
        runs.append({"run": run_id, "filter": " ".join(flags), "wall_seconds": wall})
        checks = cross_check(rows)
        (out / "plots").mkdir(parents=True, exist_ok=True)
        report = {
            "suite": str(suite_path), "started": run_id,
            "machine": {"python": platform.python_version(), "platform": platform.platform(),
                        "processor": platform.machine()},
            "executor": executor.name, "wall_seconds": wall,
            "backends": [b for b in suite.backends if any(r.get("backend") == b for r in rows)],
            "runs": runs, "rows": rows, "cross_checks": checks,
        }
        report["plots"] = plot_models(chosen, out / "plots", stream, executor) + plot_subdomains(
            [r for r in rows if r.get("run") == run_id], out / "plots")
        (out / "results.json").write_text(json.dumps(report, indent=1))
        (out / "results.md").write_text(markdown_table(report, out))
    ran = {inst.id for inst, _ in units}
    gated = [c for c in checks if c.get("instance") in ran]       # kept rows' checks: reported only
    failures = [c for c in gated if c["level"] == "fail"]
    print(f"wall time {wall:.1f} s; cross-checks: {len(gated) - len(failures)} notes, {len(failures)} failures",
          file=stream)
    for c in gated:
        print(f"  {c['level'].upper()}: {c['message']}", file=stream)
    if len(checks) > len(gated):
        print(f"  ({len(checks) - len(gated)} more on instances this run did not run, from kept rows: "
              f"in {out / 'results.md'}; they do not set the exit code)", file=stream)
    print(f"wrote {out / 'results.json'} and {out / 'results.md'}", file=stream)
    return 1 if failures else 3 if gated else 0
