"""``event_sampling.within_bound`` at its edges.

A sampled extremum is the value of ``q`` at a state a real run visits, so a sound bound
``[lo, hi]`` of the true extremum must hold it on the outer side (``v <= hi`` for a maximum,
``v >= lo`` for a minimum) up to a relative rounding allowance ``1e-9 max(1, |lo|, |hi|)``;
on the inner side the sample may fall short of the true extremum by the grid slack.
The references below are that definition evaluated at points placed a fraction of the
allowance inside and outside each edge.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from reach.backends.montecarlo.event_sampling import within_bound

RELATIVE = 1e-9        # the documented rounding allowance


@given(lo=st.floats(-1e6, 1e6), width=st.floats(0.0, 1e6), slack=st.floats(0.0, 10.0),
       sense=st.sampled_from(["max", "min"]))
@settings(max_examples=60, deadline=None)
def test_each_edge_accepts_inside_its_allowance_and_rejects_beyond(lo, width, slack, sense):
    hi = lo + width
    tol = RELATIVE * max(1.0, abs(lo), abs(hi))
    outer_lo, outer_hi = (lo - tol - slack, hi + tol) if sense == "max" else (lo - tol, hi + tol + slack)
    # points at 0.5 and 2 allowances inside and outside each end of the accepted interval
    # both ends themselves (the edges are closed), points at 0.5 and 2 allowances inside and
    # outside each end of the accepted interval, and the middle of the bound
    probes = np.array([outer_lo, outer_hi, outer_lo + 0.5 * tol, outer_hi - 0.5 * tol, outer_lo - 2 * tol,
                       outer_hi + 2 * tol, 0.5 * (lo + hi)])
    expected = np.array([True, True, True, True, False, False, True])
    assert within_bound(probes, lo, hi, sense, slack).tolist() == expected.tolist()


def test_the_slack_lies_on_the_inner_side_only():
    """Bound [0, 1], slack 0.1: a sampled maximum of 0.95 is fine and 1.05 is not (no
    run exceeds its true maximum); 0.95 below the lower end by 0.05 passes, by 0.15 not.
    The mirror holds for a minimum."""
    v = [-0.05, -0.15, 1.05, 1.15, 0.5]
    assert within_bound(v, 0.0, 1.0, "max", 0.1).tolist() == [True, False, False, False, True]
    assert within_bound(v, 0.0, 1.0, "min", 0.1).tolist() == [False, False, True, False, True]


def test_the_allowance_scales_with_the_larger_end_and_never_below_one():
    """Near zero the allowance is 1e-9 absolute; at |hi| = 1e6 it is 1e-3, set by the
    larger of |lo| and |hi| whichever end it is."""
    assert within_bound([0.9e-9, 1.1e-9], -1e-12, 0.0, "max", 0.0).tolist() == [True, False]
    assert within_bound([-0.9e-9, -1.1e-9], 0.0, 1e-12, "min", 0.0).tolist() == [True, False]
    assert within_bound([1e6 + 0.9e-3, 1e6 + 1.1e-3], 0.0, 1e6, "max", 0.0).tolist() == [True, False]
    assert within_bound([-1e6 - 0.9e-3, -1e6 - 1.1e-3], -1e6, 0.0, "min", 0.0).tolist() == [True, False]
    assert within_bound([-0.9e-3, -1.1e-3], 0.0, 1e6, "min", 0.0).tolist() == [True, False]
    assert within_bound([0.9e-3, 1.1e-3], -1e6, 0.0, "max", 0.0).tolist() == [True, False]


def test_non_finite_samples_are_not_within():
    """A run with no sampled value (nan, or ``null`` read back from a JSON record) is not
    counted as agreeing with the bound."""
    assert within_bound([np.nan, None, 0.5], 0.0, 1.0, "max", 0.5).tolist() == [False, False, True]
