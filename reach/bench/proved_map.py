"""Proved colours of a 2-D subdomain map (Fig. 4 of the Taylor-ADS paper, from proofs only).

A subdomain of the initial box is coloured from what is proved of its runs, never from an
estimated bound:

- ``PROVED_SAFE``: boxes each proved to meet the requirement for every run cover the subdomain
  entirely (their union, so several boxes may share the cover);
- ``PROVED_UNSAFE``: a box proved to break the requirement (a run, or every run of the box, proved
  to violate it) meets the subdomain (closed sets: a run on a shared edge belongs to both);
- ``UNDECIDED``: everything else, including a subdomain partly covered by proved-safe boxes
  (the proved part is drawn on its own).

Boxes and subdomains are ``(low, high)`` pairs of 2-vectors. Cover and union area are exact on
the grid of the boxes' edges (no sampling).
"""

from __future__ import annotations

import numpy as np

PROVED_SAFE, PROVED_UNSAFE, UNDECIDED = "proved safe", "proved unsafe", "undecided"
COLOURS = (PROVED_SAFE, PROVED_UNSAFE, UNDECIDED)


def _cells(boxes, low, high):
    """The grid of the boxes' edges inside ``[low, high]``: cell centres and areas."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    axes = []
    for d in range(2):
        edges = {low[d], high[d]}
        for b_low, b_high in boxes:
            edges.update(v for v in (b_low[d], b_high[d]) if low[d] < v < high[d])
        axes.append(np.array(sorted(edges)))
    xs, ys = axes
    cx, cy = np.meshgrid(0.5 * (xs[:-1] + xs[1:]), 0.5 * (ys[:-1] + ys[1:]), indexing="ij")
    area = np.outer(np.diff(xs), np.diff(ys))
    return cx, cy, area


def _inside_any(boxes, cx, cy) -> np.ndarray:
    """Which cell centres lie in some box."""
    hit = np.zeros(cx.shape, bool)
    for b_low, b_high in boxes:
        hit |= (b_low[0] <= cx) & (cx <= b_high[0]) & (b_low[1] <= cy) & (cy <= b_high[1])
    return hit


def covered_area(boxes, low, high) -> float:
    """Area of ``[low, high]`` covered by the union of ``boxes``."""
    if not boxes:
        return 0.0
    cx, cy, area = _cells(boxes, low, high)
    return float(area[_inside_any(boxes, cx, cy)].sum())


def covers(boxes, low, high) -> bool:
    """Whether the union of ``boxes`` contains the whole of ``[low, high]``."""
    if not boxes:
        return False
    cx, cy, _ = _cells(boxes, low, high)
    return bool(np.all(_inside_any(boxes, cx, cy)))


def meets(box, low, high) -> bool:
    """Whether the closed boxes ``box`` and ``[low, high]`` share a point."""
    b_low, b_high = box
    return all(b_low[d] <= high[d] and low[d] <= b_high[d] for d in range(2))


def union_area(boxes) -> float:
    """Area of the union of ``boxes`` (overlaps counted once)."""
    if not boxes:
        return 0.0
    low = np.min([b[0] for b in boxes], axis=0)
    high = np.max([b[1] for b in boxes], axis=0)
    return covered_area(boxes, low, high)


def colour(low, high, safe_boxes, unsafe_boxes) -> str:
    """The proved colour of the subdomain ``[low, high]`` (module docstring). Both a safe cover
    and an unsafe proof for one subdomain contradict each other: an error, not a colour."""
    safe = covers(safe_boxes, low, high)
    unsafe = any(meets(b, low, high) for b in unsafe_boxes)
    if safe and unsafe:
        raise ValueError(f"subdomain {low}..{high} is both proved safe and proved unsafe")
    return PROVED_SAFE if safe else PROVED_UNSAFE if unsafe else UNDECIDED


def colour_map(subdomains, safe_boxes, unsafe_boxes) -> list[dict]:
    """For each subdomain ``(low, high)``: its colour and the area its proved-safe boxes cover."""
    return [{"colour": colour(low, high, safe_boxes, unsafe_boxes),
             "proved_safe_area": covered_area(safe_boxes, low, high)} for low, high in subdomains]
