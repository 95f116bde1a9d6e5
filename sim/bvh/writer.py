"""Write an Acclaim skeleton and motion as a BVH file (opens in Blender and MotionBuilder; read back
by :mod:`sim.bvh.reader` and :mod:`sim.bvh.convert` into the same bones and points).

Layout (CMU's own BVH release's): the ROOT ``root`` with six channels, then one JOINT per bone,
named after it, at the bone's *start* (its OFFSET is the parent bone's vector; a child of the
root sits on it), carrying the bone's rotation as ``Zrotation Yrotation Xrotation``; a bone with
no children ends in an End Site at its end. A bone's BVH rotation is its Acclaim rotation in
the rest frame, ``C M C^-1`` (``C`` its ``axis`` frame, ``M`` its AMC rotation), so every joint's
position is the ASF/AMC forward kinematics' to the written precision (6 decimals: 1e-8 m in
centimetres, 1e-6 degrees).
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from sim.acclaim.records import Motion, Skeleton
from sim.bvh.convert import UNITS, UPS
from sim.errors import MotionDataError, UnknownNameError
from sim.files import write_atomic
from sim.model.kinematics import local_rotations
from sim.model.rotations import Y_UP_TO_Z_UP, continuous_euler, euler_angles_deg

_ROTATIONS = "Zrotation Yrotation Xrotation"  # R = Rz Ry Rx: X applied first ("XYZ")


def bvh_text(
    skeleton: Skeleton, motion: Motion, fps: float, *, unit: str = "cm", up: str = "y"
) -> str:
    """The BVH text of ``motion`` on ``skeleton`` at ``fps`` (see the module docstring).

    Args:
        motion: root (T, 6) as (tx, ty, tz [m], rx, ry, rz [deg]) in the skeleton's (y-up) axes;
            angles: bone -> (T, n_dofs) [deg].
        unit: the file's length unit, a key of :data:`sim.bvh.convert.UNITS` (default cm).
        up: ``"y"`` (default) or ``"z"``: the file's up axis.
    """
    if unit not in UNITS:
        raise UnknownNameError("unit", unit, UNITS)
    if up not in UPS:
        raise UnknownNameError("up axis", up, UPS)
    if not (np.isfinite(motion.root).all() and fps > 0):
        raise MotionDataError(motion.path or None, None, "root must be finite, fps positive")
    A = np.eye(3) if up == "y" else Y_UP_TO_Z_UP  # y-up axes -> the file's
    scale = 1.0 / UNITS[unit]
    rotations = local_rotations(skeleton, motion)
    children: dict[str, list] = {}
    for b in skeleton.bones:
        children.setdefault(b.parent, []).append(b)
    vector = {b.name: A @ (b.length * b.direction) * scale for b in skeleton.bones}
    vector["root"] = np.zeros(3)

    out = io.StringIO()
    w = out.write
    columns = [(motion.root[:, :3] @ A.T) * scale, _angles(A, rotations["root"])]

    def joint(name: str, parent: str, depth: int) -> None:
        ind = "  " * depth
        w(f"{ind}JOINT {name}\n{ind}{{\n{ind}  OFFSET {_vec(vector[parent])}\n")
        w(f"{ind}  CHANNELS 3 {_ROTATIONS}\n")
        columns.append(_angles(A, rotations[name]))
        kids = children.get(name, [])
        for c in kids:
            joint(c.name, name, depth + 1)
        if not kids:
            w(f"{ind}  End Site\n{ind}  {{\n{ind}    OFFSET {_vec(vector[name])}\n{ind}  }}\n")
        w(f"{ind}}}\n")

    w("HIERARCHY\nROOT root\n{\n  OFFSET 0 0 0\n")
    w(f"  CHANNELS 6 Xposition Yposition Zposition {_ROTATIONS}\n")
    for b in children.get("root", []):
        joint(b.name, "root", 1)
    w("}\n")
    w(f"MOTION\nFrames: {motion.n_frames}\nFrame Time: {1.0 / fps:.10f}\n")
    table = np.concatenate(columns, axis=1)
    np.savetxt(out, table, fmt="%.6f")
    return out.getvalue()


def write_bvh(
    path: str | os.PathLike,
    skeleton: Skeleton,
    motion: Motion,
    fps: float,
    *,
    unit: str = "cm",
    up: str = "y",
) -> Path:
    """Write ``motion`` on ``skeleton`` as a BVH file at ``path``, atomically."""
    path = Path(path)
    data = bvh_text(skeleton, motion, fps, unit=unit, up=up).encode("ascii")
    write_atomic(path, lambda f: f.write(data))
    return path


def _angles(A: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(T, 3) ``Zrotation Yrotation Xrotation`` [deg] of rotations ``R`` (y-up axes) in the
    file's axes, continuous over the take."""
    xyz = euler_angles_deg(A @ R @ A.T, "XYZ")
    xyz = np.rad2deg(continuous_euler(np.deg2rad(xyz), "XYZ"))
    return xyz[:, ::-1]


def _vec(v: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in np.round(v, 6) + 0.0)
