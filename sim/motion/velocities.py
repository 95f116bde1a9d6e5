"""True velocities: ``qvel`` from ``qpos`` and point velocities from the kinematic chain.

``qvel`` comes from central differences of ``qpos`` through ``mujoco.mj_differentiatePos`` (so the
free joint's quaternion is differentiated on the rotation group), one-sided at the ends. Point
velocities are then ``v = J(q) q̇``: MuJoCo's ``cvel`` (built from ``cdof`` by ``mj_comVel``) moved to
each point, never differences of positions.
"""

from __future__ import annotations

import mujoco
import numpy as np


def qvel_from_qpos(model, qpos: np.ndarray, fps: float, frames: np.ndarray | None = None):
    """(F, nv) generalised velocities at ``frames`` of a ``qpos`` stream sampled at ``fps``.

    Central differences ``(q[t+1] ⊖ q[t-1]) / 2h`` inside, one-sided at the first and last frame.

    Args:
        qpos: (T, nq) positions sampled every ``1 / fps`` seconds.
        frames: indices where velocities are wanted (default: all T).
    """
    T = qpos.shape[0]
    frames = np.arange(T) if frames is None else np.asarray(frames)
    out = np.zeros((len(frames), model.nv))
    if T < 2:
        return out
    h = 1.0 / fps
    for k, t in enumerate(frames):
        a, b = max(t - 1, 0), min(t + 1, T - 1)
        mujoco.mj_differentiatePos(model, out[k], (b - a) * h, qpos[a], qpos[b])
    return out


def point_kinematics(model, data, qpos, qvel, body_ids, site_ids):
    """Positions, velocities and body orientations along a trajectory.

    Args:
        qpos: (T, nq); qvel: (T, nv).
        body_ids: (J,) body of each point; site_ids: (J,) site at each point (-1: the body origin).

    Returns:
        positions (T, J, 3) [m], velocities (T, J, 3) [m/s], body quaternions (T, J, 4) ``wxyz``,
        body angular velocities (T, J, 3) [rad/s], all in the world frame.
    """
    T = qpos.shape[0]
    body_ids = np.asarray(body_ids)
    site_ids = np.asarray(site_ids)
    has_site = site_ids >= 0
    root_of = model.body_rootid[body_ids]
    xpos = np.empty((T, model.nbody, 3))
    xquat = np.empty((T, model.nbody, 4))
    site_xpos = np.empty((T, model.nsite, 3))
    cvel = np.empty((T, model.nbody, 6))  # [angular; linear] at the subtree com of the root body
    com = np.empty((T, model.nbody, 3))
    for t in range(T):
        data.qpos[:] = qpos[t]
        data.qvel[:] = qvel[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        xpos[t] = data.xpos
        xquat[t] = data.xquat
        site_xpos[t] = data.site_xpos
        cvel[t] = data.cvel
        com[t] = data.subtree_com
    pos = xpos[:, body_ids]
    pos[:, has_site] = site_xpos[:, site_ids[has_site]]
    v = cvel[:, body_ids]
    vel = v[..., 3:] + np.cross(v[..., :3], pos - com[:, root_of])
    return pos, vel, xquat[:, body_ids], v[..., :3]
