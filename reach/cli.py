"""The ``reach`` command.

    reach check MODEL PROPS [--backend B] [--json] [--option KEY=VALUE ...]
    reach lint MODEL... (files or directories of models)
    reach replay COUNTEREXAMPLE.json
    reach plot MODEL [--runs N] [--out FILE.png]
    reach plot MODEL PROPS --backend B [--backend B2] [--vars x,y] [--out FILE.png]
    reach bench [--suite suite.yaml] [--backend B] [--instance I] [-j N] [--scheduler ADDR]
    reach sweep MODEL PROPS [--radius R] [--cells N]
    reach compare OLD.json NEW.json
    reach import MODEL.xml [CONFIG.cfg] --out DIR   (SpaceEx -> models/ and properties/ YAML)
    reach check MODEL.xml CONFIG.cfg ...           (a SpaceEx model against its cfg's forbidden set)

Exit codes (``check``, ``replay``, ``bench``; see :mod:`reach.checking`):

* 0 every property SAFE (``bench``: every cross-check and expected verdict holds);
* 1 a violation: UNSAFE with a replayed counterexample, a probability wholly below its threshold
  (``replay``: the counterexample replays; ``bench``: a failed cross-check);
* 2 bad input or options: one line ``file:line: field: message``, no traceback;
* 3 undecided: UNKNOWN or UNSUPPORTED left, nothing violated (``replay``: the run does not violate).

``check`` prints the model's lints (structural findings, :mod:`reach.model.lint`) to stderr as
``warning: ...``. Names from user files are escaped on output; files written from them go inside
their output folder (:func:`reach.paths.safe_name`).
"""

from __future__ import annotations

import argparse
import errno
import json
import logging
import math
import os
import shlex
import sys
import warnings
from pathlib import Path

import yaml

from reach.errors import InputError
from reach.locate import find_model
from reach.paths import file_in_the_way, few, folder_name_message, names_folder, printable, safe_name, writable_file

EXIT_CODES = """exit codes: 0 every property SAFE; 1 a violation (UNSAFE with a replayed counterexample, a
probability below its threshold; bench: a failed cross-check); 2 bad input or options (one line
file:line: field: message); 3 undecided (UNKNOWN or UNSUPPORTED left, nothing violated)"""
MAX_OPTION_TEXT = 10_000


def _parse_options(pairs: list[str], backend: str | None = None) -> dict:
    """``{key: value}`` of ``-o KEY=VALUE`` pairs (values read as YAML); for the one ``backend``
    a check runs, ``B.KEY`` is its ``KEY`` (as ``reach plot`` reads them) and another ``B`` is
    bad input."""
    options = {}
    for pair in pairs or []:
        if len(pair) > MAX_OPTION_TEXT:
            raise InputError(f"option longer than {MAX_OPTION_TEXT} characters", field="--option")
        if "=" not in pair:
            raise InputError(f"expected KEY=VALUE, got '{pair}'", field="--option")
        key, value = pair.split("=", 1)
        try:
            options[key.strip()] = yaml.safe_load(value)
        except (yaml.YAMLError, RecursionError):
            raise InputError(f"cannot read the value of '{key}'", field="--option") from None
        if isinstance(options[key.strip()], str):
            try:                    # YAML 1.1 reads 1e-4 (no dot) as text
                options[key.strip()] = float(value)
            except ValueError:
                pass
    if backend is not None:
        from reach.backends.options import split_options

        return split_options(options, [backend])[backend]
    return options


def cmd_check(args) -> int:
    from reach.backends import validate_options
    from reach.checking import check_model, exit_code, is_spaceex, load_bound, resolve_backend

    _no_file_in_the_way(args.counterexamples)
    if is_spaceex(args.model):
        return cmd_check_spaceex(args)
    _verbose(args)
    backend = resolve_backend(args.backend)
    options = _parse_options(args.option, args.backend)
    validate_options(args.backend, options)
    model, props = load_bound(find_model(args.model), args.properties, args.property)
    for finding in model.warnings:          # after every input is read: bad input is one line
        print(printable(f"warning: {finding}"), file=sys.stderr)
    bound = {p.id: p for p in props}
    saved = {}

    def done(prop, r) -> None:          # save its counterexample; in text, print its line at once
        if args.counterexamples and r.counterexample is not None:
            path = Path(args.counterexamples) / (safe_name(f"{r.model}_{r.property}_{r.backend}") + ".json")
            writable_file(path, "--counterexamples")
            r.counterexample.save(path)
            saved[r.property] = str(path)
        if not args.json:
            if not printed:
                print(printable(f"{r.model} with {args.backend}:"), flush=True)
            _print_result(r, bound, model, saved)
            printed.append(r)

    printed: list = []
    results = check_model(backend, model, props, options, done)
    if args.json:
        return _report(args, results, bound, model, saved, results[0].model if results else args.model)
    if not printed:
        print(printable(f"{args.model} with {args.backend}:"))
    return exit_code(results)


def _verbose(args) -> None:
    """``-v``: the back-ends' progress on stderr."""
    if args.verbose:
        logging.basicConfig(stream=sys.stderr, format="%(name)s: %(message)s")
        logging.getLogger("reach").setLevel(logging.INFO)


def _report(args, results, bound: dict, model, saved: dict, title: str, empty: str | None = None) -> int:
    """Print the results (text or ``--json``) in the requirement's units; the exit code."""
    from reach.checking import exit_code
    from reach.report import json_row

    if args.json:
        rows = [json_row(r, bound.get(r.property), model, saved.get(r.property)) for r in results]
        print(json.dumps(rows, indent=1))
        return exit_code(results)
    print(printable(f"{title} with {args.backend}:"))
    if not results and empty:
        print(printable(f"  {empty}"))
    for r in results:
        _print_result(r, bound, model, saved)
    return exit_code(results)


def _print_result(r, bound: dict, model, saved: dict) -> None:
    """One result's line (and its counterexample's), in the requirement's units."""
    from reach.checking import violated
    from reach.result import Status

    status = "VIOLATED" if r.status == Status.UNKNOWN and violated(r) else r.status.value   # no run to show
    print(printable(f"  {r.property:<16} {status:<11} {r.seconds:8.2f} s  "
                    f"{summary(r, bound.get(r.property), model)}"))
    if r.property in saved:
        print(printable(f"  {'':<16} counterexample: {saved[r.property]}  "
                        f"(reach replay {shlex.quote(str(saved[r.property]))})"))
    sys.stdout.flush()


def cmd_check_spaceex(args) -> int:
    """``reach check MODEL.xml CONFIG.cfg``: the cfg's forbidden set is the property; a
    counterexample is saved with the imported YAML beside it, so ``reach replay`` reads it."""
    from reach.checking import check_spaceex
    from reach.model.spaceex import write_yaml

    _verbose(args)
    results, model, docs, bound = check_spaceex(args.model, args.properties, args.backend,
                                                _parse_options(args.option, args.backend))
    for finding in _import_findings(docs) + model.warnings:
        print(printable(f"warning: {finding}"), file=sys.stderr)
    saved = {}
    for r in results:
        if r.counterexample is not None and args.counterexamples:
            model_file, prop_file = write_yaml(docs, args.counterexamples, "--counterexamples")
            cex = r.counterexample
            cex.model_file, cex.property_file = str(model_file), str(prop_file)
            # the YAML property file names each forbidden term; replay the one that was hit
            cex.property = _term_hit(docs, model, cex)
            path = Path(args.counterexamples) / (safe_name(f"{model_file.stem}_{r.backend}") + ".json")
            cex.save(path)
            saved[r.property] = str(path)
    return _report(args, results, bound, model, saved, model.name, f"{args.properties} forbids nothing: nothing to check")


def _term_hit(docs, model, cex) -> str:
    """The id, in the imported property file, of a forbidden term the violation state is in."""
    from reach.spec import bind
    from reach.spec.properties import properties_from_doc
    from reach.yamlio import Doc
    import numpy as np

    props = properties_from_doc(Doc(docs.properties, docs.property_lines, cex.property_file))
    for p in props:
        b = bind(p, model)
        test = b.violation(cex.violation_mode) if cex.violation_mode in b.modes else None
        if test is not None and test(np.array([cex.violation_state]))[0][0]:
            return p.id
    return props[0].id


def cmd_import(args) -> int:
    """Write the YAML model (and properties) of a SpaceEx model, once the automaton they
    describe has been built from them: a model its own loader would refuse is bad input here."""
    from reach.model.spaceex import load_spaceex, write_yaml

    _named_folder(args.out, "--out")
    model, _, docs = load_spaceex(args.model, args.config)
    model_file, prop_file = write_yaml(docs, args.out)
    for finding in _import_findings(docs) + model.warnings:
        print(printable(f"warning: {finding}"), file=sys.stderr)
    print(f"wrote {model_file}" + (f" and {prop_file}" if prop_file else " (the cfg forbids nothing)"))
    return 0


def _import_findings(docs) -> list[str]:
    """What the SpaceEx import noticed: labels that block transitions, initial constraints it
    ignored."""
    notes = docs.model["notes"]
    return [f"{notes['source']}: {line}" for line in notes.get("blocked", [])] + list(notes.get("ignored", []))


def _named_folder(folder: str, option: str) -> None:
    """An output folder given as an empty name is bad input: it would be the working folder,
    which the user did not name."""
    if not folder:
        raise InputError("an empty folder name (give a folder)", field=option)


def _no_file_in_the_way(folder) -> None:
    """``--counterexamples DIR`` naming an existing file, or a folder below one, is bad input
    before any check runs (after it, the verdicts would be lost to the error)."""
    blocking = file_in_the_way(folder) if folder else None
    if blocking is not None:
        raise InputError(f"{printable(blocking)} is a file, not a folder", field="--counterexamples")


def summary(result, prop, model) -> str:
    """One line of the most telling details of a result, in the requirement's units
    (:func:`reach.report.line`)."""
    from reach.report import line

    return line(result, prop, model)


def cmd_lint(args) -> int:
    """Lint model files (a directory: every ``*.yaml`` in it except ``_`` templates and symbolic
    links); exit 1 if anything is found."""
    from reach.model import load_model

    files = []
    for name in args.models:
        path = Path(name)
        if path.is_dir():                   # its models: property files are passed over
            found = sorted(p for p in path.glob("*.yaml")      # a link may point anywhere: not read
                           if not p.name.startswith("_") and not p.is_symlink() and not _is_property_file(p))
            if not found:                   # nothing to lint is no clean bill
                raise InputError(f"{printable(name)} holds no model file (*.yaml)", field="models")
            files.extend(found)
        else:
            files.append(find_model(name))
    findings = [line for f in files for line in load_model(f).lints]
    for line in findings:
        print(printable(line))
    if not findings:
        print(f"no findings ({len(files)} model{'s' if len(files) != 1 else ''})")
    return 1 if findings else 0


def _is_property_file(path: Path) -> bool:
    """A YAML file of properties (a top-level ``properties`` and no ``modes``), not a model."""
    from reach import yamlio

    data = yamlio.load(path).data
    return isinstance(data, dict) and "properties" in data and "modes" not in data


def cmd_replay(args) -> int:
    """Re-simulate a counterexample file: exit 1 if the run violates its property, 3 if not, 2 if
    the file does not describe a run of the model (:func:`reach.backends.montecarlo.check_run`).
    The run takes the transitions the file names at its jumps (the first enabled one where a
    name is not enabled, or in a file without them)."""
    from reach.backends.montecarlo import check_run, replay
    from reach.model import load_model
    from reach.model.simulate import Branches
    from reach.report import margin_at, margin_text, quantity
    from reach.result import Counterexample
    from reach.spec import bind, load_properties
    from reach.spec.properties import BoundEvent

    cex = Counterexample.load(args.counterexample)
    def named(key: str) -> str:
        """The file the counterexample names under ``key``, which must be there."""
        path = getattr(cex, key)
        if not Path(path).exists():
            raise InputError(f"'{path}' is neither beside the counterexample nor in the working folder",
                             args.counterexample, key)
        return path

    def loaded(key: str, loader):
        """The file under ``key`` loaded; where its text does not load, its line only: the file is
        the counterexample's choice, not the user's, and a message quoting it would show any YAML
        file's text (``lint`` or ``check`` on it says what is wrong)."""
        path = named(key)
        try:
            return loader(path)
        except InputError as exc:
            if not exc.line:                # the file itself (missing, not a plain file, too large)
                raise
            raise InputError(f"the file '{printable(path)}' it names does not load as a reach "
                             f"{key.split('_')[0]} file (line {exc.line}): reach lint or reach check on it "
                             f"says why", args.counterexample, key) from None

    model = loaded("model_file", load_model)
    props = [p for p in loaded("property_file", load_properties) if p.id == cex.property]
    if not props:
        raise InputError(f"property '{cex.property}' is not in {cex.property_file}", args.counterexample, "property")
    try:
        check_run(model, cex.initial_state, cex.switch_time, cex.input_signal, cex.transitions, cex.dt)
    except InputError as exc:
        raise InputError(exc.message, args.counterexample, exc.field) from None
    prop = bind(props[0], model)
    branches = None if cex.transitions is None else Branches(prescribed=[cex.transitions])
    try:
        rep = replay(model, prop, cex.initial_state, cex.switch_time, cex.dt or None, cex.input_signal, branches)
    except InputError as exc:               # a step the replay cannot hold (the file's dt)
        if exc.file:
            raise
        raise InputError(exc.message, args.counterexample, exc.field) from None
    state = ", ".join(f"{n}={v:.6g}" for n, v in zip(model.state, rep.state))
    if cex.transitions is not None and rep.transitions[:len(cex.transitions)] != cex.transitions:
        print(printable(f"note: the run took the transitions {few(rep.transitions, 8, '(none)')}; "
                        f"the file names {few(cex.transitions, 8, '(none)')}"))
    # why a run that was a violation at its own step is none (a nonlinear flow's finer replay)
    note = rep.trajectory.get("note") if isinstance(rep.trajectory, dict) and not rep.violated else None
    if isinstance(prop, BoundEvent):        # the extremum along the run against the requirement
        verdict = "replayed" if rep.violated else "NOT replayed"
        print(printable(f"{verdict}: {model.name} {'violates' if rep.violated else 'satisfies'} '{prop.id}': "
                        f"{prop.sense} {prop.text or 'quantity'} = {quantity(prop, rep.value, 6)} at t={rep.time:.6g} "
                        f"in mode {rep.mode or '(none)'}, required {prop.op} {quantity(prop, prop.value)}"
                        + (f"; {note}" if note else "")))
        return 1 if rep.violated else 3
    if rep.violated:
        there = margin_at(prop, rep.mode, rep.state)
        if math.isnan(rep.depth):           # the run left the real numbers after the violation
            depth = "the run leaves the real numbers later"
        else:
            depth = f"deepest{' margin' if there is None else ''} {margin_text(prop, rep.depth)} along the run"
        if there is not None:
            depth = f"margin {margin_text(prop, there)} there, {depth}"
        print(printable(f"replayed: {model.name} violates '{prop.id}' at t={rep.time:.6g} in mode {rep.mode} "
                        f"({depth}); state {state}"))
        return 1
    left = _left_the_reals(rep.trajectory)
    if left is not None:
        why = rep.trajectory.get("note") or ("a flow too stiff for the step, or one that escapes to infinity, "
                                             "or leaves its domain")
        print(printable(f"NOT decided: the run of {model.name} left the real numbers (NaN or infinite states; "
                        f"first recorded at t={left:.6g}), so the replay says nothing of '{prop.id}' from there: "
                        f"{why}"))
        return 3
    print(printable(f"NOT replayed: {model.name} satisfies '{prop.id}' along this run "
                    f"(closest margin {margin_text(prop, rep.depth)})" + (f"; {note}" if note else "")))
    return 3


def _left_the_reals(trajectory) -> float | None:
    """The first time a replayed run's state is not finite, or None."""
    import numpy as np

    if not isinstance(trajectory, dict) or not trajectory.get("x"):
        return None
    bad = ~np.all(np.isfinite(np.asarray(trajectory["x"], dtype=float)), axis=1)
    return float(np.asarray(trajectory["t"], dtype=float)[np.argmax(bad)]) if bad.any() else None


def _figure_path(out: str | None, default: Path) -> Path:
    """The output file of a picture: a format matplotlib writes, in a folder that can be written."""
    from matplotlib.figure import Figure

    if out is not None and not out:
        raise InputError(f"an empty file name (give one such as {printable(default.name)})", field="--out")
    path = Path(out) if out is not None else default
    if path.is_dir():
        raise InputError(f"{printable(path)} is a folder (give a file name such as {printable(path / default.name)})",
                         field="--out")
    if out is not None and names_folder(out):        # x.png/ that does not exist yet: not the file x.png
        raise InputError(f"{folder_name_message(out)} (give a file name such as "
                         f"{printable(path / default.name)})", field="--out")
    # pgf needs a LaTeX installation (xelatex) to write: not one the tool can rely on
    formats = {k: v for k, v in Figure().canvas.get_supported_filetypes().items() if k != "pgf"}
    if path.suffix.lstrip(".").lower() not in formats:
        raise InputError(f"unknown picture format '{path.suffix or '(none)'}'; use one of "
                         f"{', '.join('.' + f for f in sorted(formats))}", field="--out")
    writable_file(path, "--out")
    return path


def _number(value: float, option: str, low: float, high: float | None = None, open_low: bool = False):
    if not math.isfinite(value) or value < low or (open_low and value <= low) or (high is not None and value > high):
        bound = f"{'>' if open_low else '>='} {low:g}" + ("" if high is None else f" and <= {high:g}")
        raise InputError(f"expected a number {bound}, got {value}", field=option)
    return value


def cmd_plot(args) -> int:
    from reach.bench.plots import plot_model_runs
    from reach.model import load_model

    if args.properties is not None:
        return cmd_plot_sets(args)
    if args.backend or args.vars:
        raise InputError("--backend and --vars need a property file: reach plot MODEL PROPS --backend B",
                         field="properties")
    _number(args.runs, "--runs", 1, 1000)          # each run is drawn: the figure's cost grows fast
    _number(args.seed, "--seed", 0, 2 ** 32 - 1)
    model = load_model(find_model(args.model))
    out = _figure_path(args.out, Path("results/plots") / f"{safe_name(model.name)}_runs.png")
    plot_model_runs(model, out, runs=args.runs, seed=args.seed)
    print(printable(f"wrote {out}"))
    return 0


def cmd_plot_sets(args) -> int:
    """The reachable sets of one or more back-ends (:mod:`reach.plotting.command`)."""
    from reach.plotting.command import plot_files

    out = _figure_path(args.out, Path("reach_sets.png")) if args.out is not None else None
    code, out, summary, seconds = plot_files(args.model, args.properties, args.backend or ["montecarlo"],
                                             args.vars, out, _parse_options(args.option), args.property,
                                             exact=not args.fast, stream=sys.stdout)
    print(printable(f"wrote {out} ({out.stat().st_size / 1024:.0f} KB, drawn in {seconds:.1f} s)"))
    return code


def cmd_bench(args) -> int:
    from reach.bench.runner import run_suite

    if args.time_limit is not None:
        _number(args.time_limit, "--time-limit", 0.0, 7 * 86400.0, open_low=True)
    if args.jobs is not None:
        _number(args.jobs, "--jobs", 1, 256)
    _named_folder(args.out, "--out")
    return run_suite(args.suite, backends=args.backend, instances=args.instance, out=args.out,
                     jobs=args.jobs, scheduler=args.scheduler, time_limit=args.time_limit)


def cmd_sweep(args) -> int:
    import time

    import numpy as np

    from reach.backends.star import arc_cells, safe_abort_map
    from reach.bench.plots import plot_abort_map
    from reach.executors import make_executor
    from reach.model import load_model

    _number(args.radius, "--radius", 0.0, 1e9, open_low=True)
    _number(args.cells, "--cells", 1, 1000)
    _number(args.start, "--start", -360.0, 720.0)
    _number(args.end, "--end", -360.0, 720.0)
    if args.jobs is not None:
        _number(args.jobs, "--jobs", 1, 256)
    model_path = find_model(args.model)
    model = load_model(model_path)
    windows = [tr.window for tr in model.transitions if tr.window is not None]
    if not windows:
        raise InputError(f"model '{model.name}' has no abort window to sweep", str(model_path))
    window = (min(w[1] for w in windows), max(w[2] for w in windows))
    missing = [name for name in ("x", "y") if name not in model.state]
    if missing:
        raise InputError(f"model '{model.name}' has no state named {' or '.join(missing)}: sweep draws its "
                         f"initial cells on an arc in the (x, y) plane", str(model_path), field="state")
    out = _figure_path(args.out, Path("results/plots") / f"{safe_name(model.name)}_abort_map.png")
    if args.property:
        from reach.spec import load_properties
        known = {p.id for p in load_properties(args.properties)}
        for pid in args.property:
            if pid not in known:
                raise InputError(f"no property '{printable(pid)}' in {printable(args.properties)} "
                                 f"(known: {', '.join(sorted(known))})", field="--property")
    cells = arc_cells(model, args.radius, args.cells, args.start, args.end)
    _cells_start_runs(model, model_path, cells)
    start = time.perf_counter()
    times = safe_abort_map(model_path, [args.properties], cells, args.property, {},
                           make_executor(args.jobs, args.scheduler))
    seconds = time.perf_counter() - start
    from reach.bench.plots import passive_margins
    from reach.spec import bind, load_properties

    bound = [bind(p, model) for p in load_properties(args.properties) if not args.property or p.id in args.property]
    abort_times = np.linspace(window[0], window[1], 25)
    margins, margin_unit = passive_margins(model, bound, cells, abort_times)
    plot_abort_map(cells, times, window, out, f"{model.name}: latest safe abort ({seconds:.1f} s)",
                   model.units.time, margins, abort_times, margin_unit)
    length = f" [{model.units.length}]" if model.dimensions is not None else ""
    print(f"| angle [deg] | x{length} | y{length} | latest safe abort{_in_unit(model.time_unit)} |")
    print("|---|---|---|---|")
    for (low, high, angle), t in zip(cells, times):
        shown = f"{t:.2f}" if np.isfinite(t) else "none proven"
        print(f"| {angle:.1f} | [{low[0]:.0f}, {high[0]:.0f}] | [{low[1]:.0f}, {high[1]:.0f}] | {shown} |")
    print(printable(f"{len(cells)} cells in {seconds:.1f} s; wrote {out}"))
    return 0


def _in_unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""


def _cells_start_runs(model, model_path, cells) -> None:
    """Bad input where a sweep cell lies wholly outside the initial mode's invariant (no run
    starts there, so its "latest safe abort" would say nothing): the arc is the user's to place
    (``--radius``, ``--start``, ``--end``) where the model's runs begin."""
    from reach.sets import Box, Star

    halfspaces = model.modes[model.initial.mode].invariant_halfspaces
    if halfspaces is None:
        return
    H, g = halfspaces
    outside = [angle for low, high, angle in cells
               if Star.from_box(Box(low, high)).intersect_halfspaces(H, g).is_empty()]
    if outside:
        raise InputError(f"{len(outside)} of {len(cells)} cells (arc angles {', '.join(f'{a:.1f}' for a in outside[:4])}"
                         f"{', ...' if len(outside) > 4 else ''} deg) lie outside the invariant of the initial mode "
                         f"'{model.initial.mode}': no run starts there; place the arc inside it (--radius, "
                         f"--start, --end)", str(model_path), field="modes")


def cmd_compare(args) -> int:
    from reach.bench.tables import compare_runs

    for line in compare_runs(args.old, args.new).splitlines():
        print(printable(line))
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with the contract's one-line errors (exit 2) instead of a usage block."""

    def error(self, message):
        print(printable(f"{self.prog}: {message}"), file=sys.stderr)
        raise SystemExit(2)


class _Once(argparse.Action):
    """An option that may be given once: a second value is an error (the first is not
    silently replaced)."""

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, f"_{self.dest}_given", False):
            parser.error(f"{option_string}: given twice ('{getattr(namespace, self.dest)}' and '{values}'); "
                         "check runs one back-end (reach bench compares back-ends)")
        setattr(namespace, f"_{self.dest}_given", True)
        setattr(namespace, self.dest, values)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="reach", description="Reachability verification of spacecraft "
                     "guidance and control: one model, several back-ends.", epilog=EXIT_CODES,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p = sub.add_parser("check", help="check a model against a property file", epilog=EXIT_CODES)
    p.add_argument("model", help="model file, or a model's name (searched in models/)")
    p.add_argument("properties", help="property file")
    p.add_argument("--backend", "-b", default="montecarlo", action=_Once)
    p.add_argument("--property", "-p", action="append", help="check only this property (repeatable)")
    p.add_argument("--option", "-o", action="append", metavar="KEY=VALUE",
                   help="back-end option (B.KEY=VALUE: the same, for back-end B)")
    p.add_argument("--json", action="store_true", help="print results as JSON")
    p.add_argument("--verbose", "-v", action="store_true", help="print the back-end's progress to stderr")
    p.add_argument("--counterexamples", default="counterexamples", metavar="DIR",
                   help="where UNSAFE counterexamples are written (default: counterexamples/)")
    p.set_defaults(func=cmd_check)
    p = sub.add_parser("lint", help="structural checks of models (zero-dwell cycles); exit 1 on findings")
    p.add_argument("models", nargs="+", help="model files, names, or directories of models")
    p.set_defaults(func=cmd_lint)
    p = sub.add_parser("replay", help="replay a counterexample file with the simulator "
                       "(exit 1: it violates the property, 3: it does not)", epilog=EXIT_CODES)
    p.add_argument("counterexample")
    p.set_defaults(func=cmd_replay)
    p = sub.add_parser("plot", help="plot the reachable sets back-ends compute (with PROPS), or sample "
                       "runs of a model coloured by mode", epilog=EXIT_CODES)
    p.add_argument("model")
    p.add_argument("properties", nargs="?", help="property file (or SpaceEx .cfg): draw the back-ends' sets")
    p.add_argument("--backend", "-b", action="append", help="back-end whose sets are drawn (repeatable)")
    p.add_argument("--vars", help="the two axes, e.g. x,y or t,vx (states, inputs, t for time)")
    p.add_argument("--property", "-p", action="append", help="check only this property (repeatable)")
    p.add_argument("--option", "-o", action="append", metavar="KEY=VALUE",
                   help="back-end option (B.KEY=VALUE for back-end B only)")
    p.add_argument("--fast", action="store_true", help="coefficient-box bounds only (no LPs to tighten)")
    p.add_argument("--runs", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", metavar="FILE", help="the picture's file (.png, .pdf, .svg, ...; not a folder): "
                   "by default results/plots/MODEL_runs.png, or MODEL_BACKENDS_X_Y.png with PROPS")
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser("bench", help="run the benchmark suite (exit 1 on a failed cross-check)", epilog=EXIT_CODES)
    p.add_argument("--suite", default="suite.yaml")
    p.add_argument("--backend", "-b", action="append", help="only this back-end (repeatable)")
    p.add_argument("--instance", "-i", action="append", help="only this instance (repeatable)")
    p.add_argument("--out", default="results")
    p.add_argument("--jobs", "-j", type=int, default=None, help="local worker processes (default: cores)")
    p.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786")
    p.add_argument("--time-limit", type=float, default=900.0,
                   help="seconds per work unit before it is stopped (default 900)")
    p.set_defaults(func=cmd_bench)
    p = sub.add_parser("sweep", help="safe-abort map: latest safe abort time per initial cell (star)")
    p.add_argument("model")
    p.add_argument("properties")
    p.add_argument("--property", "-p", action="append", help="only this property (repeatable)")
    p.add_argument("--radius", type=float, default=1000.0, help="initial arc radius (model units)")
    p.add_argument("--cells", type=int, default=12)
    p.add_argument("--start", type=float, default=180.0, help="arc start angle, degrees")
    p.add_argument("--end", type=float, default=270.0, help="arc end angle, degrees")
    p.add_argument("--jobs", "-j", type=int, default=None)
    p.add_argument("--scheduler", help="Dask scheduler address")
    p.add_argument("--out", metavar="FILE", help="the map's file (.png, .pdf, .svg, ...; not a folder): "
                   "by default results/plots/MODEL_abort_map.png")
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser("compare", help="what changed between two results.json files (rows added, changed, gone)")
    p.add_argument("old")
    p.add_argument("new")
    p.set_defaults(func=cmd_compare)
    p = sub.add_parser("import", help="write a SpaceEx model (.xml + .cfg) as model and property YAML")
    p.add_argument("model", help="SpaceEx model (.xml)")
    p.add_argument("config", nargs="?", help="SpaceEx configuration (.cfg; default: MODEL's name with .cfg)")
    p.add_argument("--out", required=True, metavar="DIR", help="writes DIR/models/NAME.yaml, DIR/properties/NAME.yaml")
    p.set_defaults(func=cmd_import)
    return parser


#: an OSError with one of these numbers is a path the user gave that cannot be used: bad input
BAD_PATH_ERRORS = {errno.ENAMETOOLONG, errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.EACCES, errno.ELOOP}


#: characters of a bad-input line at most (the file, line and field come first)
MAX_MESSAGE = 2000


def main(argv=None) -> int:
    """Run one command; every failure becomes one line on stderr and an exit code of the contract."""
    args = build_parser().parse_args(argv)
    if not os.environ.get("REACH_DEBUG"):
        # floating-point overflow in an enclosure that blows up is an answer (an unbounded
        # interval, UNKNOWN), not a message for the user
        warnings.filterwarnings("ignore", category=RuntimeWarning)
    try:
        return args.func(args)
    except InputError as exc:
        line = printable(f"reach: {exc}")
        if len(line) > MAX_MESSAGE:             # a name of megabytes quoted whole
            line = line[:MAX_MESSAGE - 3] + "..."
        print(line, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("reach: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print("reach: out of memory: the problem is too large for this machine (nothing was decided)",
              file=sys.stderr)
        return 3
    except RecursionError:
        print("reach: input nested too deeply (nothing was decided)", file=sys.stderr)
        return 2
    except BrokenPipeError:         # the reader of the output went away (reach check ... | head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())    # no error at exit either
        return 3
    except (OverflowError, FloatingPointError) as exc:
        print(printable(f"reach: floating-point overflow ({exc}): a horizon or magnitude too large for "
                        "double precision (nothing was decided)"), file=sys.stderr)
        return 3
    except Exception as exc:  # a defect in reach, not in the input: one line, and undecided
        if os.environ.get("REACH_DEBUG"):
            raise
        if isinstance(exc, OSError) and exc.errno in BAD_PATH_ERRORS:     # a path given that cannot be used
            name = str(exc.filename)
            print(printable(f"reach: {name[:80]}{'...' if len(name) > 80 else ''}: {exc.strerror}"),
                  file=sys.stderr)
            return 2
        print(printable(f"reach: internal error: {exc.__class__.__name__}: {exc} "
                        "(nothing was decided; please report it with the input)"), file=sys.stderr)
        return 3


if __name__ == "__main__":
    sys.exit(main())
