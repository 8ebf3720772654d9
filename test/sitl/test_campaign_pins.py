"""Pinned real-time campaigns (--realtime-jobs N): the CPU shares handed to the flights."""
from __future__ import annotations

import pytest

from sitl_harness.engine import core_sets


def test_core_sets_are_disjoint_equal_shares():
    sets = core_sets(3, range(16))
    assert [len(s) for s in sets] == [5, 5, 5]
    flat = [c for s in sets for c in s]
    assert len(flat) == len(set(flat)) == 15
    assert set(flat) <= set(range(16))


def test_core_sets_follow_the_allowed_cpus():
    assert core_sets(2, [9, 3, 5, 7]) == [[3, 5], [7, 9]]


def test_more_flights_than_cpus_is_a_clear_error():
    with pytest.raises(ValueError, match="need at least 4 CPUs"):
        core_sets(4, [0, 1])
