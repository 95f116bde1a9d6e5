"""Encoding: a trial -> a :class:`~sidql.codec.format.Stream` at a byte rate or an error target.

Steps: the chart of the protocol points (:func:`sidql.keyframes.spherical.chart`); quantisers
fitted to the trial (:mod:`sidql.codec.quantise`); the banded segment costs of the 16-bit
quantised keyframe values; keyframes by the whole-trial programme (:mod:`sidql.codec.plan`) or,
with a latency, by the fixed-lag one (:mod:`sidql.codec.stream`), the multiplier found by
bisection; the error of every candidate measured by running the decoder itself. ``auto`` tries
every reconstruction and keeps the least measured Q (``--rate``) or the fewest bytes
(``--max-q``).

Offline streams at a rate or a mean position error target (``max_error``) are position-coded
(coding 2, :func:`_encode_position`): keyframes by a programme over the summed point displacement
(:func:`sidql.codec.plan.position_band_costs`), values quantised by their effect on positions and
range-coded (:class:`sidql.codec.quantise.PositionQuantiser`), the step and the multiplier searched
with a size model and the exact position error (:mod:`sidql.codec.positions`).

The angle coding (``max_q``, ``objective="angle"``, Hermite, latency): offline streams are packed
(coding 1: delta + LZMA) at a bit depth of 9, 11, 13 or 16 bits per pose channel. At a rate, the trial is encoded at 11 bits with real sizes (the keyframe count is
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
from sidql.codec.entropy import encode_integers, estimate_size
from sidql.codec.plan import (
    DEFAULT_MAX_GAP,
    band_costs,
    least_keyframes,
    plan,
    plan_for_budget,
    plan_for_quality,
    position_band_costs,
)
from sidql.codec.positions import chart_points, position_errors
from sidql.codec.quantise import PositionQuantiser, fit_quantiser
from sidql.codec.skeleton import skeleton_hash
from sidql.codec.stream import horizon, stream_for_budget, stream_for_quality
from sidql.keyframes.curves import CURVES
from sidql.keyframes.metrics import q_from_angles
from sidql.keyframes.spherical import POINTS, SphericalSeries, chart, split_channels
from sim.acclaim.asf import parse_asf
from sim.errors import MotionDataError, UnknownNameError, UnmetTargetError
from sim.files import write_atomic
from sim.motion.clip import Clip
from sim.motion.ingest import load_motion

CHOICES: tuple[str, ...] = ("auto",) + CURVES


@dataclass(frozen=True)
class Encoded:
    """One encoding.

    Attributes:
        stream: the container; data: its bytes.
        q: measured Q [rad] of the decoded chart (eq. 18, keyframes included).
        bytes_per_second: ``len(data)`` over the trial's duration ``N / fps`` [B/s].
        candidates: "reconstruction/bits" -> (q, bytes) of every encoding tried.
        mean_error_mm, p95_error_mm: mean and 95th percentile of the decoded points' Euclidean
            error [mm] against the chart's points (all points, all frames).
    """

    stream: sidq.Stream
    data: bytes
    q: float
    bytes_per_second: float
    candidates: dict
    mean_error_mm: float = float("nan")
    p95_error_mm: float = float("nan")


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
        except UnmetTargetError:
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
            except UnmetTargetError:
                pass  # no plan at that depth fits: the first depth's encoding stands
    return out


def _where(where: str, problem: str) -> str:
    """``problem`` prefixed with the trial it is about (when known)."""
    return f"{where}: {problem}" if where else problem


#: step sizes tried for a mean position error target e: these multiples of e [m] (the position
#: step that moves points by about twice the target error balanced quantisation against
#: keyframe density best on the CMU trials of ``../shared``).
STEP_FACTORS: tuple[float, ...] = (1.5, 2.0, 2.5)
_LAM_LO, _LAM_HI = 1e-7, 1e3
_LAM_PRECISION = 0.01  # of a bisection on log lam
#: runs of the range coder per step size tried at a byte budget (the size model does the rest)
_REAL_CODINGS = 3
#: slope weight of the keyframe predictor of coding 2 (0: previous keyframe; 1: linear
#: extrapolation); 0.5 measured best on the CMU trials of ``../shared``.
PREDICTOR = 0.5


class _PositionSearch:
    """Keyframes and step sizes of one reconstruction under coding 2 (position-coded).

    Sizes during the searches come from a size model (:func:`~sidql.codec.entropy.estimate_size`);
    the range coder itself runs only on the few plans that may be kept."""

    def __init__(self, series, recon, G, build):
        self.series, self.recon, self.build = series, recon, build
        values, _ = series.channels()
        self.values = values
        self.lengths = sidq.position_lengths(series.lengths)
        self.truth = chart_points(values, series.lengths, series.parents)
        self.C = position_band_costs(values, values, None, G, recon, self.lengths, series.parents)
        self.plans: dict = {}
        self.coded: dict = {}
        self.last = None  # log lam of the previous search's answer
        self.header = len(sidq.header_bytes(build(np.array([0, 1]), self.quantiser(1e-3)))) + 8

    def quantiser(self, step: float) -> PositionQuantiser:
        M = self.series.n_bones
        return PositionQuantiser(
            M, self.lengths, self.series.parents, float(np.float32(step)), PREDICTOR
        )

    def keys(self, lam: float) -> np.ndarray:
        if lam not in self.plans:
            self.plans[lam] = plan(self.C, lam).keyframes
        return self.plans[lam]

    def code(self, lam: float, step: float):
        keys = self.keys(lam)
        key = (hash(keys.tobytes()), len(keys), step)  # nearby multipliers often share a plan
        if key not in self.coded:
            q = self.quantiser(step)
            codes, kv = q.encode_keyframes(self.values[keys], keys)
            self.coded[key] = (keys, q, codes, kv)
        return self.coded[key]

    @staticmethod
    def rows(keys, codes) -> np.ndarray:
        gaps = np.diff(keys, prepend=0)
        return np.vstack([np.diff(gaps, prepend=0)[None], codes.T])

    def estimate(self, keys, codes) -> float:
        return self.header + estimate_size(self.rows(keys, codes))

    def size(self, keys, codes) -> int:
        return self.header + len(encode_integers(self.rows(keys, codes)))

    def errors(self, keys, kv) -> np.ndarray:
        return position_errors(self.truth, keys, kv, self.recon, self.lengths, self.series.parents)

    def _boundary(self, good, step):
        """Bisection on log lam for the plan nearest the boundary of a predicate ``good(r)`` of
        a coded plan r = (keys, q, codes, kv) that holds at one end of [_LAM_LO, _LAM_HI] (the
        caller checked it). Starts from a narrow bracket around the previous search's answer
        (steps of nearby sizes have nearby multipliers) and widens it when needed. Returns the
        good plan nearest the boundary."""
        lo, hi = np.log(_LAM_LO), np.log(_LAM_HI)
        sparse_good = good(self.code(_LAM_HI, step))  # which end is good
        a, b = lo, hi
        if self.last is not None:
            a, b = max(lo, self.last - 1.0), min(hi, self.last + 1.0)
            while a > lo and good(self.code(float(np.exp(a)), step)) != (not sparse_good):
                a = max(lo, a - 4.0 * (b - a))
            while b < hi and good(self.code(float(np.exp(b)), step)) != sparse_good:
                b = min(hi, b + 4.0 * (b - a))
        best = self.code(float(np.exp(b if sparse_good else a)), step)  # the good end
        steps = max(int(np.ceil(np.log2(max(b - a, 1e-9) / _LAM_PRECISION))), 1)
        for _ in range(steps):
            mid = 0.5 * (a + b)
            r = self.code(float(np.exp(mid)), step)
            ok = good(r)
            if ok:
                best = r
            if ok == sparse_good:
                b = mid
            else:
                a = mid
        self.last = b if sparse_good else a
        return best

    def for_error(self, target: float, step: float):
        """(keys, q, codes, errors) of the sparsest plan at ``step`` whose mean error <= target
        [m], or None when even the densest misses it."""
        dense = self.code(_LAM_LO, step)
        if self.errors(dense[0], dense[3]).mean() > target:
            return None
        top = self.code(_LAM_HI, step)
        if self.errors(top[0], top[3]).mean() <= target:
            keys, q, codes, kv = top
        else:
            keys, q, codes, kv = self._boundary(
                lambda r: self.errors(r[0], r[3]).mean() <= target, step
            )
        return keys, q, codes, self.errors(keys, kv)

    def _densest_within(self, target: float, step: float):
        """The densest plan whose *estimated* size is <= target bytes, or None."""
        top = self.code(_LAM_HI, step)
        if self.estimate(top[0], top[2]) > target:
            return None
        dense = self.code(_LAM_LO, step)
        if self.estimate(dense[0], dense[2]) <= target:
            return dense
        return self._boundary(lambda r: self.estimate(r[0], r[2]) <= target, step)

    def for_budget(self, budget: float, step: float, real: bool = False):
        """(keys, q, codes, errors, size) of the densest plan at ``step`` that fits ``budget``
        bytes, or None. Plans are found with the size model; with ``real``, its error is
        corrected from real sizes (at most :data:`_REAL_CODINGS` runs of the range coder) and
        the size returned is the real one."""
        if not real:
            r = self._densest_within(budget, step)
            if r is None:
                return None
            keys, q, codes, kv = r
            return keys, q, codes, self.errors(keys, kv), self.estimate(keys, codes)
        scale, best, tried = 1.0, None, set()
        for _ in range(_REAL_CODINGS):
            r = self._densest_within(budget * scale, step)
            if r is None:
                break
            keys, q, codes, kv = r
            if len(keys) in tried:
                break
            tried.add(len(keys))
            real = self.size(keys, codes)
            est = self.estimate(keys, codes)
            if real <= budget and (best is None or len(keys) > len(best[0])):
                best = (keys, q, codes, kv, real)
            if real <= budget and (budget - real < 0.01 * budget or len(keys) == len(self.values)):
                break
            scale = scale * min(max(est / real, 0.5), 2.0) * (1.0 if real <= budget else 0.995)
        if best is None:
            return None
        keys, q, codes, kv, real = best
        return keys, q, codes, self.errors(keys, kv), real


def _encode_position(
    series: SphericalSeries,
    recons: tuple[str, ...],
    *,
    rate: float | None,
    max_error: float | None,
    max_gap: int,
    fps: float,
    skel_hash: bytes,
    where: str,
) -> tuple[Encoded, dict]:
    """Coding 2: keyframes by the position-error programme, values by their effect on positions
    (:class:`~sidql.codec.quantise.PositionQuantiser`), range-coded; the best of ``recons``.

    ``max_error`` [mm]: for each reconstruction and each step in :data:`STEP_FACTORS` times the
    target, the sparsest plan meeting it; the fewest bytes win. ``rate`` [B/s]: for each
    reconstruction the step is iterated towards twice the error it yields (a plan per step by the
    size model), the least mean error wins, and only the winner is range-coded (at most
    :data:`_REAL_CODINGS` times, correcting the model). Returns the encoding and every
    candidate's (mean error [mm], bytes or estimated bytes) by "reconstruction/position".
    """
    N = series.n_frames
    duration = N / fps
    G = min(max_gap, sidq.MAX_GAP)

    def builder(recon):
        def build(keys, quant, codes=None) -> sidq.Stream:
            return sidq.Stream(
                reconstruction=recon,
                latency=0,
                fps=float(np.float32(fps)),
                skeleton_hash=skel_hash,
                names=POINTS,
                parents=series.parents,
                lengths=sidq.position_lengths(series.lengths),
                quantiser=quant,
                keyframes=keys,
                pose_codes=np.zeros((len(keys), 2 * series.n_bones + 3), dtype=np.int64)
                if codes is None
                else codes,
                rate_codes=None,
                coding=2,
            )

        return build

    searches = {r: _PositionSearch(series, r, G, builder(r)) for r in recons}
    cands: dict = {}  # recon -> (keys, q, codes, errors, est bytes, step)
    if max_error is not None:
        target = max_error / 1000.0
        for recon, search in searches.items():
            for f in STEP_FACTORS:
                step = f * target
                r = search.for_error(target, step)
                while r is None and step > 1e-7:  # quantisation alone misses: finer steps
                    step *= 0.5
                    r = search.for_error(target, step)
                if r is not None:
                    est = search.estimate(r[0], r[2])
                    if recon not in cands or est < cands[recon][4]:
                        cands[recon] = (*r, est, step)
        if not cands:  # even every frame at the finest step misses it (e.g. the stored lengths)
            search = next(iter(searches.values()))
            keys, _, _, kv = search.code(_LAM_LO, 1e-7)
            floor = 1000.0 * search.errors(keys, kv).mean()
            raise UnmetTargetError(
                _where(where, f"cannot reach {max_error} mm: the finest stream has a mean error "
                       f"of {floor:.4f} mm")
            )  # fmt: skip
        recon = min(cands, key=lambda r: cands[r][4])
        keys, q, codes, E = cands[recon][:4]
    else:
        budget = rate * duration
        for recon, search in searches.items():
            step, tried = 4e-3, {}
            for _ in range(8):  # the best step is about twice the error it yields
                r = search.for_budget(budget, step)
                if r is None:  # even the sparsest plan is too large: coarser
                    step *= 4.0
                    continue
                tried[step] = r
                if len(r[0]) == N and r[4] < 0.97 * budget:  # every frame sent, room left
                    step *= max(0.25, (r[4] / budget) ** 2)
                    continue
                nxt = float(np.clip(STEP_FACTORS[1] * r[3].mean(), 1e-7, 1.0))
                if abs(np.log(nxt / step)) < 0.15:
                    break
                step = nxt
            if tried:
                s0 = min(tried, key=lambda x: tried[x][3].mean())
                for f in (STEP_FACTORS[0] / STEP_FACTORS[1], STEP_FACTORS[2] / STEP_FACTORS[1]):
                    if not any(abs(np.log(s0 * f / x)) < 0.05 for x in tried):
                        r = search.for_budget(budget, s0 * f)
                        if r is not None:
                            tried[s0 * f] = r
                step = min(tried, key=lambda x: tried[x][3].mean())
                cands[recon] = (*tried[step], step)
        if not cands:
            search = next(iter(searches.values()))
            size = search.size(*search.code(_LAM_HI, 1.0)[::2])
            raise UnmetTargetError(
                _where(where, f"rate too low: the sparsest plan needs {size} bytes, budget "
                       f"{budget:.0f}")
            )  # fmt: skip
        recon = min(cands, key=lambda r: cands[r][3].mean())
        final = None
        for f in 1.25 ** np.arange(31):  # the size model was optimistic at this step: coarser
            final = searches[recon].for_budget(budget, f * cands[recon][5], real=True)
            if final is not None:
                break
        if final is None:
            raise UnmetTargetError(_where(where, "rate too low for the position coding"))
        keys, q, codes, E = final[:4]
    stream = builder(recon)(keys, q, codes)
    data = sidq.to_bytes(stream)
    enc = Encoded(
        stream,
        data,
        _measure(series, stream),
        len(data) / duration,
        {},
        float(1000.0 * E.mean()),
        float(1000.0 * np.percentile(E, 95)),
    )
    summary = {f"{r}/position": (1000.0 * c[3].mean(), int(round(c[4]))) for r, c in cands.items()}
    summary[f"{recon}/position"] = (enc.mean_error_mm, len(data))
    return enc, summary


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
                raise UnmetTargetError(_where(where, f"rate too low for latency {H}"))
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
        raise UnmetTargetError(
            _where(
                where, f"rate too low: the sparsest plan needs {size} bytes, budget {budget:.0f}"
            )
        )
    return best


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

    Raises:
        UnmetTargetError: the rate cannot be met; UnknownNameError: an unknown reconstruction;
        ValueError: bad arguments.
    """
    if objective not in ("position", "angle"):
        raise ValueError(f"objective must be 'position' or 'angle'; got {objective!r}")
    if sum(x is not None for x in (rate, max_q, max_error)) != 1:
        raise ValueError("give exactly one of rate, max_q and max_error")
    if rate is not None and not rate > 0:
        raise ValueError(f"rate must be positive; got {rate}")
    if max_q is not None and not max_q >= 0:
        raise ValueError(f"max_q must be >= 0; got {max_q}")
    if max_error is not None and not max_error > 0:
        raise ValueError(f"max_error must be positive; got {max_error}")
    if reconstruction not in CHOICES:
        raise UnknownNameError("reconstruction", reconstruction, CHOICES)
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
    position = (
        objective == "position" and max_q is None and latency == 0 and reconstruction != "hermite"
    )
    if max_error is not None and not position:
        raise ValueError("max_error needs an offline stream (latency 0), linear or catmull_rom")
    if position:
        names = sidq.POSITION_RECONSTRUCTIONS if reconstruction == "auto" else (reconstruction,)
    else:
        names = CURVES if reconstruction == "auto" else (reconstruction,)
    common = dict(max_gap=max_gap, fps=fps, skel_hash=skel_hash, where=where)
    if position:
        enc, cand = _encode_position(series, names, rate=rate, max_error=max_error, **common)
        return replace(enc, candidates=cand)
    results, errors = {}, []
    for r in names:
        try:
            for e in _encode_one(series, r, rate=rate, max_q=max_q, latency=latency, **common):
                results[f"{r}/{e.stream.quantiser.bits}"] = e
        except UnmetTargetError as e:  # this reconstruction cannot meet the rate; others may
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
        clip = load_motion(asf, amc, fps=fps, derivatives=False)  # the chart needs no more
    except MotionDataError:
        raise
    except ValueError as e:  # e.g. an output rate that does not divide the source rate
        raise MotionDataError(str(amc), None, str(e)) from None
    enc = encode_clip(clip, skel_hash=skel, **kwargs)
    write_atomic(Path(out), lambda f: f.write(enc.data))
    return enc
