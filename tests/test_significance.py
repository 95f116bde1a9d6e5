"""The paired bootstrap that decides whether a method's simulated body falls or strays more
than the original's: checked on cases with a known answer."""

from __future__ import annotations

import numpy as np
import pytest

from sidql.evaluation.significance import paired_bootstrap, versus_original


def test_identical_samples_are_not_significant():
    a = np.random.default_rng(0).normal(size=30)
    t = paired_bootstrap(a, a.copy(), resamples=2000)
    assert t["mean_diff"] == 0 and t["ci_low"] == 0 and t["ci_high"] == 0
    assert t["p_value"] == 1.0 and not t["more"]


def test_a_shift_far_beyond_the_noise_is_significant_and_its_mirror_is_not():
    rng = np.random.default_rng(1)
    b = rng.normal(size=40)
    a = b + 1.0 + 0.1 * rng.normal(size=40)  # mean shift 1, paired noise 0.1
    t = paired_bootstrap(a, b, resamples=2000)
    assert t["more"] and t["p_value"] == 1 / 2001  # no resample of the null reaches it
    assert t["ci_low"] < t["mean_diff"] < t["ci_high"] and 0.9 < t["ci_low"] < t["ci_high"] < 1.1
    m = paired_bootstrap(b, a, resamples=2000)  # "b is larger": the other way round, no
    assert not m["more"] and m["p_value"] > 0.99


def test_the_interval_matches_the_normal_theory_on_a_large_sample():
    # independent oracle: for n large the bootstrap interval of a mean is mean +- 1.96 s / sqrt(n)
    rng = np.random.default_rng(2)
    d = rng.normal(0.2, 1.0, size=2000)
    t = paired_bootstrap(d, np.zeros_like(d), resamples=4000)
    half = 1.96 * d.std(ddof=1) / np.sqrt(d.size)
    assert t["ci_low"] == pytest.approx(d.mean() - half, abs=0.15 * half)
    assert t["ci_high"] == pytest.approx(d.mean() + half, abs=0.15 * half)
    # and the one-sided p-value near the normal tail's, 1 - Phi(mean / (s / sqrt(n)))
    from math import erf, sqrt

    z = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
    assert t["p_value"] == pytest.approx(0.5 * (1 - erf(z / sqrt(2))), abs=0.01)


def test_a_small_noisy_difference_is_not_significant():
    rng = np.random.default_rng(3)
    b = rng.normal(size=12)
    t = paired_bootstrap(b + 0.05 + rng.normal(size=12), b, resamples=2000)
    assert not t["more"] and t["ci_low"] < 0 < t["ci_high"] and t["p_value"] > 0.05


def test_falls_as_zero_one_samples():
    # 10 clips: the original falls in 1, the method in 8 (including the original's)
    orig = np.array([1, 0, 0, 0, 0, 0, 0, 0, 0, 0], float)
    meth = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0, 0], float)
    t = paired_bootstrap(meth, orig)
    assert t["mean_diff"] == pytest.approx(0.7) and t["more"] and t["p_value"] < 0.01
    same = paired_bootstrap(orig, orig)
    assert not same["more"] and same["p_value"] == 1.0


def test_bad_shapes_and_no_pairs():
    with pytest.raises(ValueError):
        paired_bootstrap(np.zeros(3), np.zeros(4))
    t = paired_bootstrap(np.zeros(0), np.zeros(0))
    assert t["n"] == 0 and np.isnan(t["p_value"]) and not t["more"]


def test_versus_original_pairs_each_method_with_the_original_on_the_same_clip():
    rows = []
    for i in range(20):
        clip = {"source": f"t{i % 4}", "start_frame": 60 * i}
        rows.append({**clip, "method": "original", "keyframes": 60, "sim_fell": 0,
                     "sim_error_mm": 100.0 + i})  # fmt: skip
        rows.append({**clip, "method": "random", "keyframes": 5, "sim_fell": 1,
                     "sim_error_mm": 150.0 + i})  # fmt: skip
        rows.append({**clip, "method": "same", "keyframes": 5, "sim_fell": 0,
                     "sim_error_mm": 100.0 + i})  # fmt: skip
    rows.append({"source": "x", "start_frame": 0, "method": "random", "keyframes": 5,
                 "sim_fell": 1, "sim_error_mm": 1e6})  # no original: left out  # fmt: skip
    out = {(r["method"], r["metric"]): r for r in versus_original(rows, ["random", "same"],
                                                                   resamples=500)}  # fmt: skip
    assert out["random", "sim_error_mm"]["clips"] == 20
    assert out["random", "sim_error_mm"]["mean_diff"] == pytest.approx(50)
    assert out["random", "sim_error_mm"]["more"] and out["random", "sim_fell"]["more"]
    assert not out["same", "sim_error_mm"]["more"] and out["same", "sim_fell"]["p_value"] == 1
    assert ("random", "sim_error_local_mm") not in out  # no such figure in the rows
