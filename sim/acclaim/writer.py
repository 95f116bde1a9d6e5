"""Write an Acclaim AMC motion (the inverse of :func:`sim.acclaim.amc.parse_amc`) and its ASF
skeleton (the inverse of :func:`sim.acclaim.asf.parse_asf`).

The file is ``:FULLY-SPECIFIED`` and ``:DEGREES``, frames numbered from ``motion.first_frame``,
the root's channels in the skeleton's ``root_order`` with translations in the skeleton's length
unit, then every bone that has dofs, in the skeleton's order, its values in dof order. CMU tools
(and this project's reader) read it with the ASF it was written for.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from sim.acclaim.records import INCH, ROOT_CHANNELS, Motion, Skeleton
from sim.errors import MotionDataError
from sim.files import write_atomic


def amc_text(skeleton: Skeleton, motion: Motion, comment: str = "") -> str:
    """The AMC text of ``motion`` for ``skeleton`` (see the module docstring).

    Args:
        motion: root (T, 6) as (tx, ty, tz [m], rx, ry, rz [deg]); angles: bone -> (T, n_dofs)
            [deg]; bones with dofs missing from ``motion.angles`` are written as zeros.
    """
    T = motion.n_frames
    root = np.asarray(motion.root, dtype=np.float64).copy()
    if root.shape != (T, 6) or not np.isfinite(root).all():
        raise MotionDataError(motion.path or None, None, "root must be finite (T, 6)")
    root[:, :3] /= skeleton.length_to_metres
    root = root[:, [ROOT_CHANNELS.index(c) for c in skeleton.root_order]]
    columns = [("root", root)]
    for b in skeleton.bones:
        if not b.dofs:
            continue
        a = motion.angles.get(b.name)
        a = np.zeros((T, len(b.dofs))) if a is None else np.asarray(a, dtype=np.float64)
        if a.shape != (T, len(b.dofs)) or not np.isfinite(a).all():
            raise MotionDataError(motion.path or None, None, f"bad angles for bone {b.name!r}")
        columns.append((b.name, a))
    # one (T, ) column of text lines per bone, then interleave frame by frame
    lines = [[f"{f}" for f in range(motion.first_frame, motion.first_frame + T)]]
    for name, values in columns:
        text = np.char.mod("%.6f", values)
        joined = [" ".join(row) for row in text.tolist()]
        lines.append([f"{name} {row}" for row in joined])
    out = io.StringIO()
    if comment:
        out.write(f"# {comment}\n")
    out.write(":FULLY-SPECIFIED\n:DEGREES\n")
    for frame in zip(*lines, strict=True):
        out.write("\n".join(frame))
        out.write("\n")
    return out.getvalue()


def write_amc(
    path: str | os.PathLike, skeleton: Skeleton, motion: Motion, comment: str = ""
) -> Path:
    """Write ``motion`` as an AMC file for ``skeleton`` at ``path``, atomically."""
    path = Path(path)
    data = amc_text(skeleton, motion, comment).encode("ascii")
    write_atomic(path, lambda f: f.write(data))
    return path


def asf_text(skeleton: Skeleton) -> str:
    """The ASF text of ``skeleton``: lengths in its own unit (``:units length L`` with
    ``L = 0.0254 / length_to_metres``, CMU's convention), angles in degrees, 9 significant
    digits."""
    L = INCH / skeleton.length_to_metres
    out = [":version 1.10", f":name {skeleton.name or 'skeleton'}", ":units", "  mass 1.0",
           f"  length {L:.12g}", "  angle deg", ":root", f"  order {' '.join(c.upper() for c in skeleton.root_order)}",
           f"  axis {skeleton.root_axis_order}", "  position 0 0 0",
           f"  orientation {_numbers(skeleton.root_orientation)}", ":bonedata"]  # fmt: skip
    for i, b in enumerate(skeleton.bones, start=1):
        out += ["  begin", f"    id {i}", f"    name {b.name}", f"    direction {_numbers(b.direction)}",
                f"    length {b.length / skeleton.length_to_metres:.12g}",
                f"    axis {_numbers(b.axis)} {b.axis_order}"]  # fmt: skip
        if b.dofs:
            out.append(f"    dof {' '.join(b.dofs)}")
            pairs = [f"({lo:.9g} {hi:.9g})" for lo, hi in b.limits]
            out.append(f"    limits {pairs[0]}")
            out += [f"           {p}" for p in pairs[1:]]
        out.append("  end")
    out.append(":hierarchy\n  begin")
    children: dict[str, list[str]] = {}
    for b in skeleton.bones:
        children.setdefault(b.parent, []).append(b.name)
    out += [f"    {parent} {' '.join(kids)}" for parent, kids in children.items()]
    out.append("  end")
    return "\n".join(out) + "\n"


def write_asf(path: str | os.PathLike, skeleton: Skeleton) -> Path:
    """Write ``skeleton`` as an ASF file at ``path``, atomically."""
    path = Path(path)
    data = asf_text(skeleton).encode("ascii")
    write_atomic(path, lambda f: f.write(data))
    return path


def _numbers(v) -> str:
    return " ".join(f"{x:.12g}" for x in np.asarray(v, dtype=np.float64) + 0.0)
