"""Result tables: the ARCH-COMP-style markdown of a run, and the comparison of two runs."""

from __future__ import annotations

from collections import defaultdict


def _cell(row, run_marks: dict) -> str:
    status = row["status"].upper()
    if status == "UNSUPPORTED":
        return "n/a"
    text = f"{status} {float(row.get('seconds') or 0):.2f}"
    if row.get("probability"):
        lo, hi = row["probability"]
        text += f" [{lo:.4f}, {hi:.4f}]"
    return text + run_marks.get(row.get("run"), "")


def markdown_table(report: dict) -> str:
    """Instance x property rows, one column per back-end with verdict and seconds."""
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
    lines = [f"# reach bench: {report['suite']}", "",
             f"{report['started']}, {report['machine']['platform']}, executor {report['executor']}, "
             f"wall time {report['wall_seconds']:.1f} s.", ""]
    if len(runs) > 1:
        lines.append("Rows come from several runs; a cell from an earlier run carries its mark:")
        lines.append("")
        for k, run in enumerate(runs[:-1], start=1):
            run_marks[run["run"]] = f" ({k})"
            lines.append(f"- ({k}) {run['run']}{', ' + run['filter'] if run.get('filter') else ' (whole suite)'}, "
                         f"wall time {float(run.get('wall_seconds') or 0):.1f} s")
        last = runs[-1]
        lines += [f"- unmarked: {last['run']}{', ' + last['filter'] if last.get('filter') else ''}", ""]
    lines += ["Verdict and seconds per back-end (n/a: the back-end does not handle this case).", "",
             "| instance | property | expected | " + " | ".join(backends) + " |",
             "|---|---|---|" + "---|" * len(backends)]
    for key in order:
        cells = [_cell(grid[key][b], run_marks) if b in grid[key] else "" for b in backends]
        lines.append(f"| {key[0]} | {key[1]} | {expected[key]} | " + " | ".join(cells) + " |")
    lines += ["", "## Cross-checks", ""]
    if not report["cross_checks"]:
        lines.append("All back-ends agree with each other and with the expected verdicts.")
    for c in report["cross_checks"]:
        lines.append(f"- **{c['level']}**: {c['message']}")
    return "\n".join(lines) + "\n"


def _seconds(row) -> float:
    try:
        return float(row.get("seconds") or 0.0)
    except (TypeError, ValueError):
        return float("nan")


def compare_runs(old_path, new_path) -> str:
    """Verdict changes and time ratios (new/old) between two results.json files, and the rows of
    the old one that the new one lacks ("gone")."""
    from reach.bench.runner import read_report

    old = read_report(old_path)
    new = read_report(new_path)
    index = {(r["instance"], r["property"], r["backend"]): r for r in old["rows"]}
    present = {(r["instance"], r["property"], r["backend"]) for r in new["rows"]}
    lines = ["| instance | property | back-end | verdict | seconds old -> new | ratio |", "|---|---|---|---|---|---|"]
    for r in new["rows"]:
        key = (r["instance"], r["property"], r["backend"])
        before = index.get(key)
        if before is None:
            lines.append(f"| {key[0]} | {key[1]} | {key[2]} | new: {r['status']} | {_seconds(r):.2f} | |")
            continue
        verdict = r["status"] if r["status"] == before["status"] else f"{before['status']} -> {r['status']}"
        ratio = (_seconds(r) / _seconds(before)) if _seconds(before) else float("nan")
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {verdict} | {_seconds(before):.2f} -> "
                     f"{_seconds(r):.2f} | {ratio:.2f} |")
    gone = [key for key in index if key not in present]
    for key in gone:
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | gone (was {index[key]['status']}) | "
                     f"{_seconds(index[key]):.2f} -> | |")
    lines.append("")
    lines.append(f"{len(new['rows'])} rows now, {len(old['rows'])} before: {len(present - set(index))} new, "
                 f"{len(gone)} gone")
    return "\n".join(lines)
