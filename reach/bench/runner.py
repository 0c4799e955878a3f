"""``reach bench``: run a suite, print progress, cross-check the back-ends, write results/."""

from __future__ import annotations

import fcntl
import json
import math
import os
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
from reach.paths import few, printable, safe_name, writable_file, writable_folder


def run_unit(model_path: str, property_path: str, backend: str, options: dict) -> list[dict]:
    """One work unit: every property of one instance with one back-end (plain dicts back)."""
    from reach.checking import check_files

    try:
        return [r.to_dict() for r in check_files(model_path, property_path, backend, options)]
    except InputError as exc:
        return [{"backend": backend, "property": "*", "status": "error", "seconds": 0.0,
                 "details": {"error": str(exc)}}]


def _timeout_rows(backend: str, time_limit: float) -> list[dict]:
    return [{"backend": backend, "property": "*", "status": "timeout", "seconds": time_limit,
             "details": {"error": f"stopped after {time_limit} s"}}]


def _read_inputs(instances) -> tuple[dict[str, str], dict[tuple, set]]:
    """Load every chosen instance's model and bind its property file, before any unit runs: a
    malformed one is bad input (exit 2, its file, line and field), not a unit error that the
    cross-checks would count as a failure (exit 1); so is an expected verdict of a property the
    file does not have (it would never be checked). Returns the models' names (by file) and the
    property ids of each (model, property file) pair."""
    from reach.checking import load_bound
    ids: dict[tuple, set] = {}
    names: dict[str, str] = {}
    for inst in instances:
        key = (str(inst.model), str(inst.properties))
        if key not in ids:
            model, bound = load_bound(*key)
            ids[key] = {p.id for p in bound}
            names[key[0]] = model.name
        unknown = sorted(set(inst.expect) - ids[key])
        if unknown:                             # an expectation that would never be checked
            raise inst.expect_where.error(f"instance '{inst.id}' expects a verdict of '{unknown[0]}', which is no "
                                          f"property of {printable(inst.properties)} (it has "
                                          f"{', '.join(sorted(ids[key]))[:200]})")
    return names, ids


def runs_picture(folder, model_name: str) -> Path:
    """The sample-run picture of a model in the bench's plots folder (the name results.md links)."""
    return Path(folder) / f"{safe_name(model_name)}_runs.png"


def subdomain_picture(folder, instance: str, prop: str) -> Path:
    """The subdomain map of a taylor result (:func:`plot_subdomains`)."""
    return Path(folder) / f"{safe_name(instance)}_{safe_name(prop)}_subdomains.png"


def check_outputs(out: Path, units, names: dict[str, str], ids: dict[tuple, set]) -> None:
    """Every file the run will write, checked before any unit runs: one that is a symbolic link
    (or a folder, or cannot be written) is bad input naming it (:func:`reach.paths.writable_file`),
    not a file written through the link after minutes of work. Each is checked again when written."""
    writable_file(out / ".results.lock", "--out", probe=False)     # another run may hold it now
    files = [out / "results.json", out / "results.md"]
    files += [runs_picture(out / "plots", names[str(inst.model)]) for inst, _ in units]
    files += [subdomain_picture(out / "plots", inst.id, prop) for inst, b in units if b == "taylor"
              for prop in sorted(ids[(str(inst.model), str(inst.properties))])]
    for path in dict.fromkeys(files):
        writable_file(path, "--out")


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
    target = runs_picture(folder, model.name)
    try:
        writable_file(target, "--out")
    except InputError as exc:           # raised again where the run waits for the pictures (exit 2)
        raise InputError(str(exc)) from None
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
        target = writable_file(subdomain_picture(folder, r["instance"], r["property"]), "--out")
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


#: the largest results file read (``reach compare``, the rows a filtered run keeps): the whole
#: suite's results.json is some 30 MB, and JSON of small objects takes ~25x its size in memory
MAX_RESULTS_BYTES = 64 * 2 ** 20
#: seconds a result row may carry at most (more than 30 years is no measured time)
MAX_SECONDS = 1e9


def _number(value, low: float, high: float) -> bool:
    """Whether ``value`` is a JSON number (not a boolean) within ``[low, high]``: a 4000-digit
    integer or ``NaN`` is none, and is compared without converting it to a float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return (math.isfinite(value) if isinstance(value, float) else True) and low <= value <= high


def _row_problem(row: dict) -> tuple[str, str] | None:
    """``(field, what is wrong)`` for the first unusable field of a result row, else None."""
    if row.get("seconds") is not None and not _number(row["seconds"], 0.0, MAX_SECONDS):
        return "seconds", f"expected a number of seconds in [0, {MAX_SECONDS:g}]"
    pair = row.get("probability")
    if pair is not None and not (isinstance(pair, list) and len(pair) == 2
                                 and all(_number(v, 0.0, 1.0) for v in pair) and pair[0] <= pair[1]):
        return "probability", "expected an interval [low, high] within [0, 1]"
    pair = row.get("bound")
    if pair is not None and not (isinstance(pair, list) and len(pair) == 2
                                 and all(_number(v, -float("inf"), float("inf")) or v in (float("inf"), -float("inf"))
                                         for v in pair)):
        return "bound", "expected an interval [low, high] of numbers"
    if row.get("details") is not None and not isinstance(row["details"], dict):
        return "details", "expected a mapping"
    for key in ("run", "expected", "model", "source"):
        if row.get(key) is not None and not isinstance(row[key], str):
            return key, "expected a string"
    return None


def read_report(path) -> dict:
    """A results.json (a read capped at ``MAX_RESULTS_BYTES``); InputError naming the file (and
    the field) if it is not one: rows need the strings instance, property, backend and status,
    and their numbers (seconds, probability, bound) must be finite and in range."""
    from reach.paths import read_text

    shown = printable(str(path))
    try:
        report = json.loads(read_text(path, (".json",), "results file", max_bytes=MAX_RESULTS_BYTES))
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise InputError(f"not a results file: invalid JSON ({exc.__class__.__name__})", shown) from None
    if not isinstance(report, dict) or not isinstance(report.get("rows"), list) or not all(
            isinstance(r, dict) and {"instance", "property", "backend", "status"} <= set(r)
            and all(isinstance(r[k], str) for k in ("instance", "property", "backend", "status"))
            for r in report["rows"]):
        raise InputError("not a results file (expected rows with instance, property, backend, status)",
                         shown)
    for i, row in enumerate(report["rows"]):
        problem = _row_problem(row)
        if problem is not None:
            raise InputError(f"{problem[1]} ({_brief(row[problem[0]])})", shown, field=f"rows[{i}].{problem[0]}")
    runs = report.get("runs")
    if runs is not None and not (isinstance(runs, list) and all(
            isinstance(r, dict) and isinstance(r.get("run"), str) and isinstance(r.get("filter", ""), str)
            and _number(r.get("wall_seconds", 0.0), 0.0, MAX_SECONDS) for r in runs)):
        raise InputError("expected a list of runs, each with run, filter and wall_seconds", shown, field="runs")
    return report


def _brief(value) -> str:
    """A value of a results file in an error message: short, one line."""
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, int):
        return str(value) if abs(value) < 10 ** 20 else f"an integer of {len(str(abs(value)))} digits"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return f"'{printable(value)[:40]}'"
    return "a list" if isinstance(value, list) else "a mapping"


def _write_text(path: Path, text: str) -> None:
    """``text`` into ``path``, checked again (:func:`reach.paths.writable_file`) and opened by
    :func:`_open_unlinked`."""
    writable_file(path, "--out")
    with _open_unlinked(path, os.O_TRUNC, "w") as handle:
        handle.write(text)


def _open_unlinked(path: Path, flag: int, mode: str):
    """``path`` opened for writing (``flag``: ``O_TRUNC`` or ``O_APPEND``) with ``O_NOFOLLOW``: a
    symbolic link planted there since it was checked is refused, not written through."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | flag | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise InputError(f"cannot write {printable(path)} ({exc.__class__.__name__}; a symbolic link is "
                         "not written through)", field="--out") from None
    return os.fdopen(fd, mode, encoding="utf-8")


@contextmanager
def _results_lock(out: Path):
    """An exclusive lock on ``out``'s results while a run merges its rows into them and writes
    them (another run writing the same folder waits, then keeps these rows)."""
    out.mkdir(parents=True, exist_ok=True)
    path = writable_file(out / ".results.lock", "--out", probe=False)
    with _open_unlinked(path, os.O_APPEND, "a") as handle:
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
    names, ids = _read_inputs(chosen)
    check_outputs(Path(out), units, names, ids)
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
            value = _timeout_rows(backend, time_limit)
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
        _write_text(out / "results.json", json.dumps(report, indent=1))
        _write_text(out / "results.md", markdown_table(report, out))
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
