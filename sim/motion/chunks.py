"""A trial read, retargeted and resampled a chunk of frames at a time (bounded memory, any length).

:func:`stream_clips` yields consecutive :class:`~sim.motion.clip.Clip` pieces of an ASF + AMC
trial, or of a BVH file, at ``fps`` on the subject's own skeleton: frame ``n`` of the
concatenated pieces is frame ``n`` of ``load_motion(asf, amc, fps=fps, derivatives=False)``. The
AMC is read by :func:`sim.acclaim.amc.iter_amc`, the BVH by :func:`sim.bvh.stream.iter_take`
(one text chunk at a time; a BVH whose rate ``fps`` does not divide is refused: it must be
resampled whole, :func:`~sim.motion.ingest.load_motion`), and each piece is retargeted with
:data:`MARGIN` source frames of context on each side, so its joint velocities (central
differences, never across a pose jump) see the same neighbours as in the whole take. A take of at
most ``chunk_frames`` output frames plus the margin is retargeted in one piece, exactly as
:func:`~sim.motion.ingest.load_motion` does it.

Positions of a frame depend only on that frame; velocities differ from the whole take's only
where a run of pose jumps is longer than the margin or an Euler-angle flip is resolved
differently (rotations equal to rounding). Memory: the pieces' source frames plus the margins,
whatever the take's length.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np

from sim.acclaim.amc import MAX_STREAMED_AMC_BYTES, iter_amc
from sim.acclaim.records import Motion
from sim.bvh.reader import parse_bvh
from sim.bvh.records import MAX_BVH_BYTES
from sim.bvh.stream import iter_take
from sim.errors import UsageError
from sim.model.kinematics import point_names, point_parents
from sim.motion.ingest import clip_from_qpos, resample_step
from sim.motion.retarget import motion_to_qpos
from sim.motion.trial import CMU_FPS, skeleton_model, subject_model, trial_files

#: Source frames of context on each side of a piece (pose-jump windows and velocity stencils).
MARGIN = 64


def stream_clips(
    asf: str | os.PathLike,
    amc: str | os.PathLike,
    *,
    fps: float = 30.0,
    chunk_frames: int = 1800,
    source_fps: float = CMU_FPS,
    max_bytes: int | None = None,
    velocities: bool = True,
):
    """Yield the trial as consecutive clips of ``chunk_frames`` frames at ``fps`` (the last one
    up to ``chunk_frames`` plus the margin), positions and velocities [m, m/s] in world axes (z
    up), no source derivatives (see the module docstring); ``velocities=False``: positions only,
    velocities zero (:func:`~sim.motion.ingest.clip_from_qpos`).

    Args:
        asf, amc: the subject's skeleton and motion, or a BVH file as either (or both; its
            length unit detected, y up); ``source_fps``: the AMC's rate (a BVH's is its own).
        max_bytes: the largest file read; None: the format's (AMC
            :data:`~sim.acclaim.amc.MAX_STREAMED_AMC_BYTES`, BVH
            :data:`~sim.bvh.records.MAX_BVH_BYTES`, the whole-file reader's bound).

    Raises:
        MotionDataError: malformed files (naming file and line), when the bad chunk is read.
        UsageError: an output rate that does not divide the source rate; ``chunk_frames`` < 1.
    """
    bvh = trial_files(asf, amc)
    if bvh is not None:
        source_fps = parse_bvh(bvh, motion=False).fps  # the hierarchy and header only
    step = resample_step(source_fps, fps)
    if chunk_frames < 1:
        raise UsageError(f"chunk_frames must be >= 1; got {chunk_frames}")
    if bvh is None:
        subject, model = subject_model(asf)
        source = iter_amc(amc, subject, max_bytes=max_bytes or MAX_STREAMED_AMC_BYTES)
    else:  # the skeleton of the first piece is the whole file's: the file is read once
        takes = iter_take(bvh, max_bytes=max_bytes or MAX_BVH_BYTES)
        first = next(takes, None)
        if first is None:
            subject, model = subject_model(bvh)
        else:
            subject, model = skeleton_model(first.skeleton, str(Path(bvh).resolve()))
        source = (take.motion for take in itertools.chain([first] if first else [], takes))
    amc = bvh or amc
    names, parents = point_names(subject), point_parents(subject)
    data = mujoco.MjData(model)
    margin = -(-MARGIN // step) * step  # whole output frames
    size = chunk_frames * step  # source frames per piece
    pieces: list[Motion] = []
    start = 0  # source index of pieces[0]'s first frame
    done = 0  # source frames already turned into output (a multiple of step)
    end = 0  # source frames read

    def emit(stop: int, last: bool):
        a = max(done - margin, start)
        b = end if last else min(stop + margin, end)
        motion = _frames(pieces, start, a, b)
        qpos = motion_to_qpos(subject, motion, model)
        del motion
        clip = clip_from_qpos(
            model, names, parents, qpos, source_fps=source_fps, fps=fps,
            source=str(Path(amc)), data=data, derivatives=False, velocities=velocities,
        )  # fmt: skip
        first = (done - a) // step
        count = -(-(stop - done) // step)
        return replace(clip.slice(first, first + count), start_frame=done)

    for piece in source:
        pieces.append(piece)
        end += piece.n_frames
        while end > done + size + margin:  # a whole piece with its margins, and more
            out = emit(done + size, last=False)
            done += size
            pieces, start = _drop(pieces, start, done - margin)
            yield out
    if end > done:
        out = emit(end, last=True)
        pieces = []
        yield out


def _frames(pieces: list[Motion], start: int, a: int, b: int) -> Motion:
    """Source frames ``[a, b)`` of the pieces (the first starting at source frame ``start``)."""
    roots, angles = [], {k: [] for k in pieces[0].angles}
    at = start
    for p in pieces:
        lo, hi = max(a - at, 0), min(b - at, p.n_frames)
        if lo < hi:
            roots.append(p.root[lo:hi])
            for k in angles:
                angles[k].append(p.angles[k][lo:hi])
        at += p.n_frames
    return Motion(
        path=pieces[0].path,
        root=np.concatenate(roots),
        angles={k: np.concatenate(v) for k, v in angles.items()},
        first_frame=pieces[0].first_frame + a - start,
        notes=pieces[-1].notes,
    )


def _drop(pieces: list[Motion], start: int, keep_from: int) -> tuple[list[Motion], int]:
    """The pieces without their source frames before ``keep_from``; the new start."""
    while pieces and start + pieces[0].n_frames <= keep_from:
        start += pieces[0].n_frames
        pieces = pieces[1:]
    return pieces, start
