"""The windows of a real trial a synthetic clip draws from: the one whose points move fastest."""

from __future__ import annotations

import mujoco
import numpy as np


def fastest_window(points: np.ndarray, n: int, starts: np.ndarray) -> int:
    """Of the windows ``points[s : s + n]`` (points (T, P, 3) [m] sampled at one rate), the
    start ``s`` of ``starts`` whose points move fastest: the largest 95th percentile, over the
    window's samples and points, of each point's step between consecutive samples (its speed
    times the sampling interval: the rate cancels); the first of equals."""
    step = np.linalg.norm(np.diff(points, axis=0), axis=-1)  # (T - 1, P)
    starts = np.asarray(starts, dtype=np.int64)
    score = [np.percentile(step[s : s + n - 1], 95) for s in starts]
    return int(starts[int(np.argmax(score))])


def body_points(model, qpos: np.ndarray) -> np.ndarray:
    """(T, B - 1, 3) [m] the origin of every body but the world at each ``qpos`` (T, nq)."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), model.nbody - 1, 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[t] = data.xpos[1:]
    return out
