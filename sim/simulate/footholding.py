"""Foot holding: what a sampled rollout pays for sliding a foot the reference stands on.

Foot skating in contact (``sim.simulate.validate.ForwardValidation.skating``) is the horizontal
speed of a sole's bottom centre while it touches the floor. The sampler's other cost terms look
at one instant and at the root and pose; none of them sees a stance foot slide. This term does:
over the ticks of a window, each sole's horizontal speed in excess of what it may move::

    slide = sum_k sum_feet counted_k max(0, |d sim_k| / dt - allowed_k)^2 / (K - 1)

[m^2/s^2] (``d x_k = x_k+1 - x_k``: the sole's horizontal step over tick k; ``dt``: the tick
[s]; K ticks). A step counts where the reference stands on that foot at both of its ends (it
may move as fast as the reference's sole, ``allowed_k = |d ref_k| / dt``), or where the
simulated sole touches the floor at both ends (its lowest corner at most :data:`CONTACT_HEIGHT`
high) while the reference lifts it (a dragged foot: ``allowed_k = 0``). Zero on the reference
itself (its soles touch the floor only where it stands on them) and wherever the simulated
foot moves no faster than allowed; it grows with the square of the excess speed, and never
asks a stance foot for less sliding than the motion itself has.

A foot may be given up when balance needs a step (``supported``, :func:`capture_supported`): a
step then counts only where the body's capture point (``com + v_com / omega``, ``omega =
sqrt(g / z_com)``: where the centre of mass comes to rest over a point foot, Pratt et al. 2006)
lies inside the support polygon (the convex hull of the bottom corners of the soles touching
the floor) at both of its ends; where it leaves it, no sole is held. Units: metres, seconds,
z up, floor at z = 0.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.simulate.balance import STANCE_HEIGHT
from sim.simulate.model import CONTROL_HZ, SOLE_GEOMS
from sim.simulate.terrain import surface_height, terrain_geoms

#: [m] a simulated sole whose lowest corner is at most this high touches the floor (skating's
#: estimator, ``sim.simulate.validate.SKATE_CONTACT``, is this height)
CONTACT_HEIGHT = 0.01


def sole_ids(model) -> np.ndarray | None:
    """(2,) geom ids of the (left, right) sole boxes; None where the body has no soles."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in SOLE_GEOMS]
    return None if min(ids) < 0 else np.array(ids)


def as_slice(ids: np.ndarray) -> slice:
    """The basic slice that picks rows ``ids`` (2,) (distinct, >= 0) in their order: a view
    where fancy indexing would copy (the sampler reads the soles after every tick)."""
    a, b = int(ids[0]), int(ids[1])
    stop = b + (1 if b > a else -1)
    return slice(a, None if stop < 0 else stop, b - a)


def sole_bottoms(xpos: np.ndarray, xmat: np.ndarray, half_height: np.ndarray) -> np.ndarray:
    """(..., 2, 3) the bottom centres [m] of boxes at ``xpos`` (..., 2, 3) with orientations
    ``xmat`` (..., 2, 9) (row-major, MuJoCo's ``geom_xmat``) and half heights ``half_height``
    (2,) [m] along their local z: the centre minus half the height along the box's z axis."""
    z_axis = xmat[..., [2, 5, 8]]  # the third column of each rotation
    return xpos - half_height[:, None] * z_axis


def sole_lowest(xpos: np.ndarray, xmat: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(..., 2) the height [m] of the lowest corner of boxes at ``xpos`` (..., 2, 3) with
    orientations ``xmat`` (..., 2, 9) and half sizes ``size`` (2, 3) [m]."""
    return xpos[..., 2] - np.sum(np.abs(xmat[..., 6:9]) * size, axis=-1)


def reference_soles(model, ref_qpos: np.ndarray, ids: np.ndarray, capture: bool = False) -> tuple:
    """Of a reference ``ref_qpos`` (T, nq at ``CONTROL_HZ``), per tick and sole (left, right):
    the horizontal bottom centre (T, 2, 2) [m] and whether the reference stands on it (T, 2)
    (the box's lowest corner at most ``sim.simulate.balance.STANCE_HEIGHT`` above the floor or
    the terrain's step under its centre, ``sim.simulate.terrain``); with
    ``capture`` (the sampler's view), third, whether its capture point lies inside the soles it
    stands on (T,) (:func:`capture_supported`), fourth, the lowest corner's height above that
    support (T, 2) [m], and fifth, each sole's heading (T, 2) [rad] (:func:`sole_yaw`)."""
    data = mujoco.MjData(model)
    T = len(ref_qpos)
    xpos, xmat, com = np.empty((T, 2, 3)), np.empty((T, 2, 9)), np.empty((T, 3))
    size = model.geom_size[ids]  # (2, 3) half sizes
    for t in range(T):
        data.qpos[:] = ref_qpos[t]
        mujoco.mj_kinematics(model, data)
        xpos[t], xmat[t] = data.geom_xpos[ids], data.geom_xmat[ids]
        if capture:
            mujoco.mj_comPos(model, data)
            com[t] = data.subtree_com[1]
    xy = sole_bottoms(xpos, xmat, size[:, 2])[..., :2]
    low = sole_lowest(xpos, xmat, size)
    terrain = terrain_geoms(model)
    if terrain is not None:  # a sole on a step stands on it
        low = low - surface_height(terrain, xpos[..., :2])
    stance = low <= STANCE_HEIGHT
    if not capture:
        return xy, stance
    return (
        xy,
        stance,
        capture_supported(com, sole_corners(xpos, xmat, size), stance, 1 / CONTROL_HZ),
        low,
        sole_yaw(xmat),
    )


def sole_yaw(xmat: np.ndarray) -> np.ndarray:
    """(...,) the heading [rad] (about z, from +x) of the local x axis (the foot's length) of
    boxes with orientations ``xmat`` (..., 9) (row-major)."""
    return np.arctan2(xmat[..., 3], xmat[..., 0])


def slide_cost(
    sim_xy: np.ndarray,
    ref_xy: np.ndarray,
    stance: np.ndarray,
    dt: float,
    contact: np.ndarray | None = None,
    supported: np.ndarray | None = None,
) -> float | np.ndarray:
    """The foot-holding cost [m^2/s^2] (module docstring) of soles at ``sim_xy`` (..., K, 2, 2)
    against the reference's ``ref_xy`` (K, 2, 2) over K ticks of ``dt`` [s], the reference
    standing on each sole where ``stance`` (K, 2) is True and the simulated sole touching the
    floor where ``contact`` (..., K, 2) is True (None: stance steps only); where ``supported``
    (..., K) is given, only the steps with it True at both ends count; 0 for K < 2.

    Returns:
        a float for one motion (``sim_xy`` (K, 2, 2)), else one cost per leading index (...).
    """
    K = sim_xy.shape[-3]
    if K < 2:
        return 0.0 if sim_xy.ndim == 3 else np.zeros(sim_xy.shape[:-3])
    v_sim = np.linalg.norm(np.diff(sim_xy, axis=-3), axis=-1) / dt  # (..., K-1, 2)
    v_ref = np.linalg.norm(np.diff(ref_xy, axis=0), axis=-1) / dt  # (K-1, 2)
    held = stance[1:] & stance[:-1]
    allowed = np.where(held, v_ref, 0.0)
    counted = held if contact is None else held | (contact[..., 1:, :] & contact[..., :-1, :])
    if supported is not None:
        counted = counted & (supported[..., 1:] & supported[..., :-1])[..., None]
    excess = np.where(counted, np.maximum(0.0, v_sim - allowed), 0.0)
    cost = np.sum(excess**2, axis=(-2, -1)) / (K - 1)
    return float(cost) if sim_xy.ndim == 3 else cost


def sole_corners(xpos: np.ndarray, xmat: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(..., 2, 4, 3) the four corners [m] of the bottom face (local -z) of boxes at ``xpos``
    (..., 2, 3) with orientations ``xmat`` (..., 2, 9) (row-major) and half sizes ``size`` (2,
    3) [m]."""
    signs = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])  # (4, 2) x, y
    local = np.concatenate(  # (2, 4, 3) per box
        [signs * size[:, None, :2], np.broadcast_to(-size[:, None, 2:], (2, 4, 1))], axis=-1
    )
    R = xmat.reshape(*xmat.shape[:-1], 3, 3)  # (..., 2, 3, 3)
    return xpos[..., None, :] + np.einsum("...ij,...cj->...ci", R, local)


def capture_supported(
    com: np.ndarray, corners: np.ndarray, touch: np.ndarray, dt: float, g: float = 9.81
) -> np.ndarray:
    """(..., K) whether the capture point lies strictly inside the support polygon at each of K
    ticks ``dt`` [s] apart: centre of mass ``com`` (..., K, 3) [m] (its velocity: the finite
    difference of consecutive ticks, the first tick taking the second's; 0 for K = 1), the soles'
    bottom corners ``corners`` (..., K, 2, 4, 3) [m], of which those of soles touching the floor
    (``touch`` (..., K, 2)) make the polygon; False where none touches.

    A point lies outside the convex hull of points ``c_j`` (or on its edge) exactly when a
    line through it along one of ``d_i = c_i - p`` has every ``d_j`` on one side."""
    v = np.zeros_like(com)
    if com.shape[-2] > 1:
        v[..., 1:, :] = np.diff(com, axis=-2) / dt
        v[..., 0, :] = v[..., 1, :]
    omega = np.sqrt(g / np.maximum(com[..., 2:], 1e-3))
    p = com[..., :2] + v[..., :2] / omega  # (..., K, 2) the capture point
    d = corners[..., :2].reshape(*corners.shape[:-3], 8, 2) - p[..., None, :]  # (..., K, 8, 2)
    valid = np.repeat(touch, 4, axis=-1)  # (..., K, 8)
    cross = d[..., :, None, 0] * d[..., None, :, 1] - d[..., :, None, 1] * d[..., None, :, 0]
    cross = np.where(valid[..., None, :], cross, 0.0)  # (..., K, 8 i, 8 j)
    one_side = np.all(cross >= 0.0, axis=-1) | np.all(cross <= 0.0, axis=-1)
    outside = np.any(valid & one_side, axis=-1)
    return valid.any(axis=-1) & ~outside


def window_hold_costs(
    records: tuple, size: np.ndarray, ref: tuple, dt: float, contact: bool, release: tuple
) -> np.ndarray:
    """(S,) the foot-holding cost (:func:`slide_cost`) of S rollouts' windows of K ticks.

    Args:
        records: the sole boxes' positions (S, K, 2, 3) [m] and orientations (S, K, 2, 9)
            and the centre of mass (S, K, 3) [m] after each tick.
        size: (2, 3) the sole boxes' half sizes [m].
        ref: the reference at those ticks (:func:`reference_soles` with ``capture``): sole
            centres (K, 2, 2) [m], stance (K, 2), capture point supported (K,).
        dt: the tick [s].
        contact: also cost a sole that touches the floor where the reference lifts it.
        release: (capture, versus_reference): ``capture`` gives the feet up at ticks where the
            rollout's capture point leaves its support (:func:`capture_supported`); with
            ``versus_reference`` only where the reference's is inside its own.
    """
    pos, mat, com = records
    xy = sole_bottoms(pos, mat, size[:, 2])[..., :2]
    touch = sole_lowest(pos, mat, size) <= CONTACT_HEIGHT
    up = None
    if release[0]:
        up = capture_supported(com, sole_corners(pos, mat, size), touch, dt)
        if release[1]:
            up = up | ~ref[2]
    return slide_cost(xy, ref[0], ref[1], dt, touch if contact else None, up)
