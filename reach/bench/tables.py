"""Result tables: the ARCH-COMP-style markdown of a run, and the comparison of two runs."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path


def _cell(row) -> str:
    status = row["status"].upper()
    if status == "UNSUPPORTED":
        return "n/a"
    text = f"{status} {float(row.get('seconds') or 0):.2f}"
    if row.get("probability"):
        lo, hi = row["probability"]
        text += f" [{lo:.4f}, {hi:.4f}]"
    return text


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
    lines = [f"# reach bench: {report['suite']}", "",
             f"{report['started']}, {report['machine']['platform']}, executor {report['executor']}, "
             f"wall time {report['wall_seconds']:.1f} s.", "",
             "Verdict and seconds per back-end (n/a: the back-end does not handle this case).", "",
             "| instance | property | expected | " + " | ".join(backends) + " |",
             "|---|---|---|" + "---|" * len(backends)]
    for key in order:
        cells = [_cell(grid[key][b]) if b in grid[key] else "" for b in backends]
        lines.append(f"| {key[0]} | {key[1]} | {expected[key]} | " + " | ".join(cells) + " |")
    lines += ["", "## Cross-checks", ""]
    if not report["cross_checks"]:
        lines.append("All back-ends agree with each other and with the expected verdicts.")
    for c in report["cross_checks"]:
        lines.append(f"- **{c['level']}**: {c['message']}")
    return "\n".join(lines) + "\n"


def compare_runs(old_path, new_path) -> str:
    """Verdict changes and time ratios (new/old) between two results.json files."""
    old = json.loads(Path(old_path).read_text())
    new = json.loads(Path(new_path).read_text())
    index = {(r["instance"], r["property"], r["backend"]): r for r in old["rows"]}
    lines = ["| instance | property | back-end | verdict | seconds old -> new | ratio |", "|---|---|---|---|---|---|"]
    for r in new["rows"]:
        key = (r["instance"], r["property"], r["backend"])
        before = index.get(key)
        if before is None:
            lines.append(f"| {key[0]} | {key[1]} | {key[2]} | new: {r['status']} | {r['seconds']:.2f} | |")
            continue
        verdict = r["status"] if r["status"] == before["status"] else f"{before['status']} -> {r['status']}"
        ratio = (r["seconds"] / before["seconds"]) if before["seconds"] else float("nan")
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {verdict} | {before['seconds']:.2f} -> "
                     f"{r['seconds']:.2f} | {ratio:.2f} |")
    return "\n".join(lines)
