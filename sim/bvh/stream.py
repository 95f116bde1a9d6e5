"""A BVH file read as Acclaim records a chunk of frames at a time (bounded memory, any length).

:func:`iter_take` yields consecutive :class:`~sim.bvh.convert.Take` pieces of one file: their
motions joined frame after frame are ``to_acclaim(parse_bvh(path)).motion``, value for value,
and every piece's skeleton is the whole file's. Two facts of the whole file make that so:

* a joint's OFFSET may be replaced by its constant position channels, read from the file's
  first frame: each piece is converted with that frame put before its own (and dropped after),
  so every piece has the skeleton (and the bone names) of the whole file;
* those channels may not move over the whole take (by more than ``1e-6`` of the first frame's
  value, :mod:`sim.bvh.convert`): their least and greatest values so far are kept, and a
  channel that moves is refused with the whole file's one-line error when the chunk that moves
  it is read.

Every other step of the conversion (the root's translation and rotation, the joints' angles)
is frame by frame: the skeleton is built from the first piece, and each later piece's motion
alone is converted (:func:`sim.bvh.convert.motion_like`). :func:`read_skeleton` is the whole file's skeleton, read this way;
:func:`first_skeleton` the same for a valid file, its first chunk alone read.

Units as :mod:`sim.bvh.convert`: lengths [m], angles [deg], y-up axes.
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np

from sim.acclaim.records import Skeleton
from sim.bvh.convert import motion_like, to_acclaim
from sim.bvh.reader import iter_bvh
from sim.bvh.records import MAX_BVH_BYTES, Bvh
from sim.errors import MotionDataError
from sim.files import excerpt


def iter_take(
    path: str | os.PathLike,
    *,
    unit: str | None = None,
    up: str = "y",
    max_bytes: int = MAX_BVH_BYTES,
):
    """Yield the BVH file ``path`` as consecutive :class:`~sim.bvh.convert.Take` pieces (see
    the module docstring; ``unit``, ``up``: :func:`sim.bvh.convert.to_acclaim`).

    Raises:
        MotionDataError: as ``to_acclaim(parse_bvh(path))`` (one line naming file and line),
            when the chunk that holds the defect is read.
        UnknownNameError: an unknown ``unit`` or ``up``.
    """
    first, fixed, made = None, None, None
    for piece in iter_bvh(path, max_bytes=max_bytes):
        if first is None:
            first, fixed = piece.values[:1].copy(), _FixedChannels(piece)
        fixed.check(piece)
        values = np.concatenate([first, piece.values])
        whole = Bvh(piece.path, piece.joints, piece.frame_time, values, piece.motion_line)
        if made is None:  # (not ``replace``: it shares ``children``)
            take = made = to_acclaim(whole, unit=unit, up=up)
        else:  # the skeleton is the first piece's: only the motion is new
            take = replace(made, motion=motion_like(whole, made))
        motion = take.motion
        motion = replace(
            motion, root=motion.root[1:], angles={k: v[1:] for k, v in motion.angles.items()}
        )
        yield replace(take, motion=motion)


def read_skeleton(path: str | os.PathLike, *, unit: str | None = None, up: str = "y") -> Skeleton:
    """``to_acclaim(parse_bvh(path), unit=unit, up=up).skeleton``, the file read a chunk at a
    time (every frame is read and checked: the same errors).

    Raises:
        MotionDataError, UnknownNameError: as :func:`iter_take`.
    """
    skeleton = None
    for take in iter_take(path, unit=unit, up=up):
        skeleton = take.skeleton if skeleton is None else skeleton
    return skeleton


def first_skeleton(path: str | os.PathLike, *, unit: str | None = None, up: str = "y") -> Skeleton:
    """:func:`read_skeleton` of a valid file from its hierarchy and first chunk of frames only
    (the skeleton depends on nothing else); a defect further on is raised, with the same one-line
    error, by whatever reads the frames next (:func:`iter_take`)."""
    takes = iter_take(path, unit=unit, up=up)
    try:
        for take in takes:
            return take.skeleton
    finally:
        takes.close()
    return read_skeleton(path, unit=unit, up=up)  # no frames: as the whole file's read says


class _FixedChannels:
    """The position channels of the joints below the ROOT over the frames read so far: the
    first frame's value and the least and greatest."""

    def __init__(self, bvh: Bvh):
        self.columns = [
            (i, f"{axis}position", j.column + j.channels.index(f"{axis}position"))
            for i, j in enumerate(bvh.joints)
            if j.parent >= 0
            for axis in "XYZ"
            if f"{axis}position" in j.channels
        ]
        cols = [c for _, _, c in self.columns]
        self.first = bvh.values[0, cols]
        self.lo, self.hi = self.first.copy(), self.first.copy()

    def check(self, bvh: Bvh) -> None:
        """Refuse a channel that moves, as :mod:`sim.bvh.convert` does over the whole file."""
        if not self.columns:
            return
        values = bvh.values[:, [c for _, _, c in self.columns]]
        self.lo = np.minimum(self.lo, values.min(axis=0))
        self.hi = np.maximum(self.hi, values.max(axis=0))
        moves = self.hi - self.lo > 1e-6 * np.maximum(1.0, np.abs(self.first))
        for k in np.flatnonzero(moves)[:1]:
            i, name, _ = self.columns[k]
            j = bvh.joints[i]
            raise MotionDataError(
                bvh.path, j.line, f"joint {excerpt(j.name)}: {name} moves; only the ROOT may move"
            )
