"""The inverse of the spherical chart (:mod:`sidql.keyframes.spherical`): points, velocities and
accelerations rebuilt down the tree from bone angles and their rates, and a whole protocol clip
made from a chart (synthetic motion, tests).

Units: metres, seconds, radians; the chart in CMU axes (y up), the points rebuilt in world axes
(z up).
"""

from __future__ import annotations

import numpy as np

from sidql.keyframes.spherical import (
    POINTS,
    chart_to_world,
    direction_rates,
    directions,
    protocol_parent_indices,
)
from sim.model import quaternion as quat
from sim.motion.clip import Clip


def positions_from_chart(
    root_pos_c: np.ndarray,
    root_vel_c: np.ndarray,
    theta: np.ndarray,
    phi: np.ndarray,
    dtheta: np.ndarray,
    dphi: np.ndarray,
    lengths: np.ndarray,
    parents: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of the M+1 points rebuilt down the tree from bone angles.

    Args:
        root_pos_c, root_vel_c: (N, 3) root position [m] / velocity [m/s], CMU axes.
        theta, phi, dtheta, dphi: (N, M) bone angles [rad] and rates [rad/s].
        lengths: (M,) bone lengths [m]; parents: (M+1,) parents, every parent before its child.

    Returns:
        (N, M+1, 3) positions [m] and (N, M+1, 3) velocities [m/s], world axes (z up). Every
        bone has exactly its given length.
    """
    N, M = theta.shape
    u = directions(theta, phi) * lengths[None, :, None]
    du = direction_rates(theta, phi, dtheta, dphi) * lengths[None, :, None]
    P = np.empty((N, M + 1, 3))
    V = np.empty((N, M + 1, 3))
    P[:, 0], V[:, 0] = root_pos_c, root_vel_c
    for j in range(1, M + 1):
        P[:, j] = P[:, parents[j]] + u[:, j - 1]
        V[:, j] = V[:, parents[j]] + du[:, j - 1]
    return chart_to_world(P), chart_to_world(V)


def direction_accelerations(theta, phi, dtheta, dphi, ddtheta, ddphi) -> np.ndarray:
    """(..., 3) second time derivative [1/s^2] of :func:`directions` given angle rates [rad/s]
    and their rates [rad/s^2]."""
    st, ct = np.sin(theta), np.cos(theta)
    sp, cp = np.sin(phi), np.cos(phi)
    d_t = np.stack([ct * cp, ct * sp, -st], axis=-1)  # d/d theta
    d_p = np.stack([-st * sp, st * cp, np.zeros_like(st)], axis=-1)  # d/d phi
    d_tt = -np.stack([st * cp, st * sp, ct], axis=-1)
    d_tp = np.stack([-ct * sp, ct * cp, np.zeros_like(st)], axis=-1)
    d_pp = np.stack([-st * cp, -st * sp, np.zeros_like(st)], axis=-1)
    tt, pp = dtheta[..., None], dphi[..., None]
    return (
        d_tt * tt**2 + 2 * d_tp * tt * pp + d_pp * pp**2
        + d_t * ddtheta[..., None] + d_p * ddphi[..., None]
    )  # fmt: skip


def accelerations_from_chart(
    root_acc_c: np.ndarray,
    theta: np.ndarray,
    phi: np.ndarray,
    dtheta: np.ndarray,
    dphi: np.ndarray,
    ddtheta: np.ndarray,
    ddphi: np.ndarray,
    lengths: np.ndarray,
    parents: np.ndarray,
) -> np.ndarray:
    """(N, M+1, 3) point accelerations [m/s^2], world axes (z up), of the points
    :func:`positions_from_chart` rebuilds, from the root's acceleration (N, 3) [m/s^2] in CMU
    axes and the bone angles, rates and their rates (N, M) [rad, rad/s, rad/s^2]."""
    N, M = theta.shape
    ddu = direction_accelerations(theta, phi, dtheta, dphi, ddtheta, ddphi)
    ddu = ddu * lengths[None, :, None]
    A = np.empty((N, M + 1, 3))
    A[:, 0] = root_acc_c
    for j in range(1, M + 1):
        A[:, j] = A[:, parents[j]] + ddu[:, j - 1]
    return chart_to_world(A)


def clip_from_chart(
    theta: np.ndarray,
    phi: np.ndarray,
    dtheta: np.ndarray,
    dphi: np.ndarray,
    root_pos_c: np.ndarray,
    root_vel_c: np.ndarray,
    lengths: np.ndarray,
    fps: float,
    source: str = "",
) -> Clip:
    """A 23-point clip (the CMU protocol tree) whose chart is the given one: the inverse of
    :func:`chart`, for synthetic motion and tests.

    Args:
        theta, phi, dtheta, dphi: (N, 22) bone angles [rad] and their exact rates [rad/s].
        root_pos_c, root_vel_c: (N, 3) root position [m] / velocity [m/s] in CMU axes.
        lengths: (22,) bone lengths [m]; fps: frame rate [1/s].

    Returns:
        A Clip with names :data:`POINTS`, positions/velocities in world axes, and local rotations
        consistent with them: the world rotation of bone m's body is ``A Rz(phi) Ry(theta) A^T``
        (A = :data:`sim.model.rotations.Y_UP_TO_Z_UP`), so the bone is that rotation applied to ``(0, -r_m, 0)``
        (the CMU z axis in world axes); the root's orientation is the identity.
    """
    parents = protocol_parent_indices()
    lengths = np.asarray(lengths, dtype=float)
    P, V = positions_from_chart(
        np.asarray(root_pos_c, float),
        np.asarray(root_vel_c, float),
        theta,
        phi,
        dtheta,
        dphi,
        lengths,
        parents,
    )
    N = theta.shape[0]
    q_a = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0])  # rotation taking chart->world
    q_c = quat.mul(quat.rot_z(phi), quat.rot_y(theta))  # (N, M, 4) in chart axes
    q_w = quat.mul(quat.mul(q_a, q_c), quat.conj(q_a))
    world = np.concatenate([np.tile([1.0, 0.0, 0.0, 0.0], (N, 1, 1)), q_w], axis=1)
    local = world.copy()
    local[:, 1:] = quat.mul(quat.conj(world[:, parents[1:]]), world[:, 1:])
    qpos = np.concatenate([P[:, 0], np.tile([1.0, 0.0, 0.0, 0.0], (N, 1))], axis=1)
    qvel = np.concatenate([V[:, 0], np.zeros((N, 3))], axis=1)
    return Clip(
        names=POINTS,
        parents=parents,
        positions=P,
        velocities=V,
        qpos=qpos,
        qvel=qvel,
        rotations=local,
        fps=float(fps),
        source=source,
    )
