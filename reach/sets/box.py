"""Axis-aligned boxes ``{x : low <= x <= high}``.

The support function of a box is closed-form,

    h_B(d) = max_{x in B} d^T x = d^T c + |d|^T r,

with centre ``c = (low + high) / 2`` and radius ``r = (high - low) / 2``, and so is the
interval hull of its affine image: ``M B + t`` lies in the box with centre ``M c + t`` and
radius ``|M| r``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from itertools import product

import numpy as np


@dataclass(frozen=True)
class Box:
    """``{x : low <= x <= high}``; its bounds are not changed in place (centre and radius are
    computed once)."""

    low: np.ndarray
    high: np.ndarray

    def __post_init__(self):
        low = np.atleast_1d(np.asarray(self.low, dtype=float))
        high = np.atleast_1d(np.asarray(self.high, dtype=float))
        if low.shape != high.shape or low.ndim != 1:
            raise ValueError(f"box bounds must be vectors of one length, got {low.shape} and {high.shape}")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    @classmethod
    def from_center_radius(cls, center, radius) -> "Box":
        center, radius = np.asarray(center, dtype=float), np.asarray(radius, dtype=float)
        return cls(center - radius, center + radius)

    @property
    def dim(self) -> int:
        return self.low.size

    @cached_property
    def center(self) -> np.ndarray:
        return (self.low + self.high) / 2

    @cached_property
    def radius(self) -> np.ndarray:
        return (self.high - self.low) / 2

    @cached_property
    def bounded(self) -> bool:
        """Whether every side is finite."""
        return bool(np.all(np.isfinite(self.radius)))

    def is_empty(self) -> bool:
        return bool(np.any(self.low > self.high))

    def contains(self, x, tol: float = 0.0) -> bool:
        x = np.asarray(x, dtype=float)
        return bool(np.all(x >= self.low - tol) and np.all(x <= self.high + tol))

    def support(self, direction) -> float:
        """``max_{x in B} d^T x = d^T c + |d|^T r``."""
        d = np.asarray(direction, dtype=float)
        return float(d @ self.center + np.abs(d) @ self.radius)

    def intersection(self, other: "Box") -> "Box":
        return Box(np.maximum(self.low, other.low), np.minimum(self.high, other.high))

    def affine_map(self, M, t=None) -> "Box":
        """Interval hull of ``{M x + t : x in B}`` (exact for the hull)."""
        M = np.atleast_2d(np.asarray(M, dtype=float))
        c = M @ self.center + (0.0 if t is None else np.asarray(t, dtype=float))
        return Box.from_center_radius(c, np.abs(M) @ self.radius)

    def corners(self) -> np.ndarray:
        """All ``2^n`` vertices (rows), for small dimensions."""
        return np.array(list(product(*zip(self.low, self.high))), dtype=float)

    def to_hpolytope(self):
        """The same set as ``A x <= b`` with ``A = [I; -I]``."""
        from reach.sets.hpolytope import HPolytope
        eye = np.eye(self.dim)
        return HPolytope(np.vstack([eye, -eye]), np.concatenate([self.high, -self.low]))
