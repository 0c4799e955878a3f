"""Result tables: the ARCH-COMP-style markdown of a run, and the comparison of two runs."""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

from reach.paths import few, printable, safe_name

#: back-ends whose verdicts are proofs (Monte Carlo is the referee, not a formal method)
FORMAL = ("star", "taylor", "fsr")
DECIDED = ("safe", "unsafe")

#: pictures embedded at the top of results.md when they are in its plots folder
KEY_PICTURES = (
    ("fig4_positions_star_linear.png", "Fig. 4: positions without Passive, star on the linear model (SRA02)"),
    ("fig4_positions_taylor_nonlinear.png", "Fig. 4: positions, taylor on the nonlinear SRNA01 with Monte Carlo runs"),
    ("fig4_velocity_mode2.png", "Fig. 4: velocity in rendezvous against the octagon"),
    ("fig4_thrust_x.png", "Fig. 4: thrust Fx"),
    ("fig4_positions_passive.png", "Fig. 4: positions after a Passive transition in [120, 125] min"),
    ("SRA08_abort_map.png", "Safe-abort map of SRA08 with the Passive margins"),
)


def md(value) -> str:
    """``value`` as the text of one markdown table cell: control characters and line separators
    escaped (:func:`reach.paths.printable`: a ``\\n`` in an instance name of a results file
    cannot start a row of its own), ``|`` as ``\\|`` (it cannot add a column)."""
    return printable(value).replace("|", "\\|")


def _cell(row, run_marks: dict) -> str:
    status = row["status"].upper()
    if status == "UNSUPPORTED":
        return "n/a"
    text = f"{status} {float(row.get('seconds') or 0):.2f}"
    if row.get("probability"):
        lo, hi = row["probability"]
        text += f" [{lo:.4f}, {hi:.4f}]"
    return md(text + run_marks.get(row.get("run"), ""))


def agreement(rows: dict) -> tuple[str, str]:
    """Whether the formal back-ends of one instance/property agree, and the time ratio between
    them: ``(agree, ratio)`` for ``rows`` = ``{backend: row}``.

    * ``yes``: at least two formal back-ends decided (SAFE/UNSAFE) and all the same way;
    * ``NO``: one says SAFE and another UNSAFE (the cross-checks say whether a counterexample
      replays);
    * ``open (B undecided)``: decided ones agree, some formal back-end gave UNKNOWN or a time-out;
    * ``one formal`` / empty: fewer than two formal back-ends answered (n/a is no answer).

    Ratio: the slowest over the fastest of the formal back-ends that decided, as ``slow/fast x``."""
    formal = {b: r for b, r in rows.items() if b in FORMAL and str(r.get("status", "")).lower() != "unsupported"}
    if len(formal) < 2:
        return ("one formal" if formal else ""), ""
    decided = {b: r for b, r in formal.items() if str(r["status"]).lower() in DECIDED}
    verdicts = {str(r["status"]).lower() for r in decided.values()}
    open_ = sorted(set(formal) - set(decided))
    if len(verdicts) > 1:
        agree = "NO"
    elif len(decided) >= 2 and not open_:
        agree = "yes"
    else:
        agree = f"open ({', '.join(open_)} undecided)" if open_ else "yes"
    ratio = ""
    if len(decided) >= 2:
        timed = sorted(decided.items(), key=lambda kv: _seconds(kv[1]))
        (fast, fr), (slow, sr) = timed[0], timed[-1]
        if _seconds(fr) > 0:
            ratio = f"{slow}/{fast} {_seconds(sr) / _seconds(fr):.1f}x"
    return agree, ratio


def _plot_names(report: dict, folder) -> set[str]:
    """The pictures of a report: those it lists and those in ``folder/plots`` (earlier runs')."""
    names = {Path(p).name for p in report.get("plots") or []}
    if folder is not None and (Path(folder) / "plots").is_dir():
        names |= {p.name for p in (Path(folder) / "plots").glob("*.png")}
    return names


def _plot_links(names: set[str], instance: str, model: str) -> str:
    """Links to the pictures of an instance (its model's runs, its subdomain maps)."""
    links = []
    runs = f"{safe_name(model)}_runs.png"
    if runs in names:
        links.append(md(f"[runs](plots/{runs})"))
    for name in sorted(names):
        prefix = f"{safe_name(instance)}_"     # the runner's file names (runner.subdomain_picture)
        if name.startswith(prefix) and name.endswith("_subdomains.png"):
            links.append(md(f"[{name[len(prefix):-len('_subdomains.png')]}](plots/{name})"))
    return " ".join(links)


def markdown_table(report: dict, folder=None) -> str:
    """Instance x property rows, one column per back-end with verdict and seconds, whether the
    formal back-ends agree and their time ratio (:func:`agreement`), and links to the instance's
    pictures; the key pictures in ``folder/plots`` embedded above the table."""
    backends = report["backends"]
    grid = defaultdict(dict)
    expected = {}
    order = []
    for r in report["rows"]:
        key = (r["instance"], r["property"])
        if key not in grid:
            order.append(key)
        grid[key][r["backend"]] = r
        expected[key] = r.get("expected") or ""
    runs = report.get("runs") or []
    run_marks = {}
    lines = [printable(f"# reach bench: {report['suite']}"), "",
             f"{report['started']}, {report['machine']['platform']}, executor {report['executor']}, "
             f"wall time {report['wall_seconds']:.1f} s.", ""]
    if len(runs) > 1:
        lines.append("Rows come from several runs; a cell from an earlier run carries its mark:")
        lines.append("")
        for k, run in enumerate(runs[:-1], start=1):
            run_marks[run["run"]] = f" ({k})"
            which = f", {run['filter']}" if run.get("filter") else " (whole suite)"
            lines.append(printable(f"- ({k}) {run['run']}{which}, wall time {float(run.get('wall_seconds') or 0):.1f} s"))
        last = runs[-1]
        lines += [printable(f"- unmarked: {last['run']}{', ' + last['filter'] if last.get('filter') else ''}"), ""]
    pictures = [(name, text) for name, text in KEY_PICTURES
                if folder is not None and (Path(folder) / "plots" / name).is_file()]
    if pictures:
        lines += ["## Pictures", ""]
        for name, text in pictures:
            lines += [f"![{text}](plots/{name})", "", f"*{text}*", ""]
    lines += ["Verdict and seconds per back-end (n/a: the back-end does not handle this case); whether the "
              f"formal back-ends ({', '.join(FORMAL)}) agree, and the time ratio of the slowest to the fastest "
              "that decided.", "",
              "| instance | property | expected | " + " | ".join(backends) + " | formal agree | time ratio | plots |",
              "|---|---|---|" + "---|" * len(backends) + "---|---|---|"]
    models = {r["instance"]: r.get("model") or r["instance"] for r in report["rows"]}
    names = _plot_names(report, folder)
    for key in order:
        cells = [_cell(grid[key][b], run_marks) if b in grid[key] else "" for b in backends]
        agree, ratio = agreement(grid[key])
        lines.append(f"| {md(key[0])} | {md(key[1])} | {md(expected[key])} | " + " | ".join(cells)
                     + f" | {md(agree)} | {md(ratio)} | {_plot_links(names, key[0], models[key[0]])} |")
    lines += ["", "## Cross-checks", ""]
    if not report["cross_checks"]:
        lines.append("All back-ends agree with each other and with the expected verdicts.")
    for c in report["cross_checks"]:
        lines.append(printable(f"- **{c['level']}**: {c['message']}"))
    return "\n".join(lines) + "\n"


def _seconds(row) -> float:
    try:
        return float(row.get("seconds") or 0.0)
    except (TypeError, ValueError):
        return float("nan")


def _by_key(report: dict, path, warn) -> dict:
    """The rows of a results file by (instance, property, back-end). A key seen twice (a file
    edited or pasted together: the runner writes each once) keeps its last row, the newest where
    runs were merged, and ``warn`` gets one line naming the file and the duplicated rows."""
    rows, again = {}, []
    for i, r in enumerate(report["rows"]):
        key = (r["instance"], r["property"], r["backend"])
        if key in rows:
            again.append(f"rows[{i}] {'/'.join(key)}")
        rows[key] = r
    if again:
        warn(f"warning: {path}: {len(again)} duplicate row{'s' if len(again) > 1 else ''} "
             f"(instance/property/back-end seen before; the last one is compared): {few(again, 5)}")
    return rows


def _warn(line: str) -> None:
    print(printable(line), file=sys.stderr)


def compare_runs(old_path, new_path, warn=_warn) -> str:
    """Verdict changes and time ratios (new/old) between two results.json files, and the rows of
    the old one that the new one lacks ("gone"). Every cell is escaped (:func:`md`); a file with
    a row twice is compared by its last one, with a warning (``warn``: one line on stderr)."""
    from reach.bench.runner import read_report

    old = _by_key(read_report(old_path), old_path, warn)
    new = _by_key(read_report(new_path), new_path, warn)
    lines = ["| instance | property | back-end | verdict | seconds old -> new | ratio |", "|---|---|---|---|---|---|"]
    for key, r in new.items():
        shown = " | ".join(md(k) for k in key)
        before = old.get(key)
        if before is None:
            lines.append(f"| {shown} | {md('new: ' + r['status'])} | {_seconds(r):.2f} | |")
            continue
        verdict = r["status"] if r["status"] == before["status"] else f"{before['status']} -> {r['status']}"
        ratio = (_seconds(r) / _seconds(before)) if _seconds(before) else float("nan")
        lines.append(f"| {shown} | {md(verdict)} | {_seconds(before):.2f} -> {_seconds(r):.2f} | {ratio:.2f} |")
    gone = [key for key in old if key not in new]
    for key in gone:
        lines.append(f"| {' | '.join(md(k) for k in key)} | {md('gone (was ' + old[key]['status'] + ')')} | "
                     f"{_seconds(old[key]):.2f} -> | |")
    lines.append("")
    lines.append(f"{len(new)} rows now, {len(old)} before: {len(set(new) - set(old))} new, {len(gone)} gone")
    return "\n".join(lines)
