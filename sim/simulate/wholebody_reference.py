"""The whole-body controller's reference (``sim.simulate.wholebody``): what the QP tracks per
control tick, computed once per reference: smoothed velocities and accelerations, the centre of
mass and centroidal angular momentum, the sole boxes' poses and whether each stands on the floor.

Units: metres, seconds, radians, z up, the floor at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.simulate.feedforward import reference_derivatives
from sim.simulate.model import CONTROL_HZ, SOLE_GEOMS, TOE_GEOMS

#: [m] a reference foot whose sole's lowest corner is at most this high stands on the floor
STANCE_GAP = 0.03
#: [s] standard deviation of the Gaussian that smooths the reference's velocities before they
#: are differentiated: a 30 fps clip resampled at 120 Hz has velocity steps at every frame
SMOOTH_S = 0.025


@dataclass
class WholeBodyReference:
    """What the QP tracks, per control tick (T ticks): ``qpos`` (T, nq), ``qvel``/``qacc``
    (T, nv), centre of mass ``com``/``com_vel``/``com_acc`` (T, 3), centroidal angular momentum
    ``angmom``/``angmom_rate`` (T, 3), per foot (left, right) the sole's centre ``sole_pos`` /
    ``sole_vel`` / ``sole_acc`` (T, 2, 3), its orientation ``sole_mat`` (T, 2, 3, 3), its
    angular velocity ``sole_angvel`` [rad/s] and acceleration ``sole_angacc`` [rad/s^2]
    (T, 2, 3, world frame) and ``stance`` (T, 2) (the sole within :data:`STANCE_GAP` of the
    floor)."""

    qpos: np.ndarray
    qvel: np.ndarray
    qacc: np.ndarray
    com: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    angmom: np.ndarray
    angmom_rate: np.ndarray
    sole_pos: np.ndarray
    sole_vel: np.ndarray
    sole_acc: np.ndarray
    sole_mat: np.ndarray
    stance: np.ndarray
    sole_angvel: np.ndarray
    sole_angacc: np.ndarray


def foot_box_ids(model) -> tuple[np.ndarray, np.ndarray]:
    """Geom ids of the (left, right) sole boxes and the (left, right) toe boxes."""
    soles = np.array([model.geom(n).id for n in SOLE_GEOMS])
    toes = np.array([model.geom(n).id for n in TOE_GEOMS])
    return soles, toes


_BOTTOM = np.array([[i, j, -1.0] for i in (-1, 1) for j in (-1, 1)])


def sole_corners(model, data, g: int) -> np.ndarray:
    """(4, 3) the bottom corners [m] of sole box ``g`` (``sim.simulate.model.add_soles``)."""
    R = data.geom_xmat[g].reshape(3, 3)
    return data.geom_xpos[g] + (_BOTTOM * model.geom_size[g]) @ R.T


def wholebody_reference(model, ref_qpos: np.ndarray) -> WholeBodyReference:
    """The :class:`WholeBodyReference` of ``ref_qpos`` (T, nq at ``CONTROL_HZ``, floor z = 0)."""
    qvel, _ = reference_derivatives(model, ref_qpos)
    sigma = SMOOTH_S * CONTROL_HZ
    if T_ok := len(ref_qpos) > 1:
        qvel = gaussian_filter1d(qvel, sigma, axis=0, mode="nearest")
    qacc = np.gradient(qvel, 1.0 / CONTROL_HZ, axis=0) if T_ok else np.zeros_like(qvel)
    data = mujoco.MjData(model)
    soles, _ = foot_box_ids(model)
    T = len(ref_qpos)
    com, com_vel, angmom = np.empty((T, 3)), np.empty((T, 3)), np.empty((T, 3))
    sole_pos, sole_mat = np.empty((T, 2, 3)), np.empty((T, 2, 3, 3))
    low = np.empty((T, 2))
    for t in range(T):
        data.qpos[:], data.qvel[:] = ref_qpos[t], qvel[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        mujoco.mj_subtreeVel(model, data)
        com[t], com_vel[t], angmom[t] = (
            data.subtree_com[1],
            data.subtree_linvel[1],
            data.subtree_angmom[1],
        )
        sole_pos[t] = data.geom_xpos[soles]
        sole_mat[t] = data.geom_xmat[soles].reshape(2, 3, 3)
        low[t] = [sole_corners(model, data, g)[:, 2].min() for g in soles]
    dt = 1.0 / CONTROL_HZ

    def d(x):  # a smoothed derivative: the reference is captured (noisy) or interpolated
        if T < 2:
            return np.zeros_like(x)
        return gaussian_filter1d(np.gradient(x, dt, axis=0), sigma, axis=0, mode="nearest")

    # the soles' angular velocity: the axial part of dR/dt R^T (world frame), smoothed
    w = np.zeros((T, 2, 3))
    if T > 1:
        W = np.gradient(sole_mat, dt, axis=0) @ np.swapaxes(sole_mat, -1, -2)
        w = 0.5 * (W[..., [2, 0, 1], [1, 2, 0]] - W[..., [1, 2, 0], [2, 0, 1]])
        w = gaussian_filter1d(w, sigma, axis=0, mode="nearest")
    stance = low <= STANCE_GAP
    # contact-consistent: a stance sole's target sits on the floor (its lowest corner at z = 0),
    # whatever height the capture's floor estimate left it at
    sole_pos[..., 2] -= np.where(stance, low, 0.0)
    sole_vel = d(sole_pos)
    return WholeBodyReference(
        qpos=ref_qpos, qvel=qvel, qacc=qacc, com=com, com_vel=com_vel, com_acc=d(com_vel),
        angmom=angmom, angmom_rate=d(angmom), sole_pos=sole_pos, sole_vel=sole_vel,
        sole_acc=d(sole_vel), sole_mat=sole_mat, stance=stance, sole_angvel=w,
        sole_angacc=d(w),
    )  # fmt: skip
