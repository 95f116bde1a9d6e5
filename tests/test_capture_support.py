"""Unsupported capture frames (``sim.simulate.capture_support``): the floor must push where the
root's vertical acceleration asks for more than the body's weight, and something must be under
the body to push on. The oracles are bodies made here: a root on a known height curve (its
acceleration in closed form) with toes placed under it, out in front or in the air."""

from __future__ import annotations

import json

import numpy as np

from sim.simulate.capture_support import (
    FORCE_SHARE,
    REACH,
    support_demand,
    unsupported_frames,
)
from sim.simulate.model import G

FPS = 30.0
T = np.arange(60) / FPS  # a 2 s clip


def bounce(amplitude: float = 0.15, hz: float = 1.5, mid: float = 0.6) -> np.ndarray:
    """(F,) a root bouncing on its legs: the bottoms ask for 1 + A w^2 / g of the weight."""
    return mid + amplitude * np.cos(2 * np.pi * hz * T)


def body(root_z: np.ndarray, toe_xy: tuple[float, float], toe_z: float) -> np.ndarray:
    """(F, 3, 3) a root at (0, 0, root_z) and two toes at ``toe_xy`` (one each side), ``toe_z`` up."""
    pos = np.zeros((len(root_z), 3, 3))
    pos[:, 0, 2] = root_z
    for k, side in ((1, 1.0), (2, -1.0)):
        pos[:, k] = [toe_xy[0], side * toe_xy[1], toe_z]
    return pos


def test_demand_follows_the_acceleration_in_closed_form():
    z = bounce()
    w = 2 * np.pi * 1.5
    exact = 1.0 - 0.15 * w**2 * np.cos(w * T) / G
    inner = slice(4, -4)  # the differences' edges aside
    assert np.abs(support_demand(z, FPS)[inner] - exact[inner]).max() < 0.15
    assert np.allclose(support_demand(np.full(60, 0.9), FPS), 1.0)


def test_standing_and_bouncing_on_feet_under_the_body_are_supported():
    assert not unsupported_frames(body(np.full(60, 0.95), (0.1, 0.1), 0.02), FPS).any()
    pos = body(bounce(), (0.15, 0.1), 0.02)
    assert (support_demand(pos[:, 0, 2], FPS) > FORCE_SHARE).any()  # it does ask for support
    assert not unsupported_frames(pos, FPS).any()


def test_a_bounce_whose_only_floor_points_are_out_in_front_is_unsupported():
    pos = body(bounce(), (REACH + 0.5, 0.1), 0.02)
    flags = unsupported_frames(pos, FPS)
    need = support_demand(pos[:, 0, 2], FPS) > FORCE_SHARE
    assert flags.any() and np.array_equal(flags, need)
    bottoms = np.flatnonzero(np.isclose(np.cos(2 * np.pi * 1.5 * T), -1.0, atol=0.05))
    assert flags[bottoms[(bottoms > 2) & (bottoms < 57)]].all()  # each bottom of the bounce


def test_a_bounce_with_the_feet_in_the_air_is_unsupported():
    flags = unsupported_frames(body(bounce(), (0.1, 0.1), 0.15), FPS)
    assert flags.any()
    assert not unsupported_frames(body(bounce(), (0.1, 0.1), 0.06), FPS).any()  # toes bear


def test_a_ballistic_flight_needs_no_floor():
    t = T[:12]
    flight = 1.0 + 2.0 * t - 0.5 * G * t**2  # free fall: the floor gives nothing
    assert not unsupported_frames(body(flight, (0.1, 0.1), 0.3), FPS).any()


def test_the_root_index_is_honoured():
    pos = body(bounce(), (REACH + 0.5, 0.1), 0.02)[:, [1, 0, 2]]  # the root second
    assert np.array_equal(unsupported_frames(pos, FPS, root=1),
                          unsupported_frames(pos[:, [1, 0, 2]], FPS))  # fmt: skip


def test_the_benchmark_page_counts_flagged_clips_and_their_falls(tmp_path):
    from types import SimpleNamespace

    from benchmark_modules import load_benchmark

    bench = load_benchmark("bench_capture_support")
    row = {"first_s": 0.1, "demand_max": 2.0, "root_min_m": 0.4}
    rows = [
        {"clip": "90_30@480", "unsupported": 6, "unsupported_s": 0.2, **row},
        {"clip": "17_10@720", "unsupported": 2, "unsupported_s": 0.07, **row},  # too short
        {"clip": "02_01@0", "unsupported": 0, "unsupported_s": 0.0, **row},
    ]
    log = tmp_path / "rows.jsonl"
    lines = [
        {"clip": "/d/90/90_30.amc@480", "controller": "c", "sim_fell": 1, "sim_fall_s": 0.7},
        {"clip": "/d/17/17_10.amc@720", "controller": "c", "sim_fell": 0, "sim_fall_s": None},
        {"clip": "/d/02/02_01.amc@0", "controller": "c", "sim_fell": 1, "sim_fall_s": 1.0},
        {"clip": "/d/02/02_01.amc@0", "controller": "other", "sim_fell": 0, "sim_fall_s": None},
    ]
    log.write_text("".join(json.dumps(x) + "\n" for x in lines))
    falls = bench.read_falls(str(log), "c")
    assert set(falls) == {"90_30@480", "17_10@720", "02_01@0"} and falls["02_01@0"]["sim_fell"]
    text = bench.page(rows, falls, "c", SimpleNamespace(force_share=1.5, reach=0.4))
    assert "**1 clips**" in text and "falls in 1 of them and stays up in 0" in text
    assert "of its 2 falls 1 are in these clips" in text
    assert "| 90_30@480 | 0.20 |" in text and "| 17_10@720 | 0.07 |" in text
    assert "02_01@0 |" not in text  # no unsupported frame: no row


def test_the_benchmark_scores_both_signals_against_the_falls():
    """``long_runs`` keeps runs of at least n frames; ``auc`` is the chance a fall scores above a
    clip that stays up (ties half); the comparison counts each rule's flagged clips and falls."""
    from benchmark_modules import load_benchmark

    bench = load_benchmark("bench_capture_support")
    mask = np.array([1, 1, 0, 1, 1, 1, 0, 1], bool)
    assert bench.long_runs(mask, 3).tolist() == [0, 0, 0, 1, 1, 1, 0, 0]
    assert not bench.long_runs(np.zeros(4, bool), 1).any()
    fell = np.array([1, 1, 0, 0, 0], bool)
    assert bench.auc([3, 2, 1, 0, 0], fell) == 1.0
    assert bench.auc([0, 0, 1, 2, 3], fell) == 0.0
    assert bench.auc([1, 1, 1, 1, 1], fell) == 0.5
    assert np.isclose(bench.auc([2, 0, 1, 3, 0], fell), 2.5 / 6)  # 2 > 1, 0; 0 ties 0: half

    def row(clip, cap, over, missing):
        return {"clip": clip, "unsupported_s": cap, "first_s": 0.2 if cap else None,
                "residual_bw": over, "residual_p95_bw": over, "residual_torque": 0.0,
                "over_s": over, "over_first_s": 0.1 if over else None, "missing_share": missing}  # fmt: skip

    rows = [row("a@0", 0.5, 0.9, 0.4), row("b@0", 0.0, 0.6, 0.3), row("c@0", 0.0, 0.5, 0.2),
            row("d@0", 0.0, 0.0, 0.0)]  # fmt: skip
    falls = {"a@0": {"sim_fell": 1, "sim_fall_s": 0.5}, "b@0": {"sim_fell": 1, "sim_fall_s": 0.05},
             "c@0": {"sim_fell": 0}, "d@0": {"sim_fell": 0}}  # fmt: skip
    text = bench.comparison(rows, falls)
    assert "(4 clips, 2 falls)" in text
    assert "| capture_support: unsupported | s | 0.750 |" in text  # a above c, d; b ties them
    assert "| residual force, mean | BW | 1.000 |" in text
    # capture: a only, before its fall; residual runs: a, b, c, b's run after its fall
    assert "(thresholds chosen on these clips) | 1 | 1 | 1 | 1 | - |" in text
    assert "for >= 0.1 s | 3 | 2 | 1 | 0 | c@0 |" in text
    assert "(`capture_unsupported`) | 3 | 2 | - | 0 | c@0 |" in text
    table = bench.joined_table(rows, falls)
    assert "| a@0 | 0.50 | 0.50 (0.20) | 0.90 / 0.90 | 0.90 (0.10) | 0.40 |" in table
    assert "d@0" not in table  # neither fell nor flagged


def test_the_auc_gain_interval_holds_its_estimate_and_excludes_zero_for_a_clear_gain():
    from benchmark_modules import load_benchmark

    bench = load_benchmark("bench_capture_support")
    rng = np.random.default_rng(1)
    fell = np.arange(60) < 15
    perfect = fell + 0.1 * rng.random(60)  # every fall above every other clip
    noise = rng.random(60)
    gain, lo, hi = bench.auc_gain(perfect, noise, fell)
    assert np.isclose(gain, 1.0 - bench.auc(noise, fell)) and lo <= gain <= hi and lo > 0
    gain, lo, hi = bench.auc_gain(noise, noise, fell)
    assert gain == lo == hi == 0.0
