"""Encoding: a trial -> a :class:`~sidql.codec.format.Stream` at a byte rate or an error target.

Steps: the chart of the protocol points (:func:`sidql.keyframes.spherical.chart`); quantisers
fitted to the trial (:mod:`sidql.codec.quantise`); the banded segment costs of the quantised
keyframe values; keyframes by the whole-trial programme (:mod:`sidql.codec.plan`) or, with a
latency, by the fixed-lag one (:mod:`sidql.codec.stream`), the multiplier found by bisection; the
error of every candidate measured by running the decoder itself. ``auto`` tries every
reconstruction and keeps the least measured Q (``--rate``) or the fewest bytes (``--max-q``).

Offline streams at a rate or a mean position error target (``max_error``) are position-coded
(coding 2, :mod:`sidql.codec.position_coding`); ``max_q``, ``objective="angle"``, Hermite and any
latency use the angle coding (codings 0 and 1, :mod:`sidql.codec.angle_coding`).

Q is eq. 18 (mean |angle error| over frames and bones [rad]) of the decoded chart against the
true one, keyframes included (so quantisation error counts; :mod:`sidql.codec.encoded`).
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from sidql.codec import format as sidq
from sidql.codec.angle_coding import encode_angles
from sidql.codec.encoded import Encoded
from sidql.codec.plan import DEFAULT_MAX_GAP
from sidql.codec.position_coding import encode_positions
from sidql.codec.skeleton import skeleton_hash
from sidql.codec.windows import WINDOW_FRAMES, TakeEncoding, encode_windows, one_stream
from sidql.keyframes.curves import CURVES
from sidql.keyframes.spherical import SphericalSeries, chart
from sim.bvh.reader import parse_bvh
from sim.errors import MotionDataError, UnknownNameError, UnmetTargetError, UsageError
from sim.files import write_atomic
from sim.motion.chunks import stream_clips
from sim.motion.clip import Clip
from sim.motion.ingest import load_motion, resample_step
from sim.motion.resample import grid_rate
from sim.motion.trial import CMU_FPS, head_skeleton, is_bvh

CHOICES: tuple[str, ...] = ("auto",) + CURVES
#: Frames (at the stream rate) read, retargeted and charted at a time by :func:`encode_files`.
READ_FRAMES = 300


def encode_series(
    series: SphericalSeries,
    *,
    rate: float | None = None,
    max_q: float | None = None,
    max_error: float | None = None,
    reconstruction: str = "auto",
    latency: int = 0,
    max_gap: int = DEFAULT_MAX_GAP,
    skel_hash: bytes = bytes(8),
    where: str = "",
    objective: str = "position",
    extra_cost=None,
) -> Encoded:
    """Encode a chart (see the module docstring).

    With ``objective="position"`` (the default), offline streams at a ``rate`` or a
    ``max_error`` are position-coded (coding 2): keyframes and bits go where they lower the mean
    joint position error most. ``max_q``, ``objective="angle"``, Hermite and any latency use the
    angle-error coding (codings 0 and 1), which minimises Q.

    Args:
        series: the trial's chart (N frames at ``1 / series.dt`` fps, M = 22 bones).
        rate: byte budget [B/s] for the whole file (header and checksum included), or
        max_q: the largest acceptable Q [rad], or
        max_error: the largest acceptable mean joint position error [mm]; exactly one of the three.
        reconstruction: "auto", "hermite", "linear" or "catmull_rom".
        latency: 0 (offline, whole trial) or the look-ahead L >= 1 [frames].
        max_gap: G, the largest gap between keyframes [frames] (<= 255).
        skel_hash: 8 bytes naming the source skeleton.
        objective: "position" (mean joint position error) or "angle" (Q).
        extra_cost: (N, G + 1) [m] added to the position coding's segment costs (e.g. the
            physical cost, :mod:`sidql.codec.contact_coding`); the position coding only.

    Raises:
        UnmetTargetError: the rate cannot be met; UnknownNameError: an unknown reconstruction;
        ValueError: bad arguments.
    """
    _check_arguments(
        series, rate, max_q, max_error, reconstruction, latency, max_gap, where, objective
    )
    fps = 1.0 / series.dt
    position = position_coded(max_q, latency, reconstruction, objective)
    if (max_error is not None or extra_cost is not None) and not position:
        what = "max_error" if max_error is not None else "a physical cost"
        raise UsageError(f"{what} needs an offline stream (latency 0), linear or catmull_rom")
    if position:
        names = sidq.POSITION_RECONSTRUCTIONS if reconstruction == "auto" else (reconstruction,)
    else:
        names = CURVES if reconstruction == "auto" else (reconstruction,)
    common = dict(max_gap=max_gap, fps=fps, skel_hash=skel_hash, where=where)
    if position:
        enc, cand = encode_positions(
            series, names, rate=rate, max_error=max_error, extra_cost=extra_cost, **common
        )
        return replace(enc, candidates=cand)
    results, errors = {}, []
    for r in names:
        try:
            for e in encode_angles(series, r, rate=rate, max_q=max_q, latency=latency, **common):
                results[f"{r}/{e.stream.quantiser.bits}"] = e
        except UnmetTargetError as e:  # this reconstruction cannot meet the rate; others may
            errors.append(e)
    if not results:
        raise errors[0]
    cand = {r: (e.q, len(e.data)) for r, e in results.items()}
    return replace(results[_best(results, rate, max_q)], candidates=cand)


def position_coded(max_q, latency: int, reconstruction: str, objective: str) -> bool:
    """Whether :func:`encode_series` position-codes (coding 2) with these arguments: its
    streams need the chart's values only, never its rates."""
    return (
        objective == "position" and max_q is None and latency == 0 and reconstruction != "hermite"
    )


def _check_arguments(
    series, rate, max_q, max_error, reconstruction, latency, max_gap, where, objective
):
    """The checks of :func:`encode_series`' arguments (see its Raises)."""
    if objective not in ("position", "angle"):
        raise UsageError(f"objective must be 'position' or 'angle'; got {objective!r}")
    if sum(x is not None for x in (rate, max_q, max_error)) != 1:
        raise UsageError("give exactly one of rate, max_q and max_error")
    if rate is not None and not rate > 0:
        raise UsageError(f"rate must be positive; got {rate}")
    if max_q is not None and not max_q >= 0:
        raise UsageError(f"max_q must be >= 0; got {max_q}")
    if max_error is not None and not max_error > 0:
        raise UsageError(f"max_error must be positive; got {max_error}")
    if reconstruction not in CHOICES:
        raise UnknownNameError("reconstruction", reconstruction, CHOICES)
    if not (0 <= latency <= 65535 and max_gap >= 1):
        raise UsageError("latency must be in 0..65535 and max_gap >= 1")
    if series.n_frames < 2:
        raise MotionDataError(where or None, None, "a trial needs at least 2 frames")
    fps = 1.0 / series.dt
    limit = sidq.frame_limit(series.theta.shape[1] + 1)
    if series.n_frames > limit:  # the decoder's stated limit: refuse rather than write it
        raise MotionDataError(
            where or None, None, f"{series.n_frames:,} frames exceed the .sidq limit of "
            f"{limit:,} ({limit / fps:.4g} s at {fps:g} fps); encode at a lower --fps",
        )  # fmt: skip


def _best(results: dict, rate, max_q) -> str:
    """Key of the least Q (rate target) or of the fewest bytes meeting ``max_q``."""
    if rate is not None:
        return min(results, key=lambda r: (results[r].q, len(results[r].data)))
    ok = [r for r in results if results[r].q <= max_q]
    if not ok:  # nothing meets the target (quantisation alone exceeds it): the least error
        return min(results, key=lambda r: (results[r].q, len(results[r].data)))
    return min(ok, key=lambda r: (len(results[r].data), results[r].q))


def encode_clip(clip: Clip, **kwargs) -> Encoded:
    """:func:`encode_series` of a clip's chart."""
    return encode_series(chart(clip), where=clip.source, **kwargs)


def _rate(bvh) -> float:
    """A BVH file's frame rate [frames per second], its hierarchy and header alone read."""
    return parse_bvh(bvh, motion=False).fps


def _divides(bvh, fps: float) -> bool:
    """Whether ``fps`` divides the BVH file's rate (it is then streamed, never resampled)."""
    rate = _rate(bvh)
    return grid_rate(rate, fps) == rate


def encode_files(
    asf: str | os.PathLike,
    amc: str | os.PathLike | None,
    out: str | os.PathLike,
    *,
    fps: float = 30.0,
    window: int = WINDOW_FRAMES,
    encoder=None,
    contacts=None,
    **kwargs,
) -> TakeEncoding:
    """Encode one CMU trial (ASF + AMC, or a BVH as ``asf``) into ``out``, written atomically.

    The AMC is read, retargeted and charted a chunk at a time (:func:`sim.motion.chunks.stream_clips`,
    the subject's own skeleton at ``fps``) and encoded ``window`` frames at a time
    (:mod:`sidql.codec.windows`), so memory does not grow with the take: a take of at most
    ``window`` frames (plus the overlap) is one ordinary ``.sidq`` stream, a longer one a sequence
    of streams (:mod:`sidql.codec.sequence`); the position coding reads positions only (its
    streams never use the chart's rates). A BVH is read the same way, unless ``fps`` does not
    divide its rate: it is then read and resampled whole. The streams record the
    skeleton's hash so the decoder can check the ASF it is given. ``kwargs``: the targets and
    options of :func:`encode_series`.

    ``contacts(clips, again, velocities=) -> (side, encode, clips)`` (e.g.
    :func:`sidql.codec.contact_coding.streamed_contacts`): the take is first read with
    velocities for the whole take's side information ``side`` (its floor is estimated on every
    frame), then encoded window by window by ``encode`` with each window's share of ``side``,
    from the clips it returns (those it kept of its read, or ``again``: a second read).
    ``encoder(clip, **kwargs) -> Encoded``: when given (e.g.
    :func:`sidql.codec.contact_coding.encode_with_contacts` with the physical cost), the take is
    read whole (:func:`sim.motion.ingest.load_motion`) and encoded as one stream by it: memory
    then grows with the take.
    """
    amc = asf if amc is None and is_bvh(asf) else amc
    skel = skeleton_hash(head_skeleton(amc if is_bvh(amc) else asf))  # a BVH: its first chunk
    rates = not position_coded(
        kwargs.get("max_q"), kwargs.get("latency", 0),
        kwargs.get("reconstruction", "auto"), kwargs.get("objective", "position"),
    )  # fmt: skip
    clips = _take(asf, amc, fps, rates, whole=encoder is not None)
    if encoder is not None:
        enc = encoder(clips[0], skel_hash=skel, **kwargs)
        write_atomic(Path(out), lambda f: f.write(enc.data))
        return one_stream(enc)
    encode, side = encode_series, None
    if contacts is not None:
        side, encode, clips = contacts(_take(asf, amc, fps, True), clips, velocities=rates)
    done = []

    def write(f):
        done.append(encode_windows(f, clips, encode, window=window, skel_hash=skel,
                                   contacts=side, **kwargs))  # fmt: skip

    write_atomic(Path(out), write)
    return done[0]


def _take(asf, amc, fps: float, velocities: bool, whole: bool = False):
    """The take's clips at ``fps``: streamed (:func:`sim.motion.chunks.stream_clips`), or one
    clip of the whole take (``whole``, or a BVH whose rate ``fps`` does not divide)."""
    try:
        if whole or (is_bvh(amc) and not _divides(amc, fps)):
            return [load_motion(asf, amc, fps=fps, derivatives=False)]
        resample_step(CMU_FPS if not is_bvh(amc) else _rate(amc), fps)  # before any frame
        return stream_clips(asf, amc, fps=fps, chunk_frames=READ_FRAMES, velocities=velocities)
    except MotionDataError:
        raise
    except ValueError as e:  # e.g. an output rate that does not divide the source rate
        raise MotionDataError(str(amc), None, str(e)) from None
