"""Reference motions for the tracking controller: time warps, floor placement, body scaling.

A reference is a ``qpos`` stream (T, nq) at the control rate (``sim.simulate.model.CONTROL_HZ``).
CMU's floor height varies per trial (the lowest foot point sits anywhere from -20 to +16 cm), and even drifts within
one, so a real reference is shifted vertically, frame by frame, by a running low percentile of its
lowest foot point (:func:`floor_track`). (The physics room's ground estimate can replace it.)
"""

from __future__ import annotations

import os

import mujoco
import numpy as np

from sim.acclaim.reader import parse_amc, parse_asf
from sim.errors import MotionDataError
from sim.model.humanoid import humanoid_model
from sim.motion.retarget import leg_length, motion_to_qpos
from sim.physics.feet import SOLE_POINTS


def trial_qpos(asf: str | os.PathLike, amc: str | os.PathLike) -> np.ndarray:
    """(T, nq) ``qpos`` of a CMU trial on the shared humanoid at the file's rate (120 Hz):
    angles copied, root translation scaled by the leg-length ratio (as ``load_motion`` with
    ``skeleton="humanoid"`` does, without computing the clip's kinematics).

    Raises:
        MotionDataError: malformed or unreadable files.
    """
    try:
        subject = parse_asf(asf)
    except FileNotFoundError as e:
        raise MotionDataError(str(asf), None, f"cannot read file: {e.strerror}") from e
    motion = parse_amc(amc, subject)
    target, model = humanoid_model()
    return motion_to_qpos(
        subject, motion, model, root_scale=leg_length(target) / leg_length(subject)
    )


def lowest_foot_point(model, qpos: np.ndarray) -> np.ndarray:
    """(T,) height [m] of the lowest surface point of the foot and toe capsules in each frame."""
    data = mujoco.MjData(model)
    ids = [model.geom(n).id for n in SOLE_POINTS if mujoco.mj_name2id(model, 5, n) >= 0]
    low = np.empty(len(qpos))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        z = np.inf
        for g in ids:
            c = data.geom_xpos[g, 2]
            r = model.geom_size[g, 0]
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
                half = model.geom_size[g, 1] * abs(data.geom_xmat[g, 8])
                z = min(z, c - half - r)
            else:
                z = min(z, c - r)
        low[t] = z
    return low


def floor_track(
    model, qpos: np.ndarray, rate: float, *, window: float = 1.5, percentile: float = 10.0
) -> np.ndarray:
    """(T,) floor height [m] under each frame: the ``percentile`` of the lowest foot point over a
    ``window``-second window centred on the frame, then averaged over the same window.

    CMU floors drift within a trial (02_01's stance foot rises 5 cm over 3 s), so one offset per
    trial leaves feet hovering or sunk; a running low percentile follows the stance foot.
    """
    low = lowest_foot_point(model, qpos)
    half = max(1, int(round(window * rate / 2)))
    pad = np.pad(low, half, mode="edge")
    wins = np.lib.stride_tricks.sliding_window_view(pad, 2 * half + 1)
    floor = np.percentile(wins, percentile, axis=1)
    pad = np.pad(floor, half, mode="edge")
    return np.convolve(pad, np.ones(2 * half + 1) / (2 * half + 1), mode="valid")


FLOOR_LIFT = 0.01  # [m]


def on_floor(model, qpos: np.ndarray, rate: float = 120.0, lift: float = FLOOR_LIFT) -> np.ndarray:
    """A copy of ``qpos`` shifted vertically, frame by frame, so the floor under it
    (:func:`floor_track`) is at z = -``lift``.

    The lift (1 cm) keeps a reference whose floor estimate is off by marker noise from driving
    the stiff legs into the floor or catching a toe: on 7 CMU trials it turned 2 falls into none.
    """
    out = qpos.copy()
    out[:, 2] -= floor_track(model, qpos, rate) - lift
    return out


def time_warp(model, qpos: np.ndarray, rate: float, speed: float, out_rate: float) -> np.ndarray:
    """``qpos`` sampled at ``rate`` replayed ``speed`` times faster, resampled at ``out_rate``.

    Positions and hinges are interpolated linearly; the root quaternion by slerp on the
    shortest arc. Returns (T', nq) covering the same motion.
    """
    if speed <= 0:
        raise ValueError(f"speed must be positive; got {speed}")
    T = len(qpos)
    duration = (T - 1) / rate / speed
    n = int(np.floor(duration * out_rate + 1e-9)) + 1
    s = np.arange(n) / out_rate * speed * rate  # source frame index (float)
    i0 = np.minimum(np.floor(s).astype(int), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    a = (s - i0)[:, None]
    out = (1 - a) * qpos[i0] + a * qpos[i1]
    q0, q1 = qpos[i0, 3:7], qpos[i1, 3:7]
    sign = np.where((q0 * q1).sum(-1, keepdims=True) < 0, -1.0, 1.0)
    dot = np.clip(np.abs((q0 * q1).sum(-1, keepdims=True)), -1, 1)
    theta = np.arccos(dot)
    small = theta < 1e-6
    st = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / st)
    w1 = np.where(small, a, np.sin(a * theta) / st)
    q = w0 * q0 + w1 * sign * q1
    out[:, 3:7] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out
