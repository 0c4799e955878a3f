"""Bounds of a Taylor polynomial over its subdomain (section 3, eqs. 21-28).

With the deviations scaled so that each ``xi_i`` ranges over ``[-1, 1]``, a monomial
``a_beta xi^beta`` lies in ``[-|a_beta|, |a_beta|]`` (eqs. 25-26), and in ``[min(0, a_beta),
max(0, a_beta)]`` when every exponent is even (a slightly sharper enclosure of the same kind);
summing gives the enclosure ``I_P`` of eq. (27), which always contains the polynomial's range.

The polynomial differs from the map it approximates by the truncation remainder ``R_n``
(eq. 21). Two ways of accounting for it are offered, and neither is a proof:

* ``estimated`` (eq. 28): the exponential fit of the order sizes extrapolated to order ``n + 1``;
* ``next-order``: the map is expanded to order ``n + 1``; the order-``n + 1`` terms are bounded
  by interval evaluation over the box (eq. 27 applied to them), and the orders beyond by a
  geometric tail ``S_{n+1} r / (1 - r)`` with ``r`` the decay ratio of the fit over orders
  ``1..n+1`` (infinite when ``r >= 1``). It assumes that the coefficient sizes keep decaying at
  least geometrically with that ratio and that the integration error of the flow is negligible.

A rigorous enclosure would need a verified (Taylor-model) integration of the flow, which bounds
the remainder by interval arithmetic through every integration step; results built on these
bounds therefore never claim SAFE.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from reach.backends.taylor.ads import NEGLIGIBLE, extrapolate
from reach.backends.taylor.da import DA, algebra


def polynomial_range(poly: DA) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure ``I_P`` of eq. (27) over ``xi in [-1, 1]^d`` (componentwise for a batch)."""
    even, odd = _parity(poly.alg.order, poly.alg.nvars)
    c = poly.c
    const = c[..., 0]
    odd_part = np.abs(c[..., odd]).sum(axis=-1)
    lo = const - odd_part + np.minimum(c[..., even], 0.0).sum(axis=-1)
    hi = const + odd_part + np.maximum(c[..., even], 0.0).sum(axis=-1)
    return lo, hi


@lru_cache(maxsize=None)
def _parity(order: int, nvars: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the non-constant monomials with every exponent even, and of the others."""
    exps = algebra(order, nvars).exps
    even = np.all(exps % 2 == 0, axis=1)
    even[0] = False
    odd = ~even
    odd[0] = False
    return np.flatnonzero(even), np.flatnonzero(odd)


def estimated_remainder(poly: DA) -> np.ndarray:
    """``R~_n = E(n + 1)`` of eq. (28) for each component."""
    rows = poly.c.reshape(-1, poly.alg.size)
    out = [extrapolate(DA(poly.alg, r).order_norms()) for r in rows]
    return np.array(out).reshape(poly.shape)


def truncate(poly: DA, order: int) -> DA:
    """The same series cut to ``order`` (in the algebra of that order)."""
    target = algebra(order, poly.alg.nvars)
    keep = poly.alg.degree <= order
    return DA(target, poly.c[..., keep])


def next_order_remainder(poly_high: DA) -> np.ndarray:
    """Remainder of the order-``n`` truncation of an order-``n + 1`` expansion: interval bound of
    the order-``n + 1`` terms plus the geometric tail (see the module docstring)."""
    rows = poly_high.c.reshape(-1, poly_high.alg.size)
    n1 = poly_high.alg.order
    out = []
    for r in rows:
        S = DA(poly_high.alg, r).order_norms()
        sizes = S[1:]
        keep = sizes > NEGLIGIBLE * max(np.max(S), 1e-300)
        if S[n1] <= NEGLIGIBLE * max(np.max(S), 1e-300):
            out.append(extrapolate(S))
            continue
        if keep.sum() < 2:
            out.append(np.inf)
            continue
        B, _ = np.polyfit(np.arange(1, n1 + 1)[keep], np.log(sizes[keep]), 1)
        ratio = np.exp(B)
        out.append(S[n1] * (1.0 + ratio / (1.0 - ratio)) if ratio < 1 else np.inf)
    return np.array(out).reshape(poly_high.shape)


def enclose(poly: DA, remainder: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``I_P + [-R, R]`` (eq. 28). An end that is not a number (a series that overflowed:
    ``inf - inf`` among its coefficients, :func:`overflows`) is unbounded: ``-inf`` below,
    ``inf`` above, so that no extremum taken over the candidates passes over it."""
    lo, hi = polynomial_range(poly)
    lo, hi = lo - remainder, hi + remainder
    return np.where(np.isnan(lo), -np.inf, lo), np.where(np.isnan(hi), np.inf, hi)


def overflows(poly: DA) -> bool:
    """Whether the enclosure ``I_P`` of ``poly`` is not finite: the quantity overflows the
    floating-point numbers somewhere on the subdomain (``exp(exp(t))`` for ``t`` past about 6.5),
    so its bound says nothing but that it is unbounded."""
    lo, hi = polynomial_range(poly)
    return not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)))


def extremum_bound(ends: dict, sense: str, partial=frozenset(), alternatives=()) -> tuple[float, float]:
    """The range over the box of a run's extremum from its candidates' enclosures ``ends``
    (``{name: (lo, hi)}``).

    For a maximum, a run's extremum is the largest value among the candidates it reaches. It is
    at most the largest upper end of all the candidates (the outer end), and at least the
    largest lower end among those that every run reaches (all but ``partial``) and, for each
    pair of ``alternatives`` (every run reaches one of the two), the smaller of the two lower
    ends (the inner end). A minimum is the mirror image. With no candidate, or none on the inner
    side, the end is the empty extremum's (``-inf`` for a maximum, ``inf`` for a minimum): some
    runs may reach none."""
    sign = 1.0 if sense == "max" else -1.0
    up = {name: (lo, hi) if sign > 0 else (-hi, -lo) for name, (lo, hi) in ends.items()}
    outer = max((hi for _, hi in up.values()), default=-np.inf)
    sure = [lo for name, (lo, _) in up.items() if name not in partial]
    either = [min(up[a][0], up[b][0]) for a, b in alternatives]
    inner = max(sure + either, default=-np.inf)
    return (inner, outer) if sign > 0 else (-outer, -inner)


def contenders(candidates: dict, sense: str, partial=frozenset(), alternatives=()) -> dict:
    """The candidates that can hold the extremum: for a maximum, those whose enclosure (eq. 27
    with the eq. 28 remainder) reaches above the inner end of the bound (:func:`extremum_bound`:
    the largest lower end among the candidates every run reaches); below it for a minimum. A
    dominated candidate changes neither end of the bound, so its truncation error need not
    drive the splitting."""
    if not candidates:
        return {}
    ends = {name: tuple(float(v) for v in enclose(p, estimated_remainder(p))) for name, p in candidates.items()}
    lo, hi = extremum_bound(ends, sense, partial, alternatives)
    if sense == "max":
        return {name: candidates[name] for name, (_, top) in ends.items() if top >= lo}
    return {name: candidates[name] for name, (bottom, _) in ends.items() if bottom <= hi}
