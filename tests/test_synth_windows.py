"""The data side's choice of the window a ``track`` clip tracks: the most active of its
candidates, by the hinges' travel."""

from __future__ import annotations

import numpy as np

from sim.simulate.generate import most_active_window


def test_the_window_where_the_hinges_travel_most_is_chosen():
    T, nq = 100, 7 + 3
    q = np.zeros((T, nq))
    q[40:60, 7] = np.linspace(0, 2.0, 20)  # one hinge swings 2 rad over ticks 40-59
    q[60:, 7] = 2.0
    # windows of 20 ticks: only the one covering 40-59 sees the whole swing
    assert most_active_window(q, 20, np.array([0, 70, 40, 10])) == 40
    assert most_active_window(q, 20, np.array([0, 70])) == 0  # equal (still): the first
    q[:, 0] = np.arange(T)  # the root's travel does not count, only the hinges'
    assert most_active_window(q, 20, np.array([70, 45])) == 45
