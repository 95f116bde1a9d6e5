"""The lead that turns a tracker's root velocity target back towards the reference's path.

A tracker that matches the reference's velocity never makes up a position error it has
already collected: the simulated root drifts off the path for good. Leading the velocity target
by a rate times the horizontal position error (reference less simulated) asks the body to head
back; the error is clipped to a length so that a body far off is not asked to run. Used by the
balance feedback (``sim.simulate.balance.Balance.k_drift``) and by the sampler's cost
(``sim.simulate.sampling.CostWeights.drift_rate``). Units: metres, seconds, z up.
"""

from __future__ import annotations

import numpy as np


def drift_lead(
    ref_xy: np.ndarray, sim_xy: np.ndarray, rate: float, max_len: float, dead: float = 0.0
) -> np.ndarray:
    """(2,) [m/s] ``rate`` [1/s] times ``ref_xy - sim_xy`` (each (2,) [m], the root's horizontal
    position), the error clipped to ``max_len`` [m] in length and then shortened by ``dead`` [m]
    (an error of at most ``dead`` asks nothing); zeros where ``rate`` is 0."""
    if rate <= 0:
        return np.zeros(2)
    err = np.asarray(ref_xy, dtype=float) - np.asarray(sim_xy, dtype=float)
    n = float(np.hypot(err[0], err[1]))
    if dead <= 0:
        return rate * (err if n <= max_len else err * (max_len / n))
    return rate * err * (max(0.0, min(n, max_len) - dead) / n) if n > dead else np.zeros(2)
