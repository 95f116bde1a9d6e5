"""A BVH file as the Acclaim records every downstream step takes: a
:class:`~sim.acclaim.records.Skeleton` and a :class:`~sim.acclaim.records.Motion` (so the humanoid,
retargeting, velocities, physics and simulation work on it unchanged).

The mapping (a BVH joint's rotation turns the segment that starts at it, as in CMU's own BVH
release, where ``LeftUpLeg`` is the ASF's ``lfemur``):

* the ROOT is the Acclaim root: its position channels (or its OFFSET, for axes without one) are
  the root translation, its rotation channels the root rotation;
* every other joint ``J`` is a bone named ``J`` that starts at ``J`` and carries ``J``'s rotation
  channels as its dofs (``Zrotation Xrotation Yrotation`` -> ``dof ry rx rz``: BVH lists the
  rotation applied last first); the bone runs to ``J``'s children when they all sit at one
  OFFSET (one child, an End Site, or CMU's branches), else it has length 0;
* an OFFSET that no bone covers (a child of the ROOT away from it; children of one joint at
  different OFFSETs) is a bone of its own without dofs, named ``<child>_offset`` (an End Site's:
  ``<joint>_tip``).

So every OFFSET is exactly one bone's length, and every joint and End Site position is a bone's
end (a point of the clip). Non-root position channels must stay constant (the joint then sits
there instead of at its OFFSET): a moving one has no place in a skeleton of fixed bones.

Units: lengths become metres by ``metres per unit`` (:data:`UNITS`), detected from the rest
pose's size when not given (:func:`detect_unit`: the unit that makes it nearest a person's
height). Axes: the file is y up (Blender's and CMU's BVH default) or z up; a z-up file gets
every bone's ``axis`` frame (and the root's) turned -90 degrees about x, so its angles are kept
exactly as written and the bones' directions are in y-up axes like an ASF's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from sim.acclaim.asf import RESERVED_NAMES
from sim.acclaim.records import MAX_METRES, ROOT_CHANNELS, Bone, Motion, Skeleton
from sim.bvh.records import Bvh
from sim.errors import MotionDataError, UnknownNameError
from sim.files import excerpt
from sim.model.rotations import euler_angles_deg, euler_matrix

#: Metres per file unit, by name.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
UPS = ("y", "z")
PERSON_HEIGHT = 1.7  # [m] what :func:`detect_unit` aims the rest pose's size at
_Z_UP_AXIS = np.array([-90.0, 0.0, 0.0])  # the z-up file's frame in y-up axes, "XYZ" [deg]
_BAD_CHARS = re.compile(r"[^A-Za-z0-9_.\-]")
_NAME_CHARS = 57  # a bone name of a joint: room for the "_offset" suffix within 64 characters


@dataclass(frozen=True)
class Take:
    """A BVH file as Acclaim records.

    Attributes:
        skeleton: bones as the module docstring maps them (lengths [m], y-up axes).
        motion: root (T, 6) as (tx, ty, tz [m], rx, ry, rz [deg], order XYZ); angles: bone ->
            (T, dofs) [deg] (the file's rotation channels, in dof order).
        fps: the file's frame rate [frames per second].
        unit: the length unit used (a key of :data:`UNITS`); up: ``"y"`` or ``"z"``.
    """

    skeleton: Skeleton
    motion: Motion
    fps: float
    unit: str
    up: str


def rest_positions(bvh: Bvh) -> np.ndarray:
    """(J, 3) every joint's (and End Site's) rest position, file units and axes (root at its
    OFFSET)."""
    p = np.zeros((len(bvh.joints), 3))
    for i, j in enumerate(bvh.joints):
        p[i] = j.offset + (p[j.parent] if j.parent >= 0 else 0.0)
    return p


def detect_unit(bvh: Bvh) -> str:
    """The unit of :data:`UNITS` that makes the rest pose's largest extent nearest
    :data:`PERSON_HEIGHT` (a ratio; metres when the rest pose has no extent)."""
    p = rest_positions(bvh)
    extent = float((p.max(axis=0) - p.min(axis=0)).max())
    if not extent > 0:
        return "m"
    return min(UNITS, key=lambda u: abs(np.log(extent * UNITS[u] / PERSON_HEIGHT)))


def to_acclaim(bvh: Bvh, *, unit: str | None = None, up: str = "y") -> Take:
    """The Acclaim skeleton and motion of ``bvh`` (see the module docstring).

    Args:
        unit: a key of :data:`UNITS`; None detects it (:func:`detect_unit`).
        up: ``"y"`` (default) or ``"z"``: the file's up axis.

    Raises:
        MotionDataError: a moving non-root position channel, a name that repeats another once
            made a valid bone name, a length or translation over :data:`MAX_METRES`.
        UnknownNameError: an unknown ``unit`` or ``up``.
    """
    if up not in UPS:
        raise UnknownNameError("up axis", up, UPS)
    unit = detect_unit(bvh) if unit is None else unit
    if unit not in UNITS:
        raise UnknownNameError("unit", unit, UNITS)
    builder = _Builder(bvh, UNITS[unit], up)
    skeleton, motion = builder.build()
    return Take(skeleton=skeleton, motion=motion, fps=bvh.fps, unit=unit, up=up)


def motion_like(bvh: Bvh, take: Take) -> Motion:
    """``to_acclaim(bvh, unit=take.unit, up=take.up).motion`` for a ``bvh`` that ``take.skeleton``
    is the skeleton of (the same hierarchy; the joints' position channels at the values they
    had: a later piece of the same file), without building that skeleton again: the root's
    motion and every bone's angles, the same arrays.

    Raises:
        MotionDataError: a root position over :data:`MAX_METRES`.
    """
    return _Builder(bvh, UNITS[take.unit], take.up).motion(take.skeleton)


def bone_name(name: str) -> str:
    """A BVH joint name as a bone name: characters outside ``[A-Za-z0-9_.-]`` become ``_``, a
    leading digit, ``.`` or ``-`` gets a ``_`` before it, at most 57 characters, and the names the
    model reserves get a trailing ``_`` (``mixamorig:Hips`` -> ``mixamorig_Hips``)."""
    out = _BAD_CHARS.sub("_", name)
    if not re.match(r"[A-Za-z_]", out):
        out = "_" + out
    out = out[:_NAME_CHARS]
    return out + "_" if out.lower() in RESERVED_NAMES else out


class _Builder:
    """Bones in topological order, and their motion, of one BVH file."""

    def __init__(self, bvh: Bvh, metres: float, up: str):
        self.bvh, self.metres, self.up = bvh, metres, up
        self.turn = np.eye(3) if up == "y" else euler_matrix(_Z_UP_AXIS, "XYZ")
        self.axis = np.zeros(3) if up == "y" else _Z_UP_AXIS
        self.bones: list[Bone] = []
        self.angles: dict[str, np.ndarray] = {}
        self.lines: dict[str, int] = {}
        self.offsets: list[np.ndarray] = []

    def _offset(self, i: int) -> np.ndarray:
        """(3,) joint ``i``'s OFFSET, or its constant position channels in their place."""
        j = self.bvh.joints[i]
        offset = j.offset.copy()
        if j.parent < 0:
            return offset
        for k, axis in enumerate("XYZ"):
            values = self.bvh.channel(i, f"{axis}position")
            if values is None or not len(values):
                continue
            if np.ptp(values) > 1e-6 * max(1.0, abs(values[0])):
                raise MotionDataError(
                    self.bvh.path, j.line,
                    f"joint {excerpt(j.name)}: {axis}position moves; only the ROOT may move",
                )  # fmt: skip
            offset[k] = values[0]
        return offset

    def build(self) -> tuple[Skeleton, Motion]:
        bvh = self.bvh
        root = bvh.joints[0]
        self.offsets = [self._offset(i) for i in range(len(bvh.joints))]
        for c in bvh.children.get(0, []):
            self._child(c, "root")
        skeleton = Skeleton(
            path=bvh.path,
            name=bone_name(root.name),
            length_to_metres=self.metres,
            angles_in_degrees=True,
            root_order=ROOT_CHANNELS,
            root_axis_order="XYZ",
            root_orientation=self.axis.copy(),
            bones=tuple(self.bones),
        )
        motion = Motion(path=bvh.path, root=self._root_motion(), angles=self.angles)
        return skeleton, motion

    def motion(self, skeleton: Skeleton) -> Motion:
        """The motion of ``skeleton``, built by :meth:`build` from a file of this hierarchy: a
        bone with dofs is its joint's own (named by :func:`bone_name`), with its angles."""
        joints = self.bvh.joints
        own = {bone_name(j.name): i for i, j in enumerate(joints) if i and not j.end_site}
        for b in skeleton.bones:
            if b.dofs:
                self._angles(b.name, own[b.name])
        return Motion(path=self.bvh.path, root=self._root_motion(), angles=self.angles)

    def _angles(self, name: str, i: int) -> None:
        """Bone ``name``'s angles: joint ``i``'s rotation channels, in dof order (if any)."""
        rotations = [c for c in self.bvh.joints[i].channels if c.endswith("rotation")]
        if rotations:
            self.angles[name] = np.column_stack(
                [self.bvh.channel(i, c) for c in reversed(rotations)]
            )

    def _child(self, c: int, parent: str) -> None:
        """Joint or End Site ``c`` below bone ``parent`` (whose end lies at ``c``'s parent): an ``_offset``/``_tip`` bone first when its OFFSET is not covered, then its own bone."""
        j = self.bvh.joints[c]
        offset = self.offsets[c]
        if j.end_site:
            self._add(f"{bone_name(self.bvh.joints[j.parent].name)}_tip", parent, offset, c)
            return
        if offset.any():
            parent = self._add(f"{bone_name(j.name)}_offset", parent, offset, c)
        self._joint(c, parent)

    def _joint(self, i: int, parent: str) -> None:
        """Joint ``i``'s own bone (its rotation channels as dofs), then its children's."""
        kids = self.bvh.children.get(i, [])
        shared = bool(kids) and all(
            np.array_equal(self.offsets[k], self.offsets[kids[0]]) for k in kids
        )
        vector = self.offsets[kids[0]] if shared else np.zeros(3)
        name = self._add(bone_name(self.bvh.joints[i].name), parent, vector, i, dofs=True)
        for k in kids:
            if shared and not self.bvh.joints[k].end_site:
                self._joint(k, name)
            elif not shared:
                self._child(k, name)

    def _add(self, name: str, parent: str, vector: np.ndarray, i: int, dofs: bool = False) -> str:
        """Append a bone of file-axes ``vector`` (file units); returns its name."""
        bvh, j = self.bvh, self.bvh.joints[i]
        if name in self.lines:
            raise MotionDataError(
                bvh.path, j.line,
                f"joint {excerpt(j.name)} makes bone {name!r}, as the joint of line {self.lines[name]} does",
            )  # fmt: skip
        self.lines[name] = j.line
        v = self.turn @ vector
        length = float(np.linalg.norm(v)) * self.metres
        if not length <= MAX_METRES:
            raise MotionDataError(
                bvh.path,
                j.line,
                f"joint {excerpt(j.name)}: OFFSET of {length:g} m exceeds {MAX_METRES:g} m",
            )
        direction = v / np.linalg.norm(v) if length > 0 else np.array([0.0, 1.0, 0.0])
        rotations = [c for c in j.channels if c.endswith("rotation")] if dofs else []
        self.bones.append(
            Bone(
                name=name, parent=parent, direction=direction, length=length,
                axis=self.axis.copy(), axis_order="XYZ",
                dofs=tuple(f"r{c[0].lower()}" for c in reversed(rotations)),
                limits=np.tile([-180.0, 180.0], (len(rotations), 1)), line=j.line,
            )
        )  # fmt: skip
        if rotations:
            self._angles(name, i)
        return name

    def _root_motion(self) -> np.ndarray:
        """(T, 6) root translation [m, y-up axes] and rotation (rx, ry, rz [deg], order XYZ)."""
        bvh = self.bvh
        T = bvh.n_frames
        root = bvh.joints[0]
        t = np.tile(root.offset, (T, 1))
        for k, axis in enumerate("XYZ"):
            values = bvh.channel(0, f"{axis}position")
            if values is not None:
                t[:, k] = values
        t = (t @ self.turn.T) * self.metres
        if T and not np.abs(t).max() <= MAX_METRES:
            raise MotionDataError(
                bvh.path, root.line, f"root position exceeds {MAX_METRES:g} m in magnitude"
            )
        rotations = [c for c in root.channels if c.endswith("rotation")]
        R = np.broadcast_to(np.eye(3), (T, 3, 3))
        if rotations:
            angles = np.column_stack([bvh.channel(0, c) for c in reversed(rotations)])
            R = euler_matrix(angles, "".join(c[0] for c in reversed(rotations)))
        return np.concatenate([t, euler_angles_deg(R, "XYZ")], axis=1)
