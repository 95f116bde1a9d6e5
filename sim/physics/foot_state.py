"""Per-frame, per-foot-point state for drawing: is the original's foot in contact, and does the
reconstruction's foot float, sink or skate there. The renderer only reads a :class:`FootState`;
:func:`sim.physics.contacts.foot_states` makes one from a trial's ground and contact labels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
