"""The block path of segments (reach.model.batch, batch_nonlinear) and the block monitors.

References: the general per-segment path of the same Simulator (the block path switched off)
for the same runs; the thermostat's closed-form flow for the switching instants; the
state-by-state SafetyMonitor for the block monitor on random blocks (hypothesis).
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.montecarlo import SafetyMonitor, random_plan, structured_plan, switch_window
from reach.model import load_model
from reach.model.simulate import Simulator
from reach.spec import bind, load_properties


def _runs(model_file, prop_file, count, general):
    model = load_model(model_file)
    props = [p for p in (bind(q, model) for q in load_properties(prop_file)) if p.modes]
    window = switch_window(model)
    Xs, ts = structured_plan(model, window, rng=np.random.default_rng(1))
    X, tau = random_plan(model, window, count, np.random.default_rng(0))
    X = np.concatenate([Xs, X])
    tau = None if tau is None else np.concatenate([ts, tau])
    sim = Simulator(model)
    if general:
        sim.tables = {name: None for name in model.modes}      # every segment on the general path
    monitors = [SafetyMonitor(model, p, X.shape[0]) for p in props]
    traj = sim.run(X, tau, observers=monitors)
    assert any(table is not None for table in sim.tables.values()) != general     # the path asked for
    return traj, monitors


@pytest.mark.parametrize("model_file,prop_file", [("models/SRA02.yaml", "properties/rendezvous.yaml"),
                                                  ("models/SRU01.yaml", "properties/rendezvous.yaml"),
                                                  ("models/SRNA01.yaml", "properties/rendezvous.yaml"),
                                                  ("models/SRA02-NL.yaml", "properties/rendezvous.yaml"),
                                                  ("models/thermostat.yaml", "properties/thermostat.yaml")])
def test_block_path_agrees_with_the_general_path(model_file, prop_file):
    """Same final states and modes, same blocked runs, same closest approach per run and
    property, the same runs violating (at the same instants): only rounding differs."""
    fast, fast_mon = _runs(model_file, prop_file, 60, general=False)
    slow, slow_mon = _runs(model_file, prop_file, 60, general=True)
    assert np.array_equal(fast.final_mode, slow.final_mode)
    assert np.array_equal(np.isnan(fast.blocked_at), np.isnan(slow.blocked_at))
    np.testing.assert_allclose(fast.final_state, slow.final_state, rtol=1e-9, atol=1e-9)
    for a, b in zip(fast_mon, slow_mon):
        np.testing.assert_allclose(a.min_depth, b.min_depth, rtol=1e-9, atol=1e-9)
        assert np.array_equal(np.isnan(a.violation_time), np.isnan(b.violation_time))
        np.testing.assert_allclose(a.violation_time, b.violation_time, rtol=0, atol=1e-9)


def test_thermostat_switches_at_the_closed_form_instants():
    """Heating T' = 4 - 0.1 T from T0 reaches 21 at -10 ln((40 - 21)/(40 - T0)); off, T' =
    1 - 0.1 T, falls from 21 to 19 in 10 ln(11/9); heating again 19 -> 21 in 10 ln(21/19)."""
    model = load_model("models/thermostat.yaml")
    sim = Simulator(model)
    T0 = np.array([[19.5], [19.9]])
    traj = sim.run(T0, record=True)
    for i, t0 in enumerate(T0[:, 0]):
        times, modes, states = traj.path[i]
        switches = times[1:][np.diff(modes) != 0]
        first = -10 * np.log(19 / (40 - t0))
        expected = [first, first + 10 * np.log(11 / 9), first + 10 * np.log(11 / 9) + 10 * np.log(21 / 19)]
        np.testing.assert_allclose(switches[:3], expected, atol=1e-9)
        # between events the recorded grid states follow the closed form too
        heating = (modes == 0) & (times < first - 1e-12)
        np.testing.assert_allclose(states[heating, 0], 40 - (40 - t0) * np.exp(-0.1 * times[heating]),
                                   rtol=1e-12)


def _state_by_state(model, prop, t, X, seen, m_index, rows):
    """The reference: the property's own vectorised test (``prop.violation``, lambdified from
    its constraints) state by state, in time order (``t`` grows along the first axis)."""
    from types import SimpleNamespace

    ref = SimpleNamespace(min_depth=np.full(rows.max() + 1, np.inf), violation_time=np.full(rows.max() + 1, np.nan),
                          violation_state=np.full((rows.max() + 1, model.n), np.nan))
    test = prop.violation(list(model.modes)[m_index])
    for j, r in zip(*np.nonzero(seen)) if test is not None else ():
        violated, depth = test(X[j, :, r][None, :])
        ref.min_depth[rows[r]] = min(ref.min_depth[rows[r]], depth[0])
        if violated[0] and np.isnan(ref.violation_time[rows[r]]):
            ref.violation_time[rows[r]] = t[j, r]
            ref.violation_state[rows[r]] = X[j, :, r]
    return ref


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 7), st.integers(1, 6), st.booleans())
def test_block_monitor_equals_the_state_by_state_monitor(seed, B, R, given_margins):
    """Random blocks of rendezvous-mode states around the requirements' boundaries: the
    block test gives the same closest depths and the same first violations as the property's
    own test state by state, whether it computes the margins of its rows itself or is handed
    them (as the block product does); so does the monitor's state-by-state call."""
    model = load_model("models/SRA01.yaml")
    props = [p for p in (bind(q, model) for q in load_properties("properties/rendezvous.yaml")) if p.modes]
    rng = np.random.default_rng(seed)
    m_index = list(model.modes).index("rendezvous")
    X = rng.normal(size=(B, model.n, R)) * np.array([60, 60, 3, 3, 50])[None, :, None]
    t = np.sort(rng.random((B, R)), axis=0)
    seen = rng.random((B, R)) < 0.7
    rows = rng.permutation(10)[:R]
    for prop in props:
        ref = _state_by_state(model, prop, t, X, seen, m_index, rows)
        mon = SafetyMonitor(model, prop, rows.max() + 1)
        margins = None
        if given_margins and mon.margin_rows(m_index) is not None:
            H, g = mon.margin_rows(m_index)
            margins = np.einsum("kn,bnr->bkr", H, X) - g[None, :, None]
        mon.block(t, X, seen, m_index, rows, margins)
        one = SafetyMonitor(model, prop, rows.max() + 1)             # the states one by one
        j, r = np.nonzero(seen)
        one(t[j, r], X[j, :, r], np.full(j.size, m_index), rows[r])
        for got in (mon, one):
            np.testing.assert_allclose(got.min_depth, ref.min_depth, rtol=1e-12)
            assert np.array_equal(np.isnan(got.violation_time), np.isnan(ref.violation_time))
            np.testing.assert_array_equal(got.violation_time[~np.isnan(ref.violation_time)],
                                          ref.violation_time[~np.isnan(ref.violation_time)])
            np.testing.assert_allclose(got.violation_state, ref.violation_state, rtol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.01, 0.99), st.floats(1e-3, 2.0), st.sampled_from([("heating", 21.0), ("off", 19.0)]))
def test_scalar_entry_is_the_bisections_entry(fraction, h, mode_level):
    """The closed-form entry of a scalar affine flow (batch.scalar_entry) and the general path's
    bisection (Simulator._first_entry) from the state that reaches the switching level after
    ``s = fraction h`` (the thermostat's flow run backwards from the level in closed form,
    T(-s) = c + (T - c) e^(0.1 s) with c = 40 heating, 10 off): both give ``s`` to the
    bisection's resolution ``h 2^-40`` (and rounding)."""
    from reach.model import batch

    mode, level = mode_level
    model = load_model("models/thermostat.yaml")
    sim = Simulator(model)
    table = batch.table_for(sim, mode)
    (_, _, guard), = table.guards
    s = fraction * h
    c = 40.0 if mode == "heating" else 10.0
    X = np.array([[c + (level - c) * np.exp(0.1 * s)]])
    got = table.entry(X, np.array([h]), guard)[0]
    want = sim._first_entry(mode, X, np.array([h]), guard)[0]
    tol = 2 * h * 2.0 ** -40 + 1e-12
    assert abs(got - s) <= tol and abs(want - s) <= tol


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from(["approach", "rendezvous", "passive"]), st.floats(0.0, 3.0))
def test_taylor_flow_is_the_exact_flow(seed, mode, steps):
    """Each run's own duration (up to ``steps`` grid steps): the series summed on the vectors
    (batch.taylor_flow) against scipy.linalg.expm of the augmented generator, run by run."""
    import scipy.linalg

    from reach.model import batch

    model = load_model("models/SRA01.yaml")
    sim = Simulator(model)
    rng = np.random.default_rng(seed)
    X, _ = random_plan(model, None, 5, rng)
    h = rng.random(5) * steps * sim.dt
    M = sim.generators[mode]
    got = batch.taylor_flow(M, X, h)
    for x, d, y in zip(X, h, got):
        want = scipy.linalg.expm(M * d) @ np.append(x, 1.0)
        np.testing.assert_allclose(y, want[:-1], rtol=1e-12, atol=1e-12 * np.abs(want).max())
    # beyond TAYLOR_PIECES pieces the caller falls back to the matrix exponential
    assert batch.taylor_flow(M, X, np.full(5, 4 * batch.TAYLOR_PIECES / np.linalg.norm(M, 1))) is None


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.floats(0.05, 1.0))
def test_linear_guard_entry_is_the_bisections_entry(seed, fraction):
    """SRA01's approach runs one grid step before they enter the rendezvous octagon (states on
    its boundary flowed back by ``s = fraction dt`` with scipy's expm): the sub-grid search
    (batch.first_entry, margins from one product per round) and the general path's bisection
    (Simulator._first_entry) both find ``s`` to the bisection's resolution ``dt 2^-40``."""
    import scipy.linalg

    from reach.model import batch

    model = load_model("models/SRA01.yaml")
    sim = Simulator(model)
    table = batch.table_for(sim, "approach")
    (_, _, guard), = table.guards
    rng = np.random.default_rng(seed)
    angle = rng.uniform(np.pi / 2 + 0.3, 3 * np.pi / 2 - 0.3, 60)          # the octagon's left side
    on = np.column_stack([100 * np.cos(angle), 100 * np.sin(angle), 0.3 * np.cos(angle + np.pi),
                          0.3 * np.sin(angle + np.pi), np.full(60, 50.0)])   # heading inwards
    on[:, 0] = np.maximum(on[:, 0], -100.0)
    H, g = guard.rows
    on *= np.min(g / np.maximum(on[:, :2] @ H[:, :2].T, 1e-12), axis=1)[:, None] ** np.r_[1, 1, 0, 0, 0]
    s = fraction * sim.dt
    back = scipy.linalg.expm(-sim.generators["approach"] * s)
    X = (np.hstack([on, np.ones((60, 1))]) @ back.T)[:, :-1]
    keep = np.all(guard(X) <= 0, axis=1) == False                           # noqa: E712 (outside at 0)
    assert keep.sum() >= 10
    X, h = X[keep], np.full(int(keep.sum()), sim.dt)
    got = batch.first_entry(sim, "approach", X, h, guard, table.sub)
    want = sim._first_entry("approach", X, h, guard)
    tol = 2 * sim.dt * 2.0 ** -40 + 1e-12
    np.testing.assert_allclose(got, want, rtol=0, atol=tol)
    np.testing.assert_allclose(got, s, rtol=0, atol=tol)


@pytest.mark.parametrize("model_file,prop_file", [("models/SRA01.yaml", "properties/rendezvous.yaml"),
                                                  ("models/thermostat.yaml", "properties/thermostat.yaml")])
def test_a_runs_outcome_does_not_depend_on_the_runs_simulated_with_it(model_file, prop_file):
    """The block schedule (block lengths depend on how many runs share a chunk) leaves each
    run's states alone: products restart from the state at fixed multiples of the table length,
    so 37 runs simulated alone or among 700 give the same depths, bit for bit."""
    model = load_model(model_file)
    props = [p for p in (bind(q, model) for q in load_properties(prop_file)) if p.modes]
    X, tau = random_plan(model, switch_window(model), 700, np.random.default_rng(3))
    sim = Simulator(model)
    depths = []
    for count in (700, 37):
        monitors = [SafetyMonitor(model, p, count) for p in props]
        sim.run(X[:count], None if tau is None else tau[:count], observers=monitors)
        depths.append([m.min_depth[:37] for m in monitors])
    for among, alone in zip(*depths):
        np.testing.assert_array_equal(among, alone)


class _Recording:
    """A block observer asking for the margins of fixed rows ``H x - g`` in one mode."""

    def __init__(self, m_index, H, g):
        self.m_index, self.rows, self.seen = m_index, (H, g), []

    def margin_rows(self, m_index):
        return self.rows if m_index == self.m_index else None

    def block(self, t, X, seen, m_index, rows, margins=None):
        if m_index == self.m_index:
            j, r = np.nonzero(seen)
            self.seen.append((rows[r], t[j, r], X[j, :, r], margins[j, :, r]))

    def __call__(self, t, X, mode, rows):
        pass


def test_block_states_and_margins_follow_solve_ivp():
    """SRA01's approach mode, 40 runs: the grid states the block product hands its observers,
    and the margins of rows an observer asked for, at a dozen grid instants per run, against
    scipy's solve_ivp (DOP853, rtol 1e-12: itself within about 1e-8 of the exact flow over
    these 110 min) and scipy.linalg.expm of the augmented generator (the exact flow)."""
    import scipy.linalg
    from scipy.integrate import solve_ivp

    model = load_model("models/SRA01.yaml")
    sim = Simulator(model)
    X0, tau = random_plan(model, switch_window(model), 40, np.random.default_rng(7))
    A, b = model.modes["approach"].linear
    M = sim.generators["approach"]
    rng = np.random.default_rng(8)
    H, g = rng.normal(size=(3, model.n)), rng.normal(size=3)
    obs = _Recording(list(model.modes).index("approach"), H, g)
    sim.run(X0, tau, observers=[obs])
    run, t, X, margins = (np.concatenate(part) for part in zip(*obs.seen))
    for r in range(40):
        pick = np.flatnonzero(run == r)
        pick = pick[np.linspace(0, pick.size - 1, 12).astype(int)]
        sol = solve_ivp(lambda s, x: A @ x + b, (0.0, t[pick].max()), X0[r], method="DOP853",
                        t_eval=t[pick], rtol=1e-12, atol=1e-12)
        exact = np.array([(scipy.linalg.expm(M * s) @ np.append(X0[r], 1.0))[:-1] for s in t[pick]])
        scale = 1.0 + np.abs(exact).max()
        np.testing.assert_allclose(X[pick], sol.y.T, rtol=0, atol=1e-7 * scale)
        np.testing.assert_allclose(X[pick], exact, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(margins[pick], exact @ H.T - g, rtol=0, atol=1e-12 * scale * np.abs(H).sum())


_SWITCHED = """
name: switched_pair
state: [x, y]
modes:
  P: {flow: {x: "-0.1*x + y", y: "-10*x - 0.1*y"}}
  Q: {flow: {x: "-0.1*x + 10*y", y: "-x - 0.1*y"}}
  R: {flow: {x: "-x", y: "-y"}}
transitions:
  - {from: P, to: Q, guard: []}
  - {from: Q, to: P, guard: []}
  - {from: Q, to: R, guard: ["x >= 3"], urgent: true}
initial: {mode: P, box: {x: [0.5, 1], y: [-0.2, 0.2]}}
horizon: 2
"""


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 31), runs=st.integers(2, 6))
def test_switches_asked_by_a_signal_are_each_runs_own(tmp_path_factory, seed, runs):
    """Runs asking for may-switches at random piece starts (P <-> Q, always enabled), and an
    urgent exit from Q, each switch once per piece start asked: a run simulated among others
    takes the same jumps, at the same instants, to the same final state as alone (a run that
    had just left P was once switched back at the same piece start when another run of the
    batch was in Q)."""
    path = tmp_path_factory.mktemp("switched") / "model.yaml"
    path.write_text(_SWITCHED)
    model = load_model(path)
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(0.5, 1, runs), rng.uniform(-0.2, 0.2, runs)])
    switch = rng.random((runs, 20)) < 0.4
    signal = (0.1, np.zeros((runs, 20, 0)), switch)
    sim = Simulator(model)
    together = sim.run(X, record=True, signal=signal)
    for r in range(runs):
        alone = sim.run(X[r:r + 1], record=True, signal=(0.1, signal[1][r:r + 1], switch[r:r + 1]))
        t_a, m_a, _ = alone.path[0]
        t_b, m_b, _ = together.path[r]
        jumps_a, jumps_b = np.flatnonzero(np.diff(m_a)) + 1, np.flatnonzero(np.diff(m_b)) + 1
        assert np.array_equal(m_a[jumps_a], m_b[jumps_b])
        np.testing.assert_allclose(t_a[jumps_a], t_b[jumps_b], rtol=0, atol=1e-12)
        assert alone.final_mode[0] == together.final_mode[r]
        np.testing.assert_allclose(alone.final_state[0], together.final_state[r], rtol=1e-12, atol=1e-12)
