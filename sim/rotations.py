"""Rotation helpers over arrays: Euler angles, matrices and unit quaternions (``wxyz``).

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


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions ``wxyz`` (w >= 0) of rotation matrices (..., 3, 3)."""
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    # Four candidate forms; take the numerically largest per element (Shepperd's method).
    t = np.stack(
        [1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22]
    )
    best = np.argmax(t, axis=0)
    q = np.empty(R.shape[:-2] + (4,))
    r = np.sqrt(np.maximum(np.take_along_axis(t, best[None], 0)[0], 1e-300))
    qs = [
        np.stack(
            [
                r,
                (R[..., 2, 1] - R[..., 1, 2]) / r,
                (R[..., 0, 2] - R[..., 2, 0]) / r,
                (R[..., 1, 0] - R[..., 0, 1]) / r,
            ],
            -1,
        ),
        np.stack(
            [
                (R[..., 2, 1] - R[..., 1, 2]) / r,
                r,
                (R[..., 0, 1] + R[..., 1, 0]) / r,
                (R[..., 0, 2] + R[..., 2, 0]) / r,
            ],
            -1,
        ),
        np.stack(
            [
                (R[..., 0, 2] - R[..., 2, 0]) / r,
                (R[..., 0, 1] + R[..., 1, 0]) / r,
                r,
                (R[..., 1, 2] + R[..., 2, 1]) / r,
            ],
            -1,
        ),
        np.stack(
            [
                (R[..., 1, 0] - R[..., 0, 1]) / r,
                (R[..., 0, 2] + R[..., 2, 0]) / r,
                (R[..., 1, 2] + R[..., 2, 1]) / r,
                r,
            ],
            -1,
        ),
    ]
    for k in range(4):
        q = np.where((best == k)[..., None], qs[k], q)
    q *= 0.5
    q = np.where(q[..., :1] < 0, -q, q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions ``wxyz`` (..., 4)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b), -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (inverse for unit quaternions) of ``wxyz`` quaternions (..., 4)."""
    return np.asarray(q) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_canonical(q: np.ndarray) -> np.ndarray:
    """Quaternions with w >= 0 (q and -q are the same rotation)."""
    q = np.asarray(q)
    return np.where(q[..., :1] < 0, -q, q)


# Acclaim's CMU axes are y up; the project's world frame is z up: (x, y, z) -> (x, -z, y),
# a +90 degree rotation about x.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
