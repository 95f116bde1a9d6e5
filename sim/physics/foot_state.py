"""Per-frame, per-foot-point state for drawing: is the original's foot in contact, and does the
reconstruction's foot float, sink or skate there. The renderer only reads a :class:`FootState`;
:func:`foot_states` makes one from a trial's ground and foot-floor contact labels
(:mod:`sim.physics.contacts`).

Units: metres, metres per second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.errors import UsageError
from sim.model.kinematics import foot_points
from sim.motion.points import PointMotion
from sim.physics.contacts import Contacts, motion_contacts
from sim.physics.feet import FOOT_PART, SUPPORT_GAP
from sim.physics.ground import Ground, horizontal_speed


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
                raise UsageError(
                    f"foot state arrays must be (T, {len(self.points)}); got {a.shape}"
                )


#: Flags of a reconstruction's foot against the original's contacts, for drawing: floating
#: higher than this above the floor while the original's is in contact [m], sinking deeper than
#: this below it [m], skating this much faster horizontally [m/s] while the original's stands.
FLOAT_HEIGHT, SINK_DEPTH, SKATE_SPEED = 0.03, 0.02, 0.3


def _point_rows(c: Contacts, points) -> tuple[np.ndarray, np.ndarray]:
    """Per foot point (ankle, ball, toes) its foot's label and its part's gap (T, P): the
    ankle stands for the heel sphere, the ball for the ball sphere, the toes for the toes'."""
    part = {"heel": "heel", "ball": "ball", "toes": "toes"}
    T = c.contact.shape[0]
    lab, gap = np.zeros((T, len(points)), bool), np.zeros((T, len(points)))
    for j, n in enumerate(points):
        x, want = FOOT_PART[n].split("_")
        f = c.sides.index(x)
        ks = [k for k in c.sole.of(x) if c.sole.part[k] == part[want]] or list(c.sole.of(x))
        gap[:, j] = c.gap[:, ks].min(axis=1)
        lab[:, j] = c.contact[:, f] & (gap[:, j] <= SUPPORT_GAP)
    return lab, gap


def foot_states(
    original: PointMotion, reconstruction: PointMotion | None, ground: Ground
) -> FootState:
    """What the renderer draws at the foot points both motions have: the original's foot in
    contact (:func:`motion_contacts`), and the reconstruction's flags by :data:`FLOAT_HEIGHT`,
    :data:`SINK_DEPTH` and :data:`SKATE_SPEED` (``None``: no flags)."""
    names = foot_points(original.names)
    if reconstruction is not None:
        names = tuple(n for n in names if n in reconstruction.names)
    o = motion_contacts(original.positions, original.names, original.fps, ground)
    names = tuple(n for n in names if n[0] in o.sides)
    contact, _ = _point_rows(o, names)
    if reconstruction is None:
        no = np.zeros_like(contact)
        return FootState(names, contact, contact.copy(), no, no.copy(), no.copy())
    r = motion_contacts(
        reconstruction.positions, reconstruction.names, reconstruction.fps, ground,
        initial=o.contact[0],
    )  # fmt: skip
    rec_contact, h_r = _point_rows(r, names)
    idx_o = [original.names.index(n) for n in names]
    idx_r = [reconstruction.names.index(n) for n in names]
    s_o = horizontal_speed(original.positions[:, idx_o], original.fps)
    s_r = horizontal_speed(reconstruction.positions[:, idx_r], reconstruction.fps)
    return FootState(
        points=names,
        contact=contact,
        rec_contact=rec_contact,
        floating=contact & (h_r > FLOAT_HEIGHT),
        sinking=h_r < -SINK_DEPTH,
        skating=contact & (s_r - s_o > SKATE_SPEED),
    )
