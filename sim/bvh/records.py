"""What a BVH file holds, as typed values in the file's own units and axes: :class:`Joint` (one
``ROOT``, ``JOINT`` or ``End Site`` of the hierarchy) and :class:`Bvh` (the whole file), and the
bounds the reader (:mod:`sim.bvh.reader`) enforces on hostile input.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: The six BVH channels, as the reader spells them (it accepts any capitalisation).
CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
MAX_BVH_BYTES = 64 << 20  # a BVH holds the skeleton and the motion: as large as an AMC
MAX_JOINTS = 500  # ROOT, JOINTs and End Sites; each becomes at most two bones of the skeleton
MAX_DEPTH = 100  # joints on the longest root-to-leaf chain
MAX_FRAMES = 1 << 24
MAX_OFFSET = 1e7  # bound on an OFFSET or position channel, in the file's units
MAX_DEGREES = 1e5  # bound on a rotation channel [deg], as for AMC angles
MAX_FRAME_RATE = 1000.0  # [frames per second]
MIN_FRAME_RATE = 1.0  # [frames per second]: a slower file resampled to 120 Hz would swell 120x


@dataclass(frozen=True)
class Joint:
    """One joint of a BVH hierarchy.

    Attributes:
        name: the name as the file spells it (an End Site: ``"<parent> End Site"``).
        parent: index of the parent joint in :attr:`Bvh.joints` (-1 for the ROOT).
        offset: (3,) position relative to the parent joint at rest, file units and axes.
        channels: the joint's channels in file order, from :data:`CHANNELS` (End Sites: none).
        column: the column of its first channel in :attr:`Bvh.values`.
        line: the file's line of the joint's ``ROOT``/``JOINT``/``End`` keyword.
        end_site: whether this is an ``End Site`` (no channels, no children).
    """

    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    column: int
    line: int
    end_site: bool = False


@dataclass(frozen=True)
class Bvh:
    """A BVH file as read: the hierarchy and the motion table.

    Attributes:
        path: source file.
        joints: every joint, parents before children, in file order (End Sites included).
        frame_time: seconds per frame (the file's ``Frame Time``).
        values: (T, C) every frame's channel values in file order (positions in file units,
            rotations [deg]); C is the sum of the joints' channel counts.
        motion_line: the line of the file's ``MOTION`` keyword.
    """

    path: str
    joints: tuple[Joint, ...]
    frame_time: float
    values: np.ndarray
    motion_line: int = 0
    children: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        for i, j in enumerate(self.joints):
            self.children.setdefault(j.parent, []).append(i)

    @property
    def n_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def fps(self) -> float:
        """Frames per second: ``1 / frame_time``, rounded to a whole number when within 1e-4 of
        one (files write 1/120 s as ``0.008333``)."""
        rate = 1.0 / self.frame_time
        whole = round(rate)
        return float(whole) if whole >= 1 and abs(rate - whole) <= 1e-4 * rate else rate

    def channel(self, joint: int, name: str) -> np.ndarray | None:
        """(T,) the values of ``joint``'s channel ``name``, or None if it has none."""
        j = self.joints[joint]
        if name not in j.channels:
            return None
        return self.values[:, j.column + j.channels.index(name)]
