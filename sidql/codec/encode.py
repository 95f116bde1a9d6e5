"""Encoding: a trial -> a :class:`~sidql.codec.format.Stream` at a byte rate or an error target.

Steps: the chart of the protocol points (:func:`sidql.keyframes.spherical.chart`); a 16-bit
quantiser fitted to the trial (:mod:`sidql.codec.quantise`); the banded segment costs of the
quantised keyframe values; keyframes by the whole-trial programme (:mod:`sidql.codec.plan`) or,
with a latency, by the fixed-lag one (:mod:`sidql.codec.stream`), the multiplier found by
bisection; the error of every candidate measured by running the decoder itself. ``auto`` tries
every reconstruction and keeps the least measured Q (``--rate``) or the fewest bytes
(``--max-q``).

Q is eq. 18 (mean |angle error| over frames and bones [rad]) of the decoded chart against the
true one, keyframes included (so quantisation error counts).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sidql.codec import format as sidq
from sidql.codec.decode import decoded_chart
from sidql.codec.plan import DEFAULT_MAX_GAP, band_costs, plan_for_budget, plan_for_quality
from sidql.codec.quantise import fit_quantiser
from sidql.codec.skeleton import skeleton_hash
from sidql.codec.stream import horizon, stream_for_budget, stream_for_quality
from sidql.keyframes.metrics import q_from_angles
from sidql.keyframes.spherical import POINTS, SphericalSeries, chart
from sim.acclaim.reader import parse_asf
from sim.errors import MotionDataError
from sim.motion.clip import Clip, write_atomic
from sim.motion.ingest import load_motion

CHOICES: tuple[str, ...] = ("auto",) + sidq.RECONSTRUCTIONS


@dataclass(frozen=True)
class Encoded:
    """One encoding.

    Attributes:
        stream: the container; data: its bytes.
        q: measured Q [rad] of the decoded chart (eq. 18, keyframes included).
        bytes_per_second: ``len(data)`` over the trial's duration ``N / fps`` [B/s].
        candidates: reconstruction -> (q, bytes) of every reconstruction tried.
    """

    stream: sidq.Stream
    data: bytes
    q: float
    bytes_per_second: float
    candidates: dict


def _series_arrays(series: SphericalSeries):
    values = np.concatenate([series.theta, series.phi, series.root_pos], axis=1)
    rates = np.concatenate([series.dtheta, series.dphi, series.root_vel], axis=1)
    return values, rates


def _measure(series: SphericalSeries, stream: sidq.Stream) -> float:
    M = series.n_bones
    x = decoded_chart(stream)["values"]
    return q_from_angles(series, x[:, :M], x[:, M : 2 * M])


def _encode_one(
    series: SphericalSeries,
    recon: str,
    *,
    rate: float | None,
    max_q: float | None,
    latency: int,
    max_gap: int,
    fps: float,
    skel_hash: bytes,
    where: str,
) -> Encoded:
    M = series.n_bones
    N = series.n_frames
    values, rates = _series_arrays(series)
    quant = fit_quantiser(values, rates if recon == "hermite" else None, M)
    Xq = quant.grid_pose(values)
    Rq = quant.grid_rates(rates) * series.dt if recon == "hermite" else None
    G = min(max_gap, sidq.MAX_GAP)
    H = horizon(latency, recon) if latency else 0
    if H:
        G = min(G, H)
    C = band_costs(
        values[:, : 2 * M], Xq[:, : 2 * M], None if Rq is None else Rq[:, : 2 * M], G, recon
    )

    def build(keys: np.ndarray) -> sidq.Stream:
        return sidq.Stream(
            reconstruction=recon,
            latency=int(latency),
            fps=float(np.float32(fps)),
            skeleton_hash=skel_hash,
            names=POINTS,
            parents=series.parents,
            lengths=series.lengths.astype(np.float32).astype(np.float64),
            quantiser=quant,
            keyframes=keys,
            pose_codes=quant.encode_pose(values[keys]),
            rate_codes=quant.encode_rates(rates[keys]) if recon == "hermite" else None,
        )

    def measure(keys):
        return _measure(series, build(keys))

    duration = N / fps
    if rate is not None:
        empty = build(np.array([0, N - 1]))
        fixed = len(sidq.header_bytes(empty)) + 4
        max_keys = int((rate * duration - fixed) // sidq.record_size(recon, M))
        if H:
            p = stream_for_budget(C, H, max_keys)
            if p is None:
                raise MotionDataError(
                    where or None, None, f"rate {rate:g} B/s too low for latency {latency}"
                )
        else:
            p = plan_for_budget(C, max_keys, where)
        keys = p.keyframes
    else:
        if H:
            p, _ = stream_for_quality(C, H, measure, max_q)
        else:
            p, _ = plan_for_quality(C, measure, max_q)
        keys = p.keyframes
    stream = build(keys)
    data = sidq.to_bytes(stream)
    return Encoded(stream, data, _measure(series, stream), len(data) / duration, {})


def encode_series(
    series: SphericalSeries,
    *,
    rate: float | None = None,
    max_q: float | None = None,
    reconstruction: str = "auto",
    latency: int = 0,
    max_gap: int = DEFAULT_MAX_GAP,
    skel_hash: bytes = bytes(8),
    where: str = "",
) -> Encoded:
    """Encode a chart (see the module docstring).

    Args:
        series: the trial's chart (N frames at ``1 / series.dt`` fps, M = 22 bones).
        rate: byte budget [B/s] for the whole file (header and checksum included), or
        max_q: the largest acceptable Q [rad]; exactly one of the two.
        reconstruction: "auto", "hermite", "linear" or "catmull_rom".
        latency: 0 (offline, whole trial) or the look-ahead L >= 1 [frames].
        max_gap: G, the largest gap between keyframes [frames] (<= 255).
        skel_hash: 8 bytes naming the source skeleton.

    Raises:
        MotionDataError: the rate cannot be met; ValueError: bad arguments.
    """
    if (rate is None) == (max_q is None):
        raise ValueError("give exactly one of rate and max_q")
    if rate is not None and not rate > 0:
        raise ValueError(f"rate must be positive; got {rate}")
    if max_q is not None and not max_q >= 0:
        raise ValueError(f"max_q must be >= 0; got {max_q}")
    if reconstruction not in CHOICES:
        raise ValueError(f"unknown reconstruction {reconstruction!r}; known: {', '.join(CHOICES)}")
    if latency < 0 or max_gap < 1:
        raise ValueError("latency must be >= 0 and max_gap >= 1")
    if series.n_frames < 2:
        raise MotionDataError(where or None, None, "a trial needs at least 2 frames")
    fps = 1.0 / series.dt
    names = sidq.RECONSTRUCTIONS if reconstruction == "auto" else (reconstruction,)
    results, errors = {}, []
    for r in names:
        try:
            results[r] = _encode_one(
                series,
                r,
                rate=rate,
                max_q=max_q,
                latency=latency,
                max_gap=max_gap,
                fps=fps,
                skel_hash=skel_hash,
                where=where,
            )
        except MotionDataError as e:
            errors.append(e)
    if not results:
        raise errors[0]
    if rate is not None:
        best = min(results, key=lambda r: (results[r].q, len(results[r].data)))
    else:
        ok = [r for r in results if results[r].q <= max_q] or list(results)
        best = min(ok, key=lambda r: (len(results[r].data), results[r].q))
    cand = {r: (e.q, len(e.data)) for r, e in results.items()}
    return replace(results[best], candidates=cand)


def encode_clip(clip: Clip, **kwargs) -> Encoded:
    """:func:`encode_series` of a clip's chart."""
    return encode_series(chart(clip), where=clip.source, **kwargs)


def encode_files(
    asf: str | os.PathLike,
    amc: str | os.PathLike,
    out: str | os.PathLike,
    *,
    fps: float = 30.0,
    **kwargs,
) -> Encoded:
    """Encode one CMU trial (ASF + AMC) into ``out`` (``.sidq``), written atomically.

    The trial is read with :func:`sim.motion.ingest.load_motion` on the subject's own skeleton at
    ``fps``; the stream records the skeleton's hash so the decoder can check the ASF it is given.
    """
    skel = skeleton_hash(parse_asf(asf))
    try:
        clip = load_motion(asf, amc, fps=fps)
    except MotionDataError:
        raise
    except ValueError as e:  # e.g. an output rate that does not divide the source rate
        raise MotionDataError(str(amc), None, str(e)) from None
    enc = encode_clip(clip, skel_hash=skel, **kwargs)
    write_atomic(Path(out), lambda f: f.write(enc.data))
    return enc
