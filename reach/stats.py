"""Confidence intervals for sampled probabilities."""

from __future__ import annotations

import numpy as np
from scipy import special


#: the confidence of the interval a sampled probability must lie wholly below its threshold at
#: to be a violation (exit 1; :func:`reach.checking.violated`): wrong once in a million checks,
#: not once in twenty as the 95 % interval it reports
VERDICT_CONFIDENCE = 1 - 1e-6


def wilson(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion."""
    if n == 0:
        return 0.0, 1.0
    z = special.ndtri(0.5 + confidence / 2)                  # the standard normal quantile
    p = successes / n
    denom = 1 + z ** 2 / n
    centre = (p + z ** 2 / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z ** 2 / (4 * n ** 2)) / denom
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def clopper_pearson_upper(failures: int, n: int, confidence: float = 0.95) -> float:
    """One-sided upper confidence bound on a failure probability from ``failures`` in ``n``."""
    if n == 0:
        return 1.0
    if failures >= n:
        return 1.0
    return float(special.betaincinv(failures + 1, n - failures, confidence))   # the Beta quantile
