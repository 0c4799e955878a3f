"""The ``reach`` command.

    reach check MODEL PROPS [--backend B] [--json] [--option KEY=VALUE ...]
    reach lint MODEL... (files or directories of models)
    reach replay COUNTEREXAMPLE.json
    reach plot MODEL [--runs N] [--out FILE.png]
    reach bench [--suite suite.yaml] [--backend B] [--instance I] [-j N] [--scheduler ADDR]
    reach sweep MODEL PROPS [--radius R] [--cells N]
    reach compare OLD.json NEW.json
    reach import MODEL.xml [CONFIG.cfg] --out DIR   (SpaceEx -> models/ and properties/ YAML)
    reach check MODEL.xml CONFIG.cfg ...           (a SpaceEx model against its cfg's forbidden set)

Bad input prints one line ``file:line: field: message`` and exits with 2. ``check`` prints the
model's lints (structural findings, :mod:`reach.model.lint`) to stderr as ``warning: ...``.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

import yaml

from reach.errors import InputError
from reach.locate import find_model
from reach.result import Status


def _parse_options(pairs: list[str]) -> dict:
    options = {}
    for pair in pairs or []:
        if "=" not in pair:
            raise InputError(f"expected KEY=VALUE, got '{pair}'", field="--option")
        key, value = pair.split("=", 1)
        try:
            options[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError:
            raise InputError(f"cannot read the value of '{key}'", field="--option") from None
        if isinstance(options[key.strip()], str):
            try:                    # YAML 1.1 reads 1e-4 (no dot) as text
                options[key.strip()] = float(value)
            except ValueError:
                pass
    return options


def cmd_check(args) -> int:
    from reach.checking import check_files, is_spaceex

    if is_spaceex(args.model):
        return cmd_check_spaceex(args)
    if args.verbose:
        logging.basicConfig(stream=sys.stderr, format="%(name)s: %(message)s")
        logging.getLogger("reach").setLevel(logging.INFO)

    model_path = find_model(args.model)
    from reach.model import load_model
    for finding in load_model(model_path).lints:
        print(f"warning: {finding}", file=sys.stderr)
    results = check_files(model_path, args.properties, args.backend, _parse_options(args.option),
                          args.property)
    saved = {}
    if args.counterexamples:
        out = Path(args.counterexamples)
        for r in results:
            if r.counterexample is not None:
                out.mkdir(parents=True, exist_ok=True)
                path = out / f"{r.model}_{r.property}_{r.backend}.json"
                r.counterexample.save(path)
                saved[r.property] = str(path)
    if args.json:
        rows = []
        for r in results:
            row = {"property": r.property, "status": r.status.value.lower(), "seconds": r.seconds}
            row.update(r.to_dict())
            if r.property in saved:
                row["counterexample_file"] = saved[r.property]
            rows.append(row)
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{results[0].model if results else args.model} with {args.backend}:")
    for r in results:
        print(f"  {r.property:<16} {r.status.value:<11} {r.seconds:8.2f} s  {summary(r)}")
        if r.property in saved:
            print(f"  {'':<16} counterexample: {saved[r.property]}  (reach replay {saved[r.property]})")
    return 0


def cmd_check_spaceex(args) -> int:
    """``reach check MODEL.xml CONFIG.cfg``: the cfg's forbidden set is the property; a
    counterexample is saved with the imported YAML beside it, so ``reach replay`` reads it."""
    from reach.checking import check_spaceex
    from reach.model.spaceex import write_yaml

    if args.verbose:
        logging.basicConfig(stream=sys.stderr, format="%(name)s: %(message)s")
        logging.getLogger("reach").setLevel(logging.INFO)
    results, model, docs = check_spaceex(args.model, args.properties, args.backend, _parse_options(args.option))
    for finding in model.lints:
        print(f"warning: {finding}", file=sys.stderr)
    if args.json:
        print(json.dumps([{"property": r.property, "status": r.status.value.lower(), "seconds": r.seconds,
                           **r.to_dict()} for r in results], indent=1))
        return 0
    print(f"{model.name} with {args.backend}:")
    if not results:
        print(f"  {args.properties} forbids nothing: nothing to check")
    for r in results:
        print(f"  {r.property:<16} {r.status.value:<11} {r.seconds:8.2f} s  {summary(r)}")
        if r.counterexample is not None and args.counterexamples:
            model_file, prop_file = write_yaml(docs, args.counterexamples)
            cex = r.counterexample
            cex.model_file, cex.property_file = str(model_file), str(prop_file)
            # the YAML property file names each forbidden term; replay the one that was hit
            cex.property = _term_hit(docs, model, cex)
            path = Path(args.counterexamples) / f"{model_file.stem}_{r.backend}.json"
            cex.save(path)
            print(f"  {'':<16} counterexample: {path}  (reach replay {path})")
    return 0


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
    from reach.model.spaceex import documents, write_yaml

    model_file, prop_file = write_yaml(documents(args.model, args.config), args.out)
    print(f"wrote {model_file}" + (f" and {prop_file}" if prop_file else " (the cfg forbids nothing)"))
    return 0


def summary(result) -> str:
    """One line of the most telling details of a result."""
    d = result.details
    if result.status == Status.UNSUPPORTED:
        return d.get("reason", "")
    if result.counterexample is not None:
        c = result.counterexample
        abort = "" if c.switch_time is None else f", switch at t={c.switch_time:g}"
        return f"violated at t={c.violation_time:.4g} in {c.violation_mode}{abort}"
    parts = []
    if result.probability is not None:
        parts.append(f"P in [{result.probability[0]:.4f}, {result.probability[1]:.4f}]")
    if result.bound is not None:
        parts.append(f"bound [{result.bound[0]:.4g}, {result.bound[1]:.4g}]")
    if "closest_depth" in d:
        parts.append(f"closest margin {d['closest_depth']:.4g}")
    if "violation_probability_upper_95" in d:
        parts.append(f"P(violation) <= {d['violation_probability_upper_95']:.2g} (95 %)")
    if "method" in d:
        parts.append(str(d["method"]))
    if "remainder" in d:
        parts.append(f"remainder {d['remainder']}")
    return ", ".join(parts)


def cmd_lint(args) -> int:
    """Lint model files (a directory: every ``*.yaml`` in it except ``_`` templates); exit 1
    if anything is found."""
    from reach.model import load_model

    files = []
    for name in args.models:
        path = Path(name)
        if path.is_dir():
            files.extend(sorted(p for p in path.glob("*.yaml") if not p.name.startswith("_")))
        else:
            files.append(find_model(name))
    findings = [line for f in files for line in load_model(f).lints]
    for line in findings:
        print(line)
    if not findings:
        print(f"no findings ({len(files)} model{'s' if len(files) != 1 else ''})")
    return 1 if findings else 0


def cmd_replay(args) -> int:
    from reach.backends.montecarlo import replay
    from reach.model import load_model
    from reach.result import Counterexample
    from reach.spec import bind, load_properties

    path = Path(args.counterexample)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError("no such file", str(path)) from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not a counterexample file: {exc.__class__.__name__}", str(path)) from None
    if not isinstance(data, dict) or not {"model_file", "property_file", "property", "initial_state"} <= set(data):
        raise InputError("not a counterexample file (needs model_file, property_file, property, initial_state)",
                         str(path))
    cex = Counterexample.from_dict(data)
    model = load_model(cex.model_file)
    props = [p for p in load_properties(cex.property_file) if p.id == cex.property]
    if not props:
        raise InputError(f"property '{cex.property}' is not in {cex.property_file}", str(path), "property")
    if len(cex.initial_state) != model.n:
        raise InputError(f"initial_state has {len(cex.initial_state)} values, the model {model.n}", str(path),
                         "initial_state")
    prop = bind(props[0], model)
    rep = replay(model, prop, cex.initial_state, cex.switch_time, cex.dt or None, cex.input_signal)
    state = ", ".join(f"{n}={v:.6g}" for n, v in zip(model.state, rep.state))
    if rep.violated:
        print(f"replayed: {model.name} violates '{prop.id}' at t={rep.time:.6g} in mode {rep.mode} "
              f"(depth {rep.depth:.3g}); state {state}")
        return 0
    print(f"NOT replayed: {model.name} satisfies '{prop.id}' along this run (closest margin {rep.depth:.4g})")
    return 1


def cmd_plot(args) -> int:
    from reach.bench.plots import plot_model_runs
    from reach.model import load_model

    model = load_model(find_model(args.model))
    out = Path(args.out or f"results/plots/{model.name}_runs.png")
    plot_model_runs(model, out, runs=args.runs, seed=args.seed)
    print(f"wrote {out}")
    return 0


def cmd_bench(args) -> int:
    from reach.bench.runner import run_suite

    return run_suite(args.suite, backends=args.backend, instances=args.instance, out=args.out,
                     jobs=args.jobs, scheduler=args.scheduler, time_limit=args.time_limit)


def cmd_sweep(args) -> int:
    import time

    from reach.backends.star import arc_cells, safe_abort_map
    from reach.bench.executors import make_executor
    from reach.bench.plots import plot_abort_map
    from reach.model import load_model

    model_path = find_model(args.model)
    model = load_model(model_path)
    windows = [tr.window for tr in model.transitions if tr.window is not None]
    if not windows:
        raise InputError(f"model '{model.name}' has no abort window to sweep", str(model_path))
    window = (min(w[1] for w in windows), max(w[2] for w in windows))
    cells = arc_cells(model, args.radius, args.cells, args.start, args.end)
    start = time.perf_counter()
    times = safe_abort_map(model_path, [args.properties], cells, args.property, {},
                           make_executor(args.jobs, args.scheduler))
    seconds = time.perf_counter() - start
    out = Path(args.out or f"results/plots/{model.name}_abort_map.png")
    plot_abort_map(cells, times, window, out, f"{model.name}: latest safe abort ({seconds:.1f} s)")
    print(f"| angle [deg] | x [m] | y [m] | latest safe abort [{model.units.time}] |")
    print("|---|---|---|---|")
    for (low, high, angle), t in zip(cells, times):
        print(f"| {angle:.1f} | [{low[0]:.0f}, {high[0]:.0f}] | [{low[1]:.0f}, {high[1]:.0f}] | {t:.2f} |")
    print(f"{len(cells)} cells in {seconds:.1f} s; wrote {out}")
    return 0


def cmd_compare(args) -> int:
    from reach.bench.tables import compare_runs

    print(compare_runs(args.old, args.new))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="reach", description="Reachability verification of spacecraft "
                                     "guidance and control: one model, several back-ends.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("check", help="check a model against a property file")
    p.add_argument("model", help="model file, or a model's name (searched in models/)")
    p.add_argument("properties", help="property file")
    p.add_argument("--backend", "-b", default="montecarlo")
    p.add_argument("--property", "-p", action="append", help="check only this property (repeatable)")
    p.add_argument("--option", "-o", action="append", metavar="KEY=VALUE", help="back-end option")
    p.add_argument("--json", action="store_true", help="print results as JSON")
    p.add_argument("--verbose", "-v", action="store_true", help="print the back-end's progress to stderr")
    p.add_argument("--counterexamples", default="counterexamples", metavar="DIR",
                   help="where UNSAFE counterexamples are written (default: counterexamples/)")
    p.set_defaults(func=cmd_check)
    p = sub.add_parser("lint", help="structural checks of models (zero-dwell cycles); exit 1 on findings")
    p.add_argument("models", nargs="+", help="model files, names, or directories of models")
    p.set_defaults(func=cmd_lint)
    p = sub.add_parser("replay", help="replay a counterexample file with the simulator")
    p.add_argument("counterexample")
    p.set_defaults(func=cmd_replay)
    p = sub.add_parser("plot", help="plot sample runs of a model, coloured by mode")
    p.add_argument("model")
    p.add_argument("--runs", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out")
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser("bench", help="run the benchmark suite")
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
    p.add_argument("--out")
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser("compare", help="what changed between two results.json files")
    p.add_argument("old")
    p.add_argument("new")
    p.set_defaults(func=cmd_compare)
    p = sub.add_parser("import", help="write a SpaceEx model (.xml + .cfg) as model and property YAML")
    p.add_argument("model", help="SpaceEx model (.xml)")
    p.add_argument("config", nargs="?", help="SpaceEx configuration (.cfg; default: MODEL's name with .cfg)")
    p.add_argument("--out", required=True, metavar="DIR", help="writes DIR/models/NAME.yaml, DIR/properties/NAME.yaml")
    p.set_defaults(func=cmd_import)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as exc:
        print(f"reach: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("reach: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
