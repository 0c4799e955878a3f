"""Automatic domain splitting (section 2.3, eqs. 15-20; Wittig et al. 2015).

For a polynomial in the scaled deviations ``xi`` (``[-1, 1]`` on a subdomain) the size of the
order-``i`` terms is ``S_i = sum_{|beta| = i} |a_beta|`` (L1, eq. 19). A least-squares fit of
``log S_i = log A + B i`` over the non-zero ``S_i``, ``i = 1..n`` (eq. 20) extrapolates the size
of the first neglected order, ``E(n + 1) = A exp(B (n + 1))``: the estimated truncation error.
The split direction is the variable whose own coefficient sizes (grouped by its power alone)
extrapolate to the largest ``E(n + 1)``; the subdomain is halved along it while the estimate
exceeds ``e_tol``, at most ``max_splits`` times on the way to any one subdomain.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from reach.backends.taylor.da import DA

log = logging.getLogger(__name__)
NEGLIGIBLE = 1e-14      # sizes below this fraction of the largest are treated as zero


def extrapolate(S: np.ndarray) -> float:
    """``E(n + 1)`` of eq. (20) from ``S = [S_0, ..., S_n]``; 0 when fewer than two orders
    ``>= 1`` are non-zero and the last of them is not ``S_n`` (the polynomial is then taken as exact
    when its top order vanishes, or the single size is carried over when it does not)."""
    S = np.asarray(S, dtype=float)
    n = len(S) - 1
    orders = np.arange(1, n + 1)
    sizes = S[1:]
    keep = sizes > NEGLIGIBLE * max(np.max(S), 1e-300)
    if keep.sum() == 0:
        return 0.0
    if keep.sum() == 1:
        return float(sizes[-1]) if keep[-1] else 0.0
    B, logA = np.polyfit(orders[keep], np.log(sizes[keep]), 1)
    return float(np.exp(logA + B * (n + 1)))


def truncation_estimate(poly: DA) -> tuple[float, int]:
    """Largest estimated truncation error over the components of ``poly`` and the variable to
    split (the one with the largest per-variable extrapolation; -1 for a point, no variable)."""
    comps = poly.c.reshape(-1, poly.alg.size)
    total, per_var = 0.0, np.zeros(poly.alg.nvars)
    for row in comps:
        p = DA(poly.alg, row)
        total = max(total, extrapolate(p.order_norms()))
        for j in range(poly.alg.nvars):
            per_var[j] = max(per_var[j], extrapolate(p.variable_norms(j)))
    return total, int(np.argmax(per_var)) if per_var.size else -1


@dataclass
class Subdomain:
    low: np.ndarray
    high: np.ndarray
    poly: object            # what ``expand`` returned for this box
    error: float            # estimated truncation error (eq. 20)
    splits: int
    converged: bool         # error <= e_tol

    @property
    def center(self):
        return 0.5 * (self.low + self.high)

    @property
    def half_width(self):
        return 0.5 * (self.high - self.low)


def split_domain(expand, low, high, e_tol: float, max_splits: int, measure=None,
                 map_boxes=None) -> list[Subdomain]:
    """Adaptive subdomains of the box ``[low, high]``, level by level.

    ``expand(center, half_width)`` returns an object whose ``measure`` (default: itself) is a
    DA in the scaled deviations of the box's variables. ``map_boxes(list of (center,
    half_width))`` expands a whole level at once (default: one after the other), so a level's
    boxes can run on an executor's workers.
    """
    measure = measure or (lambda result: result)
    map_boxes = map_boxes or (lambda boxes: [expand(c, h) for c, h in boxes])
    frontier = [(np.asarray(low, dtype=float), np.asarray(high, dtype=float), 0)]
    done = []
    level = 0
    while frontier:
        started = time.perf_counter()
        results = map_boxes([(0.5 * (lo + hi), 0.5 * (hi - lo)) for lo, hi, _ in frontier])
        deeper = []
        for (lo, hi, depth), result in zip(frontier, results):
            error, var = truncation_estimate(measure(result))
            if error > e_tol and depth < max_splits and var >= 0:
                mid = 0.5 * (lo[var] + hi[var])
                left_hi, right_lo = hi.copy(), lo.copy()
                left_hi[var], right_lo[var] = mid, mid
                deeper += [(lo, left_hi, depth + 1), (right_lo, hi, depth + 1)]
            else:
                done.append(Subdomain(lo, hi, result, error, depth, error <= e_tol))
        log.info("ADS level %d: %d boxes expanded in %.1f s, %d split, %d subdomains so far",
                 level, len(frontier), time.perf_counter() - started, len(deeper) // 2, len(done))
        frontier, level = deeper, level + 1
    done.sort(key=lambda sub: tuple(sub.low))
    return done
