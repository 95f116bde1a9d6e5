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
    return np.array(drift_lead_xy(float(err[0]), float(err[1]), rate, max_len, dead))


def drift_lead_xy(
    ex: float, ey: float, rate: float, max_len: float, dead: float = 0.0
) -> tuple[float, float]:
    """:func:`drift_lead` of the error ``(ex, ey)`` [m] (reference less simulated), on floats
    (a tick's feedback calls it: no arrays to build)."""
    if rate <= 0:
        return 0.0, 0.0
    n = float(np.hypot(ex, ey))
    if dead <= 0:
        if n <= max_len:
            return rate * ex, rate * ey
        s = max_len / n
        return rate * (ex * s), rate * (ey * s)
    if n <= dead:
        return 0.0, 0.0
    s = max(0.0, min(n, max_len) - dead) / n
    return rate * ex * s, rate * ey * s
