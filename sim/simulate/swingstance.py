"""Swing clearance and stance pivot: what a sampled rollout pays for a swing sole skimming the
floor and for a stance sole turning on it.

Eval's foot skating (``sim.simulate.validate.ForwardValidation.skating``) counts a sole's speed
wherever its lowest corner is within 1 cm of the floor. Of the sampler's excess over its
reference's (docs/synthetic.md, "What the skating is made of") a large share is a sole that
skims the floor without load where the reference's is higher, and most of the rest a loaded
sole turning about the vertical on its contact. Two terms, over the K ticks of a window:

* **clearance** [m^2]: where the reference's sole is off its support (its lowest corner more
  than :data:`~sim.simulate.footholding.CONTACT_HEIGHT` above the floor or the terrain box
  under it), the simulated sole pays the squared amount by which its own lowest corner is below
  the reference's, the reference's capped at :data:`CLEARANCE_CAP`::

      clearance = sum_k sum_feet swing_k max(0, min(h_ref_k, cap) - h_sim_k)^2 / K

  A swing foot must lift as far as the reference's does up to a few centimetres (enough to
  leave the estimator's band); higher, it may swing as low as it likes. A simulated sole below
  its support (sunk) pays its depth too.

* **pivot** [rad^2/s^2]: over each tick's step where the reference stands on a sole at both
  ends and the simulated sole touches its support at both ends, the squared difference of the
  two soles' yaw rates (heading about z, wrapped to (-pi, pi] per step)::

      pivot = sum_k sum_feet counted_k ((dpsi_sim_k - dpsi_ref_k) / dt)^2 / K

  The rate, not the heading's difference to the reference's: a foot put down turned from the
  reference's heading would be asked by a heading term to turn on the floor to it, which is the
  pivoting the skating counts; the rate asks a stance sole to turn no more than the reference's
  does, wherever it stands (as foot holding asks of its horizontal speed).

Both are zero on the reference itself and on a sole where the reference's is not counted.
Units: metres, radians, seconds, z up, floor at z = 0.
"""

from __future__ import annotations

import numpy as np

from sim.simulate.footholding import CONTACT_HEIGHT, sole_lowest, sole_yaw
from sim.simulate.terrain import surface_height

#: [m] the reference's swing sole height a simulated one must reach, at most (the skating
#: estimator counts a sole within 1 cm of the floor; 3 cm leaves it a margin)
CLEARANCE_CAP = 0.03


def clearance_cost(
    sim_h: np.ndarray, ref_h: np.ndarray, cap: float = CLEARANCE_CAP
) -> float | np.ndarray:
    """The clearance cost [m^2] (module docstring) of simulated soles whose lowest corners are
    ``sim_h`` (..., K, 2) [m] above their support (NaN: not reached, counts nothing) against
    the reference's ``ref_h`` (K, 2) [m] over K ticks; ``cap`` [m].

    Returns:
        a float for one motion (``sim_h`` (K, 2)), else one cost per leading index (...).
    """
    K = sim_h.shape[-2]
    swing = (ref_h > CONTACT_HEIGHT) & np.isfinite(sim_h)
    short = np.maximum(0.0, np.minimum(ref_h, cap) - np.where(swing, sim_h, 0.0))
    cost = np.sum(np.where(swing, short**2, 0.0), axis=(-2, -1)) / max(K, 1)
    return float(cost) if sim_h.ndim == 2 else cost


def pivot_cost(
    sim_yaw: np.ndarray, ref_yaw: np.ndarray, stance: np.ndarray, touch: np.ndarray, dt: float
) -> float | np.ndarray:
    """The pivot cost [rad^2/s^2] (module docstring) of simulated soles with headings
    ``sim_yaw`` (..., K + 1, 2) [rad] at a window's start and after each of its K ticks of
    ``dt`` [s], touching their support where ``touch`` (..., K + 1, 2) is True, against the
    reference's headings ``ref_yaw`` (K + 1, 2), standing where ``stance`` (K + 1, 2) is True.

    Returns:
        a float for one motion (``sim_yaw`` (K + 1, 2)), else one cost per leading index (...).
    """
    K = sim_yaw.shape[-2] - 1
    if K < 1:
        return 0.0 if sim_yaw.ndim == 2 else np.zeros(sim_yaw.shape[:-2])

    def step(yaw: np.ndarray) -> np.ndarray:  # wrapped to (-pi, pi]
        return np.angle(np.exp(1j * np.diff(yaw, axis=-2)))

    counted = stance[1:] & stance[:-1] & touch[..., 1:, :] & touch[..., :-1, :]
    rate = (step(sim_yaw) - step(ref_yaw)) / dt  # (..., K, 2)
    cost = np.sum(np.where(counted, rate**2, 0.0), axis=(-2, -1)) / K
    return float(cost) if sim_yaw.ndim == 2 else cost


def window_swing_stance_costs(
    records: tuple, size: np.ndarray, ref: tuple, terrain, dt: float, weights: tuple
) -> np.ndarray:
    """(S,) ``weights`` = (clearance, pivot) times :func:`clearance_cost` and
    :func:`pivot_cost` of S rollouts' windows of K ticks (a weight 0: that term not computed).

    Args:
        records: the sole boxes' positions (S, K + 1, 2, 3) [m] and orientations (S, K + 1, 2,
            9): at the window's start, then after each of its K ticks (NaN after a rollout
            stopped: counts nothing).
        size: (2, 3) the sole boxes' half sizes [m].
        ref: the reference at the same K + 1 instants (``footholding.reference_soles`` with
            ``capture``): stance (K + 1, 2) second, lowest corners' heights above the support
            (K + 1, 2) [m] fourth, headings (K + 1, 2) [rad] fifth.
        terrain: ``terrain.terrain_geoms`` of the model (None: the floor alone).
        dt: the tick [s].
    """
    pos, mat = records[0], records[1]
    h = sole_lowest(pos, mat, size) - surface_height(terrain, pos[..., :2])  # (S, K + 1, 2)
    cost = np.zeros(len(pos))
    if weights[0] > 0:  # the ticks, not the start
        cost += weights[0] * clearance_cost(h[:, 1:], ref[3][1:])
    if weights[1] > 0:
        touch = h <= CONTACT_HEIGHT  # NaN: False
        cost += weights[1] * pivot_cost(sole_yaw(mat), ref[4], ref[1], touch, dt)
    return cost
