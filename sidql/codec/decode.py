"""Decoding: a :class:`~sidql.codec.format.Stream` -> every frame of the trial at the stream rate.

Deterministic: the same bytes give the same arrays (pure numpy, no randomness, fixed order).
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from sidql.codec import format as sidq
from sidql.codec.contact_section import pin_decoded, pinned_clip
from sidql.codec.sequence import is_sequence, iter_streams
from sidql.codec.skeleton import fit_motion, skeleton_hash
from sidql.keyframes.curves import interpolate_derivatives
from sidql.keyframes.reconstructions import Reconstruction
from sidql.keyframes.spherical import POINTS, split_channels
from sidql.keyframes.unchart import accelerations_from_chart, clip_from_chart, positions_from_chart
from sim.acclaim.writer import amc_text, write_amc
from sim.bvh.writer import write_bvh
from sim.errors import MotionDataError, OutputError
from sim.files import write_atomic
from sim.motion.clip import MAX_CLIP_FRAMES, MAX_NPZ_INFLATED, Clip, save_npz
from sim.motion.trial import read_skeleton

#: Frames turned into points at a time (:func:`reconstruct_stream`, :func:`stream_to_clip`): the
#: work is per frame, so chunks keep the temporaries small however long the stream.
CLIP_CHUNK_FRAMES = 4096


def decoded_chart(stream: sidq.Stream) -> dict[str, np.ndarray]:
    """The chart the decoder rebuilds: every frame of the trial.

    Returns:
        ``{"values": (N, D), "rates": (N, D), "second": (N, D)}`` with D = 2 M + 3 channels
        [theta | phi | root position (CMU axes)] in [rad, rad, m], their rates per second and
        second derivatives per second squared (of the curve itself,
        :func:`sidql.keyframes.curves.interpolate_derivatives`).
    """
    k = np.asarray(stream.keyframes, dtype=np.int64)
    N = int(k[-1]) + 1
    q = stream.quantiser
    D = q.n_channels
    values = np.zeros((N, D))
    if stream.coding == 2:  # predicted along the keyframes: needs their times
        values[k] = q.decode_keyframes(stream.pose_codes, k)
    else:
        values[k] = q.decode_pose(stream.pose_codes)
    rates = None
    if stream.reconstruction == "hermite":
        rates = np.zeros((N, D))
        rates[k] = q.decode_rates(stream.rate_codes)
    x, xd, xdd = interpolate_derivatives(values, rates, k, 1.0 / stream.fps, stream.reconstruction)
    return {"values": x, "rates": xd, "second": xdd}


def _split(stream: sidq.Stream, chart: dict):
    """theta, phi, dtheta, dphi, root, root_vel of a :func:`decoded_chart`."""
    theta, phi, root = split_channels(chart["values"], stream.quantiser.n_bones)
    dtheta, dphi, root_vel = split_channels(chart["rates"], stream.quantiser.n_bones)
    return theta, phi, dtheta, dphi, root, root_vel


def reconstruct_stream(stream: sidq.Stream) -> Reconstruction:
    """The decoded points: positions, velocities and accelerations (N, J, 3), world axes z up
    [m, m/s, m/s^2], rebuilt a chunk of frames at a time (bounded temporaries)."""
    chart = decoded_chart(stream)
    theta, phi, dtheta, dphi, root, root_vel = _split(stream, chart)
    ddtheta, ddphi, root_acc = split_channels(chart["second"], stream.quantiser.n_bones)
    del chart
    N, J = theta.shape[0], len(stream.names)
    P, V, A = np.empty((N, J, 3)), np.empty((N, J, 3)), np.empty((N, J, 3))
    for start in range(0, N, CLIP_CHUNK_FRAMES):
        part = slice(start, start + CLIP_CHUNK_FRAMES)
        P[part], V[part] = positions_from_chart(
            *(c[part] for c in (root, root_vel, theta, phi, dtheta, dphi)),
            stream.lengths, stream.parents,
        )  # fmt: skip
        A[part] = accelerations_from_chart(
            *(c[part] for c in (root_acc, theta, phi, dtheta, dphi, ddtheta, ddphi)),
            stream.lengths, stream.parents,
        )  # fmt: skip
    if stream.contacts is not None:  # the sender's foot contacts: each foot pinned
        P, V, A = pin_decoded(stream.contacts, stream.names, stream.keyframes, stream.fps, P, V, A)
    return Reconstruction(
        positions=P,
        velocities=V,
        names=tuple(stream.names),
        parents=np.asarray(stream.parents).copy(),
        theta=theta,
        phi=phi,
        keyframes=np.asarray(stream.keyframes).copy(),
        reconstruction=stream.reconstruction,
        fps=float(stream.fps),
        accelerations=A,
    )


def decode_to_reconstruction(path: str | os.PathLike) -> Reconstruction:
    """Read a ``.sidq`` file and rebuild every frame (the hook for ``sidql report``).

    Frame ``n`` of the result is frame ``n`` of ``load_motion(ASF, AMC, fps=stream fps)`` of the
    encoded trial: positions (N, 23, 3) [m] and velocities [m/s], world axes (z up), in
    :data:`~sidql.keyframes.spherical.POINTS` order, like any reconstruction of the project.

    A sequence of streams is joined whole in memory, so it may hold at most as many frames as
    one stream may (:func:`sidql.codec.format.frame_limit`); ``sidql decode`` to ``.npz`` or
    ``.amc`` takes longer ones stream by stream.

    Raises:
        MotionDataError: the file is missing, truncated or corrupt, or a sequence too long to
            join (one line).
    """
    if not is_sequence(path):
        return reconstruct_stream(sidq.read(path))
    parts, frames = [], 0
    for rec in _sequence_reconstructions(path):
        limit = sidq.frame_limit(len(rec.names))
        frames += len(rec.positions)
        if frames > limit:  # refused before the next stream is decoded
            raise MotionDataError(
                str(path), None, f"a sequence of more than {limit:,} frames cannot be joined in "
                "memory; decode it to .npz or .amc (stream by stream)",
            )  # fmt: skip
        parts.append(rec)
    return _joined(parts)


def first_stream(path: str | os.PathLike) -> sidq.Stream:
    """The stream of a ``.sidq`` file, or the first stream of a sequence (its rate, skeleton hash
    and points are every stream's)."""
    return next(iter_streams(path)) if is_sequence(path) else sidq.read(path)


def _sequence_reconstructions(path):
    """The reconstruction of each stream of a sequence, each after the first without its first
    frame (the one before it ends there), keyframes as frame indices of the take."""
    offset = 0
    for k, stream in enumerate(iter_streams(path)):
        rec = reconstruct_stream(stream)
        keys = rec.keyframes + offset
        if k:
            rec = _frames_from(rec, 1)
            keys = keys[1:]
        yield replace(rec, keyframes=keys)
        offset += stream.n_frames - 1


def _frames_from(rec: Reconstruction, start: int) -> Reconstruction:
    """``rec`` without its first ``start`` frames (keyframes left as they are)."""
    cut = {k: getattr(rec, k)[start:] for k in ("positions", "velocities", "theta", "phi")}
    if rec.accelerations is not None:
        cut["accelerations"] = rec.accelerations[start:]
    return replace(rec, **cut)


def _joined(parts: list[Reconstruction]) -> Reconstruction:
    """One reconstruction of consecutive parts (frames and keyframes joined)."""
    cat = {k: np.concatenate([getattr(p, k) for p in parts])
           for k in ("positions", "velocities", "theta", "phi", "keyframes")}  # fmt: skip
    if all(p.accelerations is not None for p in parts):
        cat["accelerations"] = np.concatenate([p.accelerations for p in parts])
    return replace(parts[0], **cat)


def stream_to_clip(stream: sidq.Stream, source: str = "") -> Clip:
    """The decoded trial as a 23-point :class:`Clip` (the ``sidql ingest`` format)."""
    if tuple(stream.names) != POINTS:
        raise MotionDataError(source or None, None, "stream points are not the CMU protocol's")
    if stream.contacts is not None:  # the pinned points charted again (legs keep their lengths)
        return pinned_clip(reconstruct_stream(stream), stream.lengths, stream.fps, source)
    channels = _split(stream, decoded_chart(stream))
    N = channels[0].shape[0]
    parts = None
    for start in range(0, N, CLIP_CHUNK_FRAMES):
        stop = min(start + CLIP_CHUNK_FRAMES, N)
        part = clip_from_chart(
            *(c[start:stop] for c in channels), stream.lengths, stream.fps, source=source
        )
        if parts is None:  # the whole clip's arrays, filled chunk by chunk
            parts = {k: np.empty((N, *getattr(part, k).shape[1:])) for k in _FRAME_ARRAYS}
            first = part
        for k in _FRAME_ARRAYS:
            parts[k][start:stop] = getattr(part, k)
    return replace(first, **parts)


_FRAME_ARRAYS = ("positions", "velocities", "qpos", "qvel", "rotations")


def decode_file(
    path: str | os.PathLike, out: str | os.PathLike, asf: str | os.PathLike | None = None
) -> Path:
    """Decode ``path`` to ``out``: ``.npz`` (ingest format), ``.amc`` or ``.bvh`` (angles of the
    source skeleton fitted to the decoded points: needs the source ``asf``, an ASF or the BVH the
    stream was encoded from, whose skeleton hash must match the stream's). Written atomically.

    Raises:
        MotionDataError: bad stream, bad or mismatched skeleton, unknown output suffix.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".npz", ".amc", ".bvh"):
        raise MotionDataError(str(out), None, "output must end in .npz, .amc or .bvh")
    if is_sequence(path):
        return _decode_sequence(path, out, suffix, asf)
    stream = sidq.read(path)
    if suffix == ".npz":
        return save_npz(stream_to_clip(stream, str(path)), out)
    skeleton = _source_skeleton(asf, out, suffix, stream, path)
    rec = reconstruct_stream(stream)
    motion = fit_motion(skeleton, rec.positions, rec.names)
    if suffix == ".bvh":
        return write_bvh(out, skeleton, motion, stream.fps)
    write_amc(
        out, skeleton, motion, comment=f"decoded from {Path(path).name} at {stream.fps:g} fps"
    )
    return out


def _source_skeleton(asf, out: Path, suffix: str, stream: sidq.Stream, path):
    """The ``asf`` skeleton, checked against the stream's hash (AMC and BVH output)."""
    if asf is None:
        raise MotionDataError(
            str(out), None, f"an {suffix} output needs the source skeleton (--asf)"
        )
    skeleton = read_skeleton(asf)
    if skeleton_hash(skeleton) != stream.skeleton_hash:
        raise MotionDataError(
            str(asf), None, f"skeleton does not match the stream's (hash of {path})"
        )
    return skeleton


def _decode_sequence(path, out: Path, suffix: str, asf) -> Path:
    """Decode a sequence of streams one stream at a time (bounded memory): ``.npz`` and
    ``.amc`` are written as the streams are decoded; ``.bvh`` joins the whole take first."""
    first = first_stream(path)
    if suffix == ".npz":
        write_atomic(out, lambda f: _write_sequence_npz(f, path, out))
        return out
    skeleton = _source_skeleton(asf, out, suffix, first, path)
    if suffix == ".bvh":
        rec = decode_to_reconstruction(path)
        return write_bvh(out, skeleton, fit_motion(skeleton, rec.positions, rec.names), first.fps)

    def write(f):
        frame = 1
        for k, rec in enumerate(_sequence_reconstructions(path)):
            motion = replace(fit_motion(skeleton, rec.positions, rec.names), first_frame=frame)
            text = amc_text(
                skeleton, motion, f"decoded from {Path(path).name} at {first.fps:g} fps"
            )
            if k:  # the header once
                text = text[text.index(f"\n{frame}\n") + 1 :]
            f.write(text.encode("ascii"))
            frame += motion.n_frames

    write_atomic(out, write)
    return out


def _sequence_clips(path):
    """Each stream of a sequence as a clip (:func:`stream_to_clip`), each after the first without
    its first frame."""
    for k, stream in enumerate(iter_streams(path)):
        clip = stream_to_clip(stream, str(path))
        yield clip if k == 0 else clip.slice(1, clip.n_frames)


def _write_sequence_npz(f, path, out: Path) -> None:
    """The ingest-format ``.npz`` of a sequence (the keys of :func:`sim.motion.clip.save_npz`),
    each per-frame array written stream by stream (the sequence decoded once per array)."""
    frames, first = 0, None
    for clip in _sequence_clips(path):
        frames += clip.n_frames
        first = clip if first is None else first
    per_frame = [k for k in (*_FRAME_ARRAYS, "angular_velocities")
                 if getattr(first, k) is not None]  # fmt: skip
    inflated = sum(frames * getattr(first, k)[0].nbytes for k in per_frame)
    if frames > MAX_CLIP_FRAMES or inflated > MAX_NPZ_INFLATED:
        raise OutputError(str(out), None, f"a clip of {frames:,} frames ({inflated:,} bytes); "
                          f"its reader takes at most {MAX_CLIP_FRAMES:,} frames and "
                          f"{MAX_NPZ_INFLATED:,} bytes")  # fmt: skip
    constants = {
        "names": np.array(first.names),
        "parents": np.asarray(first.parents),
        "joint_names": np.array(first.joint_names, dtype=str),
        "fps": np.float64(first.fps),
        "source": np.array(first.source),
        "start_frame": np.int64(first.start_frame),
        "source_fps": np.float64(first.source_fps),
    }
    with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for key, value in constants.items():
            with z.open(f"{key}.npy", "w") as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
        for key in per_frame:
            shape = (frames, *getattr(first, key).shape[1:])
            with z.open(f"{key}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array_header_1_0(
                    member, {"descr": "<f8", "fortran_order": False, "shape": shape}
                )
                for clip in _sequence_clips(path):
                    member.write(np.ascontiguousarray(getattr(clip, key), dtype="<f8").tobytes())
