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
