"""The segment-cost matrix: the error of eq. 18 split over the segments between keyframes.

For the "hermite" and "linear" reconstructions the curve between keyframes ``i < j`` depends on those two
frames only, so the error of eq. 18 separates::

    Q(K) = sum_w C[k_w, k_{w+1}] / (N * M)

    C[i, j] = sum over frames n with i < n < j, over bones m, of
              |wrap(theta~[n, m] - theta[n, m])| + |wrap(phi~[n, m] - phi[n, m])|

(keyframes themselves are reproduced exactly and cost nothing). Entries with ``i >= j`` or
``j = i + 1`` are 0. The kernels are compiled with numba (cached on disk); one (N, N) matrix costs
O(N^3 M / 6) operations.

The "catmull_rom" reconstruction does not separate this way (a segment's curve depends on four
keyframes); see :func:`sidql.keyframes.optimal.catmull_rom_optimal`.
"""

from __future__ import annotations

import numba
import numpy as np

from sidql.keyframes.spherical import (
    SIN_EPS,
    SphericalSeries,
    _chart_kernel,
    chart_points_of,
    protocol_maps,
)
from sim.errors import MotionDataError, UnknownNameError, UsageError
from sim.model.angles import wrap_angle

#: The reconstructions (curves of :mod:`sidql.keyframes.curves`) whose Q separates over segments.
SEPARABLE: tuple[str, ...] = ("hermite", "linear")


@numba.njit(cache=True, fastmath=True)
def _cost_matrix(X, R, linear):
    """X: (N, D) angles [rad]; R: (N, D) rates times dt [rad/frame]; linear: bool.

    The curve is written ``x_i + h01 (x_j - x_i) + h10 r_i + h11 r_j`` (h00 = 1 - h01) and its
    error summed in turns (angles over 2 pi: the wrap, :func:`_turn_wrap`, is then a floor and a
    subtraction, branch-free, so the inner loop vectorises), the sums turned back into radians
    at the end.
    """
    N = X.shape[0]
    C = np.zeros((N, N))
    _fill_costs(X * TURN, R * TURN, linear, C, 2, N, np.full((N, N), np.inf), np.empty((0, 0)))
    return C * TWO_PI


#: fastmath without "no infinities / no NaNs" (the bound of :func:`_fill_costs` may be inf):
#: reassociation is what lets the sums over channels vectorise.
_FAST = {"reassoc", "contract", "nsz", "arcp", "afn"}


@numba.njit(cache=True, fastmath=_FAST)
def _fill_costs(X, R, linear, C, lo, hi, bounds, first):
    """Write ``C[i, j]`` of :func:`_cost_matrix` for every segment with ``lo <= j - i < hi``
    (:func:`_entry_cost` with bound ``bounds[i, j]``; every caller passes an (N, N) array, so
    all run one compiled loop and keep the same numbers). ``first``: (N, N) the middle frame's
    cost of each entry (:func:`_frame_cost`) where the caller knows it already (inf: an entry
    it rules out, skipped; -1: not known), else (0, 0)."""
    N, D = X.shape
    dX = np.empty(D)
    known = first.shape[0] > 0
    for i in range(N):
        for j in range(i + max(lo, 2), min(i + hi, N)):
            mid_cost = first[i, j] if known else -1.0
            if mid_cost > bounds[i, j]:  # known over its bound (inf: ruled out by the caller)
                C[i, j] = np.inf
                continue
            C[i, j] = _entry_cost(X, R, dX, i, j, linear, bounds[i, j], mid_cost)


@numba.njit(cache=True, fastmath=_FAST, inline="always")
def _entry_cost(X, R, dX, i, j, linear, bound, mid_cost=-1.0):
    """``C[i, j]`` of :func:`_cost_matrix` (``dX``: (D,) scratch), or inf if it exceeds
    ``bound``. The frames are summed from the middle out (where a segment's error is largest):
    the middle one (``mid_cost``, its :func:`_frame_cost`, where known: >= 0), then four at a time (one pass over the channels for four frames), then the
    last few one by one; after each pass the sum so far is compared with the bound and the
    entry abandoned once over it. Whatever the bound, an entry kept is the same sum in the
    same order, so the same number."""
    for d in range(X.shape[1]):
        dX[d] = X[j, d] - X[i, d]
    L = j - i
    mid = i + L // 2
    total = mid_cost  # frame t = 0: mid, alone (abandons most)
    if total < 0.0:
        total = _frame_cost(X, R, dX, i, j, mid, linear)
    if total > bound:
        return np.inf
    t = 1
    while t + 4 <= L - 1:  # frames t..t + 3: mid + 1, mid - 1, mid + 2, mid - 2, ...
        lo, hi = mid - (t + 1) // 2, mid + (t + 1) // 2  # frames hi, lo, hi + 1, lo - 1
        total += _four_frames_cost(X, R, dX, i, j, lo, hi, linear)
        if total > bound:
            return np.inf
        t += 4
    while t < L - 1:
        total += _frame_cost(X, R, dX, i, j, mid + ((t + 1) // 2 if t % 2 else -(t // 2)), linear)
        t += 1
    return np.inf if total > bound else total


@numba.njit(cache=True, fastmath=_FAST, inline="always")
def _four_frames_cost(X, R, dX, i, j, lo, hi, linear):
    """Summed |angle error| [rad] of frames lo, hi, lo - 1, hi + 1 of segment (i, j), in one
    pass over the channels (the loop vectorises over them; four frames share its loads)."""
    L = j - i
    a0, b0, c0 = segment_weights(lo, i, L, linear)
    a1, b1, c1 = segment_weights(hi, i, L, linear)
    a2, b2, c2 = segment_weights(lo - 1, i, L, linear)
    a3, b3, c3 = segment_weights(hi + 1, i, L, linear)
    acc = 0.0
    for d in range(X.shape[1]):
        xi, dx, ri, rj = X[i, d], dX[d], R[i, d], R[j, d]
        acc += (
            abs(_turn_wrap((xi - X[lo, d]) + a0 * dx + b0 * ri + c0 * rj))
            + abs(_turn_wrap((xi - X[hi, d]) + a1 * dx + b1 * ri + c1 * rj))
            + abs(_turn_wrap((xi - X[lo - 1, d]) + a2 * dx + b2 * ri + c2 * rj))
            + abs(_turn_wrap((xi - X[hi + 1, d]) + a3 * dx + b3 * ri + c3 * rj))
        )
    return acc


@numba.njit(cache=True, fastmath=_FAST, inline="always")
def _frame_cost(X, R, dX, i, j, n, linear):
    """Summed |angle error| [rad] of frame n of segment (i, j); ``dX = X[j] - X[i]``."""
    h01, h10, h11 = segment_weights(n, i, j - i, linear)
    acc = 0.0
    for d in range(X.shape[1]):
        v = (X[i, d] - X[n, d]) + h01 * dX[d] + h10 * R[i, d] + h11 * R[j, d]
        acc += abs(_turn_wrap(v))
    return acc


#: Turns per radian and radians per turn: the kernels of :func:`_fill_costs` work in turns, where
#: the wrap is the signed distance to the nearest integer.
TURN = 1.0 / (2.0 * np.pi)
TWO_PI = 2.0 * np.pi


@numba.njit(cache=True, fastmath=_FAST, inline="always")
def _turn_wrap(v):
    """An angle [turns] wrapped into [-1/2, 1/2) (:func:`sim.model.angles.wrap_angle` in turns)."""
    return v - np.floor(v + 0.5)


@numba.njit(cache=True, fastmath=True, inline="always")
def hermite_basis(s):
    """(h00, h01, h10, h11) of the cubic Hermite at ``s`` in [0, 1]: the curve is
    ``h00 x_a + h01 x_b + h10 m_a + h11 m_b`` for end values x and end rates m per unit of s
    (the one definition every compiled kernel reads)."""
    s2 = s * s
    s3 = s2 * s
    return 2.0 * s3 - 3.0 * s2 + 1.0, -2.0 * s3 + 3.0 * s2, s3 - 2.0 * s2 + s, s3 - s2


@numba.njit(cache=True, fastmath=True, inline="always")
def segment_weights(n, i, L, linear):
    """Weights (h01, h10 * L, h11 * L) of frame n in segment [i, i + L] (linear: s, 0, 0): the
    curve is ``x_i + h01 (x_j - x_i) + h10 r_i + h11 r_j`` for rates r per frame."""
    s = (n - i) / L
    if linear:
        return s, 0.0, 0.0
    _, h01, h10, h11 = hermite_basis(s)
    return h01, h10 * L, h11 * L


@numba.njit(cache=True, fastmath=True)
def _segment_cost(X, R, i, j, linear):
    """C[i, j] alone, with the same arithmetic as :func:`_cost_matrix`."""
    D = X.shape[1]
    L = j - i
    total = 0.0
    for n in range(i + 1, j):
        h01, h10, h11 = segment_weights(n, i, L, linear)
        acc = 0.0
        for d in range(D):
            v = (X[i, d] - X[n, d]) + h01 * (X[j, d] - X[i, d]) + h10 * R[i, d] + h11 * R[j, d]
            v = wrap_angle(v)
            acc += abs(v)
        total += acc
    return total


@numba.njit(cache=True)
def _greedy(X, R, W, linear):
    """Greedy keyframes computing only the segment costs it needs (O(W N^2 D) at worst)."""
    N = X.shape[0]
    key = np.zeros(N, dtype=np.bool_)
    key[0] = True
    key[N - 1] = True
    left = np.zeros(N)  # C[a, f] for the segment (a, b) holding f
    right = np.zeros(N)  # C[f, b]
    start = np.zeros(N, dtype=np.int64)
    seg_total = np.zeros(N)  # C[a, b] indexed by the segment's start a
    seg_total[0] = _segment_cost(X, R, 0, N - 1, linear)
    for f in range(1, N - 1):
        left[f] = _segment_cost(X, R, 0, f, linear)
        right[f] = _segment_cost(X, R, f, N - 1, linear)
    for _ in range(W - 2):
        best = np.inf
        arg = -1
        for f in range(1, N - 1):
            if not key[f]:
                delta = left[f] + right[f] - seg_total[start[f]]
                if delta < best:
                    best = delta
                    arg = f
        a = start[arg]
        b = arg + 1
        while not key[b]:
            b += 1
        key[arg] = True
        seg_total[a] = left[arg]
        seg_total[arg] = right[arg]
        for g in range(a + 1, arg):
            right[g] = _segment_cost(X, R, g, arg, linear)
        for g in range(arg + 1, b):
            start[g] = arg
            left[g] = _segment_cost(X, R, arg, g, linear)
    return np.flatnonzero(key)


def greedy_keyframes(
    series: SphericalSeries, W: int, reconstruction: str = "hermite"
) -> np.ndarray:
    """(W,) greedy keyframes under a separable reconstruction: from both ends, W - 2 times add the
    frame that lowers Q the most (ties: the lowest index). Computes only the segment costs it
    needs."""
    if reconstruction not in SEPARABLE:
        raise UnknownNameError("separable reconstruction", reconstruction, SEPARABLE)
    if not 2 <= W <= series.n_frames:
        raise UsageError(f"W must be in [2, {series.n_frames}]; got {W}")
    X, R = stacked(series)
    return _greedy(X, R, W, reconstruction == "linear").astype(np.int64)


def stacked(series: SphericalSeries) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2M) angles [theta | phi] [rad] and (N, 2M) rates times dt [rad per frame], C-ordered."""
    X = np.ascontiguousarray(np.concatenate([series.theta, series.phi], axis=1))
    R = np.ascontiguousarray(np.concatenate([series.dtheta, series.dphi], axis=1) * series.dt)
    return X, R


def segment_cost_matrix(series: SphericalSeries, reconstruction: str = "hermite") -> np.ndarray:
    """The (N, N) segment-cost matrix C [rad] of ``series`` (see the module docstring).

    Args:
        series: a chart with N frames and M bones.
        reconstruction: "hermite" (cubic Hermite with transmitted rates) or "linear"
            (:data:`SEPARABLE`; catmull_rom: :func:`sidql.keyframes.optimal.catmull_rom_optimal`).

    Returns:
        (N, N) float64; ``Q(K) = sum_w C[k_w, k_{w+1}] / (N * M)``.
    """
    if reconstruction not in SEPARABLE:
        raise UnknownNameError("separable reconstruction", reconstruction, SEPARABLE)
    X, R = stacked(series)
    return _cost_matrix(X, R, reconstruction == "linear")


@numba.njit(cache=True, fastmath=True)
def _catmull_rom_costs(X):
    """(N+1, N, N, N+1) costs of segment (y, z) given the keyframes x before and n after it.

    Index ``x + 1`` (0: no keyframe before, only when y = 0) and ``n`` (N: none, only when
    z = N - 1); invalid combinations are inf. X: (N, D) angles [rad].
    """
    N, D = X.shape
    Q = np.full((N + 1, N, N, N + 1), np.inf)
    A = np.empty((N, D))
    ha = np.empty(N)
    hb = np.empty(N)
    ma = np.empty(D)
    mb = np.empty(D)
    for y in range(N - 1):
        for z in range(y + 1, N):
            L = z - y
            for f in range(y + 1, z):
                h00, h01, h10, h11 = hermite_basis((f - y) / L)
                ha[f] = h10 * L
                hb[f] = h11 * L
                for d in range(D):
                    A[f, d] = h00 * X[y, d] + h01 * X[z, d] - X[f, d]
            x_lo, x_hi = (-1, 0) if y == 0 else (0, y)
            n_lo, n_hi = (N, N + 1) if z == N - 1 else (z + 1, N)
            for x in range(x_lo, x_hi):
                for d in range(D):
                    if x < 0:
                        ma[d] = (X[z, d] - X[y, d]) / L
                    else:
                        ma[d] = (X[z, d] - X[x, d]) / (z - x)
                for n in range(n_lo, n_hi):
                    for d in range(D):
                        if n == N:
                            mb[d] = (X[z, d] - X[y, d]) / L
                        else:
                            mb[d] = (X[n, d] - X[y, d]) / (n - y)
                    total = 0.0
                    for f in range(y + 1, z):
                        for d in range(D):
                            v = A[f, d] + ha[f] * ma[d] + hb[f] * mb[d]
                            v = wrap_angle(v)
                            total += abs(v)
                    Q[x + 1, y, z, n] = total
    return Q


def catmull_rom_costs(series: SphericalSeries) -> np.ndarray:
    """(N+1, N, N, N+1) Catmull-Rom segment costs [rad]: entry ``[x + 1, y, z, n]`` is the summed
    |angle error| over the frames strictly inside segment (y, z) when the keyframes around it are
    x (``x + 1 = 0``: none, y = 0) and n (``n = N``: none, z = N - 1); inf where invalid.

    Q(K) = sum over segments of these entries / (N * M).
    """
    X, _ = stacked(series)
    return _catmull_rom_costs(X)


@numba.njit(cache=True)
def _chart_and_costs(P, V, parents, dt, sin_eps, linear):
    """The chart (:func:`sidql.keyframes.spherical._chart_kernel`) and the (N, N) segment costs
    (:func:`_cost_matrix`) of (N, J, 3) world-axes points in one compiled call: the same
    arithmetic as ``segment_cost_matrix(chart_arrays(P, V, parents, dt))``."""
    X, R = _stacked_chart(P, V, parents, dt, sin_eps)
    return _cost_matrix(X, R, linear)


@numba.njit(cache=True)
def _stacked_chart(P, V, parents, dt, sin_eps):
    """:func:`stacked` of the chart of (N, J, 3) world-axes points, in compiled code."""
    theta, phi, dtheta, dphi, _ = _chart_kernel(P, V, parents, sin_eps)
    N, M = theta.shape
    X = np.empty((N, 2 * M))
    R = np.empty((N, 2 * M))
    for n in range(N):
        for m in range(M):
            X[n, m] = theta[n, m]
            X[n, M + m] = phi[n, m]
            R[n, m] = dtheta[n, m] * dt
            R[n, M + m] = dphi[n, m] * dt
    return X, R


@numba.njit(cache=True)
def _clip_stacked_chart(positions, velocities, idx, parents, dt, sin_eps):
    """:func:`_stacked_chart` of the points ``idx`` of (N, J, 3) ``positions`` and
    ``velocities``, gathered here; ``ok`` False (and empty arrays) if any of them is not
    finite. Returns (X, R, ok)."""
    N = positions.shape[0]
    K = idx.shape[0]
    P = np.empty((N, K, 3))
    V = np.empty((N, K, 3))
    for n in range(N):
        for k in range(K):
            for a in range(3):
                p = positions[n, idx[k], a]
                v = velocities[n, idx[k], a]
                if not (np.isfinite(p) and np.isfinite(v)):
                    return np.empty((0, 0)), np.empty((0, 0)), False
                P[n, k, a] = p
                V[n, k, a] = v
    X, R = _stacked_chart(P, V, parents, dt, sin_eps)
    return X, R, True


def clip_stacked(clip) -> tuple[np.ndarray, np.ndarray]:
    """The chart of ``clip`` as :func:`stacked` lays it out, (N, 2M) angles [rad] and rates
    times dt [rad/frame]: :func:`sidql.keyframes.spherical.chart_points_of` and the chart in one
    compiled call (the same numbers).

    Raises:
        MotionDataError: as :func:`sidql.keyframes.spherical.chart`.
    """
    idx, parents = protocol_maps(clip)
    X, R, ok = _clip_stacked_chart(clip.positions, clip.velocities, idx, parents,
                                   float(clip.dt), SIN_EPS)  # fmt: skip
    if not ok:
        raise MotionDataError(clip.source or None, None, "non-finite positions or velocities")
    return X, R


def clip_cost_matrix(clip, reconstruction: str = "hermite") -> np.ndarray:
    """:func:`segment_cost_matrix` of ``chart(clip)``, chart and costs in one compiled pass (the
    exact optimum of a clip needs nothing else from the chart).

    Raises:
        MotionDataError: as :func:`sidql.keyframes.spherical.chart`.
    """
    if reconstruction not in SEPARABLE:
        raise UnknownNameError("separable reconstruction", reconstruction, SEPARABLE)
    P, V, parents = chart_points_of(clip)
    return _chart_and_costs(P, V, parents, float(clip.dt), SIN_EPS, reconstruction == "linear")


def clip_stacked_costs(
    clip, reconstruction: str = "hermite"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The chart of ``clip`` as :func:`stacked` lays it out, (N, 2M) angles [rad] and rates
    times dt [rad/frame], and its (N, N) segment costs [rad] (:func:`clip_cost_matrix`'s
    numbers), in one compiled pass: what a learned policy needs (features and costs).

    Raises:
        MotionDataError: as :func:`sidql.keyframes.spherical.chart`.
    """
    if reconstruction not in SEPARABLE:
        raise UnknownNameError("separable reconstruction", reconstruction, SEPARABLE)
    X, R = clip_stacked(clip)
    return X, R, _cost_matrix(X, R, reconstruction == "linear")
