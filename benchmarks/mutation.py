"""Mutation testing of the soundness-critical functions with mutmut (not part of CI).

Each target is a list of functions in one module and the test files that should guard them.
For each target the repository (the working tree, or ``--rev`` for an earlier commit) is copied
to a scratch directory, mutmut is configured there to mutate only that module and to run only
those tests, and the mutants of the listed functions are run (``nice -n 10``). The kill rate per
target is written to a markdown table (``--out``, default results/mutation.md, one section per
``--label``; the raw counts are kept beside it in mutation.json, so targets can be run one at a
time), with the surviving mutants and their diffs in a companion file for review: a
survivor is either a missing test or an equivalent mutant (same behaviour), and the table
counts the ones judged equivalent in ``EQUIVALENT`` separately.

    pip install -e '.[test,mutation]'
    python benchmarks/mutation.py --label after                  # all targets, working tree
    python benchmarks/mutation.py --rev 0404ccd --label before taylor_remainder crosscheck
    python benchmarks/mutation.py --label after --survivors-of before star_segments   # rerun survivors only
    python benchmarks/mutation.py --merge /tmp/other/mutation.json        # add a parallel run's rows
    python benchmarks/mutation.py --list

Kill rate = (killed + timed out) / (all mutants run - equivalent ones).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import io
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Target:
    file: str
    functions: tuple[str, ...]      # function names, or Class.method
    tests: tuple[str, ...]

    @property
    def module(self) -> str:
        """The dotted name of the file's mutants (mutmut names a package's ``__init__`` by the package)."""
        return self.file[:-3].replace("/", ".").removesuffix(".__init__")

    def patterns(self) -> list[str]:
        out = []
        for f in self.functions:
            mangled = f"x\u01c1{f.replace('.', chr(0x1c1))}" if "." in f else f"x_{f}"
            out.append(f"{self.module}.{mangled}__mutmut_*")
        return out


TARGETS = {
    "star_segments": Target("reach/backends/star/flowpipe.py",
                            ("AffineFlow.curvature", "AffineFlow.deviation", "_chain_bounds", "_chain_abs_bounds",
                             "_segment", "_drift_segment", "_plus_box"),
                            ("tests/test_star_segment_bounds.py", "tests/test_star.py", "tests/test_star_inputs.py",
                             "tests/test_star_soundness.py")),
    "star_tightened": Target("reach/backends/star/flowpipe.py", ("_tightened",),
                             ("tests/test_star_tightened.py", "tests/test_star_soundness.py",
                              "tests/test_star_inputs.py", "tests/test_star_aff.py")),
    "chord_hull": Target("reach/sets/star.py", ("chord_hull",), ("tests/test_sets.py", "tests/test_star.py")),
    "fsr_intervals": Target("reach/backends/fsr/__init__.py",
                            ("reach", "reach_avoid", "_sequential", "_verdict", "leave_bound"),
                            ("tests/test_fsr.py", "tests/test_fsr_intervals.py")),
    "taylor_remainder": Target("reach/backends/taylor/bound.py",
                               ("polynomial_range", "_parity", "estimated_remainder", "truncate",
                                "next_order_remainder", "enclose", "contenders"),
                               ("tests/test_taylor_da.py", "tests/test_remainder_estimate.py")),
    "taylor_ads": Target("reach/backends/taylor/ads.py", ("extrapolate", "truncation_estimate"),
                         ("tests/test_taylor_da.py", "tests/test_remainder_estimate.py")),
    "simulator_events": Target("reach/model/simulate.py",
                               ("Simulator._first_entry", "Simulator._urgent_now", "Simulator._jump"),
                               ("tests/test_urgent_location.py", "tests/test_simulator_events.py", "tests/test_dynamics.py",
                                "tests/test_vtxo_supervisor.py", "tests/test_montecarlo.py")),
    "crosscheck": Target("reach/bench/crosscheck.py", ("cross_check", "_replays"),
                         ("tests/test_bench.py", "tests/test_crosscheck.py")),
    "within_bound": Target("reach/backends/montecarlo/event_sampling.py", ("within_bound",),
                           ("tests/test_within_bound.py", "tests/test_event_sampling.py", "tests/test_crosscheck.py")),
    "constraints": Target("reach/model/constraints.py",
                          ("Constraint.negated", "from_comparisons", "affine_coefficients", "halfspaces",
                           "lambdify_margins", "violation_test"),
                          ("tests/test_expr.py", "tests/test_loader.py", "tests/test_invariants.py",
                           "tests/test_constraint_margins.py")),
}

# Survivors judged equivalent after reading their diffs (mutant name -> why).
_RESHAPE = "numpy reads any negative size in reshape as the inferred one"
_TIE = "differs only when a size equals the negligible threshold exactly"
_DTYPE = "the values are float arrays already"
_CACHE = "the cache is skipped: the bound is recomputed, same values"
_EINSUM = "einsum labels in upper case name the same contraction"
_FLOAT_ARITH = "the array enters only float arithmetic (c1 - c0, V1 - V0, E = r), so any numeric input gives the same values"
_NO_ROWS = "with rows = 0 the slice of A is empty and the star is returned before b is used"
_WARNINGS = "errstate with the default for one kind: only a floating-point warning differs, never a value"
_NO_BREAK = "array_equal with None is False: the loop never stops early, and the rounds left repeat the fixed point"
EQUIVALENT: dict[str, str] = {
    "reach.backends.taylor.bound.x_estimated_remainder__mutmut_7": _RESHAPE,
    "reach.backends.taylor.bound.x_next_order_remainder__mutmut_7": _RESHAPE,
    "reach.backends.taylor.bound.x_next_order_remainder__mutmut_18": _TIE,
    "reach.backends.taylor.bound.x_next_order_remainder__mutmut_26": _TIE,
    "reach.backends.taylor.bound.x_next_order_remainder__mutmut_68": "at ratio 1 both give inf (S / 0)",
    "reach.backends.taylor.ads.x_truncation_estimate__mutmut_7": _RESHAPE,
    "reach.backends.taylor.ads.x_extrapolate__mutmut_3": _DTYPE,
    "reach.backends.taylor.ads.x_extrapolate__mutmut_5": _DTYPE,
    "reach.backends.taylor.ads.x_extrapolate__mutmut_20": _TIE,
    "reach.model.constraints.x_affine_coefficients__mutmut_3": "an unknown name then fails float(c)",
    "reach.model.constraints.x_halfspaces__mutmut_19": _DTYPE,
    "reach.model.constraints.x_halfspaces__mutmut_21": _DTYPE,
    "reach.model.constraints.x_halfspaces__mutmut_23": _RESHAPE,
    "reach.model.constraints.x_halfspaces__mutmut_25": _DTYPE,
    "reach.model.constraints.x_halfspaces__mutmut_27": _DTYPE,
    "reach.model.constraints.x_lambdify_margins__mutmut_6": "the general path gives the same values",
    "reach.model.constraints.x_lambdify_margins__mutmut_18": "lambdify's default modules include numpy",
    "reach.model.constraints.x_lambdify_margins__mutmut_21": "lambdify's default modules include numpy",
    "reach.model.constraints.x_violation_test__mutmut_27": "a tie with the allowance only",
    "reach.model.simulate.x\u01c1Simulator\u01c1_first_entry__mutmut_2":
        "np.zeros_like(None) is a 0-d zero: the bisection computes the same values (object dtype)",
    "reach.model.simulate.x\u01c1Simulator\u01c1_first_entry__mutmut_20":
        "differs only when a margin is exactly 0 at a bisection midpoint, by at most dt 2^-40",
    "reach.backends.star.flowpipe.x\u01c1AffineFlow\u01c1deviation__mutmut_2": _CACHE,
    "reach.backends.star.flowpipe.x\u01c1AffineFlow\u01c1deviation__mutmut_3": _CACHE,
    "reach.backends.star.flowpipe.x\u01c1AffineFlow\u01c1deviation__mutmut_29": _CACHE,
    "reach.backends.star.flowpipe.x__chain_bounds__mutmut_9": _EINSUM,
    "reach.backends.star.flowpipe.x__chain_abs_bounds__mutmut_9": _EINSUM,
    "reach.backends.star.flowpipe.x__chain_abs_bounds__mutmut_20": _EINSUM,
    "reach.backends.star.flowpipe.x__plus_box__mutmut_3": _DTYPE,
    "reach.backends.star.flowpipe.x__plus_box__mutmut_5": _DTYPE,
    "reach.backends.star.flowpipe.x__drift_segment__mutmut_30": _DTYPE,
    "reach.backends.star.flowpipe.x__drift_segment__mutmut_32": _DTYPE,
    "reach.backends.star.flowpipe.x__segment__mutmut_22": _RESHAPE,
    "reach.backends.star.flowpipe.x__segment__mutmut_31": _RESHAPE,
    "reach.backends.star.flowpipe.x__segment__mutmut_40": _RESHAPE,
    "reach.backends.star.flowpipe.x__segment__mutmut_54": _RESHAPE,
    "reach.model.simulate.x\u01c1Simulator\u01c1_urgent_now__mutmut_3":
        "one more round than modes: differs only for a cycle of urgent guards that all hold at once",
    "reach.model.simulate.x\u01c1Simulator\u01c1_urgent_now__mutmut_4": "None and False are both falsy",
    "reach.model.simulate.x\u01c1Simulator\u01c1_urgent_now__mutmut_5":
        "starting a round with moved = True only runs the remaining rounds, which change nothing once a round moved no run",
    "reach.backends.star.flowpipe.x__tightened__mutmut_8": _NO_ROWS,
    "reach.backends.star.flowpipe.x__tightened__mutmut_10": _NO_ROWS,
    **{f"reach.backends.star.flowpipe.x__tightened__mutmut_{i}": _WARNINGS for i in range(43, 49)},
    **{f"reach.backends.star.flowpipe.x__tightened__mutmut_{i}": _NO_BREAK for i in (100, 101, 104, 105)},
    "reach.backends.fsr.x_reach_avoid__mutmut_164":
        "at exactly max_rows rows the cap chooses them all (linspace hits every index): nothing is cut",
    "reach.sets.star.x_chord_hull__mutmut_5": _FLOAT_ARITH,
    "reach.sets.star.x_chord_hull__mutmut_7": _FLOAT_ARITH,
    "reach.sets.star.x_chord_hull__mutmut_10": _FLOAT_ARITH,
    "reach.sets.star.x_chord_hull__mutmut_12": _FLOAT_ARITH,
    "reach.sets.star.x_chord_hull__mutmut_19": _FLOAT_ARITH,
    "reach.sets.star.x_chord_hull__mutmut_21": _FLOAT_ARITH,
    "reach.sets.star.x_chord_hull__mutmut_14": "np.asarray(None, dtype=float) is nan, and nan > 0 selects no error",
    "reach.sets.star.x_chord_hull__mutmut_65": "1 - 2a is +1 or -1 at the tent points 0 and 1: x and / agree",
    "reach.sets.star.x_chord_hull__mutmut_118": "the b box is implied by the homogenised box rows b <= lam hi, lam <= 1",
}

STATUS = {1: "killed", 3: "killed", -24: "timeout", 24: "timeout", 36: "timeout", 152: "timeout",
          0: "survived", 33: "no tests", 34: "skipped", 5: "no tests"}


def copy_tree(rev: str | None, dest: Path):
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    if rev:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True).stdout
        tarfile.open(fileobj=io.BytesIO(archive)).extractall(dest)
    else:
        files = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-co", "--exclude-standard"], check=True,
                               capture_output=True, text=True).stdout.split("\n")
        for name in filter(None, files):
            src = ROOT / name
            if src.is_file():
                (dest / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, dest / name)
    subprocess.run(["git", "init", "-q", str(dest)], check=True)


def configure(dest: Path, target: Target):
    tests = [t for t in target.tests if (dest / t).exists()]
    config = {
        "source_paths": ["reach"],
        "only_mutate": [target.file],
        "also_copy": ["models", "properties", "suite.yaml"],
        "pytest_add_cli_args": ["-p", "no:cacheprovider", "-x", "-q", "-W", "ignore"],
        "pytest_add_cli_args_test_selection": tests,
    }
    text = (dest / "pyproject.toml").read_text()
    text += "\n[tool.mutmut]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in config.items())
    (dest / "pyproject.toml").write_text(text)
    return tests


def run_target(name: str, target: Target, rev: str | None, workdir: Path, jobs: int, log, collect=False,
               only: list[str] | None = None):
    """Run (or with ``collect`` read back) the mutants of ``target``; ``only``: just these
    mutant names (the rest of the target is left out of the counts)."""
    dest = workdir / name
    patterns = target.patterns() if only is None else only
    mutmut = [str(Path(sys.executable).with_name("mutmut"))]
    started = time.perf_counter()
    if collect:
        tests = [t for t in target.tests if (dest / t).exists()]
        returncode = 0
    else:
        copy_tree(rev, dest)
        tests = configure(dest, target)
        env = {**os.environ, "HYPOTHESIS_PROFILE": "ci", "MPLBACKEND": "Agg"}
        command = ["nice", "-n", "10", *mutmut, "run", "--max-children", str(jobs), *patterns]
        run = subprocess.run(command, cwd=dest, env=env, capture_output=True, text=True)
        log.write(f"## {name}\n$ {' '.join(command)}\n{run.stdout[-4000:]}\n{run.stderr[-4000:]}\n")
        returncode = run.returncode
    seconds = time.perf_counter() - started
    meta = dest / "mutants" / (target.file + ".meta")
    codes = json.loads(meta.read_text())["exit_code_by_key"] if meta.exists() else {}
    wanted = [re.compile(p.replace(".", r"\.").replace("*", ".*") + "$") for p in patterns]
    codes = {k: v for k, v in codes.items() if any(w.match(k) for w in wanted)}
    counts: dict[str, int] = {}
    survivors = []
    for key, code in sorted(codes.items()):
        status = "not run" if code is None else STATUS.get(code, f"exit {code}")
        if status == "survived" and key in EQUIVALENT:
            status = "equivalent"
        counts[status] = counts.get(status, 0) + 1
        if status in ("survived", "no tests"):
            diff = subprocess.run([*mutmut, "show", key], cwd=dest, capture_output=True, text=True).stdout
            survivors.append((key, status, diff))
    return {"file": target.file, "functions": target.functions, "tests": tests,
            "counts": counts, "survivors": survivors, "seconds": seconds, "returncode": returncode}


def rerun_survivors(previous: dict, row: dict) -> dict:
    """``previous`` (a full run) with its survivors replaced by ``row``, a run of just those
    mutants against the current tests. Tests are only ever added, so a mutant killed before
    stays killed; ``seconds`` is the time of the rerun."""
    counts = dict(previous["counts"])
    for _, status, _ in previous["survivors"]:
        counts[status] -= 1
    for status, n in row["counts"].items():
        counts[status] = counts.get(status, 0) + n
    return {**row, "counts": {k: v for k, v in counts.items() if v}, "rerun_of": previous["rev"]}


def apply_equivalents(row: dict) -> dict:
    """``row`` with the survivors judged equivalent since it was run (``EQUIVALENT``) counted as such."""
    counts, survivors = dict(row["counts"]), []
    for key, status, diff in row["survivors"]:
        if status == "survived" and key in EQUIVALENT:
            counts["survived"] -= 1
            counts["equivalent"] = counts.get("equivalent", 0) + 1
        else:
            survivors.append((key, status, diff))
    return {**row, "counts": {k: v for k, v in counts.items() if v}, "survivors": survivors}


def kill_rate(counts: dict) -> tuple[int, int, float]:
    killed = counts.get("killed", 0) + counts.get("timeout", 0)
    considered = sum(v for k, v in counts.items() if k not in ("equivalent", "skipped", "not run"))
    return killed, considered, (100.0 * killed / considered if considered else float("nan"))


def write_report(out: Path, store: dict):
    """The markdown report from every run kept in ``store`` (label -> target -> row)."""
    text = ["# Mutation testing", "",
            "Written by benchmarks/mutation.py (mutmut on the listed functions only, the listed tests",
            "only). Kill rate = (killed + timed out) / (mutants run - equivalent ones). Survivors",
            f"with their diffs: {out.stem}_survivors.md.", ""]
    for label, rows in store.items():
        text += [f"## {label}", "",
                 "| target | module | functions | tests | mutants | killed | survived | no tests | equivalent | kill rate | minutes |",
                 "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for name, r in rows.items():
            c = r["counts"]
            killed, considered, rate = kill_rate(c)
            partial = f" ({c['not run']} not run)" if c.get("not run") else ""
            text.append(f"| {name} | {r['file']} {r['rev']} | {', '.join(r['functions'])} | "
                        f"{', '.join(Path(t).name for t in r['tests'])} | {sum(c.values())} | {killed} | "
                        f"{c.get('survived', 0)} | {c.get('no tests', 0)} | {c.get('equivalent', 0)} | "
                        f"{rate:.0f} %{partial} | {r['seconds'] / 60:.1f} |")
        text.append("")
    notes = ""
    if out.exists() and "\n## Notes" in out.read_text():
        notes = out.read_text()[out.read_text().index("\n## Notes"):]     # hand-written, kept
    out.write_text("\n".join(text) + notes.rstrip("\n") + "\n")
    lines = ["# Surviving mutants", ""]
    for label, rows in store.items():
        for name, r in rows.items():
            for key, status, diff in r["survivors"]:
                lines += [f"## {label}: {key} ({status})", "", "```diff", diff.strip(), "```", ""]
    out.with_name(out.stem + "_survivors.md").write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("targets", nargs="*", help=f"targets to run (default all): {', '.join(TARGETS)}")
    ap.add_argument("--rev", help="git revision to test instead of the working tree")
    ap.add_argument("--label", default="after", help="section name in the report")
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/reach-mutation"))
    ap.add_argument("--jobs", type=int, default=1, help="mutants run at once")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "mutation.md")
    ap.add_argument("--list", action="store_true", help="list the targets and exit")
    ap.add_argument("--survivors-of", metavar="LABEL",
                    help="run only the survivors recorded under LABEL and count the rest as recorded there")
    ap.add_argument("--tests", action="append", metavar="FILE",
                    help="run only this one of the target's test files (repeat for more): a mutant they kill "
                         "is killed by all of them")
    ap.add_argument("--merge", type=Path, metavar="JSON",
                    help="first add the rows of another store (a run in parallel with its own --out)")
    ap.add_argument("--collect", action="store_true",
                    help="do not run: read the results already in the work directory")
    args = ap.parse_args(argv)
    if args.list:
        for name, t in TARGETS.items():
            print(f"{name}: {t.file} [{', '.join(t.functions)}] <- {', '.join(t.tests)}")
        return 0
    names = args.targets or list(TARGETS)
    unknown = [n for n in names if n not in TARGETS]
    if unknown:
        ap.error(f"unknown target(s): {', '.join(unknown)}")
    args.workdir.mkdir(parents=True, exist_ok=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    store_path = args.out.with_suffix(".json")
    store = json.loads(store_path.read_text()) if store_path.exists() else {}
    if args.merge:
        for label, rows in json.loads(args.merge.read_text()).items():
            store.setdefault(label, {}).update(rows)
    store = {label: {name: apply_equivalents(r) for name, r in rows.items()} for label, rows in store.items()}
    if args.merge and not args.targets:          # only merge: rewrite the store and the report
        store_path.write_text(json.dumps(store, indent=1, ensure_ascii=False) + "\n")
        write_report(args.out, store)
        return 0
    with open(args.workdir / f"mutmut_{args.label}.log", "a") as log:
        for name in names:
            previous = store.get(args.label, {}).get(name, {})
            base = store.get(args.survivors_of, {}).get(name) if args.survivors_of else None
            if args.survivors_of and base is None:
                ap.error(f"no {args.survivors_of} run of {name} recorded")
            only = None if base is None else [key for key, _, _ in base["survivors"]]
            if only == []:
                row = {**base, "seconds": 0.0, "survivors": []}
            else:
                target = TARGETS[name]
                if args.tests:
                    target = dataclasses.replace(target, tests=tuple(t for t in target.tests if t in args.tests))
                row = run_target(name, target, args.rev, args.workdir / args.label, args.jobs, log,
                                 args.collect, only)
                if base is not None:
                    row = rerun_survivors(base, row)
            if args.collect:
                row["seconds"] = previous.get("seconds", row["seconds"])
            row["rev"] = args.rev or "working tree"
            killed, considered, rate = kill_rate(row["counts"])
            print(f"{name}: {killed}/{considered} killed ({rate:.0f} %) in {row['seconds'] / 60:.1f} min "
                  f"{row['counts']}", flush=True)
            store.setdefault(args.label, {})[name] = row
            store_path.write_text(json.dumps(store, indent=1, ensure_ascii=False) + "\n")
            write_report(args.out, store)
    return 0


if __name__ == "__main__":
    sys.exit(main())
