"""Ingest: ASF + AMC (or a BVH) -> a :class:`~sim.motion.clip.Clip` of positions and true velocities.

Parse, retarget to a humanoid (the subject's own or the shared one), differentiate ``qpos`` at the
source rate, resample by taking every k-th frame, and read positions, velocities and orientations
off the kinematic chain.
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from sim.acclaim.amc import parse_amc
from sim.errors import MotionDataError, UnknownNameError, UsageError
from sim.model.humanoid import humanoid_model
from sim.model.kinematics import point_names, point_parents
from sim.motion.clip import Clip
from sim.motion.resample import grid_rate, resample_qpos, resampled_frames
from sim.motion.retarget import (
    leg_length,
    local_rotations_from_world,
    motion_to_qpos,
    retarget_rotations,
)
from sim.motion.trial import CMU_FPS, read_trial, subject_model, trial_files
from sim.motion.velocities import (
    body_rotation_steps,
    derivative_noise,
    kin_related,
    point_cuts,
    point_derivatives,
    point_kinematics,
    pose_jumps,
    qvel_from_qpos,
)

SKELETONS = ("subject", "humanoid")
#: Memory bound of :func:`load_motion`: the arrays it builds, about :data:`BYTES_PER_POINT_FRAME`
#: per point and source frame (measured: ``benchmarks/fuzz_campaign.py``), at most
#: :data:`ARRAY_BYTES_PER_INPUT_BYTE` times the AMC file's size or :data:`ARRAY_BYTES_FLOOR`
#: (any trial of up to ~12,000 source frames), checked from the parsed frame count before any
#: is built. A real CMU trial needs ~25x its size; a root-only AMC (20 bytes a frame) ~700x.
BYTES_PER_POINT_FRAME = 700
ARRAY_BYTES_PER_INPUT_BYTE = 128
ARRAY_BYTES_FLOOR = 256 << 20


def resample_step(source_fps: float, fps: float) -> int:
    """Frames of the source per output frame; the ratio must be a whole number.

    Raises:
        UsageError: a rate that is not positive, or an output rate that does not divide the
            source rate by a whole number.
    """
    if not (0 < fps < np.inf and 0 < source_fps < np.inf):
        raise UsageError(
            f"frame rates must be positive and finite (source {source_fps}, output {fps})"
        )
    step = source_fps / fps
    if abs(step - round(step)) > 1e-9 or round(step) < 1:
        raise UsageError(
            f"output rate {fps} fps must divide the source rate {source_fps} fps by a whole number"
        )
    return int(round(step))


def clip_from_qpos(
    model,
    names: tuple[str, ...],
    parents: np.ndarray,
    qpos: np.ndarray,
    *,
    source_fps: float,
    fps: float,
    source: str = "",
    data: mujoco.MjData | None = None,
    derivatives: bool = True,
    velocities: bool = True,
) -> Clip:
    """Clip at ``fps`` of a ``qpos`` stream sampled at ``source_fps`` on ``model``.

    Point ``j`` is the site ``<names[j]>_end`` (the root: the root body's origin). Velocities are
    taken at the source rate (central differences of qpos, never across a pose jump of the data:
    :func:`sim.motion.velocities.qvel_from_qpos`), then mapped through the chain; the
    points' ``source_velocities`` and ``accelerations`` come from their positions in every source
    frame (:func:`sim.motion.velocities.point_derivatives`), never across a pose jump either.
    ``data``: the job's ``MjData`` of ``model``, reused for every frame (made here when None: one
    per trial). ``derivatives=False`` leaves ``source_velocities`` and ``accelerations`` out (None):
    a caller that needs neither (the codec) saves the kinematics of every source frame.
    ``velocities=False`` (and no ``derivatives``): ``qvel`` and all velocities zero, positions alone.

    Raises:
        MotionDataError: (naming ``source``) a non-finite ``qpos`` or any non-finite result; the
            reader's bounds make this unreachable for parsed files, it guards every other caller.
    """
    if not np.isfinite(qpos).all():
        raise MotionDataError(source or None, None, "non-finite joint positions (qpos)")
    step = resample_step(source_fps, fps)
    frames = np.arange(0, qpos.shape[0], step)
    body_ids, site_ids = [], []
    for n in names:
        body_ids.append(model.body(n).id)
        site_ids.append(-1 if n == "root" else model.site(f"{n}_end").id)
    data = mujoco.MjData(model) if data is None else data
    with np.errstate(all="ignore"):  # overflow shows up as non-finite values, refused below
        qvel, jumps = _joint_velocities(model, qpos, source_fps, frames, velocities or derivatives)
        if not np.isfinite(qvel).all():
            raise MotionDataError(source or None, None, "non-finite joint velocities (qvel)")
        pos, vel, xquat, omega = point_kinematics(
            model, data, qpos[frames], qvel if velocities or derivatives else None, body_ids,
            site_ids,
        )  # fmt: skip
        src_vel = acc = noise = None
        if derivatives:
            every = point_kinematics(model, data, qpos, None, body_ids, site_ids)[0]
            cuts = point_cuts(model, jumps, body_ids)
            src_vel, acc = point_derivatives(every, source_fps, frames, cuts=cuts)
            noise = derivative_noise(len(qpos), frames, cuts=cuts)
    joint_names = tuple(model.joint(j).name for j in range(1, model.njnt))
    arrays = (("positions", pos), ("velocities", vel), ("rotations", xquat),
              ("source velocities", src_vel), ("accelerations", acc))  # fmt: skip
    for what, a in arrays:
        if a is not None and not np.isfinite(a).all():
            raise MotionDataError(source or None, None, f"non-finite {what} from the motion")
    if not np.isfinite(omega).all():
        raise MotionDataError(source or None, None, "non-finite angular velocities")
    return Clip(
        names=tuple(names),
        parents=np.asarray(parents, dtype=np.int64),
        positions=pos,
        velocities=vel,
        qpos=qpos[frames].copy(),
        qvel=qvel,
        rotations=local_rotations_from_world(xquat, np.asarray(parents)),
        fps=float(fps),
        source=source,
        start_frame=0,
        source_fps=float(source_fps),
        joint_names=joint_names,
        angular_velocities=omega,
        source_velocities=src_vel,
        accelerations=acc,
        derivative_noise=noise,
    )


def _joint_velocities(model, qpos, source_fps: float, frames, velocities: bool):
    """``qvel`` at ``frames`` (never differenced across a pose jump) and the pose jumps; zeros
    and None without ``velocities``."""
    if not velocities:
        return np.zeros((len(frames), model.nv)), None
    jumps = pose_jumps(body_rotation_steps(model, qpos), source_fps, kin_related(model))
    qvel = qvel_from_qpos(model, qpos, source_fps, frames, across_jumps=False, jumps=jumps)
    return qvel, jumps


def load_motion(
    asf: str | os.PathLike,
    amc: str | os.PathLike | None = None,
    *,
    skeleton: str = "subject",
    fps: float = 30.0,
    source_fps: float = CMU_FPS,
    derivatives: bool = True,
    unit: str | None = None,
    up: str = "y",
) -> Clip:
    """A whole trial as one clip at ``fps``.

    Args:
        asf, amc: the subject's skeleton and one of its motions; or a BVH file as ``asf`` (or
            both): its skeleton and motion, at its own rate (:mod:`sim.bvh.convert`: ``unit``
            None detects the length unit, ``up`` is its up axis).
        skeleton: ``"subject"`` (the subject's own generated model: exact ASF/AMC kinematics) or
            ``"humanoid"`` (the shared ``models/cmu_humanoid.xml``; angles copied, root translation
            scaled by the leg-length ratio; a BVH's rotations are re-expressed in its bones'
            frames, :func:`sim.motion.retarget.retarget_rotations`).
        fps: output rate; ``source_fps / fps`` must be a whole number (CMU: 120 -> 30 takes every
            4th frame). A BVH whose rate it does not divide is first interpolated onto the least
            whole multiple of ``fps`` above its rate (:mod:`sim.motion.resample`: 100 -> 120).
        derivatives: also the points' velocities and accelerations from every source frame
            (``source_velocities``, ``accelerations``; :func:`clip_from_qpos`).

    Raises:
        MotionDataError: malformed files (naming file, line and problem).
    """
    if skeleton not in SKELETONS:
        raise UnknownNameError("skeleton", skeleton, SKELETONS)
    bvh = trial_files(asf, amc)
    if bvh is None:  # a BVH's own rate is known once it is read
        resample_step(source_fps, fps)  # refused before any file is read
    subject, model = subject_model(bvh or asf, unit=unit, up=up)
    if bvh is None:
        motion = parse_amc(amc, subject)
    else:
        _, motion, source_fps = read_trial(bvh, unit=unit, up=up)
    frames = motion.n_frames
    if bvh is not None:  # a rate the clip rate does not divide: the frames once resampled
        frames = resampled_frames(frames, source_fps, grid_rate(source_fps, fps))
    check_memory(bvh or amc, frames, len(point_names(subject)))
    root_scale = 1.0
    target = subject
    if skeleton == "humanoid":
        target, model = humanoid_model()
        if bvh is not None:
            subject, motion = retarget_rotations(subject, motion, target)
        root_scale = leg_length(target) / leg_length(subject)
    qpos = motion_to_qpos(subject if bvh is None else target, motion, model, root_scale=root_scale)
    if bvh is not None and grid_rate(source_fps, fps) != source_fps:
        qpos = resample_qpos(qpos, source_fps, grid_rate(source_fps, fps))
        source_fps = grid_rate(source_fps, fps)
    return clip_from_qpos(
        model,
        point_names(target),
        point_parents(target),
        qpos,
        source_fps=source_fps,
        fps=fps,
        source=str(Path(bvh or amc)),
        derivatives=derivatives,
    )


def check_memory(amc, frames: int, points: int) -> None:
    """Refuse a trial whose arrays would pass the stated bound (see :data:`ARRAY_BYTES_FLOOR`)."""
    need = frames * points * BYTES_PER_POINT_FRAME
    size = os.stat(amc).st_size
    limit = max(ARRAY_BYTES_FLOOR, ARRAY_BYTES_PER_INPUT_BYTE * size)
    if need > limit:
        raise MotionDataError(
            str(amc), None, f"{frames:,} frames of {points} points need ~{need >> 20:,} MB of "
            f"arrays; at most {ARRAY_BYTES_PER_INPUT_BYTE}x the file's {size:,} bytes "
            f"(or {ARRAY_BYTES_FLOOR >> 20} MB)",
        )  # fmt: skip


def load_clips(
    asf: str | os.PathLike,
    amc: str | os.PathLike | None = None,
    *,
    fps: float = 30.0,
    length: int = 60,
    skeleton: str = "subject",
) -> list[Clip]:
    """Non-overlapping ``length``-frame clips from frame 0 of a trial at ``fps``.

    Raises:
        UsageError: ``length`` is not a whole number of frames >= 2 (and as :func:`load_motion`).
    """
    if isinstance(length, bool) or not isinstance(length, (int, np.integer)) or length < 2:
        raise UsageError(f"clip length must be a whole number of frames >= 2; got {length!r}")
    return load_motion(asf, amc, skeleton=skeleton, fps=fps).split(length)
