"""The position coding of a trial (coding 2): keyframes and bits where they lower the mean joint
position error most.

Keyframes by a programme over the summed point displacement
(:func:`sidql.codec.plan.position_band_costs`), values quantised by their effect on positions and
range-coded (:class:`sidql.codec.quantise.PositionQuantiser`), the step and the multiplier searched
with a size model and the exact position error (:mod:`sidql.codec.positions`).

Units: metres inside, millimetres in the targets and figures; bytes, bytes per second.
"""

from __future__ import annotations

import os
import weakref
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from sidql.codec import format as sidq
from sidql.codec.cones import rigid_cones
from sidql.codec.encoded import Encoded, measure, where_prefix
from sidql.codec.entropy import encode_integers
from sidql.codec.plan import plan, position_band_costs
from sidql.codec.position_format import channel_kinds, coded_rows, estimated_block
from sidql.codec.positions import chart_points, position_errors
from sidql.codec.quantise import PositionQuantiser, aim_basis
from sidql.codec.shared_cache import SharedCache
from sidql.keyframes.spherical import POINTS, SphericalSeries
from sim.errors import UnmetTargetError

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
#: the root position channels' slope weight: 1 (linear extrapolation; the pelvis moves smoothly)
#: measured best against 0.5 and 0.75 on the CMU trials of ``../shared``.
ROOT_PREDICTOR = 1.0
#: each bone's keyframe value aims from its decoded parent point at its true point (see
#: :func:`sidql.codec.dpcm.dpcm`): errors stop piling up down the chain.
AIM = True
#: the subtree size's exponent in the quantiser's levers with aiming (k / 16 in the stream):
#: 1/8 measured best against 1/16, 1/4 and 3/8 on the CMU trials of ``../shared`` with the
#: version-4 coder (bytes at equal 95th percentile 1-4 % fewer than 1/4, at equal mean error
#: 0-1.5 % more; 1/16 loses at both ends).
LEVER_EXPONENT = 0.125
#: with ``max_error`` E, no segment whose inner frames' first-order mean error bound passes
#: FRAME_CAP x E is planned (:func:`sidql.codec.plan.position_band_costs`): the error tail.
FRAME_CAP = 3.0
#: each keyframe's step times ``(mean w / w)^g`` with w the frames its value moves
#: (:func:`sidql.codec.quantise.keyframe_steps`; version 5): 1/4 measured best against 0, 1/2
#: and 3/4 on the CMU trials of ``../shared`` (with 1/2 the same bytes, a heavier tail).
GAP_EXPONENT = 0.25
#: bones tied to others at a fixed angle are predicted on their cones (:mod:`sidql.codec.cones`,
#: version 6): on the CMU trials of ``../shared`` 6, 5 and 3 % fewer bytes at equal mean error
#: of 1, 3 and 10 mm, the cone section (25 bytes a stream there) included.
CONES = True
#: bytes of coded plans kept per search, the least recently used dropped first (at least the last
#: two): each holds (W, D) codes and decoded values, 0.7 MB at W = 900 keyframes (11 kept), so
#: memory does not grow with the take when it is encoded whole; repeats are rare past the last few.
#: A chart's searches share theirs (:mod:`sidql.codec.shared_cache`): the densest and the
#: sparsest plans at a step are every reconstruction's.
CODED_BYTES = 8 << 20


class _PositionSearch:
    """Keyframes and step sizes of one reconstruction under coding 2 (position-coded).

    Sizes during the searches come from a size model (:func:`~sidql.codec.entropy.estimate_size`,
    :func:`~sidql.codec.position_format.estimated_block`);
    the range coder itself runs only on the few plans that may be kept."""

    def __init__(self, series, recon, G, build, extra_cost=None, frame_cap_mm=np.inf, coded=None,
                 chart=None):  # fmt: skip
        self.series, self.recon, self.build = series, recon, build
        self.values, self.truth, self.basis = _chart_arrays(series) if chart is None else chart
        values = self.values
        self.lengths = sidq.position_lengths(series.lengths)
        self.cones = rigid_cones(values, series.n_bones, series.parents) if CONES else None
        self.C = position_band_costs(
            values, values, None, G, recon, self.lengths, series.parents,
            frame_cap_mm=frame_cap_mm,
        )  # fmt: skip
        if extra_cost is not None:  # e.g. the physical cost (sidql.codec.contact_coding) [m]
            self.C = self.C + extra_cost[:, : G + 1]
        self.plans: dict = {}
        self.coded = _coded_cache(1) if coded is None else coded  # may be other searches' too
        self.last = None  # log lam of the previous search's answer
        self.sized: dict = {}  # id(codes) -> (weak references to codes and keys, block bytes)
        self.header = len(sidq.header_bytes(build(np.array([0, 1]), self.quantiser(1e-3)))) + 8

    def quantiser(self, step: float) -> PositionQuantiser:
        M = self.series.n_bones
        return PositionQuantiser(
            M, self.lengths, self.series.parents, float(np.float32(step)), PREDICTOR,
            exponent=LEVER_EXPONENT, root_rho=ROOT_PREDICTOR, gap_exponent=GAP_EXPONENT,
            partner=False, cones=self.cones,
        )  # fmt: skip

    def keys(self, lam: float) -> np.ndarray:
        if lam not in self.plans:
            self.plans[lam] = plan(self.C, lam).keyframes
        return self.plans[lam]

    def code(self, lam: float, step: float):
        keys = self.keys(lam)
        key = (hash(keys.tobytes()), len(keys), step)  # nearby multipliers often share a plan

        def make():
            q = self.quantiser(step)
            codes, kv = q.encode_keyframes(self.values, keys, AIM, self.basis, rows=keys)
            return keys, q, codes, kv

        return self.coded.get(key, make)

    def estimate(self, keys, codes) -> float:
        """Estimated bytes of the coded plan ``(keys, codes)``: worked out once per plan the
        search holds (it asks about each about twice; the same arrays, the same float)."""
        hit = self.sized.get(id(codes))
        if hit is None or hit[0]() is not codes or hit[1]() is not keys:
            hit = (weakref.ref(codes), weakref.ref(keys), estimated_block(keys, codes))
            self.sized[id(codes)] = hit
        return self.header + hit[2]

    def size(self, keys, codes) -> int:
        kinds = channel_kinds(self.series.n_bones)
        return self.header + len(encode_integers(coded_rows(keys, codes), kinds=kinds))

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


def encode_positions(
    series: SphericalSeries,
    recons: tuple[str, ...],
    *,
    rate: float | None,
    max_error: float | None,
    max_gap: int,
    fps: float,
    skel_hash: bytes,
    where: str,
    extra_cost: np.ndarray | None = None,
) -> tuple[Encoded, dict]:
    """Coding 2: keyframes by the position-error programme, values by their effect on positions
    (:class:`~sidql.codec.quantise.PositionQuantiser`), range-coded; the best of ``recons``.

    ``max_error`` [mm]: for each reconstruction and each step in :data:`STEP_FACTORS` times the
    target, the sparsest plan meeting it; the fewest bytes win. ``rate`` [B/s]: for each
    reconstruction the step is iterated towards twice the error it yields (a plan per step by the
    size model), the least mean error wins, and only the winner is range-coded (at most
    :data:`_REAL_CODINGS` times, correcting the model). Returns the encoding and every
    candidate's (mean error [mm], bytes or estimated bytes) by "reconstruction/position".
    ``extra_cost``: (N, >= G + 1) [m] added to the keyframe programme's segment costs.
    """
    duration = series.n_frames / fps
    G = min(max_gap, sidq.MAX_GAP)
    cap = FRAME_CAP * max_error if max_error is not None else np.inf
    coded = _coded_cache(len(recons))  # the codes do not depend on the reconstruction
    arrays = _chart_arrays(series)  # nor do the values, true points and aiming directions
    searches = {
        r: _PositionSearch(
            series, r, G, _builder(series, r, fps, skel_hash), extra_cost, cap, coded, arrays
        )  # fmt: skip
        for r in recons
    }
    if max_error is not None:
        cands, recon, (keys, q, codes, E) = _for_error(searches, max_error, where)
    else:
        cands, recon, (keys, q, codes, E) = _for_rate(searches, rate * duration, where)
    stream = _builder(series, recon, fps, skel_hash)(keys, q, codes)
    data = sidq.to_bytes(stream)
    enc = Encoded(
        stream,
        data,
        measure(series, stream),
        len(data) / duration,
        {},
        float(1000.0 * E.mean()),
        float(1000.0 * np.percentile(E, 95)),
    )
    summary = {f"{r}/position": (1000.0 * c[3].mean(), int(round(c[4]))) for r, c in cands.items()}
    summary[f"{recon}/position"] = (enc.mean_error_mm, len(data))
    return enc, summary


def _chart_arrays(series: SphericalSeries):
    """(values (N, 2 M + 3) contiguous, read in place by rows; true points (N, J, 3) [m];
    aiming directions (N, M, 5)) of a chart: what every reconstruction's search reads."""
    values, _ = series.channels()
    values = np.ascontiguousarray(values, dtype=np.float64)
    truth = chart_points(values, series.lengths, series.parents)
    return values, truth, aim_basis(values, series.n_bones)


def _coded_cache(searches: int) -> SharedCache:
    """The coded plans of ``searches`` searches of one chart: :data:`CODED_BYTES` each."""
    return SharedCache(searches * CODED_BYTES, lambda r: r[2].nbytes + r[3].nbytes)


def _builder(series: SphericalSeries, recon: str, fps: float, skel_hash: bytes):
    """``build(keys, quant, codes=None) -> Stream``: a coding-2 stream of ``recon``."""

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


def _each(fn, searches: dict) -> dict:
    """``{recon: fn(search)}`` for every reconstruction's search, side by side in threads (each
    search is independent and its compiled kernels release the GIL): the results one after the
    other would give, sooner where there are cores to spare."""
    if len(searches) < 2 or (os.cpu_count() or 1) < 2:
        return {r: fn(search) for r, search in searches.items()}
    with ThreadPoolExecutor(max_workers=len(searches)) as pool:
        futures = {r: pool.submit(fn, search) for r, search in searches.items()}
        return {r: f.result() for r, f in futures.items()}


def _for_error(searches: dict, max_error: float, where: str):
    """At a mean error target ``max_error`` [mm]: the candidates by reconstruction, the winner
    (fewest estimated bytes) and its (keys, quantiser, codes, errors)."""
    target = max_error / 1000.0

    def fewest_bytes(search):  # -> (keys, q, codes, errors, est bytes, step) or None
        best = None
        for f in STEP_FACTORS:
            step = f * target
            r = search.for_error(target, step)
            while r is None and step > 1e-7:  # quantisation alone misses: finer steps
                step *= 0.5
                r = search.for_error(target, step)
            if r is not None:
                est = search.estimate(r[0], r[2])
                if best is None or est < best[4]:
                    best = (*r, est, step)
        return best

    cands = {r: c for r, c in _each(fewest_bytes, searches).items() if c is not None}
    if not cands:  # even every frame at the finest step misses it (e.g. the stored lengths)
        search = next(iter(searches.values()))
        keys, _, _, kv = search.code(_LAM_LO, 1e-7)
        floor = 1000.0 * search.errors(keys, kv).mean()
        raise UnmetTargetError(
            where_prefix(where, f"cannot reach {max_error} mm: the finest stream has a mean "
                         f"error of {floor:.4f} mm")
        )  # fmt: skip
    recon = min(cands, key=lambda r: cands[r][4])
    return cands, recon, cands[recon][:4]


def _for_rate(searches: dict, budget: float, where: str):
    """At ``budget`` bytes: the candidates by reconstruction, the winner (least mean error) and
    its (keys, quantiser, codes, errors), range-coded to fit."""
    found = _each(lambda search: _step_for_budget(search, budget), searches)
    cands = {r: c for r, c in found.items() if c is not None}  # (keys, q, codes, errors, B, step)
    if not cands:
        search = next(iter(searches.values()))
        size = search.size(*search.code(_LAM_HI, 1.0)[::2])
        raise UnmetTargetError(
            where_prefix(where, f"rate too low: the sparsest plan needs {size} bytes, budget "
                         f"{budget:.0f}")
        )  # fmt: skip
    recon = min(cands, key=lambda r: cands[r][3].mean())
    final = None
    for f in 1.25 ** np.arange(31):  # the size model was optimistic at this step: coarser
        final = searches[recon].for_budget(budget, f * cands[recon][5], real=True)
        if final is not None:
            break
    if final is None:
        raise UnmetTargetError(where_prefix(where, "rate too low for the position coding"))
    return cands, recon, final[:4]


def _step_for_budget(search: _PositionSearch, budget: float):
    """(keys, q, codes, errors, estimated bytes, step) of the step of least mean error at
    ``budget`` bytes for one reconstruction, or None when no plan fits."""
    N = len(search.values)
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
    if not tried:
        return None
    s0 = min(tried, key=lambda x: tried[x][3].mean())
    for f in (STEP_FACTORS[0] / STEP_FACTORS[1], STEP_FACTORS[2] / STEP_FACTORS[1]):
        if not any(abs(np.log(s0 * f / x)) < 0.05 for x in tried):
            r = search.for_budget(budget, s0 * f)
            if r is not None:
                tried[s0 * f] = r
    step = min(tried, key=lambda x: tried[x][3].mean())
    return (*tried[step], step)
