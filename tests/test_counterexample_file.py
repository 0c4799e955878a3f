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


def _saved_counterexample(tmp_path, model_file="m.yaml", trajectory=None, flow="-0.5*x"):
    """A thermostat-like one-state model ``x' = flow`` from x = 1, a property x <= 0.9, and a
    counterexample file naming them (``model_file`` as written into the file)."""
    import yaml

    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "m", "state": ["x", "t"], "horizon": 2,
        "modes": {"a": {"flow": {"x": flow, "t": 1}}}, "initial": {"mode": "a", "box": {"x": [1, 1], "t": 0}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "low", "kind": "safety", "modes": ["a"], "require": ["x >= 0.9"]}]}))
    data = {"model": "m", "property": "low", "model_file": model_file, "property_file": "p.yaml",
            "initial_state": [1.0, 0.0], "switch_time": None, "dt": 0.01}
    if trajectory is not None:
        data["trajectory"] = trajectory
    (tmp_path / "cex.json").write_text(__import__("json").dumps(data))
    return str(tmp_path / "cex.json")


def test_replay_quotes_nothing_of_a_file_the_counterexample_names(tmp_path, capsys):
    """A counterexample may name any .yaml file: one that is no model is named with its line,
    and none of its text is shown (a key such as a password hash was quoted whole)."""
    from reach.cli import main

    (tmp_path / "secrets.yaml").write_text("aws_secret_access_key: AKIAEXAMPLESECRET\n")
    assert main(["replay", _saved_counterexample(tmp_path, "secrets.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "model_file" in err and "secrets.yaml" in err
    assert "aws_secret" not in err and "AKIA" not in err
    assert main(["replay", _saved_counterexample(tmp_path)]) == 1      # the model itself replays


def test_a_trajectory_of_unequal_lists_is_bad_input(tmp_path, capsys):
    """A trajectory whose mode list is shorter than its times (past the thinning's 4000 points)
    was an IndexError, exit 3: it is bad input at the field."""
    from reach.cli import main

    t = [k * 0.001 for k in range(5000)]
    path = _saved_counterexample(tmp_path, trajectory={"t": t, "mode": ["a"] * 10, "x": [[1.0, v] for v in t]})
    assert main(["replay", path]) == 2
    assert "trajectory" in capsys.readouterr().err


def test_a_replay_that_leaves_the_real_numbers_decides_nothing(tmp_path, capsys):
    """x' = -1e12 x needs more than 1000 RK4 substeps per step: the run is not simulated (NaN)
    and the replay says so, exit 3, naming the step that would take it. It took a minute of
    1000 substeps and printed "satisfies"."""
    from reach.cli import main

    assert main(["replay", _saved_counterexample(tmp_path, flow="-1e12*x + 0.001*x**2")]) == 3
    out = capsys.readouterr().out
    assert out.startswith("NOT decided") and "too stiff for RK4" in out and "-o dt=1.5e-09" in out


def test_a_violation_before_the_run_leaves_the_real_numbers_replays(tmp_path, capsys):
    """x' = -1, y' = sqrt(x) from x = 1: x >= 0.5 is violated at t = 0.5, and from t = 1 the
    run is NaN (the square root of a negative). The file keeps those rows as JSON strings
    ("nan"); replay read them as a malformed trajectory (exit 2). It replays the violation."""
    import json

    import yaml

    from reach.cli import main

    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "m", "state": ["x", "y"], "horizon": 2,
        "modes": {"a": {"flow": {"x": -1, "y": "sqrt(x)"}}}, "initial": {"mode": "a", "box": {"x": 1, "y": 0}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "low", "kind": "safety", "modes": ["a"], "require": ["x >= 0.5"]}]}))
    folder = tmp_path / "cex"
    assert main(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "montecarlo",
                 "--counterexamples", str(folder)]) == 1
    [path] = folder.glob("*.json")
    assert "nan" in json.loads(path.read_text())["trajectory"]["x"][-1]
    capsys.readouterr()
    assert main(["replay", str(path)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("replayed:") and "the run leaves the real numbers later" in out


def test_a_replay_too_large_to_hold_is_bad_input_at_the_file(tmp_path, capsys):
    """151 states at dt = 6e-5 over 300 s: 5e6 recorded steps (inside the step cap), 45 GiB of
    recorded states; the replay grew past 18 GB. It is refused before it runs, naming the file
    and its dt."""
    import json

    import yaml

    from reach.cli import main

    names = [f"x{i}" for i in range(151)]
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "wide", "state": names, "horizon": 300,
        "modes": {"a": {"flow": {n: f"-0.01*{n}" for n in names}}},
        "initial": {"mode": "a", "box": {n: 1 for n in names}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "low", "kind": "safety", "modes": ["a"], "require": ["x0 <= 0.5"]}]}))
    (tmp_path / "cx.json").write_text(json.dumps({
        "model": "wide", "property": "low", "model_file": "m.yaml", "property_file": "p.yaml",
        "initial_state": [1.0] * 151, "switch_time": None, "dt": 6e-5}))
    assert main(["replay", str(tmp_path / "cx.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "cx.json: dt:" in err and "GiB" in err


def test_an_overflowing_requirement_is_a_violation_not_a_touch(tmp_path, capsys):
    """``exp(exp(t)) <= 1e300`` with a step that jumps from below the bound to an overflow: the
    margin is -inf and the row's magnitude inf, and ``1e-9 * (1 + inf)`` read it as a touch
    (UNKNOWN, exit 3). The bound is passed at t = ln(ln(1e300)) = 6.5377: UNSAFE, replayed."""
    import math

    import yaml

    from reach.cli import main

    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "name": "m", "state": ["x", "t"], "horizon": 8,
        "modes": {"a": {"flow": {"x": 0, "t": 1}}}, "initial": {"mode": "a", "box": {"x": 0, "t": 0}}}))
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(
        {"properties": [{"id": "big", "kind": "safety", "modes": ["a"], "require": ["exp(exp(t)) <= 1e300"]}]}))
    code = main(["check", str(tmp_path / "m.yaml"), str(tmp_path / "p.yaml"), "-b", "montecarlo",
                 "-o", "dt=0.125", "--counterexamples", str(tmp_path / "cx")])
    out = capsys.readouterr().out
    assert code == 1, out
    t = float(out.split("violated at t=")[1].split()[0])
    assert math.log(math.log(1e300)) <= t <= math.log(math.log(1e300)) + 0.125 + 1e-9
    assert main(["replay", str(tmp_path / "cx" / "m_big_montecarlo.json")]) == 1
