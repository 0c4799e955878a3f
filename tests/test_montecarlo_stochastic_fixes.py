"""Monte Carlo on stochastic models against closed forms and plain numpy simulations.

* kicks land at their instants ``k * step`` whatever the simulator step ``dt`` (one that does not
  divide the kick step put them on the wrong grid points, one above twice the kick step dropped
  them);
* a polytopic initial set is sampled over the polytope for reach probabilities, not over its
  bounding box;
* membership and violation tolerances are per constraint row, scaled by what the row combines,
  so a large coordinate (a range of 7e6 m) no longer hides a small one (an angle of 1e-4 rad),
  in targets, safety requirements and invariants; a position keeps the scale of the velocity it
  is integrated from, so an event located to the bisection's resolution is no violation.
"""

import numpy as np
import pytest
from scipy.stats import norm

from reach.backends.montecarlo import BACKEND
from reach.model.simulate import Simulator
from reach.result import Status
from reach.stats import wilson
from tests.model_files import load_files

# x' = -a x, Gaussian kicks N(mu, s^2) at t = 0, 1, ..., 9; x(0) = 1 (the tester's OU1)
A, MU, S = 0.1, 0.05, 0.1
OU = """\
    name: OU1
    state: [x]
    modes:
      m: {flow: {x: "-0.1*x"}}
    initial: {mode: m, box: {x: 1}}
    horizon: 10
    disturbance: {gaussian: {mean: [0.05], cov: [0.01]}, enters: [x], step: 1}
"""
OU_PROPS = """\
    properties:
      - {id: band, kind: reach, at: 10, target: {box: {x: [0.5, 0.8]}}}
      - {id: corridor, kind: reach_avoid, at: 10, target: {box: {x: [0.5, 0.8]}}, safe: ["x >= 0.45"]}
"""


def interval(result) -> tuple[float, float]:
    """A 99.9 % Wilson interval of a reach probability from its sampled successes (the
    result's own interval is 95 %: several checks per test would fail too often by chance)."""
    lo, hi = wilson(result.details["successes"], result.details["samples"], confidence=0.999)
    return lo - 1e-12, hi + 1e-12


def ou_band_probability() -> float:
    """P(0.5 <= x(10) <= 0.8): x(10) is Gaussian, mean e^{-10a} + mu sum_j e^{-a(10-j)},
    variance s^2 sum_j e^{-2a(10-j)}, j = 0..9."""
    decay = np.exp(-A * (10 - np.arange(10)))
    mean, sd = np.exp(-10 * A) + MU * decay.sum(), S * np.sqrt((decay ** 2).sum())
    return norm.cdf((0.8 - mean) / sd) - norm.cdf((0.5 - mean) / sd)


def ou_corridor_probability(runs: int = 1_000_000) -> tuple[float, float]:
    """The reach-avoid probability by the exact discrete recursion x_{k+1} = e^{-a} (x_k + w_k)
    (states before the kicks at t = 0..9 in the safe set, x_10 in the target): (estimate, sd)."""
    rng = np.random.default_rng(7)
    x, ok = np.ones(runs), np.ones(runs, dtype=bool)
    for _ in range(10):
        ok &= x >= 0.45
        x = np.exp(-A) * (x + MU + S * rng.standard_normal(runs))
    p = float(np.mean(ok & (x >= 0.5) & (x <= 0.8)))
    return p, np.sqrt(p * (1 - p) / runs)


@pytest.mark.parametrize("dt", [0.3, 0.7, 2.5])
def test_kicks_land_at_their_instants_whatever_the_step(tmp_path, dt):
    """Kicks of exactly 1 (no noise) on the OU flow: the state at 10 is the closed form
    ``e^{-10a} + sum_j e^{-a(10-j)}`` for steps that do not divide the kick step (2.5: two
    kicks between some grid points), and the observers see the state just before each kick
    at its instant, as at a segment end of the general path."""
    model, _ = load_files(tmp_path, OU, OU_PROPS)
    seen = []
    Simulator(model, dt).run(np.ones((1, 1)), kicks=lambda k, count: np.ones((count, 1)),
                             observers=[lambda t, X, mode, rows: seen.extend(zip(t, X[:, 0]))])
    times, states = np.array(seen).T
    decay = np.exp(-A * (10 - np.arange(10)))
    assert times[-1] == pytest.approx(10.0) and states[-1] == pytest.approx(np.exp(-1.0) + decay.sum(), rel=1e-12)
    for k in range(1, 10):                          # x(k-) = e^{-ka} + sum_{j<k} e^{-a(k-j)}
        at = np.flatnonzero(np.isclose(times, k, rtol=0, atol=1e-9))
        assert at.size == 1
        before = np.exp(-k * A) + np.exp(-A * (k - np.arange(k))).sum()
        assert states[at[0]] == pytest.approx(before, rel=1e-12)


@pytest.mark.parametrize("dt", [0.3, 2.5])
def test_reach_probabilities_do_not_depend_on_a_step_that_misses_the_kicks(tmp_path, dt):
    """The tester's OU1 at dt = 0.3 gave P in [0.4367, 0.4505] against 0.5502: the Wilson
    intervals hold the closed form and the reach-avoid probability of a plain numpy recursion."""
    model, props = load_files(tmp_path, OU, OU_PROPS)
    band, corridor = BACKEND.check_many(model, [props["band"], props["corridor"]],
                                        {"samples": 20000, "dt": dt, "seed": 3})
    lo, hi = interval(band)
    assert lo <= ou_band_probability() <= hi
    p, sd = ou_corridor_probability()
    lo, hi = interval(corridor)
    assert lo - 3 * sd <= p <= hi + 3 * sd


SIMPLEX = """\
    name: SIMPLEX
    state: [x, y, z]
    modes:
      m: {flow: {x: "0", y: "0", z: "0"}}
    initial:
      mode: m
      box: {x: [0, 1], y: [0, 1], z: [0, 1]}
      constraints: [%s]
    horizon: 1
    disturbance: {gaussian: {mean: [0, 0, 0], cov: [1e-12, 1e-12, 1e-12]}, enters: [x, y, z], step: 1}
"""
SIMPLEX_PROPS = """\
    properties:
      - {id: on_plane, kind: reach, at: 1, target: ["x + y + z >= 0.999", "x + y + z <= 1.001"]}
      - {id: x_low, kind: reach, at: 1, target: ["x <= 0.5"]}
      - {id: xy_low, kind: reach, at: 1, target: ["x + y <= 0.5"]}
"""


@pytest.mark.parametrize("constraints, shares, drawn_by", [
    # the face x + y + z == 1 (a triangle in 3-D, hit-and-run in its plane): x and z are
    # Beta(1, 2), P(x <= 1/2) = 3/4, P(x + y <= 1/2) = P(z >= 1/2) = 1/4
    ('"x + y + z == 1"', {"on_plane": 1.0, "x_low": 0.75, "xy_low": 0.25}, "hit-and-run"),
    # the corner x + y + z <= 1 (a tetrahedron, a sixth of its box: by rejection): x + y + z
    # has density 3 s^2, x + y density 6 s (1 - s)
    ('"x + y + z <= 1"', {"on_plane": 1 - 0.999 ** 3, "x_low": 1 - 0.5 ** 3, "xy_low": 0.5}, "rejection"),
])
def test_a_polytope_initial_set_is_sampled_uniformly_over_the_polytope(tmp_path, constraints, shares, drawn_by):
    """With kicks of 1e-6 the reach probabilities are the shares of the initial polytope (volume
    fractions, closed forms; uniform over the bounding box would give about 0.001, 0.5 and
    0.125), and the details say which law the initial state had. The tester's segment x + y == 1
    gave P(on the segment) in [0.022, 0.044]."""
    model, props = load_files(tmp_path, SIMPLEX % constraints, SIMPLEX_PROPS)
    results = BACKEND.check_many(model, list(props.values()), {"samples": 20000, "seed": 5})
    for prop_id, result in zip(props, results):
        lo, hi = interval(result)
        assert lo <= shares[prop_id] <= hi, prop_id
        assert "uniform over the polytope" in result.details["initial"]
        assert drawn_by in result.details["initial"]


SCALE = """\
    name: SCALE
    state: [r, th]
    modes:
      m: {flow: {r: "0", th: "-0.01*th"}}
    initial: {mode: m, box: {r: %s, th: 0}}
    horizon: 10
    disturbance: {gaussian: {mean: [0, 0], cov: [1, 1e-8]}, enters: [r, th], step: 10}
"""
SCALE_PROPS = """\
    properties:
      - {id: th_pos, kind: reach, at: 10, target: ["th >= 0"]}
      - {id: th_1sd, kind: reach, at: 10, target: ["th >= -9.05e-5", "th <= 9.05e-5"]}
      - {id: th_bound, kind: safety, require: ["th <= 0.00015"]}
"""


def test_a_large_coordinate_does_not_widen_the_target_of_a_small_one(tmp_path):
    """th(10) = w e^{-0.1}, w ~ N(0, 1e-8), beside r = 7e6 m: P(th >= 0) = 1/2 and
    P(|th| <= 9.05e-5) = 2 Phi(9.05e-5 e^{0.1} / 1e-4) - 1 (the tester saw [0.9998, 1] for both)."""
    model, props = load_files(tmp_path, SCALE % 7e6, SCALE_PROPS)
    pos, band = BACKEND.check_many(model, [props["th_pos"], props["th_1sd"]], {"samples": 20000, "seed": 11})
    assert interval(pos)[0] <= 0.5 <= interval(pos)[1]
    truth = 2 * norm.cdf(9.05e-5 * np.exp(0.1) / 1e-4) - 1
    assert interval(band)[0] <= truth <= interval(band)[1]


@pytest.mark.parametrize("r", [7.0, 7e6])
def test_a_large_coordinate_does_not_hide_a_violation_of_a_small_one(tmp_path, r):
    """th(t) = w e^{-0.01 t} from the kick at 0, watched from the first grid point dt on: a run
    violates th <= 1.5e-4 when w e^{-0.01 dt} > 1.5e-4, probability 1 - Phi(1.5 e^{0.01 dt}),
    whatever r (the tester found no violating run at r = 7e6). The share of violating i.i.d.
    runs is binomial around it."""
    model, props = load_files(tmp_path, SCALE % r, SCALE_PROPS)
    (result,) = BACKEND.check_many(model, [props["th_bound"]], {"samples": 4000, "seed": 13})
    truth = 1 - norm.cdf(1.5 * np.exp(0.01 * result.details["dt"]))
    lo, hi = wilson(result.details["violating_runs"], result.details["random_runs"], confidence=0.999)
    assert lo <= truth <= hi
    assert result.status == Status.UNKNOWN            # sampled under disturbance: no replayable run


INVARIANT = """\
    name: POINTING
    state: [r, th]
    modes:
      m:
        flow: {r: "0", th: "0.001"}
        invariant: ["th <= 0.0001"]
    initial: {mode: m, box: {r: 7000000, th: 0}}
    horizon: 1
"""


def test_an_invariant_on_a_small_coordinate_stops_its_runs_at_its_own_bound(tmp_path):
    """th = 0.001 t leaves th <= 1e-4 at t = 0.1, beside r = 7e6: the run is blocked there (it
    ran on to t = 0.17, th = 1.7e-4, within the old tolerance 1e-11 (1 + 7e6)), and th <= 1.05e-4
    holds on every state Monte Carlo watches (a violation tolerance per row with an invariant
    tolerance per state would report one on states no run of the automaton visits)."""
    model, props = load_files(tmp_path, INVARIANT,
                              "properties:\n  - {id: cap, kind: safety, require: ['th <= 0.000105']}\n")
    runs = Simulator(model).run(np.array([[7e6, 0.0]]))
    assert runs.blocked_at[0] == pytest.approx(0.1, abs=1e-12)
    (result,) = BACKEND.check_many(model, [props["cap"]],
                                   {"samples": 50, "search_rounds": 1, "search_size": 20, "optimise": False})
    assert result.status == Status.UNKNOWN
    assert result.details["closest_depth"] == pytest.approx(5e-6, rel=1e-6)


BALL = """\
    name: FAST_BALL
    state: [x, v]
    modes:
      fall:
        flow: {x: v, v: -9.81}
        invariant: ["x >= 0"]
    transitions:
      - {from: fall, to: fall, guard: ["x <= 0", "v <= 0"], reset: {v: "-0.9*v"}, urgent: true}
    initial: {mode: fall, box: {x: [1000, 1200], v: [-3000, -2000]}}
    horizon: 10
"""


def test_an_event_located_to_the_bisection_resolution_is_no_violation(tmp_path):
    """A ball at 2-3 km/s bounces at x = 0; the bounce is located to dt 2^-40, so the watched
    state there has x down to about -3000 dt 1e-12 (-8e-9 at dt = 5), below a tolerance of
    1e-9 (1 + |x|). x is integrated from v, so the row x >= 0 keeps v's scale: no run of a
    ball that never goes below 0 is reported as violating it."""
    model, props = load_files(tmp_path, BALL, "properties:\n  - {id: above, kind: safety, require: ['x >= 0']}\n")
    low = []
    Simulator(model, 5.0).run(np.array([[1000.0, -3000.0]]), observers=[lambda t, X, m, r: low.extend(X[:, 0])])
    assert min(low) < -1e-9                         # the bounce's state, as located
    (result,) = BACKEND.check_many(model, [props["above"]],
                                   {"samples": 200, "search_rounds": 1, "search_size": 50, "optimise": False, "dt": 5.0})
    assert result.status == Status.UNKNOWN and result.details["violating_runs"] == 0
