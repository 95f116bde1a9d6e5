"""The data side's choice of the window a ``track`` clip tracks: the fastest of its candidates,
by the 95th percentile of its points' speeds."""

from __future__ import annotations

import numpy as np

from sim.simulate.windows import fastest_window


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
