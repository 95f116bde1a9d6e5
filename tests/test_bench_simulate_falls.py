"""``benchmarks/bench_simulate_falls.py``: each fall gets one category, in the documented order,
from its row's figures; the longest flight is the longest run of ticks off the floor."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_modules import load_benchmark


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("bench_simulate_falls")


def _row(**kw):
    row = {"fell": True, "cause": "head", "ref_flight_near_s": 0.0, "ref_part_near_m": None,
           "ref_head_at_fall_m": 1.6, "ref_jump_before_fall": False, "drift_at_fall_m": 0.1}  # fmt: skip
    return {**row, **kw}


def test_a_fall_gets_the_first_category_that_fits(bench):
    assert bench.fall_category(_row(fell=False)) == ""
    assert bench.fall_category(_row()) == "balance"
    assert bench.fall_category(_row(drift_at_fall_m=0.5)) == "drift"
    assert bench.fall_category(_row(drift_at_fall_m=0.5, ref_jump_before_fall=True)) == "jump"
    low_head = _row(ref_head_at_fall_m=0.8, ref_jump_before_fall=True)
    assert bench.fall_category(low_head) == "head-reference-low"
    part = _row(cause="contact:rtibia", ref_part_near_m=0.04, ref_head_at_fall_m=0.8)
    assert bench.fall_category(part) == "reference-part"
    assert bench.fall_category({**part, "ref_part_near_m": 0.3}) == "balance"
    assert bench.fall_category({**part, "ref_flight_near_s": 0.5}) == "reference-unsupported"


def test_longest_run_counts_the_longest_stretch_of_true(bench):
    assert bench.longest_run(np.array([], bool)) == 0
    assert bench.longest_run(np.array([0, 1, 1, 0, 1, 1, 1, 0], bool)) == 3
    assert bench.longest_run(np.ones(5, bool)) == 5
