"""Cross-checks between back-ends and against the suite's expectations.

Failures (``reach bench`` exits 1):
* a SAFE from one back-end where another gives UNSAFE with a counterexample that replays;
* an UNSAFE whose counterexample does not replay (checked again here, independently);
* two probability intervals for the same property that do not overlap;
* an event bound that excludes a value sampled by Monte Carlo;
* a verdict contradicting the expected one (SAFE where unsafe is expected, or UNSAFE where
  safe is expected); an error or time-out.
Notes (``reach bench`` exits 3 when there is one and no failure: undecided): an expected
verdict that no back-end reached, an expected-unsafe property that no back-end falsified or an
expected-safe one that none proved. Each check names its instance: a filtered run's exit code
counts only the checks of the instances it ran (rows kept from earlier runs are checked and
reported, not gated on).
"""

from __future__ import annotations

from collections import defaultdict

from reach.backends.montecarlo.event_sampling import within_bound


def _replays(row) -> bool:
    from reach.backends.montecarlo import replay
    from reach.model import load_model
    from reach.model.simulate import Branches
    from reach.spec import bind, load_properties

    cex = row["counterexample"]
    model = load_model(cex["model_file"])
    prop = next(p for p in load_properties(cex["property_file"]) if p.id == cex["property"])
    branches = None if cex.get("transitions") is None else Branches(prescribed=[cex["transitions"]])
    return replay(model, bind(prop, model), cex["initial_state"], cex["switch_time"], cex["dt"],
                  cex.get("input_signal"), branches).violated


def cross_check(rows: list[dict]) -> list[dict]:
    checks, current = [], {"instance": None}

    def add(level, message):
        checks.append({"level": level, "message": message, "instance": current["instance"]})

    by_key = defaultdict(list)
    for r in rows:
        by_key[(r["instance"], r["property"])].append(r)
        if r["status"] in ("error", "timeout"):
            current["instance"] = r["instance"]
            add("fail", f"{r['instance']} with {r['backend']}: {r['status']}: {r['details'].get('error', '')}")
    for (inst, prop), group in by_key.items():
        current["instance"] = inst
        if prop == "*":
            continue
        replayed = []
        for r in group:
            if r["status"] == "unsafe":
                if r.get("counterexample") and _replays(r):
                    replayed.append(r["backend"])
                else:
                    add("fail", f"{inst}/{prop}: {r['backend']} says UNSAFE without a counterexample that replays")
        for r in group:
            if r["status"] == "safe" and replayed:
                add("fail", f"{inst}/{prop}: {r['backend']} says SAFE but {', '.join(replayed)} "
                            f"found a counterexample that replays")
        expected = group[0].get("expected")
        for r in group:
            if expected == "safe" and r["status"] == "unsafe":
                add("fail", f"{inst}/{prop}: {r['backend']} says UNSAFE, expected safe ({r.get('source', '')})")
            if expected == "unsafe" and r["status"] == "safe":
                add("fail", f"{inst}/{prop}: {r['backend']} says SAFE, expected unsafe ({r.get('source', '')})")
        if expected == "unsafe" and not replayed:
            add("note", f"{inst}/{prop}: expected unsafe, but no back-end produced a counterexample")
        if expected == "safe" and not any(r["status"] == "safe" for r in group):
            add("note", f"{inst}/{prop}: expected safe, but no back-end proved it "
                        f"({', '.join(sorted(r['backend'] + ' ' + r['status'].upper() for r in group))})")
        intervals = [(r["backend"], r["probability"]) for r in group if r.get("probability")]
        for i in range(len(intervals)):
            for j in range(i + 1, len(intervals)):
                (a, (alo, ahi)), (b, (blo, bhi)) = intervals[i], intervals[j]
                if ahi < blo - 1e-9 or bhi < alo - 1e-9:       # touching intervals overlap
                    add("fail", f"{inst}/{prop}: probability intervals of {a} [{alo:.4f}, {ahi:.4f}] and "
                                f"{b} [{blo:.4f}, {bhi:.4f}] do not overlap")
        # sampled extrema against every sound bound of the same event (within_bound: strict on
        # the outer side, the sampler's grid slack on the inner side)
        samples = [r["details"] for r in group if r["details"].get("sampled_range")]
        for r in group:
            if r.get("bound") and samples:
                lo, hi = r["bound"]
                for d in samples:
                    s_lo, s_hi = d["sampled_range"]
                    if not within_bound([s_lo, s_hi], lo, hi, d.get("sense", "max"), d.get("grid_slack", 0.0)).all():
                        add("fail", f"{inst}/{prop}: {r['backend']} bound [{lo:.6g}, {hi:.6g}] excludes sampled "
                                    f"values in [{s_lo:.6g}, {s_hi:.6g}]")
    return checks
