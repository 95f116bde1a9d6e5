"""Per-trial ground height from the original motion's foot points.

CMU trials do not share a floor level: the soles' markers stand anywhere from about -11 cm to
+16 cm in the files' own frame. The estimator, per trial:

1. foot points: the ankle (end of ``ltibia``/``rtibia``), the ball (end of ``lfoot``/``rfoot``, the
   toe base) and the toes (end of ``ltoes``/``rtoes``), those present in the motion;
2. per frame, the lowest sole point (ball or toes; the ankle when the motion has neither) and its
   horizontal speed;
3. keep the frames where that point is slow (< ``slow_speed``, i.e. it bears weight);
4. ``ground_z`` = the ``percentile``-th percentile of its height over those frames (all frames
   when fewer than ``min_frames`` are slow).

A low percentile rather than the minimum ignores single-frame marker glitches; the slow-frame
filter ignores feet swinging low. Every foot point also gets its own *clearance*: its height
above ``ground_z`` while it is slow (same percentile), since the ankle stands ~5-8 cm above the sole
markers in stance. Heights "above ground" of a point are ``z - ground_z - clearance``.

Units: metres, metres per second; world z up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Foot points, in the order metrics use them: (ankle ~ heel, ball, toes) per side.
FOOT_POINTS: tuple[str, ...] = ("ltibia", "lfoot", "ltoes", "rtibia", "rfoot", "rtoes")
#: Foot point -> the part of the foot it stands for.
FOOT_PART = {
    "ltibia": "l_heel", "lfoot": "l_ball", "ltoes": "l_toes",
    "rtibia": "r_heel", "rfoot": "r_ball", "rtoes": "r_toes",
}  # fmt: skip
SOLE_POINTS = ("lfoot", "ltoes", "rfoot", "rtoes")
#: [m] radius of the sole's bone capsules in the replay scene (``sim.replay.capsules``): the floor
#: plane on which those capsules rest lies this far below ``ground_z``.
SOLE_RADIUS = 0.02


@dataclass(frozen=True)
class Ground:
    """A trial's ground.

    Attributes:
        z: ground height [m]: the level of the sole markers in stance.
        points: (F,) foot point names the clearances belong to.
        clearance: (F,) each foot point's stance height above ``z`` [m].
        frames: how many frames the estimate used (slow ones, or all).
    """

    z: float
    points: tuple[str, ...]
    clearance: np.ndarray
    frames: int

    @property
    def floor_z(self) -> float:
        """Height [m] of the plane the replay's foot capsules stand on (for replay and rendering)."""
        return float(self.z - SOLE_RADIUS)

    def clearance_of(self, names) -> np.ndarray:
        """(len(names),) clearances [m] of the foot points ``names`` (each must be in ``points``)."""
        return np.array([self.clearance[self.points.index(n)] for n in names])


def horizontal_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ...) horizontal speed [m/s] of ``positions`` (T, ..., 3) [m] (central differences)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    return np.linalg.norm(np.gradient(p[..., :2], 1.0 / fps, axis=0), axis=-1)


def foot_points(names) -> tuple[str, ...]:
    """The foot points among ``names``, in :data:`FOOT_POINTS` order."""
    return tuple(n for n in FOOT_POINTS if n in names)


def estimate_ground(
    positions: np.ndarray,
    names,
    fps: float,
    *,
    percentile: float = 5.0,
    slow_speed: float = 0.25,
    min_frames: int = 10,
) -> Ground:
    """Ground height and foot-point clearances of a trial (see the module docstring).

    Args:
        positions: (T, J, 3) the original's points [m] over the whole trial (clips concatenated
            are fine: speeds at the seams are off for one frame each).
        names: (J,) point names; at least one foot point must be among them.
        fps: frame rate [1/s].
        percentile: the low percentile taken [%].
        slow_speed: a point slower than this horizontally [m/s] may bear weight.
        min_frames: below this many slow frames, every frame counts.

    Returns:
        The :class:`Ground`.
    """
    names = tuple(names)
    feet = foot_points(names)
    if not feet:
        raise ValueError(f"no foot point among {names}; need one of {FOOT_POINTS}")
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(names), 3) or p.shape[0] < 1:
        raise ValueError(f"positions must be (T, {len(names)}, 3); got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("positions must be finite")
    idx = [names.index(n) for n in feet]
    z = p[:, idx, 2]  # (T, F)
    speed = horizontal_speed(p[:, idx], fps)  # (T, F)
    sole = [k for k, n in enumerate(feet) if n in SOLE_POINTS] or list(range(len(feet)))
    low = np.argmin(z[:, sole], axis=1)
    t = np.arange(len(z))
    zlow = z[:, sole][t, low]
    slow = speed[:, sole][t, low] < slow_speed
    use = slow if slow.sum() >= min_frames else np.ones_like(slow)
    ground = float(np.percentile(zlow[use], percentile))
    clearance = np.empty(len(feet))
    for k in range(len(feet)):
        s = speed[:, k] < slow_speed
        h = (z[:, k] - ground)[s if s.sum() >= min_frames else slice(None)]
        clearance[k] = max(float(np.percentile(h, percentile)), 0.0)
    return Ground(ground, feet, clearance, int(use.sum()))
