"""Latency-bounded keyframe decisions: a fixed-lag (windowed) version of the whole-trial programme.

A live sender that has committed keyframe ``a`` waits until it has seen frame ``e = a + H``
(``H`` the horizon), solves the programme of :mod:`sidql.codec.plan` on the window ``a..e``
(ending at ``e``, gaps at most ``min(G, H)``) and commits only the window plan's first keyframe
``b`` after ``a``, which it emits at time ``e``; then it repeats from ``b``.

A decoder can rebuild frame ``n`` in ``(a, b]`` once it holds keyframe ``b`` (Hermite, linear),
or also the keyframe after ``b`` (Catmull-Rom, whose tangent at ``b`` needs it). With latency
``L`` frames the horizon is ``H = L`` for Hermite and linear (frame ``n`` waits at most
``a + L - n < L`` frames) and ``H = max(1, L // 2)`` for Catmull-Rom (at most
``b + H - n <= 2 H - 1 < L``). :func:`frame_delays` measures this for any plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from sidql.codec.plan import sparsest_within
from sim.errors import UsageError


def horizon(latency: int, reconstruction: str) -> int:
    """Window length H [frames] for a latency of ``latency`` frames (see the module docstring)."""
    if latency < 1:
        raise UsageError(f"latency must be >= 1 frame; got {latency}")
    return max(1, latency // 2) if reconstruction == "catmull_rom" else int(latency)


@numba.njit(cache=True)
def _windowed(C, per_key, H):
    N, G1 = C.shape
    G = G1 - 1
    keys = np.zeros(N, dtype=np.int64)
    when = np.zeros(N, dtype=np.int64)
    D = np.empty(H + 1)
    prev = np.empty(H + 1, dtype=np.int64)
    n_keys = 1
    dist = 0.0
    a = 0
    while a < N - 1:
        e = min(a + H, N - 1)
        L = e - a
        D[0] = 0.0
        for t in range(1, L + 1):
            best = np.inf
            arg = -1
            for g in range(1, min(G, t) + 1):
                v = D[t - g] + C[a + t - g, g]
                if v < best:
                    best = v
                    arg = t - g
            D[t] = best + per_key
            prev[t] = arg
        t = L
        while prev[t] != 0:
            t = prev[t]
        b = a + t
        dist += C[a, t]
        keys[n_keys] = b
        when[n_keys] = e
        n_keys += 1
        a = b
    return keys[:n_keys].copy(), when[:n_keys].copy(), dist


@dataclass(frozen=True)
class StreamPlan:
    """Keyframes of a latency-bounded encoder.

    Attributes:
        keyframes: (W,) indices from 0 to N - 1.
        decided_at: (W,) the last frame the encoder had seen when it committed each keyframe.
        distortion: total segment cost [rad] of the band table; lam: the multiplier used.
    """

    keyframes: np.ndarray
    decided_at: np.ndarray
    distortion: float
    lam: float


def plan_stream(C: np.ndarray, lam: float, H: int) -> StreamPlan:
    """Fixed-lag plan of banded costs ``C`` (gaps at most ``min(G, H)``) for ``lam``."""
    G = min(C.shape[1] - 1, H)
    keys, when, dist = _windowed(np.ascontiguousarray(C[:, : G + 1]), float(lam), int(H))
    return StreamPlan(keys, when, float(dist), float(lam))


def frame_delays(keyframes: np.ndarray, decided_at: np.ndarray, reconstruction: str) -> np.ndarray:
    """(N,) frames each frame waits at the decoder: the time its last needed keyframe is
    emitted minus its own index (keyframes emitted at ``decided_at``)."""
    k = np.asarray(keyframes)
    N = int(k[-1]) + 1
    n = np.arange(N)
    seg_end = np.searchsorted(k, n, side="left")  # index of the first keyframe >= n
    need = seg_end.copy()
    if reconstruction == "catmull_rom":
        need = np.minimum(seg_end + 1, len(k) - 1)
        need[n == 0] = 1  # frame 0's segment tangent needs keyframe 1
    return np.asarray(decided_at)[need] - n


_LAM_LO, _LAM_HI, _STEPS = 1e-6, 1e7, 40


def stream_for_budget(C: np.ndarray, H: int, max_keys: int) -> StreamPlan | None:
    """The fixed-lag plan with the smallest multiplier found by bisection whose keyframe count
    is at most ``max_keys`` (None when even the largest multiplier needs more)."""
    p = plan_stream(C, _LAM_LO, H)
    if len(p.keyframes) <= max_keys:
        return p
    best = plan_stream(C, _LAM_HI, H)
    if len(best.keyframes) > max_keys:
        return None
    lo, hi = np.log(_LAM_LO), np.log(_LAM_HI)
    for _ in range(_STEPS):
        mid = 0.5 * (lo + hi)
        p = plan_stream(C, float(np.exp(mid)), H)
        if len(p.keyframes) <= max_keys:
            hi, best = mid, p
        else:
            lo = mid
    return best


def stream_for_quality(C: np.ndarray, H: int, measure, max_q: float) -> tuple[StreamPlan, float]:
    """The fixed-lag plan with the largest multiplier (bisection) whose measured error is
    <= ``max_q``; every frame a keyframe is the fallback."""
    return sparsest_within(lambda lam: plan_stream(C, lam, H), measure, max_q, _STEPS // 2)
