"""Keyframes by inter-frame pitch (Li, Hou and Gan 2015, "Extraction of Motion Key-frame Based on
Inter-frame Pitch", Computer Engineering).

* Distance between frames a and b: the sum over joints of the angle of the rotation between their
  local rotation quaternions, ``2 atan2(|vec(q_a^-1 q_b)|, |w(q_a^-1 q_b)|)``, which is the same for
  ``q`` and ``-q``. The joints are the bodies of the 23 protocol points (root orientation included).
* Selection: frame 0 is a keyframe; scanning forward, a frame becomes a keyframe when its distance
  to the last keyframe exceeds a threshold. Our protocol also keeps the last frame.
* For a fixed keyframe count W we search the threshold: every distinct pairwise distance is a
  candidate (the count only changes there) and we take the largest threshold giving exactly W.
  When no threshold gives exactly W (the count can jump), we take the largest count below W and
  top it up with the frame farthest (in pitch) from its preceding keyframe, repeatedly.
* Reconstruction: slerp of every joint's local rotation between keyframes, the root position
  linear, points rebuilt by forward kinematics with constant offsets fitted to the clip.
* Error: the paper's abstract defines it as pose position error plus motion speed error; only the
  abstract is available to us, so we read it as the mean over frames and the 23 points of
  ``|p - p~|`` [m] plus the same mean of ``|dp - dp~|`` [m per frame], with ``dp`` the frame-to-frame
  displacement (equal weights).

Pure numpy (numba for the threshold scan). Quaternions ``wxyz``; metres, seconds, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from sidql.keyframes.curves import validate_keyframes
from sidql.keyframes.spherical import protocol_indices, protocol_parents
from sim.errors import MotionDataError, UsageError
from sim.model import quaternion as quat
from sim.motion.clip import Clip


@dataclass(frozen=True)
class Rig:
    """Forward kinematics of the 23 protocol points from local rotations.

    ``R_j = R_parent(j) * q_j`` (root: ``R_0 = q_0``) and
    ``p_j = p_parent(j) + R_parent(j) o_j + R_j d_j`` (root: the root position).

    Attributes:
        parents: (23,) parent indices into :data:`sidql.keyframes.spherical.POINTS`.
        origin: (23, 3) offset o_j [m] of body j's origin from its parent point, parent frame.
        offset: (23, 3) offset d_j [m] of point j from body j's origin, body j's frame.
    """

    parents: np.ndarray
    origin: np.ndarray
    offset: np.ndarray


def world_rotations(local: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(N, J, 4) world rotations from (N, J, 4) local ones (parents before children)."""
    world = np.empty_like(local)
    world[:, 0] = local[:, 0]
    for j in range(1, local.shape[1]):
        world[:, j] = quat.mul(world[:, parents[j]], local[:, j])
    return world


def fit_rig(positions: np.ndarray, local: np.ndarray, parents: np.ndarray) -> tuple[Rig, float]:
    """Least-squares constant offsets that rebuild ``positions`` from ``local`` rotations.

    Args:
        positions: (N, 23, 3) point positions [m]; local: (N, 23, 4) local rotations (wxyz);
        parents: (23,) parent indices.

    Returns:
        The :class:`Rig` and the largest residual [m] of ``p_j - p_parent`` over frames and points
        (about 1e-12 for positions that come from these rotations).
    """
    world = world_rotations(local, parents)
    J = len(parents)
    child = np.arange(1, J)
    par = np.asarray(parents)[child]
    R = quat.to_matrix(world)  # (N, J, 3, 3)
    # p_j - p_parent = R_parent o_j + R_j d_j: 3N equations, 6 unknowns per joint (batched)
    A = np.concatenate([R[:, par], R[:, child]], axis=-1)  # (N, J-1, 3, 6)
    A = A.transpose(1, 0, 2, 3).reshape(J - 1, -1, 6)
    b = (positions[:, child] - positions[:, par]).transpose(1, 0, 2).reshape(J - 1, -1)
    x = np.einsum("jik,jk->ji", np.linalg.pinv(A, rcond=1e-10), b)  # minimum-norm least squares
    worst = float(np.abs(np.einsum("jki,ji->jk", A, x) - b).max())
    origin = np.zeros((J, 3))
    offset = np.zeros((J, 3))
    origin[child], offset[child] = x[:, :3], x[:, 3:]
    return Rig(parents=np.asarray(parents, np.int64), origin=origin, offset=offset), worst


def forward(rig: Rig, root_pos: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 23, 3) positions [m] and (N, 23, 4) world rotations from root positions (N, 3) [m]
    and local rotations (N, 23, 4)."""
    world = world_rotations(local, rig.parents)
    P = np.empty(local.shape[:2] + (3,))
    P[:, 0] = root_pos
    for j in range(1, local.shape[1]):
        p = rig.parents[j]
        P[:, j] = (
            P[:, p]
            + quat.rotate(world[:, p], rig.origin[j])
            + quat.rotate(world[:, j], rig.offset[j])
        )
    return P, world


def protocol_rotations(clip: Clip) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 23, 3) positions [m], (N, 23, 4) local rotations and (23,) parents of the protocol
    points of ``clip``."""
    idx = protocol_indices(clip)
    try:
        parents = protocol_parents(clip.names, clip.parents)
    except MotionDataError as e:
        raise MotionDataError(clip.source or None, None, e.problem) from None
    return clip.positions[:, idx], clip.rotations[:, idx], parents


def pitch_distances(local: np.ndarray) -> np.ndarray:
    """(N, N) inter-frame pitch [rad]: sum over joints of the rotation angle between frames.

    Args:
        local: (N, J, 4) local joint rotations (wxyz, unit; q and -q give the same distance).

    The angle between unit quaternions a and b is ``2 arccos |a . b|`` (accurate to about 1e-8
    rad near zero, ample for thresholding).
    """
    dots = np.abs(np.einsum("ajk,bjk->abj", local, local))
    return (2.0 * np.arccos(np.minimum(dots, 1.0))).sum(axis=-1)


@numba.njit(cache=True)
def _scan(D, tau):
    N = D.shape[0]
    keys = np.zeros(N, dtype=np.int64)
    count = 1
    last = 0
    for n in range(1, N):
        if D[n, last] > tau:
            keys[count] = n
            count += 1
            last = n
    if keys[count - 1] != N - 1:
        keys[count] = N - 1
        count += 1
    return keys[:count]


@numba.njit(cache=True)
def _counts(D, taus):
    out = np.empty(len(taus), dtype=np.int64)
    for t in range(len(taus)):
        out[t] = len(_scan(D, taus[t]))
    return out


def threshold_keyframes(D: np.ndarray, tau: float) -> np.ndarray:
    """Keyframes of the threshold rule (plus the last frame) for pitch matrix D and threshold
    ``tau`` [rad]."""
    return _scan(np.ascontiguousarray(D, dtype=np.float64), float(tau))


def keyframes_for_count(D: np.ndarray, W: int) -> tuple[np.ndarray, float]:
    """(W,) keyframes of the threshold rule for the threshold [rad] searched to give W of them.

    Returns the keyframes and the threshold used (see the module docstring for the fall-back).
    """
    D = np.ascontiguousarray(D, dtype=np.float64)
    N = D.shape[0]
    if not 2 <= W <= N:
        raise UsageError(f"W must be in [2, {N}]; got {W}")
    cand = np.unique(D[np.triu_indices(N, 1)])
    taus = np.concatenate([[-1.0], cand])  # -1: every frame is a keyframe
    counts = _counts(D, taus)
    exact = np.flatnonzero(counts == W)
    if len(exact):
        tau = float(taus[exact[-1]])
        return _scan(D, tau), tau
    below = np.flatnonzero(counts < W)
    t = below[np.argmax(counts[below])] if len(below) else len(taus) - 1
    t = below[counts[below] == counts[t]][-1] if len(below) else t
    tau = float(taus[t])
    keys = list(_scan(D, tau))
    while len(keys) < W:
        ks = np.array(sorted(keys))
        n = np.arange(N)
        prev = ks[np.clip(np.searchsorted(ks, n, side="right") - 1, 0, len(ks) - 1)]
        gap = D[n, prev]
        gap[ks] = -np.inf
        keys.append(int(np.argmax(gap)))
    return np.array(sorted(keys), dtype=np.int64), tau


def _segments(keyframes: np.ndarray, N: int):
    n = np.arange(N)
    seg = np.clip(np.searchsorted(keyframes, n, side="right") - 1, 0, len(keyframes) - 2)
    a, b = keyframes[seg], keyframes[seg + 1]
    return seg, a, b, (n - a) / (b - a)


def _slerp_points(rig: Rig, root: np.ndarray, local: np.ndarray, a, b, s, dt: float):
    """Positions, velocities and accelerations (n, 23, 3) of the slerp reconstruction at ``n``
    instants, the instant ``i`` a share ``s[i]`` of the way through the segment from keyframe
    ``a[i]`` to keyframe ``b[i]`` (frame indices). Within a segment every local rotation turns at a
    constant rate ``w`` in its body's frame (``log(q_a^-1 q_b) / h``), so a body's world angular
    acceleration is its parent's plus ``Om x (R w)``, and the root moves at a constant velocity."""
    h = (b - a) * dt
    root_rec = root[a] + s[:, None] * (root[b] - root[a])
    slope = (root[b] - root[a]) / h[:, None]
    local_rec = quat.slerp(local[a], local[b], s[:, None])
    omega = quat.log(quat.mul(quat.conj(local[a]), local[b])) / h[:, None, None]
    P, world = forward(rig, root_rec, local_rec)
    rel = quat.rotate(world, omega)  # each body's rate relative to its parent, world axes
    Om, Al = rel.copy(), np.zeros_like(rel)
    V, A = np.empty_like(P), np.empty_like(P)
    V[:, 0], A[:, 0] = slope, 0.0
    Al[:, 0] = quat.cross(Om[:, 0], rel[:, 0])  # = 0: the root's own rate is constant
    for j in range(1, len(rig.parents)):
        p = rig.parents[j]
        Om[:, j] = Om[:, p] + rel[:, j]
        Al[:, j] = Al[:, p] + quat.cross(Om[:, j], rel[:, j])
        r1 = quat.rotate(world[:, p], rig.origin[j])
        r2 = quat.rotate(world[:, j], rig.offset[j])
        V[:, j] = V[:, p] + quat.cross(Om[:, p], r1) + quat.cross(Om[:, j], r2)
        A[:, j] = (
            A[:, p]
            + quat.cross(Al[:, p], r1) + quat.cross(Om[:, p], quat.cross(Om[:, p], r1))
            + quat.cross(Al[:, j], r2) + quat.cross(Om[:, j], quat.cross(Om[:, j], r2))
        )  # fmt: skip
    return P, V, A


def slerp_points(
    clip: Clip, keyframes, rig: Rig | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Li et al. 2015 reconstruction of ``clip``'s 23 protocol points from its keyframes (the
    ``slerp`` reconstruction of :mod:`sidql.keyframes.reconstructions`).

    Local rotations are slerped between keyframes (shorter arc), the root position interpolated
    linearly, and points rebuilt by forward kinematics with offsets fitted to the clip (or the
    given ``rig``, from :func:`fit_rig`, to save refitting).

    Returns:
        Positions, velocities and accelerations (N, 23, 3) world z-up [m, m/s, m/s^2], the
        exact derivatives of the interpolants (at an inner keyframe, where the rates jump, the
        velocity is the mean of both sides and the acceleration the mean of both sides' plus
        the velocity's jump spread over the frame, ``(a(t-) + a(t+)) / 2 + (v(t+) - v(t-)) /
        dt``, an impulse), and the (23,) parent indices.
    """
    pos, local, parents = protocol_rotations(clip)
    N = clip.n_frames
    k = validate_keyframes(keyframes, N)
    dt = clip.dt
    if rig is None:
        rig, _ = fit_rig(pos, local, parents)
    _, a, b, s = _segments(k, N)
    root = pos[:, 0]
    P, V, A = _slerp_points(rig, root, local, a, b, s, dt)
    inner = k[1:-1]
    if len(inner):
        nxt = k[np.searchsorted(k, inner) + 1]
        prv = k[np.searchsorted(k, inner) - 1]
        one = np.ones(len(inner))
        _, v_at, _ = _slerp_points(rig, root, local, prv, inner, one, dt)
        _, v_right, _ = _slerp_points(rig, root, local, inner, nxt, 0.5 / (nxt - inner), dt)
        _, v_left, _ = _slerp_points(rig, root, local, prv, inner, 1 - 0.5 / (inner - prv), dt)
        V[inner] = 0.5 * (V[inner] + v_at)
        A[inner] = (v_right - v_left) / dt
    return P, V, A, parents


def pitch_error(true_pos: np.ndarray, rec_pos: np.ndarray) -> float:
    """Li et al.'s reconstruction error as we read it: mean |p - p~| [m] plus mean |dp - dp~|
    [m per frame] over frames and points, ``dp`` the frame-to-frame displacement.

    Args:
        true_pos, rec_pos: (N, J, 3) positions [m].
    """
    pose = np.linalg.norm(rec_pos - true_pos, axis=-1).mean()
    speed = np.linalg.norm(np.diff(rec_pos, axis=0) - np.diff(true_pos, axis=0), axis=-1).mean()
    return float(pose + speed)
