"""Per-frame, per-foot-point state for drawing: is the original's foot in contact, and does the
reconstruction's foot float, sink or skate there.

This is the renderer's *simple* stand-in (heights above one ground height and horizontal speeds, no
hysteresis): :func:`simple_foot_states` is the one function to replace by a calibrated ground and
contact labeller (``sim.physics``) — the renderer only reads a :class:`FootState`.

Units: metres, seconds; world z up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.motion.points import PointMotion, finite_velocity

#: Name endings of foot points, heel side first: ankle (``*tibia``, the heel's proxy in the 23
#: protocol points), ball (``*foot``) and toes (``*toes``, 31-point sets only).
FOOT_SUFFIXES = ("tibia", "foot", "toes")


@dataclass(frozen=True)
class FootState:
    """What the renderer draws at the foot points. Every array is (T, F) bool.

    Attributes:
        points: (F,) foot point names.
        contact: the original's point is on the ground.
        rec_contact: the reconstruction's point is on the ground (same rule).
        floating: the original's point is in contact but the reconstruction's is above it.
        sinking: the reconstruction's point is below where the original's ever rests.
        skating: the original's point is in contact but the reconstruction's slides.
    """

    points: tuple[str, ...]
    contact: np.ndarray
    rec_contact: np.ndarray
    floating: np.ndarray
    sinking: np.ndarray
    skating: np.ndarray

    def __post_init__(self):
        T = self.contact.shape[0]
        for a in (self.contact, self.rec_contact, self.floating, self.sinking, self.skating):
            if a.shape != (T, len(self.points)):
                raise ValueError(
                    f"foot state arrays must be (T, {len(self.points)}); got {a.shape}"
                )


def foot_points(names) -> tuple[str, ...]:
    """The foot points among ``names``: ``l``/``r`` + a :data:`FOOT_SUFFIXES` ending."""
    return tuple(n for n in names if n[:1] in "lr" and n[1:] in FOOT_SUFFIXES and len(n) > 1)


def simple_ground(original: PointMotion, *, sole: float = 0.025, q: float = 5.0) -> float:
    """Ground height [m]: the ``q``-th percentile over frames of the lowest ball/toe point, less the
    foot capsule's radius ``sole`` [m] (the point rides one radius above the floor). ``0.0`` when
    the motion has no ball or toe point."""
    idx = [i for i, n in enumerate(original.names) if n in foot_points(original.names)]
    idx = [i for i in idx if not original.names[i].endswith("tibia")]
    if not idx:
        return 0.0
    low = original.positions[:, idx, 2].min(axis=1)
    return float(np.percentile(low, q) - sole)


def simple_foot_states(
    original: PointMotion,
    reconstruction: PointMotion | None = None,
    *,
    ground_z: float = 0.0,
    contact_height: float = 0.03,
    contact_speed: float = 0.5,
    float_height: float = 0.03,
    sink_depth: float = 0.02,
    skate_speed: float = 0.3,
) -> FootState:
    """Foot states from heights above ``ground_z`` and horizontal speeds.

    Each point's rest height is the 5th percentile of the original's height above ground over the
    clip (an ankle rests ~8 cm up, a ball ~2.5 cm). The original's point is in contact where it is
    within ``contact_height`` [m] of its rest height and moves slower than ``contact_speed`` [m/s]
    horizontally; the reconstruction's by the same rule with the original's rest heights. Flags of
    the reconstruction: floating where the original is in contact and the reconstruction's point
    is ``float_height`` [m] higher; sinking where it is ``sink_depth`` [m] below the rest height;
    skating where the original is in contact, the reconstruction's point is near the ground (within
    ``contact_height`` of the rest height) and moves ``skate_speed`` [m/s] faster horizontally
    than the original's.

    Args:
        original, reconstruction: (T, P, 3) motions; the reconstruction's points must include the
            foot points used (``None``: no flags, ``rec_contact`` = ``contact``).
    """
    names = foot_points(original.names)
    if reconstruction is not None:
        names = tuple(n for n in names if n in reconstruction.names)
    T = original.n_frames
    if not names:
        z = np.zeros((T, 0), dtype=bool)
        return FootState((), z, z, z, z, z)

    def height_speed(m: PointMotion):
        idx = [m.names.index(n) for n in names]
        p = m.positions[:, idx]
        v = finite_velocity(p, m.fps)
        return p[..., 2] - ground_z, np.linalg.norm(v[..., :2], axis=-1)

    h_o, s_o = height_speed(original)
    rest = np.percentile(h_o, 5, axis=0)
    contact = (h_o - rest < contact_height) & (s_o < contact_speed)
    if reconstruction is None:
        no = np.zeros_like(contact)
        return FootState(names, contact, contact.copy(), no, no.copy(), no.copy())
    h_r, s_r = height_speed(reconstruction)
    rec_contact = (h_r - rest < contact_height) & (s_r < contact_speed)
    floating = contact & (h_r - h_o > float_height)
    sinking = h_r < rest - sink_depth
    skating = contact & (h_r - rest < contact_height) & (s_r - s_o > skate_speed)
    return FootState(names, contact, rec_contact, floating, sinking, skating)
