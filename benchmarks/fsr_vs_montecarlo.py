"""Forward stochastic reach (fsr) against Monte Carlo on the seed's scenarios.

For every scenario (model x property): the fsr probability interval and its run time; Monte
Carlo estimates with 95 % Wilson intervals from

* ``sampler``: a vectorised sampler written here from the model's closed loop ``(A, b)``, the
  matrix exponential between kicks, the kicks drawn from the model's law and the property's own
  constraint functions (nothing shared with the fsr code path), and
* ``montecarlo``: the suite's montecarlo back-end (its runs cost one simulator segment per
  kick, so ``--referee-budget`` limits runs x kicks per scenario);

whether the intervals overlap, both run times, and the speed-up over Monte Carlo of equal
precision (samples ``p (1 - p) (1.96 / h)^2`` for the fsr half-width ``h``, at least 1e-4).
Then: the reach-avoid method study on the tight corridor (Genz with and without dropping,
sequential conditioning), non-Gaussian kicks through the Fourier path against the sampler,
and the eccentric-orbit (LTV) checks. Plots go to ``results/plots/fsr_*.png``; every number
to ``results/fsr_vs_montecarlo.json``.

    python benchmarks/fsr_vs_montecarlo.py [--samples 100000] [--referee-samples 100000]
                                           [--referee-budget 2e7] [--skip-referee] [--quick]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import scipy.linalg

from reach.backends.fsr import fourier as F
from reach.backends.base import run
from reach.backends.fsr import BACKEND, GaussianProblem, reach_avoid
from reach.model.constraints import halfspaces, lambdify_margins
from reach.model.loader import load_model
from reach.model.ltv import (KickedLinearSystem, cwh_matrix, eccentric_orbit_system,
                             mean_anomaly, true_anomaly, yamanaka_ankersen)
from reach.sets.gaussian import interval_form, polytope_probability
from reach.spec.properties import BoundReachAvoid, bind, load_properties
from reach.stats import wilson

ROOT = Path(__file__).resolve().parents[1]
PLOTS = ROOT / "results" / "plots"
SCENARIOS = [
    ("seed Table 1: LQR-1 reach", "fsr_lqr1_reach", "fsr_lqr1_reach", "dock"),
    ("seed Table 2: LQR-2 reach", "fsr_lqr2_reach", "fsr_lqr2_reach", "dock"),
    ("seed Table 3: LQR-1 reach-avoid", "fsr_lqr1_reach_avoid", "fsr_lqr1_reach_avoid", "corridor"),
    ("Table 3, tight corridor", "fsr_lqr1_reach_avoid", "fsr_lqr1_reach_avoid", "corridor_tight"),
    ("seed Table 4: uncertain burn", "fsr_burn", "fsr_burn", "arrive"),
    ("Table 4 with the corridor", "fsr_burn", "fsr_burn", "arrive_safe"),
    ("Table 4, uniform burn error", "fsr_burn_uniform", "fsr_burn", "arrive"),
]


def load(model_file, property_file, pid):
    model = load_model(ROOT / "models" / f"{model_file}.yaml")
    prop = next(bind(p, model) for p in load_properties(ROOT / "properties" / f"{property_file}.yaml")
                if p.id == pid)
    return model, prop


def timed(fn, repeat=3):
    """``(result, best seconds)`` over ``repeat`` calls after one warm-up call."""
    result = fn()
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return result, best


# ------------------------------------------------------------------ the independent sampler

def sample(model, prop, samples, rng, kick_law=None, batch=50_000):
    """Fraction of sampled runs meeting ``prop`` and the seconds it took.

    Kicks at ``k * step < at`` (before them the state is observed for the safe set), exact flow
    ``[x; 1](t + h) = expm([[A, b], [0, 0]] h) [x; 1]`` in between, initial state uniform in
    the model's box. ``kick_law(rng, size)`` replaces the model's Gaussian kicks if given.
    """
    start = time.perf_counter()
    A, b = model.modes[model.initial.mode].linear
    n = model.n
    dist = model.disturbance
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    instants = [k * dist.step for k in range(int(prop.at / dist.step) + 2)
                if k * dist.step < prop.at - 1e-9 * max(1.0, prop.at)]
    gaps = np.diff(instants + [prop.at])
    flows = {g: scipy.linalg.expm(M * g) for g in set(np.round(gaps, 12))}
    target = lambdify_margins(prop.target, model.symbols)
    safe = lambdify_margins(prop.safe, model.symbols) if isinstance(prop, BoundReachAvoid) else None
    vals, vecs = np.linalg.eigh(dist.cov)
    factor = vecs * np.sqrt(np.maximum(vals, 0.0))          # w = mean + factor @ N(0, I)
    hits = 0
    for first in range(0, samples, batch):
        count = min(batch, samples - first)
        X = model.initial.low + (model.initial.high - model.initial.low) * rng.random((count, n))
        ok = np.ones(count, bool)
        for gap in gaps:
            if safe is not None:
                ok &= np.all(safe(X) <= 0, axis=1)
            w = (kick_law(rng, count) if kick_law is not None
                 else dist.mean + rng.standard_normal((count, factor.shape[1])) @ factor.T)
            X[:, dist.enters] += w
            E = flows[np.round(gap, 12)]
            X = X @ E[:n, :n].T + E[:n, n]
        hits += int(np.count_nonzero(ok & np.all(target(X) <= 0, axis=1)))
    return hits, time.perf_counter() - start


def monte_carlo_summary(hits, samples, seconds):
    lo, hi = wilson(hits, samples)
    return {"estimate": hits / samples, "interval": (lo, hi), "samples": samples, "seconds": seconds}


def speedup(fsr_interval, fsr_seconds, mc):
    """Monte Carlo seconds for the fsr precision (half-width >= 1e-4) over the fsr seconds."""
    p = min(max(mc["estimate"], 1e-6), 1 - 1e-6)
    h = max(0.5 * (fsr_interval[1] - fsr_interval[0]), 1e-4)
    needed = p * (1 - p) * (1.96 / h) ** 2
    return {"precision": h, "mc_seconds_equal_precision": mc["seconds"] / mc["samples"] * needed,
            "ratio": mc["seconds"] / mc["samples"] * needed / fsr_seconds}


def overlap(a, b):
    return bool(a[0] <= b[1] and b[0] <= a[1])


# ------------------------------------------------------------------ plots

def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def ellipse(mean2, cov2, sigma=3.0, points=100):
    vals, vecs = np.linalg.eigh(cov2)
    angle = np.linspace(0, 2 * np.pi, points)
    circle = np.stack([np.cos(angle), np.sin(angle)])
    return (mean2[:, None] + sigma * vecs @ (np.sqrt(np.maximum(vals, 0))[:, None] * circle)).T


def plot_scenario(name, model, prop, path):
    """Mean trajectory with covariance ellipses and the target; probability against time.

    For a box initial state (uniform, non-Gaussian) the ellipses use the exact covariance, the
    middle panel shows the densities of x and y at ``at`` from the FFT (eq. 8), and the
    probabilities come from the Fourier path.
    """
    plt = _pyplot()
    problem = GaussianProblem.from_model(model, prop.at)
    point = np.array_equal(model.initial.low, model.initial.high)
    if not point:
        problem.P0 = np.diag(((model.initial.high - model.initial.low) / 2) ** 2 / 3)
    means, covs = problem.moments()
    times = problem.system.times
    K = len(times) - 1
    H, g = halfspaces(prop.target, prop.symbols)
    T, lower, upper = interval_form(H, g)
    ix, iy = model.state.index("x"), model.state.index("y")
    box = _box_xy(T, lower, upper, ix, iy)
    km = 1e3 if model.units.length == "km" else 1.0
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    ax = axes[0]
    ax.plot(means[:, iy] * km, means[:, ix] * km, "k-", lw=1, label="mean trajectory")
    for k in np.linspace(0, K, 9).astype(int)[1:]:
        e = ellipse(means[k, [iy, ix]], covs[k][np.ix_([iy, ix], [iy, ix])])
        ax.plot(e[:, 0] * km, e[:, 1] * km, "b-", lw=0.8)
    ax.plot(means[0, iy] * km, means[0, ix] * km, "go", label="start")
    if isinstance(prop, BoundReachAvoid):
        Hs, gs = halfspaces(prop.safe, prop.symbols)
        for h, bound in zip(Hs, gs):
            if np.count_nonzero(h) == 1 and h[iy] != 0:
                ax.axvline(bound / h[iy] * km, color="r", ls="--", label="safe-set boundary")
            if np.count_nonzero(h) == 1 and h[ix] != 0:
                ax.axhline(bound / h[ix] * km, color="r", ls="--", label="safe-set boundary")
    ax.set_xlabel("y, along-track [m]")
    ax.set_ylabel("x, radial [m]")
    ax.set_title(f"{name}\n3-sigma ellipses (x-y)")
    ax.legend(fontsize=8)
    ax = axes[1]
    if point:
        for s in (1, 2, 3):
            e = ellipse(means[K, [iy, ix]], covs[K][np.ix_([iy, ix], [iy, ix])], sigma=s)
            ax.plot(e[:, 0] * km, e[:, 1] * km, "b-", lw=0.8,
                    label=f"1, 2, 3 sigma ellipses at t = {prop.at:g} s" if s == 1 else None)
        if box is not None:
            (ylo, yhi), (xlo, xhi) = box
            ax.plot(np.array([ylo, yhi, yhi, ylo, ylo]) * km, np.array([xlo, xlo, xhi, xhi, xlo]) * km,
                    "r-", label="target")
        ax.plot(means[K, iy] * km, means[K, ix] * km, "k+")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("y [m]")
        ax.set_ylabel("x [m]")
        ax.xaxis.set_major_locator(plt.MaxNLocator(5))     # long tick labels must not overlap
        ax.set_title(f"at t = {prop.at:g} s")
    else:
        _plot_marginals(ax, model, problem, means[K], covs[K], box, (ix, iy), km)
    ax.legend(fontsize=8)
    ax = axes[2]
    if point:
        grid = np.linspace(0.75 * prop.at, prop.at, 61)
        probs = [polytope_probability(*moments_at(model, problem, means, covs, t), H, g,
                                      abs_error=1e-3).value for t in grid]
        ax.plot(grid, probs, "b.-", label="P(x(t) in target)")
    else:
        grid = np.linspace(0.75 * prop.at, prop.at, 13)
        probs = []
        for t in grid:
            system = GaussianProblem.from_model(model, t).system
            z = F.ProjectedSum.of(system, T, _initial_law(model), F.GaussianLaw(problem.w_mean, problem.w_cov))
            probs.append(F.box_probability(z, lower, upper, tol=1e-2, max_frequencies=2 ** 16).value)
        ax.plot(grid, probs, "b.-", label="P(x(t) in target), Fourier path")
    if isinstance(prop, BoundReachAvoid):
        Hs, gs = halfspaces(prop.safe, prop.symbols)
        marginal = [1 - polytope_probability(means[k], covs[k], Hs, gs, abs_error=1e-4).value
                    for k in range(K)]
        shown = (times[:K] >= grid[0]) & (times[:K] <= grid[-1])     # the stretch on the time axis
        values = np.asarray(marginal)[shown]
        axes2 = ax.twinx()
        floor = max(float(values[values > 0].min()) / 10, 1e-300) if np.any(values > 0) else 1e-16
        axes2.semilogy(times[:K][shown], np.maximum(values, floor), "r.-", lw=0.8)
        axes2.set_ylim(floor, 1)
        axes2.set_ylabel("P(x(t_k) outside the safe set)", color="r")
        axes2.tick_params(axis="y", colors="r")
        ax.plot([], [], "r.-", label="P(x(t_k) outside the safe set), right axis"
                + ("" if np.any(values > 0) else ": 0 to working precision"))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("probability")
    ax.set_title("probability against time")
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_marginals(ax, model, problem, mean, cov, box, indices, km):
    """Densities of x and y at ``at`` by FFT (eq. 8), the Gaussian of the same moments dashed."""
    for i, colour, label in zip(indices, ("tab:blue", "tab:orange"), ("x", "y")):
        z = F.ProjectedSum.of(problem.system, np.eye(model.n)[[i]], _initial_law(model),
                              F.GaussianLaw(problem.w_mean, problem.w_cov))
        (grid,), density = F.density_on_grid(z, points=1024)
        ax.plot(grid * km, density / km, color=colour, label=f"{label}: FFT density")
        sd = np.sqrt(cov[i, i])
        gauss = np.exp(-0.5 * ((grid - mean[i]) / sd) ** 2) / (np.sqrt(2 * np.pi) * sd)
        ax.plot(grid * km, gauss / km, color=colour, ls="--", lw=0.8, label=f"{label}: Gaussian, same moments")
    if box is not None:
        for (lo, hi), colour in zip((box[1], box[0]), ("tab:blue", "tab:orange")):
            ax.axvspan(lo * km, hi * km, color=colour, alpha=0.1)
    ax.set_xlabel("position [m] (shaded: target interval)")
    ax.set_ylabel("density [1/m]")
    ax.set_title(f"x and y at t = {problem.system.times[-1]:g} s, uniform burn error")


def _initial_law(model):
    return F.UniformLaw(model.initial.low, model.initial.high)


def moments_at(model, problem, means, covs, t):
    """Mean and covariance of ``x(t)`` between kicks: the state after the last kick, flowed."""
    times = problem.system.times
    k = int(np.searchsorted(times, t, side="right") - 1)
    if k >= len(times) - 1 or t == times[k]:
        return means[k], covs[k]
    A, b = model.modes[model.initial.mode].linear
    n = model.n
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n] = A, b
    E = scipy.linalg.expm(M * (t - times[k]))
    G = problem.system.G
    mean = E[:n, :n] @ (means[k] + G @ problem.w_mean) + E[:n, n]
    cov = E[:n, :n] @ (covs[k] + G @ problem.w_cov @ G.T) @ E[:n, :n].T
    return mean, cov


def _box_xy(T, lower, upper, ix, iy):
    """The target's ``(y, x)`` bounds if it is an axis box in those coordinates."""
    bounds = {}
    for row, lo, hi in zip(T, lower, upper):
        j = int(np.argmax(np.abs(row)))
        if np.count_nonzero(row) == 1 and j in (ix, iy):
            a, b = sorted((lo / row[j], hi / row[j]))
            bounds[j] = (a, b)
    if ix in bounds and iy in bounds:
        return bounds[iy], bounds[ix]
    return None


# ------------------------------------------------------------------ studies

def method_study():
    """Reach-avoid on the tight corridor: width reached and seconds, per method and budget."""
    model, prop = load("fsr_lqr1_reach_avoid", "fsr_lqr1_reach_avoid", "corridor_tight")
    problem = GaussianProblem.from_model(model, prop.at)
    target = halfspaces(prop.target, prop.symbols)
    safe = halfspaces(prop.safe, prop.symbols)
    rows = []
    for method, budget, error in [("genz", None, 1e-3), ("genz", None, 3e-4), ("genz", 0.0, 1e-3),
                                  ("markov", None, 3e-3), ("markov", None, 1e-3)]:
        start = time.perf_counter()
        p, info = reach_avoid(problem, target, safe, abs_error=error, drop_budget=budget, method=method)
        seconds = time.perf_counter() - start
        rows.append({"method": method, "drop_budget": "abs_error/10" if budget is None else budget,
                     "abs_error": error, "interval": (p.low, p.high), "width": p.width,
                     "seconds": seconds, "rows": info["rows"], "kept": info["kept"],
                     "boole": info["boole"], "points": info["points"]})
        print(f"  {method:6s} budget={rows[-1]['drop_budget']!s:12s} abs_error={error:g}: "
              f"[{p.low:.5f}, {p.high:.5f}] width {p.width:.1e} in {seconds:.2f} s "
              f"({info['kept']} of {info['rows']} rows, {info['points']} points)")
    return rows


def non_gaussian_study(samples, rng):
    """LQR-1 for 1000 s with uniform and Laplace kicks of the seed's covariance: the Fourier
    path against the sampler, and the Gaussian answer with the same covariance."""
    model, prop = load("fsr_lqr1_reach_avoid", "fsr_lqr1_reach_avoid", "box5")
    problem = GaussianProblem.from_model(model, prop.at)
    H, g = halfspaces(prop.target, prop.symbols)
    T, lower, upper = interval_form(H, g)
    var = model.disturbance.cov[0, 0]
    laws = {"uniform": F.UniformLaw(-np.sqrt(3 * var) * np.ones(3), np.sqrt(3 * var) * np.ones(3)),
            "laplace": F.LaplaceLaw(np.zeros(3), np.sqrt(var / 2) * np.ones(3))}
    rows = []
    means, covs = problem.moments()
    gaussian = polytope_probability(means[-1], covs[-1], H, g, abs_error=1e-5)
    for name, law in laws.items():
        z = F.ProjectedSum.of(problem.system, T, F.point_law(problem.x0), law)
        p, seconds = timed(lambda: F.box_probability(z, lower, upper, tol=1e-4), repeat=1)
        hits, mc_seconds = sample(model, prop, samples, rng, kick_law=law.sample)
        mc = monte_carlo_summary(hits, samples, mc_seconds)
        rows.append({"kicks": name, "fourier": (p.low, p.high), "fourier_seconds": seconds,
                     "frequencies": p.points, "sampler": mc, "overlap": overlap((p.low, p.high), mc["interval"]),
                     "gaussian_same_covariance": gaussian.value})
        print(f"  {name:8s} Fourier [{p.low:.5f}, {p.high:.5f}] in {seconds:.2f} s; sampler "
              f"{mc['estimate']:.5f} [{mc['interval'][0]:.5f}, {mc['interval'][1]:.5f}] "
              f"({samples} runs, {mc_seconds:.1f} s); Gaussian with the same covariance {gaussian.value:.5f}")
    return rows


def ltv_study():
    """Yamanaka-Ankersen at e = 0 against CWH (the seed's Fig. 8 run) and at e = 0.3 against
    numerical integration of the linearised equations."""
    from scipy.integrate import solve_ivp
    mu, a = 396856.656, 7228.1
    n = np.sqrt(mu / a ** 3)
    G = np.zeros((6, 3))
    G[3:] = np.eye(3)
    x0 = np.array([0, -2, 0, 0, -5e-4, 0])
    period = 2 * np.pi / n
    ltv = eccentric_orbit_system(0.0, a, mu, 0.0, G, 10.0, period)
    lti = KickedLinearSystem.from_continuous(cwh_matrix(n), None, G, 10.0, period)
    m1, _ = ltv.moments(x0, None, np.zeros(3), np.zeros((3, 3)))
    m2, _ = lti.moments(x0, None, np.zeros(3), np.zeros((3, 3)))
    circular = float(np.max(np.abs(m1 - m2)) / np.max(np.abs(m2)))
    e, theta0, dt = 0.3, 0.7, 3000.0
    p = a * (1 - e ** 2)
    h = np.sqrt(mu * p)

    def rhs(t, X):
        theta = true_anomaly(mean_anomaly(theta0, e) + n * t, e)
        r = p / (1 + e * np.cos(theta))
        w, wdot = h / r ** 2, -2 * h * np.sqrt(mu / p) * e * np.sin(theta) / r ** 3
        x, y, z, vx, vy, vz = X
        k = mu / r ** 3
        return [vx, vy, vz, 2 * w * vy + wdot * y + w ** 2 * x + 2 * k * x,
                -2 * w * vx - wdot * x + w ** 2 * y - k * y, -k * z]

    ref = np.array([solve_ivp(rhs, [0, dt], np.eye(6)[i], rtol=1e-12, atol=1e-14, method="DOP853").y[:, -1]
                    for i in range(6)]).T
    eccentric = float(np.max(np.abs(yamanaka_ankersen(e, a, mu, theta0, dt) - ref)) / np.max(np.abs(ref)))
    print(f"  e = 0: one orbit from (0, -2, 0) km at -0.5 m/s, max |LTV - CWH| / max|CWH| = {circular:.1e}")
    print(f"  e = 0.3: |YA - integrated| / max = {eccentric:.1e}")
    return {"circular_vs_cwh": circular, "eccentric_vs_integration": eccentric}


# ------------------------------------------------------------------ main

def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000, help="runs of the sampler")
    parser.add_argument("--referee-samples", type=int, default=100_000,
                        help="runs of the montecarlo back-end (at most)")
    parser.add_argument("--referee-budget", type=float, default=2e7,
                        help="limit on runs x kicks for the montecarlo back-end per scenario")
    parser.add_argument("--skip-referee", action="store_true", help="do not run the montecarlo back-end")
    parser.add_argument("--quick", action="store_true", help="scenarios only, no studies")
    args = parser.parse_args()
    PLOTS.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(2024)
    report = {"scenarios": []}
    for name, model_file, property_file, pid in SCENARIOS:
        model, prop = load(model_file, property_file, pid)
        result, seconds = timed(lambda: run(BACKEND, model, prop))
        row = {"scenario": name, "model": model_file, "property": pid, "fsr": result.probability,
               "fsr_seconds": seconds, "fsr_status": result.status.value, "fsr_details": result.details}
        hits, mc_seconds = sample(model, prop, args.samples, rng)
        row["sampler"] = monte_carlo_summary(hits, args.samples, mc_seconds)
        row["sampler_overlap"] = overlap(result.probability, row["sampler"]["interval"])
        row["sampler_speedup"] = speedup(result.probability, seconds, row["sampler"])
        if not args.skip_referee:
            from reach.backends.montecarlo import BACKEND as MONTECARLO
            kicks = result.details["kicks"]
            runs = int(min(args.referee_samples, max(1000, args.referee_budget // max(kicks, 1))))
            options = {"samples": runs, "dt": model.disturbance.step}
            start = time.perf_counter()
            ref = MONTECARLO.check(model, prop, options)
            mc = {"estimate": ref.details["estimate"], "interval": ref.probability,
                  "samples": ref.details["samples"], "seconds": time.perf_counter() - start}
            row["montecarlo"] = mc
            row["montecarlo_overlap"] = overlap(result.probability, mc["interval"])
            row["montecarlo_speedup"] = speedup(result.probability, seconds, mc)
        report["scenarios"].append(row)
        lo, hi = result.probability
        s = row["sampler"]
        line = (f"{name:34s} fsr [{lo:.5f}, {hi:.5f}] {seconds:7.3f} s | sampler {s['estimate']:.5f} "
                f"[{s['interval'][0]:.5f}, {s['interval'][1]:.5f}] {s['seconds']:6.1f} s "
                f"overlap={row['sampler_overlap']} x{row['sampler_speedup']['ratio']:.0f}")
        if "montecarlo" in row:
            m = row["montecarlo"]
            line += (f" | montecarlo {m['estimate']:.5f} [{m['interval'][0]:.5f}, {m['interval'][1]:.5f}] "
                     f"{m['seconds']:6.1f} s overlap={row['montecarlo_overlap']}")
        print(line, flush=True)
        plot_scenario(name, model, prop, PLOTS / f"{model_file}_{pid}.png")   # model files are fsr_*
    if not args.quick:
        print("reach-avoid methods, tight corridor (", SCENARIOS[3][0], "):")
        report["reach_avoid_methods"] = method_study()
        print("non-Gaussian kicks (Fourier path), LQR-1 5 m box at 1000 s:")
        report["non_gaussian"] = non_gaussian_study(args.samples, rng)
        print("eccentric orbit (LTV):")
        report["ltv"] = ltv_study()
    out = ROOT / "results" / "fsr_vs_montecarlo.json"
    out.write_text(json.dumps(report, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
    print(f"wrote {out} and {PLOTS}/fsr_*.png")


if __name__ == "__main__":
    main()
