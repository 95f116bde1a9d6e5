"""What Acclaim files hold, as typed values: :class:`Bone`, :class:`Skeleton` (an ASF file),
:class:`Motion` (an AMC file), and the bounds both readers (:mod:`sim.acclaim.asf`,
:mod:`sim.acclaim.amc`) enforce on hostile input.

Values are in the file's own axes (CMU: y up) with lengths in metres and angles in degrees.

Length units: Acclaim writes ``:units length L``; CMU's convention is
``metres = value * 0.0254 / L`` (values are inches scaled by L = 0.45).

Hostile input: every number must be finite and within generous physical bounds (lengths and root
translations at most :data:`MAX_METRES`, angles at most :data:`MAX_DEGREES` in magnitude).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sim.errors import UnknownNameError

INCH = 0.0254  # [m]
ROTATION_DOFS = ("rx", "ry", "rz")
ROOT_CHANNELS = ("tx", "ty", "tz", "rx", "ry", "rz")

MAX_METRES = 1e4  # bound on a bone length or root translation [m]
MAX_DEGREES = 1e5  # bound on any angle [deg] (real CMU motions reach ~1,500)
MAX_BONES = 1000
MAX_DEPTH = 200  # bones on the longest root-to-leaf chain (the MJCF nests one body per bone)
UNITS_LENGTH_RANGE = (1e-6, 1e6)  # accepted ``:units length`` values


@dataclass(frozen=True)
class Bone:
    """One ASF bone.

    Attributes:
        name: bone name.
        parent: parent bone name (``"root"`` for the root's children).
        direction: (3,) unit vector of the bone in the rest pose, file axes (CMU: y up).
        length: bone length [m].
        axis: (3,) Euler angles [deg] of the bone's local frame C, applied in ``axis_order``.
        axis_order: rotation order of ``axis``, e.g. ``"XYZ"`` (X applied first).
        dofs: rotational degrees of freedom in AMC value order, e.g. ``("rx", "ry", "rz")``.
        limits: (len(dofs), 2) joint limits [deg].
        line: the line of the bone's ``begin`` in its file (None if built in memory).
    """

    name: str
    parent: str
    direction: np.ndarray
    length: float
    axis: np.ndarray
    axis_order: str
    dofs: tuple[str, ...]
    limits: np.ndarray
    line: int | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Skeleton:
    """An ASF skeleton.

    Attributes:
        path: source file ("" if built in memory).
        name: the file's ``:name``.
        length_to_metres: factor taking the file's length values to metres.
        angles_in_degrees: whether the file's angles are degrees (else radians).
        root_order: AMC channel order of the root, e.g. ``("tx","ty","tz","rx","ry","rz")``.
        root_axis_order: rotation order of the root, e.g. ``"XYZ"``.
        root_orientation: (3,) Euler angles [deg] of the root's frame.
        bones: bones in topological order (every parent before its children).
    """

    path: str
    name: str
    length_to_metres: float
    angles_in_degrees: bool
    root_order: tuple[str, ...]
    root_axis_order: str
    root_orientation: np.ndarray
    bones: tuple[Bone, ...]
    _index: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        self._index.update({b.name: i for i, b in enumerate(self.bones)})

    @property
    def bone_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.bones)

    def bone(self, name: str) -> Bone:
        """The bone called ``name``; the error lists the valid names."""
        try:
            return self.bones[self._index[name]]
        except KeyError:
            raise UnknownNameError("bone", name, self.bone_names) from None

    def has_bone(self, name: str) -> bool:
        return name in self._index


@dataclass(frozen=True)
class Motion:
    """An AMC motion in the file's units, one row per frame.

    Attributes:
        path: source file.
        root: (T, 6) root channels reordered to (tx, ty, tz, rx, ry, rz); translations [m],
            rotations [deg].
        angles: dict bone name -> (T, len(bone.dofs)) rotations [deg] in the bone's dof order.
            Bones with dofs that the file never mentions are zeros (read-only).
        first_frame: the file's number of its first frame (usually 1).
        notes: repairs made while reading (e.g. an incomplete final frame dropped), each naming
            the file and line.
    """

    path: str
    root: np.ndarray
    angles: dict
    first_frame: int = 1
    notes: tuple[str, ...] = ()

    @property
    def n_frames(self) -> int:
        return int(self.root.shape[0])
