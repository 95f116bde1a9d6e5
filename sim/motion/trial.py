"""A trial's files, whatever their format: an Acclaim pair (ASF skeleton + AMC motion) or one BVH
file (skeleton and motion together), read into the same Acclaim records
(:class:`~sim.acclaim.records.Skeleton`, :class:`~sim.acclaim.records.Motion`) and the source
frame rate.

Everywhere a command takes ``ASF AMC`` it takes a ``.bvh`` alone: the BVH's path stands in for
both (a :class:`~sim.motion.dataset.Trial` of a BVH has ``asf == amc``).
"""

from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import mujoco

from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import parse_asf
from sim.acclaim.records import Motion, Skeleton
from sim.acclaim.writer import write_amc, write_asf
from sim.bvh.convert import to_acclaim
from sim.bvh.reader import parse_bvh
from sim.bvh.records import MAX_BVH_BYTES
from sim.bvh.stream import first_skeleton
from sim.bvh.stream import read_skeleton as bvh_skeleton
from sim.bvh.writer import write_bvh
from sim.errors import MotionDataError, UsageError
from sim.files import read_regular
from sim.model import humanoid
from sim.motion.clip import load_npz
from sim.motion.retarget import qpos_to_motion

CMU_FPS = 120.0  # an AMC file holds no rate: CMU's


def is_bvh(path: str | os.PathLike | None) -> bool:
    """Whether ``path`` names a BVH file (by its suffix, any capitalisation)."""
    return path is not None and Path(path).suffix.lower() == ".bvh"


def read_skeleton(path: str | os.PathLike, *, unit: str | None = None, up: str = "y") -> Skeleton:
    """The skeleton of an ASF file or of a BVH file (``unit``, ``up``: :func:`sim.bvh.convert.to_acclaim`;
    the BVH read a chunk at a time, :func:`sim.bvh.stream.read_skeleton`).

    Raises:
        MotionDataError: a malformed or unreadable file (one line naming file and line).
    """
    if is_bvh(path):
        return bvh_skeleton(path, unit=unit, up=up)
    return parse_asf(path)


def trial_files(asf, amc) -> str | os.PathLike | None:
    """The BVH file among a trial's arguments (None for an ASF + AMC pair).

    Raises:
        UsageError: an ASF without its AMC, or a BVH given with a second file.
    """
    if is_bvh(asf) or is_bvh(amc):
        if amc is not None and asf is not None and amc != asf:
            raise UsageError(f"a .bvh holds its skeleton and motion: give it alone, not with {amc}")
        return asf if is_bvh(asf) else amc
    if amc is None:
        raise UsageError(f"{asf}: an ASF skeleton needs its AMC motion (or give one .bvh file)")
    return None


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
    bvh = trial_files(asf, amc)
    if bvh is not None:
        take = to_acclaim(parse_bvh(bvh), unit=unit, up=up)
        return take.skeleton, take.motion, take.fps
    skeleton = parse_asf(asf)
    return skeleton, parse_amc(amc, skeleton), source_fps


def subject_model(path: str | os.PathLike, *, unit: str | None = None, up: str = "y"):
    """(skeleton, MjModel) of a subject's own humanoid: an ASF's
    (:func:`sim.model.humanoid.subject_model`) or a BVH's (its skeleton, ``unit`` and ``up`` as
    :func:`read_skeleton` takes them: every bone's length one of its OFFSETs), cached per file
    content.

    Raises:
        MotionDataError: an unreadable or malformed file, or a skeleton MuJoCo refuses.
    """
    if not is_bvh(path):
        return humanoid.subject_model(path)
    data = read_regular(path, MAX_BVH_BYTES)  # a regular file of bounded size, never a device
    return _bvh_model(str(Path(path).resolve()), hashlib.sha256(data).hexdigest(), unit, up)


def head_skeleton(path: str | os.PathLike) -> Skeleton:
    """:func:`read_skeleton` of a valid file, a BVH's frames read no further than its first chunk
    (:func:`sim.bvh.stream.first_skeleton`: a defect further on is raised by the reading of the
    frames that follows, e.g. :func:`sim.motion.chunks.stream_clips`)."""
    return first_skeleton(path) if is_bvh(path) else parse_asf(path)


@lru_cache(maxsize=16)
def _bvh_model(path: str, digest: str, unit: str | None, up: str):
    return skeleton_model(read_skeleton(path, unit=unit, up=up), path)


def skeleton_model(skeleton: Skeleton, path: str | os.PathLike):
    """(skeleton, MjModel) of the humanoid of a BVH file's ``skeleton`` (read from ``path``,
    named in errors), uncached.

    Raises:
        MotionDataError: a skeleton MuJoCo refuses.
    """
    try:
        return skeleton, mujoco.MjModel.from_xml_string(humanoid.build_mjcf(skeleton))
    except ValueError as e:  # MuJoCo's compiler; MotionDataError (also a ValueError) passes
        if isinstance(e, MotionDataError):
            raise
        raise MotionDataError(path, None, f"cannot build a model: {e}") from e


def convert_trial(
    asf: str | os.PathLike,
    amc: str | os.PathLike | None,
    out: str | os.PathLike,
    *,
    unit: str | None = None,
    up: str = "y",
) -> list[Path]:
    """Write a trial in the other format: ASF + AMC -> ``out`` ``.bvh`` (in ``unit``, default
    centimetres, ``up`` axis), or a BVH (read with ``unit`` and ``up``) -> ``out`` ``.amc`` and
    its skeleton beside it (``out`` with ``.asf``); or a clip ``.npz`` (with its skeleton's ASF or
    BVH as ``amc``, or none: the shared humanoid's) -> ``.bvh`` (:func:`export_clip`). Written
    atomically; returns the paths.

    Raises:
        UsageError: an output that is neither ``.bvh`` nor ``.amc``, or the format of the input.
        MotionDataError: a malformed input (one line naming file and line).
    """
    out = Path(out)
    if Path(asf).suffix.lower() == ".npz":
        if out.suffix.lower() != ".bvh":
            raise UsageError(f"{out}: a clip (.npz) converts to .bvh")
        return [export_clip(asf, out, amc, unit=unit or "cm", up=up)]
    bvh = trial_files(asf, amc)
    suffix = out.suffix.lower()
    wanted = ".amc" if bvh is not None else ".bvh"
    if suffix != wanted:
        raise UsageError(f"{out}: a {'BVH' if bvh else 'ASF + AMC'} input converts to {wanted}")
    if bvh is None:
        skeleton, motion, fps = read_trial(asf, amc)
        return [write_bvh(out, skeleton, motion, fps, unit=unit or "cm", up=up)]
    skeleton, motion, fps = read_trial(bvh, unit=unit, up=up)
    comment = f"converted from {Path(bvh).name}: {fps:g} fps"
    return [write_asf(out.with_suffix(".asf"), skeleton), write_amc(out, skeleton, motion, comment)]


def export_clip(
    clip_path: str | os.PathLike,
    out: str | os.PathLike,
    skeleton_path: str | os.PathLike | None = None,
    *,
    unit: str = "cm",
    up: str = "y",
) -> Path:
    """Write a clip file (``.npz`` of ``ingest``, ``synth``, ``decode``: its ``qpos`` and
    ``joint_names``) as a BVH at ``out``, on the skeleton whose model the ``qpos`` is of: the ASF
    or BVH ``skeleton_path``, by default the shared humanoid's (``synth``'s clips).

    Raises:
        MotionDataError: a bad clip, or one whose hinges are not the skeleton's.
    """
    clip = load_npz(clip_path)
    skeleton = (
        humanoid.canonical_skeleton() if skeleton_path is None else read_skeleton(skeleton_path)
    )
    motion = qpos_to_motion(skeleton, clip.qpos, clip.joint_names)
    return write_bvh(out, skeleton, motion, clip.fps, unit=unit, up=up)
