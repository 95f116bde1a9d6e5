"""Rotation helpers over arrays: Euler angles and matrices (quaternions: ``sim.model.quaternion``).

All functions broadcast over leading axes. Angles in radians unless a name says ``deg``.
"""

from __future__ import annotations

import numpy as np

from sim.errors import UsageError
from sim.model.angles import wrap_angle

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


def euler_twin(angles: np.ndarray) -> np.ndarray:
    """(..., 3) the other Euler triple of the same rotation: ``(a + pi, pi - b, c + pi)`` [rad].

    For three distinct axes applied in order (``R = R_k(c) R_j(b) R_i(a)``) the two triples give
    one matrix: ``R_k(pi) R_j(pi - b) R_i(pi) = R_j(b)``, because a half-turn about k reverses
    axis j and ``R_k(pi) R_i(pi) = R_j(pi)``. Applying it twice gives back ``angles`` + 2 pi.
    """
    a = np.asarray(angles, dtype=np.float64)
    return np.stack([a[..., 0] + np.pi, np.pi - a[..., 1], a[..., 2] + np.pi], axis=-1)


#: Largest step [rad] of any one angle across which :func:`continuous_euler` keeps a path
#: continuous: beyond it, even the nearest equivalent triple is that far away, so the rotation
#: itself jumped (or spun about a gimbal-locked axis) and there is no continuity to keep.
EULER_BREAK = 0.5 * np.pi


def continuous_euler(angles: np.ndarray, order: str) -> np.ndarray:
    """(T, k) the rotations of ``angles`` with every angle continuous along axis 0 [rad].

    ``angles[t, i]`` [rad] turns about axis ``order[i]`` (the first applied first, as in
    :func:`euler_matrix`; ``k = len(order)`` distinct axes, 1 to 3). A stream of Euler triples can
    jump to the twin of the same rotation (:func:`euler_twin`, three axes only) or by whole turns
    while the rotation moves smoothly. Each frame here takes, among the file's triple and its twin
    and all their 2 pi shifts, the one nearest (in the sum of squared angle steps) to the frame
    before. Where even that one is more than :data:`EULER_BREAK` away in some angle the rotation
    itself jumped, and the path is cut there. Of the variants of each piece (itself or its twin,
    shifted by whole turns) the one equal to ``angles`` on the most frames is returned, so only
    frames that flipped change, each by a rotation-preserving move: ``euler_matrix`` of the
    result equals that of ``angles`` to rounding.

    A pure function of ``angles``: no frame rate, no limits. T = 0 or 1 is returned unchanged.
    """
    a = np.asarray(angles, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != len(order):
        raise UsageError(f"angles must be (T, {len(order)}); got {a.shape}")
    T, k = a.shape
    if T < 2:
        return a.copy()
    branch = np.zeros(T, dtype=bool)  # True: the frame's twin is on the path
    raw = np.abs(np.diff(a, axis=0)).max()  # below pi: no whole turn to take out
    step = np.abs(wrap_angle(np.diff(a, axis=0)))
    if k == 3:
        # the twin of a frame is as far from the frame before as it is from that frame's twin
        twin_step = np.abs(wrap_angle(euler_twin(a[1:]) - a[:-1]))
        flip = (twin_step**2).sum(axis=1) < (step**2).sum(axis=1)
        if not flip.any() and raw < np.pi:
            return a.copy()  # nothing flipped, nothing wrapped
        step = np.where(flip[:, None], twin_step, step)
        branch[1:] = np.cumsum(flip) % 2 == 1
        rep = np.where(branch[:, None], euler_twin(a), a)
    elif raw < np.pi:
        return a.copy()
    else:
        rep = a
    # whole turns: each step taken the short way, the count of turns kept an exact integer
    path = rep[0] + np.concatenate(
        [np.zeros((1, k)), np.cumsum(wrap_angle(np.diff(rep, axis=0)), axis=0)]
    )
    path = rep + 2 * np.pi * np.round((path - rep) / (2 * np.pi))
    # per piece, the variant agreeing with the file on most frames: per frame, which variant and
    # which whole turns would give its own triple back; ties go to the variant met first
    piece = np.concatenate([[0], np.cumsum(step.max(axis=1) > EULER_BREAK)])
    twin = euler_twin(path) if k == 3 else path
    mine = np.where(branch[:, None], twin, path)
    keys = np.column_stack([piece, branch, np.round((a - mine) / (2 * np.pi))])
    uniq, first, inverse, counts = np.unique(
        keys, axis=0, return_index=True, return_inverse=True, return_counts=True
    )
    inverse = inverse.reshape(-1)
    ranked = np.lexsort((first, -counts, uniq[:, 0]))  # by piece, most frames, first met
    leads = ranked[np.r_[True, np.diff(uniq[ranked, 0]) != 0]]  # each piece's best key
    best = leads[np.searchsorted(uniq[leads, 0], piece)]  # (T,) the key each frame follows
    out = np.where(uniq[best, 1:2] == 1, twin, path) + 2 * np.pi * uniq[best, 2:]
    agree = inverse == best
    out[agree] = a[agree]  # frames that did not flip keep the file's numbers exactly
    return out
