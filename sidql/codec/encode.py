"""Encoding: a trial -> a :class:`~sidql.codec.format.Stream` at a byte rate or an error target.

Steps: the chart of the protocol points (:func:`sidql.keyframes.spherical.chart`); quantisers
fitted to the trial (:mod:`sidql.codec.quantise`); the banded segment costs of the 16-bit
quantised keyframe values; keyframes by the whole-trial programme (:mod:`sidql.codec.plan`) or,
with a latency, by the fixed-lag one (:mod:`sidql.codec.stream`), the multiplier found by
bisection; the error of every candidate measured by running the decoder itself. ``auto`` tries
every reconstruction and keeps the least measured Q (``--rate``) or the fewest bytes
(``--max-q``).

Offline streams are packed (coding 1: delta + LZMA) at a bit depth of 9, 11, 13 or 16 bits per
pose channel. At a rate, the trial is encoded at 11 bits with real sizes (the keyframe count is
corrected from the measured size a few times); the other depths are judged with a size model
(each extra bit costs one bit per pose channel per keyframe) and their measured Q at the
modelled keyframe count, and the best is re-encoded with real sizes if it beats 11 bits. With
``--max-q`` every depth is encoded and the smallest file meeting Q kept. Live streams (a
latency) use fixed 16-bit records (coding 0), which a sender can emit one by one.

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
from sidql.codec.plan import (
    DEFAULT_MAX_GAP,
    band_costs,
    least_keyframes,
    plan_for_budget,
    plan_for_quality,
)
from sidql.codec.quantise import fit_quantiser
from sidql.codec.skeleton import skeleton_hash
from sidql.codec.stream import horizon, stream_for_budget, stream_for_quality
from sidql.keyframes.metrics import q_from_angles
from sidql.keyframes.spherical import POINTS, SphericalSeries, chart, split_channels
from sim.acclaim.reader import parse_asf
from sim.errors import MotionDataError
from sim.files import write_atomic
from sim.motion.clip import Clip
from sim.motion.ingest import load_motion

CHOICES: tuple[str, ...] = ("auto",) + sidq.RECONSTRUCTIONS


@dataclass(frozen=True)
class Encoded:
    """One encoding.

    Attributes:
        stream: the container; data: its bytes.
        q: measured Q [rad] of the decoded chart (eq. 18, keyframes included).
        bytes_per_second: ``len(data)`` over the trial's duration ``N / fps`` [B/s].
        candidates: "reconstruction/bits" -> (q, bytes) of every encoding tried.
    """

    stream: sidq.Stream
    data: bytes
    q: float
    bytes_per_second: float
    candidates: dict


def _measure(series: SphericalSeries, stream: sidq.Stream) -> float:
    theta, phi, _ = split_channels(decoded_chart(stream)["values"], series.n_bones)
    return q_from_angles(series, theta, phi)


#: bits per pose channel tried for packed (offline) streams; live streams use 16.
PACKED_BITS: tuple[int, ...] = (9, 11, 13, 16)
#: the bit depth encoded first; the others are judged by a size model, the best re-encoded.
AUTO_BITS = 11
_ROUNDS = 8


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
    bit_depths: tuple[int, ...] = PACKED_BITS,
) -> list[Encoded]:
    """Encodings of one reconstruction, one per bit depth tried."""
    M = series.n_bones
    N = series.n_frames
    values, rates = series.channels()
    q16 = fit_quantiser(values, rates if recon == "hermite" else None, M)
    Xq = q16.grid_pose(values)
    Rq = q16.grid_rates(rates) * series.dt if recon == "hermite" else None
    G = min(max_gap, sidq.MAX_GAP)
    H = horizon(latency, recon) if latency else 0
    if H:
        G = min(G, H)
    C = band_costs(
        values[:, : 2 * M], Xq[:, : 2 * M], None if Rq is None else Rq[:, : 2 * M], G, recon
    )
    coding = 0 if latency else 1
    duration = N / fps

    def quantiser(bits):
        if bits == 16:
            return q16
        return replace(fit_quantiser(values, None, M, bits), rate_step=q16.rate_step)

    def build(keys: np.ndarray, quant) -> sidq.Stream:
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
            coding=coding,
        )

    def finish(keys, quant) -> Encoded:
        stream = build(keys, quant)
        data = sidq.to_bytes(stream)
        return Encoded(stream, data, _measure(series, stream), len(data) / duration, {})

    out = []
    if coding == 0:
        quant = q16
        if rate is not None:
            keys = _keys_for_budget(
                C, lambda k: build(k, quant), rate * duration, H, recon, M, where
            )
        else:
            keys = stream_for_quality(C, H, lambda k: _measure(series, build(k, quant)), max_q)[0]
            keys = keys.keyframes
        return [finish(keys, quant)]
    if max_q is not None:
        for bits in bit_depths:
            quant = quantiser(bits)
            p, _ = plan_for_quality(
                C, lambda k, quant=quant: _measure(series, build(k, quant)), max_q
            )
            out.append(finish(p.keyframes, quant))
        return out
    # packed, at a rate: real sizes at the first depth, then a size model picks the depth
    budget = rate * duration
    b0 = AUTO_BITS if AUTO_BITS in bit_depths else bit_depths[0]
    q0 = quantiser(b0)
    keys = _keys_for_budget(C, lambda k: build(k, q0), budget, 0, recon, M, where)
    first = finish(keys, q0)
    out.append(first)
    fixed = len(first.data) - _payload(first)
    per_key0 = _payload(first) / len(keys)
    estimates = {}
    for bits in bit_depths:
        if bits == b0:
            continue
        # each bit of precision adds about one incompressible bit per pose channel
        per_key = max(per_key0 + (2 * M + 3) * (bits - b0) / 8.0, 1.0)
        quant = quantiser(bits)
        try:
            p = plan_for_budget(C, int((budget - fixed) // per_key), where)
        except MotionDataError:
            continue
        estimates[bits] = (_measure(series, build(p.keyframes, quant)), per_key, quant)
    if estimates:
        bits = min(estimates, key=lambda b: estimates[b][0])
        q_est, per_key, quant = estimates[bits]
        if q_est < first.q:
            guess = per_key / sidq.record_size(recon, M)
            try:
                keys = _keys_for_budget(
                    C, lambda k: build(k, quant), budget, 0, recon, M, where, guess
                )
                out.append(finish(keys, quant))
            except MotionDataError:
                pass  # no plan at that depth fits: the first depth's encoding stands
    return out


def _payload(enc: Encoded) -> int:
    """Bytes of a packed encoding's keyframes (its size less header, count, .lzma header, CRC)."""
    return len(enc.data) - len(sidq.header_bytes(enc.stream)) - 4 - 13 - 4


def _keys_for_budget(C, build, budget, H, recon, M, where, guess=0.5) -> np.ndarray:
    """Keyframes of the densest Lagrangian plan whose whole container fits in ``budget`` bytes.

    Fixed records: the keyframe count follows from the budget. Packed records: the bytes per
    keyframe are estimated, the plan's real size measured, and the count corrected (a few
    rounds), keeping the densest plan that fits."""

    def solve(max_keys):
        if H:
            p = stream_for_budget(C, H, max_keys)
            if p is None:
                raise MotionDataError(where or None, None, f"rate too low for latency {H}")
            return p.keyframes
        return plan_for_budget(C, max_keys, where).keyframes

    N = C.shape[0]
    empty = build(np.array([0, N - 1]))
    fixed = len(sidq.header_bytes(empty)) + 4
    per_key = sidq.record_size(recon, M)
    if empty.coding == 0:
        return solve(int((budget - fixed) // per_key))
    fixed += 4 + 13  # keyframe count and the .lzma header
    per_key *= guess  # first guess, corrected below from the measured size
    least = least_keyframes(C)
    best, tried = None, set()
    target = int((budget - fixed) // per_key)
    for _ in range(_ROUNDS):
        if best is not None and len(tried) >= 3:
            break
        target = max(target, least)
        if target in tried:
            break
        tried.add(target)
        keys = solve(target)
        size = len(sidq.to_bytes(build(keys)))
        if size <= budget and (best is None or len(keys) > len(best)):
            best = keys
        per_key = max((size - fixed) / len(keys), 1.0)
        nxt = int((budget - fixed) // per_key)
        if size <= budget and (nxt <= len(keys) or budget - size < max(2 * per_key, budget / 100)):
            break  # within two keyframes (or 1 %) of the budget
        target = nxt if size <= budget else min(nxt, len(keys) - 1)
    if best is None:
        raise MotionDataError(
            where or None,
            None,
            f"rate too low: the sparsest plan needs {size} bytes, budget {budget:.0f}",
        )
    return best


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
    if not (0 <= latency <= 65535 and max_gap >= 1):
        raise ValueError("latency must be in 0..65535 and max_gap >= 1")
    if series.n_frames < 2:
        raise MotionDataError(where or None, None, "a trial needs at least 2 frames")
    fps = 1.0 / series.dt
    limit = sidq.frame_limit(series.theta.shape[1] + 1)
    if series.n_frames > limit:  # the decoder's stated limit: refuse rather than write it
        raise MotionDataError(
            where or None, None, f"{series.n_frames:,} frames exceed the .sidq limit of "
            f"{limit:,} ({limit / fps:.4g} s at {fps:g} fps); encode at a lower --fps",
        )  # fmt: skip
    names = sidq.RECONSTRUCTIONS if reconstruction == "auto" else (reconstruction,)
    results, errors = {}, []
    common = dict(
        rate=rate,
        max_q=max_q,
        latency=latency,
        max_gap=max_gap,
        fps=fps,
        skel_hash=skel_hash,
        where=where,
    )
    for r in names:
        try:
            for e in _encode_one(series, r, **common):
                results[f"{r}/{e.stream.quantiser.bits}"] = e
        except MotionDataError as e:
            errors.append(e)
    if not results:
        raise errors[0]
    cand = {r: (e.q, len(e.data)) for r, e in results.items()}
    return replace(results[_best(results, rate, max_q)], candidates=cand)


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
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    write_atomic(Path(out), lambda f: f.write(enc.data))
    return enc
