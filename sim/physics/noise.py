"""Noise floors: the original re-captured with mocap-level marker noise.

Every figure of a reconstruction is compared with the original's; a difference smaller than what
capture noise alone makes is no difference. :func:`noisy_original` gives the original's points as
if captured again with independent Gaussian noise of ``sigma`` (default :data:`NOISE_MM`, the
1-2 mm of optical motion capture) on every point in every *source* frame, its velocities and
accelerations through the same local polynomial the original's own derivatives use
(:func:`sim.motion.velocities.point_derivatives`). The figures of that copy against the original
are each figure's noise floor.

Units: metres, seconds.
"""

from __future__ import annotations

import numpy as np

from sim.errors import UsageError
from sim.motion.velocities import SOURCE_WINDOW, point_derivatives

#: [mm] standard deviation of the marker noise of the noise floors.
NOISE_MM = 1.5


def noisy_original(
    positions: np.ndarray,
    velocities: np.ndarray,
    accelerations: np.ndarray,
    fps: float,
    source_fps: float,
    *,
    sigma_mm: float = NOISE_MM,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The original's points (T, P, 3) [m] with its velocities and accelerations [m/s, m/s^2]
    re-captured with ``sigma_mm`` of noise per point and source frame (seeded).

    Noise is drawn at ``source_fps`` over the clip's span plus the derivative filter's reach,
    sampled at the clip's frames for the positions and differentiated by the original's filter
    for the derivatives, so a noisy frame is what capture noise makes of it, no more.
    """
    p = np.asarray(positions, dtype=np.float64)
    T = p.shape[0]
    step = int(round(source_fps / fps))
    if step < 1 or abs(source_fps / fps - step) > 1e-9:
        raise UsageError(f"fps {fps} must divide the source rate {source_fps}")
    pad = SOURCE_WINDOW
    rng = np.random.default_rng(seed)
    n = rng.normal(0.0, 1e-3 * sigma_mm, (step * (T - 1) + 1 + 2 * pad,) + p.shape[1:])
    frames = pad + step * np.arange(T)
    dv, da = point_derivatives(n, source_fps, frames)
    return p + n[frames], np.asarray(velocities) + dv, np.asarray(accelerations) + da
