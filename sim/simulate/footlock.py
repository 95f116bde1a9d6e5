"""Foot locking: a reference whose stance soles stand still, flat on the floor.

The IK fits the tracker follows let a stance foot slide (median 160 mm/s on the CMU clips) and
stamp through the floor (down to -8 cm); the simulated body, whose soles grip, then has to
skate or trip to follow them. Here each sole's stance intervals (the lowest corner of its box
within ``reference.STANCE_GAP``) are held at one pose each, on the floor: its horizontal
position and yaw the interval's mean, its bottom flat at z = 0; the leg's six hinges (hip,
knee, ankle) are solved for that pose by damped Gauss-Newton, and their change from the
captured angles is blended out over :data:`BLEND_S` into the swing either side. The root, the
other leg and the rest of the body stay as they are. After Kovar, Schreiner & Gleicher,
"Footskate cleanup for motion capture editing" (SCA 2002).
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.simulate.model import CONTROL_HZ, SOLE_GEOMS

#: [m] a sole box whose lowest corner is at most this high is in stance (``reference.STANCE_GAP``)
LOCK_GAP = 0.03
#: [m/s] a stance interval starts at its first frame and ends at its last where the sole's centre
#: moves horizontally slower than this (touch-down and push-off are left to the blend)
LOCK_SPEED = 0.5
#: [s] shorter locked intervals are left as they are
MIN_LOCK_S = 0.05
#: [s] the legs' change is blended out over this much swing either side of a stance interval
BLEND_S = 0.1
#: the leg hinges solved per side (hip 3, knee 1, ankle 2): the sole's six degrees of freedom
LEG_JOINTS = ("femur_rz", "femur_ry", "femur_rx", "tibia_rx", "foot_rz", "foot_rx")
LOCK_ITERATIONS = 10
LOCK_DAMPING = 1e-3  # [m^2] Levenberg damping of the Gauss-Newton steps
LOCK_MAX_STEP = 0.3  # [rad] largest joint step per iteration
LOCK_TOLERANCE = 1e-5  # [m] or [rad]: converged
#: [m] or [rad] a locked pose the leg misses by more (out of its reach: the root has moved on
#: at push-off, or the captured knee is straight) ends the interval there: it is trimmed to its
#: first and last frames within reach, the rest left to the blend
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


def _solve_leg(model, data, g, body, dofs, adr, lo, hi, q, target) -> np.ndarray:
    """Leg angles (6,) from ``q`` (6,) that put sole ``g`` at ``target`` = (centre (3,),
    rotation (3, 3)), by damped Gauss-Newton within the hinges' ranges, and the largest
    remaining error [m or rad]; ``data.qpos`` holds the frame's other coordinates."""
    centre, R_t = target
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))

    def error(q):
        data.qpos[adr] = q
        mujoco.mj_kinematics(model, data)
        R = data.geom_xmat[g].reshape(3, 3)
        return np.concatenate([centre - data.geom_xpos[g], 0.5 * np.cross(R, R_t, axis=0).sum(1)])

    e, damping = error(q), LOCK_DAMPING
    for _ in range(LOCK_ITERATIONS):
        if np.abs(e).max() < LOCK_TOLERANCE:
            return q, float(np.abs(e).max())
        mujoco.mj_comPos(model, data)
        mujoco.mj_jac(model, data, jacp, jacr, data.geom_xpos[g], body)
        J = np.vstack([jacp[:, dofs], jacr[:, dofs]])
        step = np.linalg.solve(J.T @ J + damping * np.eye(len(dofs)), J.T @ e)
        step *= min(1.0, LOCK_MAX_STEP / max(np.abs(step).max(), 1e-12))
        q1 = np.clip(q + step, lo, hi)
        e1 = error(q1)
        if e1 @ e1 < e @ e:  # Levenberg-Marquardt: a better step is taken, damping eased
            q, e, damping = q1, e1, damping / 4
        else:  # out of reach or past a joint limit: shorter steps
            damping *= 8
            error(q)  # data back at q for the next Jacobian
    return q, float(np.abs(e).max())


def _lock_interval(model, data, qpos: np.ndarray, leg, target):
    """The leg's angle changes over one stance interval's frames ``qpos`` (n, nq) that hold
    its sole at ``target`` (:func:`_solve_leg`; ``leg`` = its sole geom, body, dof and qpos
    addresses, ranges), each frame warm-started by the previous one's change: (the first
    frame within :data:`LOCK_REACH`, (m, 6) the changes from it to the last such frame), or
    None where fewer than :data:`MIN_LOCK_S` of frames are within reach."""
    g, body, dofs, adr, lo, hi = leg
    prev, miss, delta = np.zeros(len(adr)), np.empty(len(qpos)), np.empty((len(qpos), len(adr)))
    for t, q0 in enumerate(qpos):
        data.qpos[:] = q0
        start = np.clip(q0[adr] + prev, lo, hi)
        q, miss[t] = _solve_leg(model, data, g, body, dofs, adr, lo, hi, start, target)
        delta[t] = prev = q - q0[adr]
    reach = np.flatnonzero(miss <= LOCK_REACH)
    if len(reach) == 0 or reach[-1] + 1 - reach[0] < MIN_LOCK_S * CONTROL_HZ:
        return None
    return int(reach[0]), delta[reach[0] : reach[-1] + 1]


def _ramp(n: int) -> np.ndarray:
    """(n,) weights from 1 down towards 0 (smoothstep), the first below 1."""
    x = np.arange(1, n + 1) / (n + 1)
    return 1.0 - x * x * (3.0 - 2.0 * x)


def lock_leg(model, qpos: np.ndarray, side: str, rate: float) -> np.ndarray:
    """A copy of ``qpos`` (T, nq, floor at z = 0, at ``rate`` [Hz]) with leg ``side`` ("l" or
    "r") locked (module docstring); the other coordinates unchanged."""
    g = model.geom(f"{side}sole").id
    body = int(model.geom_bodyid[g])
    jids = [model.joint(f"{side}{j}").id for j in LEG_JOINTS]
    adr = model.jnt_qposadr[jids]
    dofs = model.jnt_dofadr[jids]
    lo, hi = model.jnt_range[jids, 0], model.jnt_range[jids, 1]
    data = mujoco.MjData(model)
    T = len(qpos)
    centres, rots, low = np.empty((T, 3)), np.empty((T, 3, 3)), np.empty(T)
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        centres[t], rots[t], low[t] = _sole_pose(model, data, g)
    delta = np.zeros((T, len(adr)))  # the leg angles' change
    weight = np.zeros(T)
    half = float(model.geom_size[g, 2])
    n = max(1, int(round(BLEND_S * rate)))
    for a, b in lock_intervals(low, centres, rate):
        target = _locked_targets(centres, rots, a, b, half)
        solved = _lock_interval(model, data, qpos[a:b], (g, body, dofs, adr, lo, hi), target)
        if solved is None:  # out of reach throughout: left as it was
            continue
        first, d = solved
        a, b = a + first, a + first + len(d)
        delta[a:b], weight[a:b] = d, 1.0
        for edge, frames in ((a, np.arange(a - 1, a - n - 1, -1)), (b - 1, np.arange(b, b + n))):
            for t, w in zip(frames, _ramp(n), strict=True):  # blended out into the swing
                if 0 <= t < T and weight[t] < 1.0:
                    delta[t] += w * delta[edge]
                    weight[t] += w
    out = qpos.copy()
    out[:, adr] = np.clip(qpos[:, adr] + delta, lo, hi)
    changed = weight > 0
    out[~changed, :] = qpos[~changed, :]  # swing frames far from stance exactly as they were
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
