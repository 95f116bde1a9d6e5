"""A trial's files, whatever their format: an Acclaim pair (ASF skeleton + AMC motion) or one BVH
file (skeleton and motion together), read into the same Acclaim records
(:class:`~sim.acclaim.records.Skeleton`, :class:`~sim.acclaim.records.Motion`) and the source
frame rate.

Everywhere a command takes ``ASF AMC`` it takes a ``.bvh`` alone: the BVH's path stands in for
both (a :class:`~sim.motion.dataset.Trial` of a BVH has ``asf == amc``).
"""

from __future__ import annotations

import os
from pathlib import Path

from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import parse_asf
from sim.acclaim.records import Motion, Skeleton
from sim.bvh.convert import to_acclaim
from sim.bvh.reader import parse_bvh

CMU_FPS = 120.0  # an AMC file holds no rate: CMU's


def is_bvh(path: str | os.PathLike | None) -> bool:
    """Whether ``path`` names a BVH file (by its suffix, any capitalisation)."""
    return path is not None and Path(path).suffix.lower() == ".bvh"


def read_skeleton(path: str | os.PathLike, *, unit: str | None = None, up: str = "y") -> Skeleton:
    """The skeleton of an ASF file or of a BVH file (``unit``, ``up``: :func:`sim.bvh.convert.to_acclaim`).

    Raises:
        MotionDataError: a malformed or unreadable file (one line naming file and line).
    """
    if is_bvh(path):
        return to_acclaim(parse_bvh(path), unit=unit, up=up).skeleton
    return parse_asf(path)


def read_trial(
    asf: str | os.PathLike,
    amc: str | os.PathLike | None = None,
    *,
    unit: str | None = None,
    up: str = "y",
    source_fps: float = CMU_FPS,
) -> tuple[Skeleton, Motion, float]:
    """(skeleton, motion, source rate [frames per second]) of a trial: ``asf`` and ``amc``, or a
    BVH file as either (its own rate; ``source_fps`` is the AMC's).

    Raises:
        MotionDataError: a malformed or unreadable file (one line naming file and line).
    """
    bvh = asf if is_bvh(asf) else amc if is_bvh(amc) else None
    if bvh is not None:
        take = to_acclaim(parse_bvh(bvh), unit=unit, up=up)
        return take.skeleton, take.motion, take.fps
    skeleton = parse_asf(asf)
    return skeleton, parse_amc(amc, skeleton), source_fps
