"""Foot locking: a reference whose stance soles stand still, flat on the floor.

The IK fits the tracker follows let a stance foot slide (median 160 mm/s on the CMU clips) and
stamp through the floor (down to -8 cm); the simulated body, whose soles grip, then has to
skate or trip to follow them. Here each sole's stance intervals (the lowest corner of its box
within ``reference.STANCE_GAP``) are held at one pose each, on the floor: its horizontal
position and yaw the interval's mean, its bottom flat at z = 0; the leg's six hinges (hip,
knee, ankle) are solved for that pose by damped Gauss-Newton (the interval trimmed to its
longest run the leg reaches), and over :data:`BLEND_S` into the swing either side the sole is
carried back from that pose to the captured one, the leg solved along the way. The root, the
other leg and the rest of the body stay as they are. After Kovar, Schreiner & Gleicher,
"Footskate cleanup for motion capture editing" (SCA 2002).
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from sim.simulate.model import SOLE_GEOMS

#: [m] a sole box whose lowest corner is at most this high is in stance (``reference.STANCE_GAP``)
LOCK_GAP = 0.03
#: [m/s] a stance interval starts at its first frame and ends at its last where the sole's centre
#: moves horizontally slower than this (touch-down and push-off are left to the blend)
LOCK_SPEED = 0.5
#: [s] shorter locked intervals are left as they are
MIN_LOCK_S = 0.05
#: [s] the legs' change is blended out over this much swing either side of a stance interval
BLEND_S = 0.1
#: [s] the blend's angle changes are smoothed by a Gaussian of this scale
BLEND_SMOOTH_S = 0.02
#: the leg hinges solved per side (hip 3, knee 1, ankle 2): the sole's six degrees of freedom
LEG_JOINTS = ("femur_rz", "femur_ry", "femur_rx", "tibia_rx", "foot_rz", "foot_rx")
LOCK_ITERATIONS = 20
LOCK_DAMPING = 1e-3  # [m^2] Levenberg damping of the Gauss-Newton steps
#: [m^2 / rad^2] weight of the distance from the captured angles: the hip's twist and the
#: ankle's turn nearly share an axis when the knee is straight, and the pose alone leaves the
#: split between them to wherever the solver starts
LOCK_PRIOR = 1e-4
#: weight of the yaw (the turn about the vertical) in the locked pose's error, beside 1 for
#: its position [m] and tilt [rad]
LOCK_YAW = 1.0
LOCK_MAX_STEP = 0.3  # [rad] largest joint step per iteration
LOCK_TOLERANCE = 1e-6  # [rad] a smaller step: converged
#: [m] or [rad] a locked pose the leg misses by more (out of its reach: the root has moved on
#: at push-off, or the captured knee is straight) ends the interval there: it is trimmed to its
#: longest run of frames within reach, the rest left to the blend
LOCK_REACH = 0.003


def _sole_pose(model, data, g: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Sole box ``g``'s centre (3,), rotation (3, 3) and lowest corner height [m]."""
    R = data.geom_xmat[g].reshape(3, 3)
    size = model.geom_size[g]
    low = data.geom_xpos[g, 2] - np.abs(R[2]) @ size
    return data.geom_xpos[g].copy(), R.copy(), float(low)


def stance_intervals(stance: np.ndarray) -> list[tuple[int, int]]:
    """The runs [a, b) of True in ``stance`` (T,) bool."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], stance.astype(int), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def lock_intervals(low: np.ndarray, centres: np.ndarray, rate: float) -> list[tuple[int, int]]:
    """The intervals [a, b) a sole is locked in: its stance runs (lowest corner ``low`` (T,) [m]
    within :data:`LOCK_GAP`) trimmed at both ends to the frames where its centre ``centres``
    (T, 3) [m] moves horizontally slower than :data:`LOCK_SPEED` (a foot still swinging in
    low over the floor, or already pushing off, is not held), at least :data:`MIN_LOCK_S` long."""
    speed = np.linalg.norm(np.gradient(centres[:, :2], 1.0 / rate, axis=0), axis=-1)
    out = []
    for a, b in stance_intervals(low <= LOCK_GAP):
        slow = np.flatnonzero(speed[a:b] < LOCK_SPEED)
        if len(slow) and (slow[-1] + 1 - slow[0]) >= MIN_LOCK_S * rate:
            out.append((a + int(slow[0]), a + int(slow[-1]) + 1))
    return out


def _locked_targets(centres: np.ndarray, rots: np.ndarray, a: int, b: int, half: float):
    """The locked pose of a stance interval [a, b): centre (3,) at the interval's median
    horizontal position (the IK fits' stamps and twists are outliers), the box's half
    thickness ``half`` high (its bottom on z = 0), and rotation (3, 3) flat, turned by the
    median yaw of the box's long axis (unwrapped about the interval's circular mean)."""
    xy = np.median(centres[a:b, :2], axis=0)
    fwd = rots[a:b, :2, 0]  # the box's long axis, horizontal part
    mean = np.arctan2(fwd[:, 1].sum(), fwd[:, 0].sum())
    yaw = mean + np.median(np.angle(np.exp(1j * (np.arctan2(fwd[:, 1], fwd[:, 0]) - mean))))
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.array([xy[0], xy[1], half]), R


def _solve_leg(model, data, g, body, dofs, adr, lo, hi, q, target) -> tuple[np.ndarray, float]:
    """Leg angles (6,) from ``q`` (6,) that put sole ``g`` at ``target`` = (centre (3,),
    rotation (3, 3)), by Levenberg-Marquardt within the hinges' ranges, lightly held near the
    captured angles (:data:`LOCK_PRIOR`), and the largest remaining error [m or rad];
    ``data.qpos`` holds the captured frame."""
    centre, R_t = target
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    W = np.array([1.0, 1.0, 1.0, 1.0, 1.0, LOCK_YAW])  # the turn about the vertical weighted

    def error(q):
        data.qpos[adr] = q
        mujoco.mj_kinematics(model, data)
        R = data.geom_xmat[g].reshape(3, 3)
        rot = 0.5 * np.cross(R, R_t, axis=0).sum(1)
        return np.concatenate([centre - data.geom_xpos[g], rot]) * W

    def cost(q, e):  # the pose's error and, lightly, the distance from the captured angles
        return e @ e + LOCK_PRIOR * (q - q0) @ (q - q0)

    q0, e, damping = data.qpos[adr].copy(), error(q), LOCK_DAMPING  # the captured angles
    eye = np.eye(len(dofs))
    for _ in range(LOCK_ITERATIONS):  # to the cost's minimum, not the first pose within reach
        mujoco.mj_comPos(model, data)
        mujoco.mj_jac(model, data, jacp, jacr, data.geom_xpos[g], body)
        J = np.vstack([jacp[:, dofs], jacr[:, dofs]]) * W[:, None]
        rhs = J.T @ e - LOCK_PRIOR * (q - q0)
        step = np.linalg.solve(J.T @ J + (damping + LOCK_PRIOR) * eye, rhs)
        step *= min(1.0, LOCK_MAX_STEP / max(np.abs(step).max(), 1e-12))
        if np.abs(step).max() < LOCK_TOLERANCE:
            break
        q1 = np.clip(q + step, lo, hi)
        e1 = error(q1)
        if cost(q1, e1) < cost(q, e):  # Levenberg-Marquardt: a better step, damping eased
            q, e, damping = q1, e1, damping / 4
        else:  # out of reach or past a joint limit: shorter steps
            damping *= 8
            error(q)  # data back at q for the next Jacobian
    return q, float(np.abs(e).max())


def _solve(model, data, leg, q0: np.ndarray, start: np.ndarray, target):
    """:func:`_solve_leg` for the frame ``q0`` (nq,) from the leg angles ``start`` (6,), and
    again from the captured angles where that misses by more than :data:`LOCK_REACH` (a warm
    start can sit in a local minimum the captured pose is not in): the better (angles, miss)."""
    g, body, dofs, adr, lo, hi = leg
    data.qpos[:] = q0
    q, miss = _solve_leg(model, data, g, body, dofs, adr, lo, hi, np.clip(start, lo, hi), target)
    if miss > LOCK_REACH:
        data.qpos[:] = q0
        q1, miss1 = _solve_leg(model, data, g, body, dofs, adr, lo, hi, q0[adr], target)
        if miss1 < miss:
            q, miss = q1, miss1
    return q, miss


def _lock_interval(model, data, qpos: np.ndarray, leg, target, rate: float):
    """The leg's angles over one stance interval's frames ``qpos`` (n, nq) that hold its sole
    at ``target`` (:func:`_solve`; ``leg`` = its sole geom, body, dof and qpos addresses,
    ranges), each frame warm-started by the previous one's change: (the first frame of the
    longest run within :data:`LOCK_REACH`, (m, 6) the angles over that run), or None where
    that run is shorter than :data:`MIN_LOCK_S` (at ``rate`` [Hz])."""
    adr = leg[3]
    prev, miss, out = np.zeros(len(adr)), np.empty(len(qpos)), np.empty((len(qpos), len(adr)))
    for t, q0 in enumerate(qpos):
        out[t], miss[t] = _solve(model, data, leg, q0, q0[adr] + prev, target)
        prev = out[t] - q0[adr]
    runs = stance_intervals(miss <= LOCK_REACH)
    if not runs:
        return None
    a, b = max(runs, key=lambda r: r[1] - r[0])
    return (a, out[a:b]) if b - a >= MIN_LOCK_S * rate else None


def _between(centre, R, target, w: float):
    """The pose ``w`` of the way from (``centre`` (3,), ``R`` (3, 3)) to ``target``'s: the
    centre interpolated linearly, the rotation along its shortest arc."""
    rel = Rotation.from_matrix(target[1] @ R.T).as_rotvec()
    return centre + w * (target[0] - centre), Rotation.from_rotvec(w * rel).as_matrix() @ R


def _ramp(n: int) -> np.ndarray:
    """(n,) weights from 1 down towards 0 (smoothstep), the first below 1."""
    x = np.arange(1, n + 1) / (n + 1)
    return 1.0 - x * x * (3.0 - 2.0 * x)


def _blend_weights(locks: list, T: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame (T,): the weight of the nearest lock (1 in it, :func:`_ramp` over ``n``
    frames either side, 0 beyond), that lock's index (-1: none) and its edge frame."""
    weight, which, edge = np.zeros(T), np.full(T, -1), np.zeros(T, int)
    for i, (a, b, _, _) in enumerate(locks):
        weight[a:b], which[a:b], edge[a:b] = 1.0, i, np.arange(a, b)
        for e, frames in ((a, np.arange(a - 1, a - n - 1, -1)), (b - 1, np.arange(b, b + n))):
            for t, w in zip(frames, _ramp(n), strict=True):
                if 0 <= t < T and w > weight[t]:  # the nearer lock wins where two overlap
                    weight[t], which[t], edge[t] = w, i, e
    return weight, which, edge


def lock_leg(model, qpos: np.ndarray, side: str, rate: float) -> np.ndarray:
    """A copy of ``qpos`` (T, nq, floor at z = 0, at ``rate`` [Hz]) with leg ``side`` ("l" or
    "r") locked (module docstring): in each lock interval its sole held at the interval's
    pose; over :data:`BLEND_S` either side, the sole carried from that pose back to the
    captured one along the way between them (:func:`_between`), the leg solved for it; the
    other coordinates unchanged."""
    g = model.geom(f"{side}sole").id
    jids = [model.joint(f"{side}{j}").id for j in LEG_JOINTS]
    adr = model.jnt_qposadr[jids]
    leg = (g, int(model.geom_bodyid[g]), model.jnt_dofadr[jids], adr, *model.jnt_range[jids].T)
    mid = model.jnt_range[jids].mean(axis=1)
    turns = 2 * np.pi * np.round((qpos[:, adr] - mid) / (2 * np.pi))  # an IK fit's wrapped angle
    qpos = qpos.copy()
    qpos[:, adr] -= turns  # solved nearest its range, given back with its turns
    data = mujoco.MjData(model)
    T = len(qpos)
    centres, rots, low = np.empty((T, 3)), np.empty((T, 3, 3)), np.empty(T)
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        centres[t], rots[t], low[t] = _sole_pose(model, data, g)
    half = float(model.geom_size[g, 2])
    locks = []  # (first, end, target, angles)
    for a, b in lock_intervals(low, centres, rate):
        target = _locked_targets(centres, rots, a, b, half)
        solved = _lock_interval(model, data, qpos[a:b], leg, target, rate)
        if solved is not None:  # else out of reach throughout: left as it was
            first, angles = solved
            locks.append((a + first, a + first + len(angles), target, angles))
    out = qpos.copy()
    weight, which, edge = _blend_weights(locks, T, max(1, int(round(BLEND_S * rate))))
    for t in np.flatnonzero(weight > 0):
        a, _, target, angles = locks[which[t]]
        q_edge = angles[edge[t] - a]  # the lock's angles at its nearer end
        if weight[t] == 1.0:
            out[t, adr] = q_edge
            continue
        start = qpos[t, adr] + weight[t] * (q_edge - qpos[edge[t], adr])
        pose = _between(centres[t], rots[t], target, weight[t])
        out[t, adr] = _solve(model, data, leg, qpos[t], start, pose)[0]
    # the blend's changes smoothed (the locks' kept exact): where the pose asked is out of
    # reach, the hip's twist and the ankle's turn can trade places from one frame to the next
    blend = np.flatnonzero((weight > 0) & (weight < 1))
    delta = gaussian_filter1d(out[:, adr] - qpos[:, adr], BLEND_SMOOTH_S * rate, axis=0)
    q = qpos[np.ix_(blend, adr)]  # within the range, or no farther out than captured
    out[np.ix_(blend, adr)] = np.clip(
        q + delta[blend], np.minimum(q, leg[4]), np.maximum(q, leg[5])
    )
    out[:, adr] += turns
    return out


def foot_locked(model, qpos: np.ndarray, rate: float = 120.0) -> np.ndarray:
    """A copy of ``qpos`` (T, nq, its floor at z = 0, e.g. the contact-consistent reference) with
    both legs locked (:func:`lock_leg`): in stance each sole still, flat on z = 0. Models
    without soles come back unchanged."""
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, SOLE_GEOMS[0]) < 0:
        return qpos.copy()
    out = qpos
    for side in "lr":
        out = lock_leg(model, out, side, rate)
    return out if out is not qpos else qpos.copy()
