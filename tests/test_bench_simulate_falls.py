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
    # the original capture lacking support on the floor comes first; a log without it is judged
    # by the rest
    bare = {**part, "ref_flight_near_s": 0.5, "orig_support_missing_share": 0.62}
    assert bench.fall_category(bare) == "capture-unsupported"
    assert (
        bench.fall_category({**bare, "orig_support_missing_share": 0.05}) == "reference-unsupported"
    )
    assert (
        bench.fall_category({**bare, "orig_support_missing_share": None}) == "reference-unsupported"
    )
    assert bench.fall_category({**bare, "fell": False}) == ""


def test_longest_run_counts_the_longest_stretch_of_true(bench):
    assert bench.longest_run(np.array([], bool)) == 0
    assert bench.longest_run(np.array([0, 1, 1, 0, 1, 1, 1, 0], bool)) == 3
    assert bench.longest_run(np.ones(5, bool)) == 5


def test_the_page_names_what_else_explains_a_capture_unsupported_fall(bench):
    base = {"sim_fall_s": 0.5, "cause": "head", "ref_part_at_fall_m": None, "ref_part_near_m": None,
            "sim_head_at_fall_m": 0.6, "ref_head_at_fall_m": 1.5, "ref_min_part": "ltibia",
            "ref_min_part_m": 0.04, "ref_min_sole_m": -0.01, "ref_longest_flight_s": 0.0,
            "ref_root_vz_max": 0.2, "drift_mid_m": 0.1, "drift_end_m": 0.1, "sim_error_local_mm": 50,
            "sim_error_mm": 80, "worst_points": [], "ref_flight_near_s": 0.0,
            "ref_jump_before_fall": False}  # fmt: skip
    rows = [
        {**base, "clip": "a@0", "fell": True, "drift_at_fall_m": 0.5, "orig_support_missing_share": 0.6},
        {**base, "clip": "b@0", "fell": True, "drift_at_fall_m": 0.1, "orig_support_missing_share": 0.0},
        {**base, "clip": "c@0", "fell": False, "drift_at_fall_m": None, "orig_support_missing_share": 0.6},
    ]  # fmt: skip
    for r in rows:
        r["category"] = bench.fall_category(r)
    text = bench.table_markdown(rows)
    assert "- **capture-unsupported**: 1 (a@0 (drift))" in text
    assert "- **balance**: 1 (b@0)" in text
    assert "| c@0 | no |" in text and "| 0.60, - |" in text  # its support beside, no residual
