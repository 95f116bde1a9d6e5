"""The windows of a real trial a synthetic clip draws from: the one whose points move fastest."""

from __future__ import annotations

import mujoco
import numpy as np


def window_steps(points: np.ndarray, n: int, starts: np.ndarray) -> np.ndarray:
    """(len(starts),) the 95th percentile, over the samples and points of each window
    ``points[s : s + n]`` (points (T, P, 3) [m] sampled at one rate), of each point's step
    between consecutive samples [m]: its speed times the sampling interval."""
    step = np.linalg.norm(np.diff(points, axis=0), axis=-1)  # (T - 1, P)
    return np.array([np.percentile(step[s : s + n - 1], 95) for s in np.asarray(starts)])


def fastest_window(
    points: np.ndarray, n: int, starts: np.ndarray, cap: float | None = None
) -> int:  # fmt: skip
    """Of the windows ``points[s : s + n]`` (points (T, P, 3) [m] sampled at one rate), the
    start ``s`` of ``starts`` whose points move fastest (:func:`window_steps`: the rate
    cancels); the first of equals. With ``cap`` [m per sample interval] the fastest whose step
    is within it, else (none is) the slowest: velocity-rich, no faster than asked."""
    starts = np.asarray(starts, dtype=np.int64)
    score = window_steps(points, n, starts)
    if cap is not None:
        if not (score <= cap).any():
            return int(starts[int(np.argmin(score))])
        score = np.where(score <= cap, score, -np.inf)
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
