"""The proved colours of the CW SIREN Fig. 4 map (reach/bench/proved_map.py) on synthetic rectangles:
a subdomain is proved safe only when proved boxes cover it entirely, proved unsafe only on an unsafe
proof, and an estimated bound never enters."""

import pytest

from reach.bench.proved_map import (PROVED_SAFE, PROVED_UNSAFE, UNDECIDED, colour, colour_map, covered_area,
                                    covers, union_area)

SUB = ([0.0, 0.0], [4.0, 2.0])            # a 4 x 2 subdomain


def test_one_box_covering_the_subdomain_proves_it_safe():
    assert colour(*SUB, [([-1.0, -1.0], [5.0, 3.0])], []) == PROVED_SAFE


def test_two_boxes_that_together_cover_it_prove_it_safe():
    halves = [([0.0, 0.0], [2.5, 2.0]), ([2.0, -0.5], [4.0, 2.0])]
    assert covers(halves, *SUB)
    assert colour(*SUB, halves, []) == PROVED_SAFE


def test_two_boxes_with_a_gap_leave_it_undecided_with_the_proved_part():
    gap = [([0.0, 0.0], [1.9, 2.0]), ([2.0, 0.0], [4.0, 2.0])]    # the strip 1.9 < x < 2 is not proved
    assert not covers(gap, *SUB)
    assert colour(*SUB, gap, []) == UNDECIDED
    assert covered_area(gap, *SUB) == pytest.approx(8.0 - 0.2)


def test_a_partial_cover_stays_undecided_and_counts_only_its_area_inside():
    part = [([3.0, 1.0], [6.0, 5.0])]
    assert colour(*SUB, part, []) == UNDECIDED
    assert covered_area(part, *SUB) == pytest.approx(1.0)


def test_unsafe_only_from_an_unsafe_proof():
    unsafe_run = ([1.0, 1.0], [1.0, 1.0])              # one run proved to keep L > 1
    assert colour(*SUB, [], [unsafe_run]) == PROVED_UNSAFE
    assert colour(*SUB, [], [([5.0, 0.0], [6.0, 1.0])]) == UNDECIDED       # elsewhere
    assert colour(*SUB, [], []) == UNDECIDED           # nothing proved: no colour from a bound


def test_an_estimated_bound_never_colours_a_subdomain():
    """colour_map takes the subdomains' rectangles only: rows with estimated bounds above or
    below the threshold, with no proof, are all undecided."""
    rows = [{"low": [0.0, 0.0], "high": [1.0, 1.0], "bound": [0.66, 0.77]},
            {"low": [1.0, 0.0], "high": [2.0, 1.0], "bound": [1.5, 2.0]}]
    out = colour_map([(r["low"], r["high"]) for r in rows], [], [])
    assert [o["colour"] for o in out] == [UNDECIDED, UNDECIDED]
    assert [o["proved_safe_area"] for o in out] == [0.0, 0.0]


def test_safe_cover_and_unsafe_proof_together_are_an_error():
    with pytest.raises(ValueError):
        colour(*SUB, [([0.0, 0.0], [4.0, 2.0])], [([1.0, 1.0], [1.0, 1.0])])


def test_union_area_counts_overlaps_once():
    boxes = [([0.0, 0.0], [2.0, 2.0]), ([1.0, 1.0], [3.0, 3.0]), ([0.5, 0.5], [1.0, 1.0])]
    assert union_area(boxes) == pytest.approx(7.0)
