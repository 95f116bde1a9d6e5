"""The angle coding of a trial (codings 0 and 1): keyframes that minimise Q, eq. 18.

Offline streams are packed (coding 1: delta + LZMA) at a bit depth of 9, 11, 13 or 16 bits per
pose channel. At a rate, the trial is encoded at 11 bits with real sizes (the keyframe count is
corrected from the measured size a few times); the other depths are judged with a size model
(each extra bit costs one bit per pose channel per keyframe) and their measured Q at the
modelled keyframe count, and the best is re-encoded with real sizes if it beats 11 bits. With a
Q target every depth is encoded and the smallest file meeting Q kept. Live streams (a latency)
use fixed 16-bit records (coding 0), which a sender can emit one by one; keyframes by the
fixed-lag programme (:mod:`sidql.codec.stream`).

Units: radians, bytes, frames.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sidql.codec import format as sidq
from sidql.codec.encoded import Encoded, measure, where_prefix
from sidql.codec.plan import band_costs, least_keyframes, plan_for_budget, plan_for_quality
from sidql.codec.quantise import fit_quantiser
from sidql.codec.stream import horizon, stream_for_budget, stream_for_quality
from sidql.keyframes.spherical import POINTS, SphericalSeries
from sim.errors import UnmetTargetError

#: bits per pose channel tried for packed (offline) streams; live streams use 16.
PACKED_BITS: tuple[int, ...] = (9, 11, 13, 16)
#: the bit depth encoded first; the others are judged by a size model, the best re-encoded.
AUTO_BITS = 11
_ROUNDS = 8


def encode_angles(
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
    """Encodings of one reconstruction ``recon`` at a byte ``rate`` [B/s] or a Q target
    ``max_q`` [rad], one per bit depth tried (one for a live stream, ``latency`` > 0)."""
    coder = _AngleCoder(series, recon, latency, max_gap, fps, skel_hash, where)
    if coder.coding == 0:
        return [coder.live(rate, max_q)]
    if max_q is not None:
        return [coder.for_quality(max_q, bits) for bits in bit_depths]
    return coder.at_rate(rate, bit_depths)


class _AngleCoder:
    """One reconstruction's angle coding of a trial: its quantisers, banded segment costs and the
    streams built from keyframes (see the module docstring)."""

    def __init__(self, series, recon, latency, max_gap, fps, skel_hash, where):
        self.series, self.recon, self.latency = series, recon, latency
        self.fps, self.skel_hash, self.where = fps, skel_hash, where
        M = self.M = series.n_bones
        values, rates = self.values, self.rates = series.channels()
        q16 = self.q16 = fit_quantiser(values, rates if recon == "hermite" else None, M)
        Xq = q16.grid_pose(values)
        Rq = q16.grid_rates(rates) * series.dt if recon == "hermite" else None
        G = min(max_gap, sidq.MAX_GAP)
        self.H = horizon(latency, recon) if latency else 0
        if self.H:
            G = min(G, self.H)
        self.C = band_costs(
            values[:, : 2 * M], Xq[:, : 2 * M], None if Rq is None else Rq[:, : 2 * M], G, recon
        )
        self.coding = 0 if latency else 1
        self.duration = series.n_frames / fps

    def quantiser(self, bits: int):
        if bits == 16:
            return self.q16
        q = fit_quantiser(self.values, None, self.M, bits)
        return replace(q, rate_step=self.q16.rate_step)

    def build(self, keys: np.ndarray, quant) -> sidq.Stream:
        hermite = self.recon == "hermite"
        return sidq.Stream(
            reconstruction=self.recon,
            latency=int(self.latency),
            fps=float(np.float32(self.fps)),
            skeleton_hash=self.skel_hash,
            names=POINTS,
            parents=self.series.parents,
            lengths=self.series.lengths.astype(np.float32).astype(np.float64),
            quantiser=quant,
            keyframes=keys,
            pose_codes=quant.encode_pose(self.values[keys]),
            rate_codes=quant.encode_rates(self.rates[keys]) if hermite else None,
            coding=self.coding,
        )

    def measure(self, keys: np.ndarray, quant) -> float:
        return measure(self.series, self.build(keys, quant))

    def finish(self, keys, quant) -> Encoded:
        stream = self.build(keys, quant)
        data = sidq.to_bytes(stream)
        return Encoded(stream, data, measure(self.series, stream), len(data) / self.duration, {})

    def keys_for_budget(self, quant, budget: float, H: int, guess: float = 0.5) -> np.ndarray:
        return _keys_for_budget(
            self.C, lambda k: self.build(k, quant), budget, H, self.recon, self.M, self.where,
            guess,
        )  # fmt: skip

    def live(self, rate: float | None, max_q: float | None) -> Encoded:
        """Coding 0 (fixed 16-bit records) at a rate or a Q target."""
        quant = self.q16
        if rate is not None:
            keys = self.keys_for_budget(quant, rate * self.duration, self.H)
        else:
            plan = stream_for_quality(self.C, self.H, lambda k: self.measure(k, quant), max_q)[0]
            keys = plan.keyframes
        return self.finish(keys, quant)

    def for_quality(self, max_q: float, bits: int) -> Encoded:
        """Coding 1 at ``bits``: the fewest keyframes meeting ``max_q``."""
        quant = self.quantiser(bits)
        p, _ = plan_for_quality(self.C, lambda k: self.measure(k, quant), max_q)
        return self.finish(p.keyframes, quant)

    def at_rate(self, rate: float, bit_depths: tuple[int, ...]) -> list[Encoded]:
        """Coding 1 at a rate: real sizes at the first depth, then a size model picks the depth
        (see the module docstring)."""
        budget = rate * self.duration
        b0 = AUTO_BITS if AUTO_BITS in bit_depths else bit_depths[0]
        q0 = self.quantiser(b0)
        keys = self.keys_for_budget(q0, budget, 0)
        first = self.finish(keys, q0)
        out = [first]
        fixed = len(first.data) - _payload(first)
        per_key0 = _payload(first) / len(keys)
        estimates = {}
        for bits in bit_depths:
            if bits == b0:
                continue
            # each bit of precision adds about one incompressible bit per pose channel
            per_key = max(per_key0 + (2 * self.M + 3) * (bits - b0) / 8.0, 1.0)
            quant = self.quantiser(bits)
            try:
                p = plan_for_budget(self.C, int((budget - fixed) // per_key), self.where)
            except UnmetTargetError:
                continue
            estimates[bits] = (self.measure(p.keyframes, quant), per_key, quant)
        if estimates:
            bits = min(estimates, key=lambda b: estimates[b][0])
            q_est, per_key, quant = estimates[bits]
            if q_est < first.q:
                guess = per_key / sidq.record_size(self.recon, self.M)
                try:
                    out.append(self.finish(self.keys_for_budget(quant, budget, 0, guess), quant))
                except UnmetTargetError:
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
                raise UnmetTargetError(where_prefix(where, f"rate too low for latency {H}"))
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
            where_prefix(
                where, f"rate too low: the sparsest plan needs {size} bytes, budget {budget:.0f}"
            )
        )
    return best
