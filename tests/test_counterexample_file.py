"""A counterexample's trajectory is thinned to what a picture needs, so its file stays within what
``reach replay`` reads, whatever the run's length and step."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.result import MAX_TRAJECTORY_POINTS, Counterexample, thinned


def _trajectory(count: int, jumps: list[int]):
    t = np.linspace(0.0, 10.0, count).tolist()
    mode = ["a"] * count
    for k in sorted(jumps):
        mode[k:] = ["b" if mode[k] == "a" else "a"] * (count - k)
    return {"t": t, "mode": mode, "x": [[v, -v] for v in t]}


@given(count=st.integers(1, 30_000), jumps=st.lists(st.integers(1, 29_999), max_size=50),
       when=st.floats(0, 10))
@settings(max_examples=60, deadline=None)
def test_thinned_keeps_the_ends_the_violation_and_every_jump_within_the_cap(count, jumps, when):
    jumps = [k for k in jumps if k < count]
    full = _trajectory(count, jumps)
    out = thinned(full, when)
    kept = out["t"]
    assert len(kept) == len(out["mode"]) == len(out["x"]) <= max(count, 1)
    assert len(kept) <= MAX_TRAJECTORY_POINTS
    assert kept == sorted(kept) and kept[0] == full["t"][0] and kept[-1] == full["t"][-1]
    rows = [full["t"].index(v) for v in kept]                 # rows kept whole, in order
    assert all(out["mode"][i] == full["mode"][r] and out["x"][i] == full["x"][r] for i, r in enumerate(rows))
    nearest = min(full["t"], key=lambda v: abs(v - when))
    assert nearest in kept
    for k in range(1, count):                                 # both sides of every jump
        if full["mode"][k] != full["mode"][k - 1]:
            assert full["t"][k - 1] in kept and full["t"][k] in kept


def test_a_long_fine_run_writes_a_file_replay_reads(tmp_path):
    """200 000 states of 6 numbers (the run that wrote 38 MB): thinned to the cap, well under
    the 5 MB a counterexample file may have, and read back."""
    count = 200_000
    t = np.linspace(0.0, 600.0, count)
    traj = {"t": t.tolist(), "mode": ["drift"] * count, "x": np.outer(t, np.ones(6)).tolist()}
    cex = Counterexample("m", "p", "m.yaml", "p.yaml", [0.0] * 6, None, 0.005, "drift", [0.0] * 6, 0.003, traj)
    path = tmp_path / "cex.json"
    cex.save(path)
    assert path.stat().st_size < 1_000_000
    again = Counterexample.load(path)
    assert MAX_TRAJECTORY_POINTS // 2 < len(again.trajectory["t"]) <= MAX_TRAJECTORY_POINTS
    assert again.trajectory["t"][0] == 0.0 and again.trajectory["t"][-1] == 600.0


@given(width=st.integers(1, 1000))
@settings(max_examples=15, deadline=None)
def test_a_wide_state_is_thinned_to_a_file_replay_reads(tmp_path_factory, width):
    """A run of 5000 states of ``width`` numbers each with 17 significant digits (as a 270-state
    ISS run writes them): the file stays under the 5 MB ``reach replay`` reads, with at least
    100 states kept."""
    from reach.paths import MAX_BYTES
    count = 5000
    rng = np.random.default_rng(width)
    traj = {"t": np.linspace(0.0, 20.0, count).tolist(), "mode": ["m"] * count,
            "x": (rng.standard_normal((count, width)) * 1e-4).tolist()}
    cex = Counterexample("m", "p", "m.yaml", "p.yaml", [0.0] * width, None, 19.0, "m", [0.0] * width, 0.004, traj)
    path = tmp_path_factory.mktemp("cex") / "cex.json"
    cex.save(path)
    assert path.stat().st_size < MAX_BYTES
    again = Counterexample.load(path)
    assert 100 <= len(again.trajectory["t"]) <= MAX_TRAJECTORY_POINTS
