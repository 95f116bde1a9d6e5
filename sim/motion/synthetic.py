"""Velocity-rich synthetic motion generated on the shared humanoid.

Every hinge follows a sum of sinusoids inside its joint limits, the root travels and turns, and the
figure is kept on the floor (its lowest foot point at z = 0). Motion is sampled at 120 Hz like CMU
data and run through the same pipeline as real files, so clips carry kinematic-chain velocities.
The generalised velocities of the hinges are known analytically (:func:`synthetic_qpos` returns
them), which makes these motions a check on the numerical differentiation too.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.errors import require_positive
from sim.model import quaternion as quat
from sim.model.humanoid import humanoid_model
from sim.model.kinematics import SOLE_POINTS, point_names, point_parents
from sim.model.rotations import Y_UP_TO_Z_UP, axis_rotation
from sim.motion.clip import Clip
from sim.motion.ingest import CMU_FPS, clip_from_qpos, resample_step


def synthetic_qpos(
    model,
    seconds: float,
    *,
    seed: int = 0,
    rate: float = CMU_FPS,
    energy: float = 0.35,
    data: mujoco.MjData | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Sinusoidal motion of ``model``'s hinges and free root.

    Args:
        seconds: duration [s]; rate: sampling rate [1/s].
        energy: fraction of each joint's half range used as amplitude (0..1).
        data: the job's ``MjData`` of ``model`` (made here when None).

    Returns:
        qpos (T, nq) and the analytic hinge velocities (T, nq - 7) [rad/s].
    """
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(seconds * rate))) / rate
    T = len(t)
    nh = model.nq - 7
    lo, hi = model.jnt_range[1:, 0], model.jnt_range[1:, 1]
    mid = (lo + hi) / 2
    # Stay near the rest pose (0) where the limits allow it, so the figure looks human.
    centre = 0.7 * np.clip(0.0, lo, hi) + 0.3 * mid
    k = 3
    freq = rng.uniform(0.3, 2.0, (nh, k))  # [Hz]
    phase = rng.uniform(0, 2 * np.pi, (nh, k))
    amp = energy * np.minimum(hi - centre, centre - lo)[:, None] * rng.dirichlet(np.ones(k), nh)
    arg = 2 * np.pi * freq[None] * t[:, None, None] + phase[None]
    hinges = centre + (amp[None] * np.sin(arg)).sum(-1)
    dhinges = (amp[None] * 2 * np.pi * freq[None] * np.cos(arg)).sum(-1)

    qpos = np.zeros((T, model.nq))
    speed = rng.uniform(0.6, 1.4)  # [m/s]
    yaw = rng.uniform(-0.5, 0.5) * np.sin(2 * np.pi * 0.1 * t)
    heading = np.cumsum(np.stack([np.cos(yaw), np.sin(yaw)], -1), 0) * speed / rate
    qpos[:, 0:2] = heading
    qpos[:, 2] = 1.0
    upright = Y_UP_TO_Z_UP  # CMU's y-up skeleton stood on the z-up floor
    R = axis_rotation("Z", yaw + np.pi / 2) @ upright
    qpos[:, 3:7] = quat.from_matrix(R)
    qpos[:, 7:] = hinges
    _stand_on_floor(model, mujoco.MjData(model) if data is None else data, qpos)
    return qpos, dhinges


def _stand_on_floor(model, data, qpos: np.ndarray) -> None:
    """Shift the root height so the lowest foot site touches z = 0 (smoothed over time)."""
    feet = [model.site(f"{n}_end").id for n in SOLE_POINTS]
    low = np.empty(len(qpos))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        low[i] = data.site_xpos[feet, 2].min()
    width = 9
    kernel = np.hanning(width + 2)[1:-1]
    padded = np.pad(low, width // 2, mode="edge")
    smooth = np.convolve(padded, kernel / kernel.sum(), mode="valid")
    qpos[:, 2] -= smooth - 0.03  # ~ the foot capsule's radius


def synthetic_motion(seconds: float = 4.0, *, seed: int = 0, fps: float = 30.0) -> Clip:
    """A synthetic clip on the shared humanoid at ``fps`` (sampled at 120 Hz underneath).

    Points and parents follow the canonical CMU skeleton (root + 30 bones).

    Raises:
        UsageError: ``seconds`` or ``fps`` not positive, or ``fps`` not dividing 120.
    """
    require_positive(seconds, "seconds")
    resample_step(CMU_FPS, fps)
    skeleton, model = humanoid_model()
    data = mujoco.MjData(model)  # the job's MuJoCo state, shared by both passes
    qpos, _ = synthetic_qpos(model, seconds, seed=seed, data=data)
    return clip_from_qpos(
        model,
        point_names(skeleton),
        point_parents(skeleton),
        qpos,
        source_fps=CMU_FPS,
        fps=fps,
        source=f"synthetic(seed={seed})",
        data=data,
    )
