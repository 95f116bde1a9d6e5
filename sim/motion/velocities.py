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


#: Derivatives of the original's points from its source frames: a local polynomial of degree
#: SOURCE_DEGREE through SOURCE_WINDOW source samples around each frame (at CMU's 120 fps, 17
#: samples = +-67 ms, two 30 fps frames either side; shifted inward at a take's ends). Its gain
#: (:func:`local_polynomial_gain`) on an acceleration is 1.00 up to 3 Hz, 0.975 at 5 Hz and 0.72
#: at 10 Hz (velocity: 0.994, 0.96, 0.59); an impulse spreads over +-2 frames at 30 fps and no
#: further. Marker noise is why it is not the exact 3-sample difference: at 120 Hz a second
#: difference turns 1 mm of noise into ~35 m/s^2.
SOURCE_WINDOW, SOURCE_DEGREE = 17, 4


def local_polynomial_weights(k: int, where: int, h: float, degree: int) -> np.ndarray:
    """(2, k) weights giving the first and second derivative at sample ``where`` of ``k`` samples
    ``h`` [s] apart from the least-squares polynomial of ``degree`` through them."""
    x = (np.arange(k) - where) * h
    V = np.vander(x, degree + 1, increasing=True)
    coef = np.linalg.pinv(V)
    return np.stack([coef[1], 2 * coef[2] if degree >= 2 else 0 * coef[1]])


def local_polynomial_gain(freq, fps: float, k: int = SOURCE_WINDOW, degree: int = SOURCE_DEGREE):
    """(velocity, acceleration) gains of the centred local polynomial on a sinusoid of
    frequency ``freq`` [Hz] sampled at ``fps``: 1 where it differentiates exactly."""
    f = np.atleast_1d(np.asarray(freq, dtype=np.float64))
    W = local_polynomial_weights(k, k // 2, 1.0 / fps, degree)
    t = (np.arange(k) - k // 2) / fps
    w = 2 * np.pi * f[:, None]
    vel = (W[0] * np.sin(w * t)).sum(axis=1) / w[:, 0]
    acc = -(W[1] * np.cos(w * t)).sum(axis=1) / w[:, 0] ** 2
    return vel, acc


def point_derivatives(
    positions: np.ndarray,
    fps: float,
    frames: np.ndarray | None = None,
    *,
    window: int = SOURCE_WINDOW,
    degree: int = SOURCE_DEGREE,
) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations (F, J, 3) [m/s, m/s^2] at ``frames`` of points
    ``positions`` (T, J, 3) [m] sampled at ``fps``, by the local polynomial of
    :data:`SOURCE_WINDOW` (fewer than 3 samples: zeros). Positions, unlike joint angles, are
    smooth through the Euler-angle flips of some AMC files."""
    p = np.asarray(positions, dtype=np.float64)
    T = p.shape[0]
    frames = np.arange(T) if frames is None else np.asarray(frames)
    vel = np.zeros((len(frames),) + p.shape[1:])
    acc = np.zeros_like(vel)
    k = min(window, T)
    if k < 3:
        return vel, acc
    degree = min(degree, k - 1)
    lo = np.clip(frames - k // 2, 0, T - k)
    weights = {w: local_polynomial_weights(k, w, 1.0 / fps, degree) for w in np.unique(frames - lo)}
    for w, W in weights.items():
        sel = np.flatnonzero(frames - lo == w)
        stack = p[lo[sel][:, None] + np.arange(k)]  # (n, k, J, 3)
        vel[sel] = np.einsum("k,nkjc->njc", W[0], stack)
        acc[sel] = np.einsum("k,nkjc->njc", W[1], stack)
    return vel, acc


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
