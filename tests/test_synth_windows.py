"""The data side's choice of the window a ``track`` clip tracks: the fastest of its candidates,
by the 95th percentile of its points' speeds."""

from __future__ import annotations

import numpy as np
import pytest

from sim.simulate.windows import fastest_window, window_steps


def test_the_window_whose_points_move_fastest_is_chosen():
    T, P = 100, 20
    x = np.zeros((T, P, 3))
    # every point walks 1 cm per sample, except over samples 40-59, where 10 of the 20 points
    # (half: above the 95th percentile's rank) move 5 cm per sample
    x[:, :, 0] = 0.01 * np.arange(T)[:, None]
    x[40:60, :10, 1] = 0.05 * np.arange(1, 21)[:, None]
    x[60:, :10, 1] = 1.0
    assert fastest_window(x, 20, np.array([0, 70, 40, 10])) == 40  # covers the whole burst
    assert fastest_window(x, 20, np.array([0, 70])) == 0  # equally fast: the first
    # the percentile, not the mean: one point racing for 9 samples (9 of the window's 380
    # steps, 2 %: below the 95th percentile's rank) loses against a window where half the
    # points move a little faster
    x2 = np.zeros((T, P, 3))
    x2[:10, 0, 2] = 1.0 * np.arange(10)  # one point, 1 m per sample, then still
    x2[10:, 0, 2] = 9.0
    x2[50:70, :10, 2] = 0.02 * np.arange(20)[:, None]  # ten points, 2 cm per sample
    assert fastest_window(x2, 20, np.array([0, 50])) == 50


def test_a_cap_keeps_the_fastest_window_within_it_else_the_slowest():
    T, P = 100, 4
    x = np.zeros((T, P, 3))
    # windows of 20 samples: steps of 1 cm from 0, 3 cm from 40, 6 cm from 70 (every point)
    speed = np.full(T - 1, 0.01)
    speed[40:59], speed[70:89] = 0.03, 0.06
    x[1:, :, 0] = np.cumsum(speed)[:, None]
    starts = np.array([0, 40, 70])
    assert window_steps(x, 20, starts) == pytest.approx([0.01, 0.03, 0.06])
    assert fastest_window(x, 20, starts) == 70  # no cap: the fastest
    assert fastest_window(x, 20, starts, cap=0.05) == 40  # the fastest within the cap
    assert fastest_window(x, 20, starts, cap=0.035) == 40
    assert fastest_window(x, 20, starts, cap=0.005) == 0  # none within it: the slowest


class _Starts:
    """A stand-in for the episode's random stream that draws the window starts ``starts``."""

    def __init__(self, starts):
        self.starts = np.asarray(starts)

    def integers(self, low, high, size):
        assert size == len(self.starts) and np.all((low <= self.starts) & (self.starts < high))
        return self.starts


def _band_window(cmu_dir, monkeypatch, band, speed: float):
    """``source_window`` of a track task on 55_12 (a long trial: room for any warp) under the
    speed ``band``, the drawn warp ``speed``: (window, its parameters, the trial at 120 Hz)."""
    from sim.model.humanoid import canonical_skeleton
    from sim.simulate import episode_scene
    from sim.simulate.episode_body import episode_bodies
    from sim.simulate.generate import SynthTask
    from sim.simulate.model import scaled_skeleton
    from sim.simulate.reference import trial_qpos

    monkeypatch.setitem(episode_scene.WINDOW_CANDIDATES, "track", 2)
    monkeypatch.setitem(episode_scene.WINDOW_SPEED_BAND, "track", band)
    asf, amc = cmu_dir / "55" / "55.asf", cmu_dir / "55" / "55_12.amc"
    task = SynthTask("track", 0, 0, str(asf), str(amc), seconds=0.5, terrain=False)
    body = episode_bodies(scaled_skeleton(canonical_skeleton(), 1.0), 1.0, 1.0)[0][0]
    p = {"scale": 1.0, "speed": speed, "gain": 1.0, "controller": "plain"}
    window, _, _ = episode_scene.source_window(task, p, body, 60, _Starts([300, 900]))
    return window, p, trial_qpos(task.asf, task.amc), body


def _step_speed(body, window) -> float:
    """[m/s] ``window_steps``' measure of a (T, nq) window at the control rate."""
    from sim.simulate.model import CONTROL_HZ
    from sim.simulate.windows import body_points

    return float(window_steps(body_points(body, window), len(window), [0])[0]) * CONTROL_HZ


@pytest.mark.parametrize("band, expect", [((0.0, 1e-3, 2.0), 1.0), ((50.0, 60.0, 1.8), 1.8)])
def test_the_warp_is_moved_towards_the_speed_band_at_the_windows_source_time(
    cmu_dir, monkeypatch, band, expect
):
    """A cap no window meets lowers the drawn warp to 1 (never below); a floor no window meets
    raises it to the highest warp allowed; either way the window starts where the drawn one
    did in the source (its first pose is the trial's there) and both warps are recorded."""
    drawn = 1.4
    _, p0, _, body = _band_window(cmu_dir, monkeypatch, (0.0, 1e3, 2.0), drawn)
    window, p, trial, _ = _band_window(cmu_dir, monkeypatch, band, drawn)
    assert p0["speed"] == drawn and p["speed"] == pytest.approx(expect)
    assert p["window_band"] == {"floor": band[0], "cap": band[1], "highest": band[2],
                                "drawn_speed": drawn}  # fmt: skip
    source = p["start_tick"] * p["speed"]  # the window's first source tick, as warped
    assert source == pytest.approx(300 * drawn, abs=p["speed"]) or source == pytest.approx(
        900 * drawn, abs=p["speed"]
    )
    i = int(round(source))
    assert np.abs(window[0, 7:] - trial[i, 7:]).max() < 0.05  # the hinges there [rad]
    # its speed is the source's over the same stretch times the warp
    source_speed = _step_speed(body, trial[i : i + int(round(60 * p["speed"]))])
    assert _step_speed(body, window) == pytest.approx(p["speed"] * source_speed, rel=0.1)
