"""Keyframes over a whole trial: exact dynamic programme with a maximum gap and a rate multiplier.

With ``C[i, g]`` the distortion of the segment from keyframe ``i`` to keyframe ``i + g``
(summed ``|wrap(angle error)|`` [rad] over the frames strictly inside, all 2 M angles, computed
from the *quantised* keyframe values the decoder will see), and ``B`` the bytes of one keyframe
record, the plan for a multiplier ``lam`` [rad per byte] minimises::

    J(K) = sum over segments C[k_w, k_{w+1} - k_w] + lam * B * |K|

over keyframe sets K containing 0 and N - 1 with gaps 1..G:
``D[j] = min_{1 <= g <= G} D[j - g] + C[j - g, g] + lam B``: O(N G) per multiplier, O(N G) memory
(the banded cost table); the table costs O(N G^2 M) once.

Hermite and linear segments depend on their two end keyframes only, so ``C`` is exact. A
Catmull-Rom segment also depends on the neighbouring keyframes (through its end tangents); its
table uses a proxy, the Hermite curve whose tangents are the central differences of the
quantised pose over ``+-g`` frames (the Catmull-Rom tangent if the neighbouring gaps equal this
one), and the true distortion of the chosen keyframes is measured afterwards.

Rate control: the number of keyframes of the optimum never increases with ``lam``, and its
distortion never decreases, so bisection on ``log lam`` finds the cheapest plan that meets a byte
budget, or the sparsest plan whose measured Q stays under a target.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from sidql.keyframes.curves import CURVES
from sidql.keyframes.segment_costs import segment_weights
from sim.errors import UnmetTargetError, UsageError
from sim.model.angles import wrap_angle

#: Kernel mode of each curve: its index in CURVES (0 hermite, 1 linear, 2 catmull_rom).
MODES = {curve: i for i, curve in enumerate(CURVES)}
DEFAULT_MAX_GAP = 60


@numba.njit(cache=True, inline="always")
def _end_rates(Xq, Rq, i, j, g, mode, ma, mb):
    """Fill ``ma``, ``mb`` (D,) with the rates [per frame] the decoder's curve has at the ends
    of segment (i, j = i + g): the transmitted ones (mode 0, hermite), Catmull-Rom's proxy from
    the keyframe values g frames away (mode 2); linear (mode 1) uses none (left as they are)."""
    N, D = Xq.shape
    if mode == 0:
        for d in range(D):
            ma[d] = Rq[i, d]
            mb[d] = Rq[j, d]
    elif mode == 2:
        lo_a = max(i - g, 0)
        hi_a = min(i + g, N - 1)
        lo_b = max(j - g, 0)
        hi_b = min(j + g, N - 1)
        for d in range(D):
            ma[d] = (Xq[hi_a, d] - Xq[lo_a, d]) / (hi_a - lo_a)
            mb[d] = (Xq[hi_b, d] - Xq[lo_b, d]) / (hi_b - lo_b)


@numba.njit(cache=True, fastmath=True, inline="always")
def _band_row(
    X, Xq, Rq, G, mode, i, C, ma, mb, e, weight, sin_theta, root_weight, cap, position, frame_cap
):
    """Row ``i`` of a banded cost table ``C`` (N, G + 1): entry [i, g] for the segment
    (i, i + g); ``ma``, ``mb``, ``e``: (D,) scratch. Each inner frame adds its summed
    |wrapped angle error| or, with ``position``, its first-order point displacement (see
    :func:`_position_band_costs`), which also ends the row at ``cap`` (the segment's mean) or
    ``frame_cap`` (one inner frame's)."""
    N, D = X.shape
    M = (D - 3) // 2
    C[i, 0] = 0.0
    for g in range(1, G + 1):
        j = i + g
        if j >= N:
            break
        _end_rates(Xq, Rq, i, j, g, mode, ma, mb)
        total = 0.0
        for n in range(i + 1, j):
            h01, h10, h11 = segment_weights(n, i, g, mode == 1)
            acc = 0.0
            if position:
                for d in range(D):
                    e[d] = (
                        Xq[i, d] + h01 * (Xq[j, d] - Xq[i, d]) + h10 * ma[d] + h11 * mb[d] - X[n, d]
                    )
                for b in range(M):
                    et = wrap_angle(e[b])
                    ep = wrap_angle(e[M + b]) * sin_theta[n, b]
                    acc += weight[b] * np.sqrt(et * et + ep * ep)
                r0 = e[2 * M]
                r1 = e[2 * M + 1]
                r2 = e[2 * M + 2]
                acc += root_weight * np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                if acc > frame_cap:
                    total = np.inf
                    break
            else:
                for d in range(D):
                    v = Xq[i, d] + h01 * (Xq[j, d] - Xq[i, d]) + h10 * ma[d] + h11 * mb[d] - X[n, d]
                    v = wrap_angle(v)
                    acc += abs(v)
            total += acc
        C[i, g] = total
        if position and total > cap * (g - 1):  # also ends at a frame beyond frame_cap (inf)
            break


@numba.njit(cache=True, fastmath=True)
def _band_costs(X, Xq, Rq, G, mode):
    """(N, G + 1) segment costs: entry [i, g] for the segment (i, i + g) (inf past the end).

    X: (N, D) true angles [rad]; Xq: (N, D) quantised keyframe angles [rad]; Rq: (N, D)
    quantised rates times dt [rad/frame] (hermite only); mode 0 hermite, 1 linear,
    2 Catmull-Rom proxy.
    """
    N, D = X.shape
    C = np.full((N, G + 1), np.inf)
    ma = np.zeros(D)  # zeros: "linear" multiplies the end rates by 0 (0 x stale NaN is NaN)
    mb = np.zeros(D)
    e = np.zeros(D)
    none = np.zeros(0)
    for i in range(N):
        _band_row(X, Xq, Rq, G, mode, i, C, ma, mb, e, none, X, 0.0, 0.0, False, 0.0)
    return C


@numba.njit(cache=True, fastmath=True, parallel=True)
def _position_band_costs(X, Xq, Rq, G, mode, weight, sin_theta, root_weight, cap, frame_cap):
    """(N, G + 1) position-error segment costs [m]: like :func:`_band_costs`, but frame n adds
    ``sum_b weight[b] sqrt(e_theta_b^2 + sin(theta_b)^2 e_phi_b^2) + root_weight |e_root|``, the
    summed displacement of all points to first order (a bone's error moves every point below it).
    A segment whose mean cost per inner frame exceeds ``cap``, or one of whose inner frames
    costs more than ``frame_cap``, ends the row: it and every longer segment from the same
    keyframe stay inf (no plan worth having uses them; the second bounds the error tail).

    X, Xq, Rq: (N, 2 M + 3) all channels [theta | phi | root]; weight: (M,) bone length times the
    number of points at or below the bone [m]; sin_theta: (N, M) of the true angles.
    """
    N, D = X.shape
    C = np.full((N, G + 1), np.inf)
    for i in numba.prange(N):
        # zeros, not empty: "linear" (mode 1) multiplies the end rates by 0, and 0 x a stale
        # inf or NaN would leak garbage into the costs
        ma = np.zeros(D)
        mb = np.zeros(D)
        e = np.zeros(D)
        _band_row(
            X, Xq, Rq, G, mode, i, C, ma, mb, e, weight, sin_theta, root_weight, cap, True,
            frame_cap,
        )  # fmt: skip
    return C


#: segments whose frames' first-order mean position error bound exceeds this [mm] are not
#: considered (far beyond any error a plan at a useful rate has; saves most of the table).
POSITION_COST_CAP_MM = 100.0


def subtree_sizes(parents: np.ndarray) -> np.ndarray:
    """(J,) number of points at or below each point of a tree (parents before children)."""
    parents = np.asarray(parents)
    n = np.ones(len(parents), dtype=np.int64)
    for j in range(len(parents) - 1, 0, -1):
        n[parents[j]] += n[j]
    return n


def position_weights(lengths: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(M,) how far all points move together per radian of a bone's direction: the bone's length
    [m] times the number of points at or below it (every one of them moves with the bone)."""
    return np.asarray(lengths, dtype=np.float64) * subtree_sizes(parents)[1:]


def position_band_costs(
    X: np.ndarray,
    Xq: np.ndarray,
    Rq: np.ndarray | None,
    max_gap: int,
    reconstruction: str,
    lengths: np.ndarray,
    parents: np.ndarray,
    cap_mm: float = POSITION_COST_CAP_MM,
    frame_cap_mm: float = np.inf,
) -> np.ndarray:
    """(N, G + 1) banded segment costs in summed point displacement [m] (first order; see
    :func:`_position_band_costs`): divided by ``N J`` a plan's total is an upper bound on its
    mean joint position error, to first order. Segments from a keyframe stop at the first whose
    frames' mean error bound exceeds ``cap_mm`` [mm], or one of whose frames' bound exceeds
    ``frame_cap_mm`` [mm] (longer ones stay inf; segments of one frame are always allowed).

    Args:
        X: (N, 2 M + 3) true channels [theta | phi | root]; Xq: the keyframe values the decoder
            will see; Rq: (hermite) their rates times dt, else None.
        lengths: (M,) bone lengths [m]; parents: (M + 1,) parent indices.
    """
    if max_gap < 1:
        raise UsageError(f"max gap must be >= 1; got {max_gap}")
    X = np.ascontiguousarray(X, dtype=np.float64)
    Xq = np.ascontiguousarray(Xq, dtype=np.float64)
    Rq = X if Rq is None else np.ascontiguousarray(Rq, dtype=np.float64)
    M = (X.shape[1] - 3) // 2
    G = int(min(max_gap, max(X.shape[0] - 1, 1)))
    w = position_weights(lengths, parents)
    sin_theta = np.ascontiguousarray(np.sin(X[:, :M]))
    J = float(len(parents))
    cap = J * cap_mm / 1000.0
    frame_cap = J * frame_cap_mm / 1000.0
    return _position_band_costs(
        X, Xq, Rq, G, MODES[reconstruction], w, sin_theta, J, cap, frame_cap
    )


@numba.njit(cache=True, nogil=True)
def _dp(C, per_key):
    """Optimal keyframes of the banded table C for a cost ``per_key`` per keyframe.

    Returns (keyframe count, distortion, (N,) predecessor array)."""
    N, G1 = C.shape
    G = G1 - 1
    D = np.full(N, np.inf)
    dist = np.zeros(N)
    cnt = np.zeros(N, dtype=np.int64)
    prev = np.full(N, -1, dtype=np.int64)
    D[0] = per_key
    cnt[0] = 1
    for j in range(1, N):
        best = np.inf
        arg = -1
        for g in range(1, min(G, j) + 1):
            i = j - g
            v = D[i] + C[i, g]
            if v < best:
                best = v
                arg = i
        D[j] = best + per_key
        prev[j] = arg
        dist[j] = dist[arg] + C[arg, j - arg]
        cnt[j] = cnt[arg] + 1
    return cnt[N - 1], dist[N - 1], prev


@numba.njit(cache=True, nogil=True)
def _backtrack(prev, last):
    n = 1
    j = last
    while prev[j] >= 0:
        j = prev[j]
        n += 1
    out = np.empty(n, dtype=np.int64)
    j = last
    for w in range(n - 1, -1, -1):
        out[w] = j
        j = prev[j]
    return out


def _count(C: np.ndarray, lam: float) -> int:
    return int(_dp(C, float(lam))[0])


def band_costs(
    X: np.ndarray, Xq: np.ndarray, Rq: np.ndarray | None, max_gap: int, reconstruction: str
) -> np.ndarray:
    """(N, G + 1) banded segment costs [rad] (see the module docstring).

    Args:
        X: (N, 2 M) true angles [theta | phi] [rad].
        Xq: (N, 2 M) the same rounded to the quantisation grid [rad].
        Rq: (N, 2 M) quantised rates times dt [rad/frame] (hermite), else None.
        max_gap: G >= 1; reconstruction: "hermite", "linear" or "catmull_rom".
    """
    if max_gap < 1:
        raise UsageError(f"max gap must be >= 1; got {max_gap}")
    X = np.ascontiguousarray(X, dtype=np.float64)
    Xq = np.ascontiguousarray(Xq, dtype=np.float64)
    Rq = X if Rq is None else np.ascontiguousarray(Rq, dtype=np.float64)
    G = int(min(max_gap, max(X.shape[0] - 1, 1)))
    return _band_costs(X, Xq, Rq, G, MODES[reconstruction])


@dataclass(frozen=True)
class Plan:
    """Keyframes chosen by the programme.

    Attributes:
        keyframes: (W,) indices from 0 to N - 1.
        distortion: the programme's total segment cost [rad] (exact for hermite/linear).
        lam: the multiplier [rad per keyframe] that produced them.
    """

    keyframes: np.ndarray
    distortion: float
    lam: float


def plan(C: np.ndarray, lam: float) -> Plan:
    """The optimal keyframes of banded costs ``C`` for ``lam`` [rad per keyframe]."""
    count, dist, prev = _dp(C, float(lam))
    k = _backtrack(prev, C.shape[0] - 1)
    assert len(k) == count
    return Plan(k, float(dist), float(lam))


_LAM_LO, _LAM_HI, _STEPS = 1e-6, 1e7, 48


def least_keyframes(C: np.ndarray) -> int:
    """The fewest keyframes any plan over the banded cost table ``C`` (N, G + 1) can have: the
    two ends and enough between them that no gap exceeds G."""
    N, G1 = C.shape
    return int(np.ceil((N - 1) / max(G1 - 1, 1))) + 1 if N > 1 else 1


def plan_for_budget(C: np.ndarray, max_keys: int, where: str = "") -> Plan:
    """The least-distortion Lagrangian plan with at most ``max_keys`` keyframes (bisection).

    Raises:
        UnmetTargetError: even the sparsest plan the maximum gap allows needs more keyframes.
    """
    G1 = C.shape[1]
    least = least_keyframes(C)
    if max_keys < least:
        problem = (
            f"rate too low: the maximum gap of {G1 - 1} frames needs at least {least} keyframes, "
            f"the budget allows {max_keys}"
        )
        raise UnmetTargetError(f"{where}: {problem}" if where else problem)
    if _count(C, _LAM_LO) <= max_keys:
        return plan(C, _LAM_LO)
    lo, hi = np.log(_LAM_LO), np.log(_LAM_HI)
    for _ in range(_STEPS):
        mid = 0.5 * (lo + hi)
        if _count(C, float(np.exp(mid))) <= max_keys:
            hi = mid
        else:
            lo = mid
    return plan(C, float(np.exp(hi)))


def plan_for_quality(
    C: np.ndarray, measure: Callable[[np.ndarray], float], max_q: float
) -> tuple[Plan, float]:
    """The sparsest Lagrangian plan whose measured error ``measure(keyframes)`` is <= ``max_q``.

    Returns the plan and its measured error. Every frame a keyframe is the fallback (error 0).
    """
    return sparsest_within(lambda lam: plan(C, lam), measure, max_q, _STEPS // 2)


def sparsest_within(
    make: Callable, measure: Callable[[np.ndarray], float], max_q: float, steps: int
):
    """Rate control for quality, for any planner ``make(lam)`` (a plan with ``.keyframes``):
    the plan of the largest multiplier ``lam`` in [1e-6, 1e7] found by ``steps`` bisection steps
    on ``log lam`` whose measured error ``measure(keyframes)`` is <= ``max_q``, and that error.
    The plan at the smallest multiplier (densest) is the fallback."""
    lo, hi = np.log(_LAM_LO), np.log(_LAM_HI)
    best = make(_LAM_LO)
    best_q = measure(best.keyframes)
    top = make(_LAM_HI)
    top_q = measure(top.keyframes)
    if top_q <= max_q:
        return top, top_q
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        p = make(float(np.exp(mid)))
        q = measure(p.keyframes)
        if q <= max_q:
            lo, best, best_q = mid, p, q
        else:
            hi = mid
    return best, best_q
