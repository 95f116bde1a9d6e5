"""Rotation helpers over arrays: Euler angles and matrices (quaternions: ``sim.model.quaternion``).

All functions broadcast over leading axes. Angles in radians unless a name says ``deg``.
"""

from __future__ import annotations

import numpy as np

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def axis_rotation(axis: str, angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices about ``axis`` ('X', 'Y' or 'Z') by ``angle`` [rad]."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (3, 3))
    i = _AXIS[axis.upper()]
    j, k = (i + 1) % 3, (i + 2) % 3
    R[..., i, i] = 1.0
    R[..., j, j] = c
    R[..., k, k] = c
    R[..., j, k] = -s
    R[..., k, j] = s
    return R


def euler_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """(..., 3, 3) matrix of Euler angles ``angles_deg[..., i]`` about axis ``order[i]`` [deg].

    The rotation about ``order[0]`` is applied first: for ``"XYZ"`` the result is Rz @ Ry @ Rx
    (Acclaim's convention for ``axis`` and for ``dof rx ry rz``).
    """
    angles = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    R = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for i, ax in enumerate(order):
        R = axis_rotation(ax, angles[..., i]) @ R
    return R


def euler_angles_deg(R: np.ndarray, order: str) -> np.ndarray:
    """(..., 3) Euler angles [deg] with ``euler_matrix(angles, order) == R`` (rotation about
    ``order[0]`` applied first; three distinct axes), for (..., 3, 3) rotations R. The middle
    angle is in [-90, 90] deg."""
    i, j, k = (_AXIS[c] for c in order.upper())
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    beta = np.arcsin(np.clip(-s * R[..., k, i], -1.0, 1.0))
    gamma = np.arctan2(s * R[..., j, i], R[..., i, i])
    alpha = np.arctan2(s * R[..., k, j], R[..., k, k])
    return np.degrees(np.stack([alpha, beta, gamma], axis=-1))


#: (3, 3) the one axis change: Acclaim's CMU axes (and the spherical chart's) are y up, the
#: project's world frame is z up. ``v_z_up = Y_UP_TO_Z_UP @ v_y_up``: (x, y, z) -> (x, -z, y), a
#: +90 degree rotation about x.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def y_up_to_z_up(v: np.ndarray) -> np.ndarray:
    """(..., 3) y-up vectors -> (..., 3) z-up: ``Y_UP_TO_Z_UP @ v``, as an exact permutation."""
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 0], -v[..., 2], v[..., 1]], axis=-1)


def z_up_to_y_up(v: np.ndarray) -> np.ndarray:
    """(..., 3) z-up vectors -> (..., 3) y-up: ``Y_UP_TO_Z_UP.T @ v`` = (x, z, -y)."""
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 0], v[..., 2], -v[..., 1]], axis=-1)
