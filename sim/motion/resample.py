"""A ``qpos`` stream moved onto another frame rate, for sources whose rate the clip rate does not
divide (a 100 fps BVH for 30 fps clips): ingest takes every k-th source frame
(:func:`sim.motion.ingest.resample_step`), so such a stream is first interpolated onto the least
rate that is a whole multiple of the clip rate and at least the source's (100 -> 120 fps for
30 fps clips), then goes on exactly as a 120 fps AMC does.
"""

from __future__ import annotations

import math

import numpy as np

from sim.errors import UsageError
from sim.model import quaternion as quat


def grid_rate(source_fps: float, fps: float) -> float:
    """The least whole multiple of ``fps`` at least ``source_fps`` [frames per second]: the
    source rate itself when ``fps`` divides it.

    Raises:
        UsageError: a rate that is not positive.
    """
    if not (fps > 0 and source_fps > 0):
        raise UsageError(f"frame rates must be positive (source {source_fps:g}, output {fps:g})")
    k = source_fps / fps
    if abs(k - round(k)) <= 1e-9 and round(k) >= 1:
        return float(source_fps)
    return float(math.ceil(k) * fps)


def resampled_frames(frames: int, source_fps: float, rate: float) -> int:
    """How many frames :func:`resample_qpos` makes of ``frames`` at ``source_fps``."""
    return int(math.floor((frames - 1) * rate / source_fps + 1e-9)) + 1 if frames else 0


def resample_qpos(qpos: np.ndarray, source_fps: float, rate: float) -> np.ndarray:
    """(T', nq) ``qpos`` (T, nq) of a free-root model sampled at ``rate`` over the same span.

    Frame ``n`` is at ``n / rate`` seconds, ``n = 0 .. floor((T - 1) rate / source_fps)``; between
    source frames, the root position and every hinge angle move linearly (hinge angles are
    continuous over the take, ``sim.motion.retarget``), the root orientation (``qpos[:, 3:7]``,
    ``wxyz``) by slerp. Frames that fall on a source frame are that frame exactly.
    """
    qpos = np.asarray(qpos, dtype=np.float64)
    T = qpos.shape[0]
    n = resampled_frames(T, source_fps, rate)
    t = np.arange(n) * (source_fps / rate)  # source frame position of every output frame
    i = np.minimum(np.floor(t + 1e-9).astype(np.int64), T - 1)
    s = np.clip(t - i, 0.0, 1.0)
    j = np.minimum(i + 1, T - 1)
    out = qpos[i] + s[:, None] * (qpos[j] - qpos[i])
    out[:, 3:7] = quat.slerp(qpos[i, 3:7], qpos[j, 3:7], s)
    exact = s <= 1e-9
    out[exact] = qpos[i[exact]]
    return out
