"""The exact minimum of Q over all keyframe sets, for every keyframe count at once.

Q separates over segments (see :mod:`sidql.keyframes.segment_costs`), so with ``D[w, j]`` the least cost of
covering frames ``0..j`` with ``w`` keyframes of which the last is ``j``::

    D[1, 0] = 0,   D[w, j] = min_{i < j} D[w - 1, i] + C[i, j]

and the optimum for W keyframes is ``D[W, N - 1]``. One table answers every W from 2 to N in
O(N^3) (O(W N^2) per W). Ties go to the smallest predecessor index, so results are deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from sidql.keyframes.segment_costs import (
    _FAST,
    SEPARABLE,
    TURN,
    TWO_PI,
    _fill_costs,
    _frame_cost,
    catmull_rom_costs,
    clip_cost_matrix,
    clip_stacked,
    segment_cost_matrix,
)
from sidql.keyframes.single_costs import single_cost_matrix, turn_rates, weights_of
from sidql.keyframes.spherical import M_BONES, SphericalSeries
from sim.errors import UnknownNameError, UsageError, require_type


@numba.njit(cache=True)
def _dp(C, w_max, reach=0):
    """(D, P) over (N, N) costs C for w = 1..w_max: ``D[w, j]`` as in the module docstring and
    ``P[w, j]`` the least i reaching it (-1 where none is below inf). With ``reach`` > 0 the
    entries with ``j - i >= reach`` are taken to be inf and not read (the same D and P if they
    are: an inf candidate never replaces anything).

    The predecessors i run in the outer loop, in increasing order, and the frames j in the inner
    one, along row i of C: each candidate replaces ``D[w, j]`` only if strictly smaller, so the
    least i wins a tie, as in a scan over i per j; the same sums and comparisons, written as
    selects so that the inner loop vectorises."""
    N = C.shape[0]
    D = np.full((w_max + 1, N), np.inf)
    P = np.full((w_max + 1, N), -1, dtype=np.int64)
    D[1, 0] = 0.0
    for w in range(2, w_max + 1):
        Dw = D[w]
        Pw = P[w]
        for i in range(w - 2, N - 1):
            hi = N if reach <= 0 else min(N, i + reach)
            _relax(Dw, Pw, C[i], D[w - 1, i], i, max(i + 1, w - 1), hi)
    return D, P


@numba.njit(cache=True, inline="always")
def _relax(Dw, Pw, row, d, i, lo, hi):
    """``Dw[j], Pw[j] = d + row[j], i`` where that is strictly smaller, for lo <= j < hi (on
    slices indexed from 0, so that the compiler knows no index wraps and vectorises)."""
    Dj, Pj, cj = Dw[lo:hi], Pw[lo:hi], row[lo:hi]
    for t in range(hi - lo):
        v = d + cj[t]
        better = v < Dj[t]
        Dj[t] = v if better else Dj[t]
        Pj[t] = i if better else Pj[t]


@numba.njit(cache=True)
def _backtrack_all(P, n_frames):
    w_max = P.shape[0] - 1
    out = np.full((w_max + 1, n_frames), -1, dtype=np.int64)
    for W in range(2, w_max + 1):
        j = n_frames - 1
        out[W, W - 1] = j
        for w in range(W, 1, -1):
            j = P[w, j]
            out[W, w - 2] = j
    return out


@dataclass(frozen=True)
class KeyframeTable:
    """Exact optima of Q for every keyframe count W = 2..w_max: what both programmes give.

    Attributes:
        cost: (w_max + 1,) least total segment cost [rad] for W keyframes (inf for W < 2).
        n_frames: N; n_bones: M (the normaliser of Q is N * M).
    """

    cost: np.ndarray
    n_frames: int
    n_bones: int

    def keyframes(self, W: int) -> np.ndarray:
        """(W,) sorted optimal keyframe indices, 0 and N-1 included."""
        if not 2 <= W < len(self.cost):
            raise UsageError(f"W must be in [2, {len(self.cost) - 1}]; got {W}")
        return self._backtrack(W)

    def _backtrack(self, W: int) -> np.ndarray:
        raise NotImplementedError  # each programme keeps its own back pointers

    def q(self, W: int) -> float:
        """The optimal Q [rad] for W keyframes."""
        return float(self.cost[W] / (self.n_frames * self.n_bones))


@dataclass(frozen=True, kw_only=True)
class OptimalTable(KeyframeTable):
    """Exact optima of a segment-cost matrix for every keyframe count (:class:`KeyframeTable`).

    Attributes:
        pointers: (w_max + 1, N) predecessor of keyframe j in the best W-keyframe cover of 0..j.
    """

    pointers: np.ndarray

    def _backtrack(self, W: int) -> np.ndarray:
        out = [self.n_frames - 1]
        for w in range(W, 1, -1):
            out.append(int(self.pointers[w, out[-1]]))
        return np.array(out[::-1], dtype=np.int64)

    def all_keyframes(self) -> np.ndarray:
        """(w_max + 1, N) int64: row W holds the optimal keyframes for W in its first W entries
        (-1 after them; rows 0 and 1 are all -1)."""
        return _backtrack_all(self.pointers, self.n_frames)


def solve(C: np.ndarray, n_bones: int, w_max: int | None = None) -> OptimalTable:
    """Exact optima of an (N, N) segment-cost matrix for all W from 2 to ``w_max`` (default N)."""
    C = np.ascontiguousarray(C, dtype=np.float64)
    N = C.shape[0]
    w_max = N if w_max is None else int(w_max)
    if not 2 <= w_max <= N:
        raise UsageError(f"w_max must be in [2, {N}]; got {w_max}")
    D, P = _dp(C, w_max)
    return OptimalTable(cost=D[:, N - 1].copy(), pointers=P, n_frames=N, n_bones=n_bones)


def optimal_table(
    series: SphericalSeries, reconstruction: str = "hermite", w_max: int | None = None
) -> OptimalTable:
    """Exact optima of Q (eq. 18) for ``series`` under a separable reconstruction, all W at once."""
    return solve(segment_cost_matrix(series, reconstruction), series.n_bones, w_max)


def clip_optimal_table(
    clip, reconstruction: str = "hermite", w_max: int | None = None
) -> OptimalTable:
    """:func:`optimal_table` of a clip's chart, chart and costs in one compiled pass
    (:func:`sidql.keyframes.segment_costs.clip_cost_matrix`); the same optima."""
    return solve(clip_cost_matrix(clip, reconstruction), M_BONES, w_max)


def clip_optimal_keyframes(clip, W: int, reconstruction: str = "hermite") -> np.ndarray:
    """(W,) the same keyframes as ``clip_optimal_table(clip, reconstruction, W).keyframes(W)``,
    from :func:`optimum_cost_matrix` (only the segments that can be in the optimum): a fraction
    of the work, in one compiled call after the chart."""
    if reconstruction not in SEPARABLE:
        raise UnknownNameError("separable reconstruction", reconstruction, SEPARABLE)
    X, R = clip_stacked(clip)
    if not 2 <= W <= X.shape[0]:
        raise UsageError(f"W must be in [2, {X.shape[0]}]; got {W}")
    return _optimum_keyframes(X, R, reconstruction == "linear", int(W), weights_of(len(X)))


@numba.njit(cache=True)
def _optimum_keyframes(X, R, linear, W, H):
    """(W,) the optimum's keyframes from the stacked chart: :func:`_optimum_costs`, the
    programme (:func:`_dp`) and :meth:`OptimalTable.keyframes`' walk back, compiled."""
    _, P = _dp(_optimum_costs(X, R, linear, W, H), W)
    out = np.empty(W, np.int64)
    out[W - 1] = X.shape[0] - 1
    for w in range(W, 1, -1):
        out[w - 2] = P[w, out[w - 1]]
    return out


def optimum_cost_matrix(clip, W: int, reconstruction: str = "hermite") -> np.ndarray:
    """The (N, N) segment costs of ``clip`` (:func:`sidql.keyframes.segment_costs.clip_cost_matrix`)
    that the optimum for exactly W keyframes can use; the others are inf.

    The optimum's total is at most U, the optimum over segments of at most
    ``ceil(1.5 (N - 1) / (W - 1))`` frames (a band of the matrix, computed first, with its own
    programme). A longer segment (i, j) can be in it only if its cost plus the least the rest
    of the clip can cost around it (programmes over lower bounds of every entry: the band's
    exact costs, one middle frame's cost outside it) is at most U (1 + 1e-9); it is summed
    frame by frame and abandoned, set to inf, once that fails. The entries kept are the numbers
    of ``clip_cost_matrix``. A path through an inf entry costs more than U, so this matrix's
    W-keyframe optimum, tie-breaking included, is the full matrix's; its optima for fewer
    keyframes are not.

    For few keyframes (a wide band) and the Hermite reconstruction it screens instead
    (:func:`_screened_costs`): U is the exact cost of the path the single-precision matrix
    (:mod:`sidql.keyframes.single_costs`, cheaper than the band) finds best, the lower bounds
    are that matrix's entries less their largest possible rounding error
    (:func:`single_lower_bounds`), and only the entries that pass are summed in float64 (a
    handful): the same argument, so the same optimum.

    Raises:
        MotionDataError: as :func:`sidql.keyframes.spherical.chart`. UsageError: W out of range.
    """
    if reconstruction not in SEPARABLE:
        raise UnknownNameError("separable reconstruction", reconstruction, SEPARABLE)
    X, R = clip_stacked(clip)
    if not 2 <= W <= X.shape[0]:
        raise UsageError(f"W must be in [2, {X.shape[0]}]; got {W}")
    return _optimum_costs(X, R, reconstruction == "linear", int(W), weights_of(len(X)))


@numba.njit(cache=True)
def _optimum_costs(X, R, linear, W, H):
    """:func:`optimum_cost_matrix` from the stacked chart (N, D) ``X`` [rad], ``R`` [rad/frame]:
    :func:`_screened_costs` where its single-precision matrix costs less than the band of
    :func:`_banded_costs` (few keyframes: long segments, a wide band) and applies (Hermite),
    else :func:`_banded_costs`.

    Its disk cache does not notice a change in segment_costs.py's kernels: clear
    ``sidql/keyframes/__pycache__/*.nb*`` after one (tests/test_keyframes_fused.py checks the
    numbers against the full matrix)."""
    N = X.shape[0]
    band = min(N, int(np.ceil(1.5 * (N - 1) / (W - 1))) + 1)
    if not linear and band * band * SCREEN_SHARE >= N * N and _screenable(X, R):
        return _screened_costs(X, R, H, W)
    return _banded_costs(X, R, linear, W)


@numba.njit(cache=True, fastmath=_FAST)  # the flags of the kernels it shares
def _banded_costs(X, R, linear, W):
    """:func:`optimum_cost_matrix` by a band of exact costs: the optimum over segments of at
    most ``ceil(1.5 (N - 1) / (W - 1))`` frames bounds the optimum; lower bounds (the band's
    costs, one middle frame outside it) bound the rest of the clip around each segment."""
    N, D = X.shape
    X, R = X * TURN, R * TURN  # the kernels' unit (turns), back to radians at the end
    band = min(N, int(np.ceil(1.5 * (N - 1) / (W - 1))) + 1)  # segments with j - i < band
    C = np.zeros((N, N))
    bounds = np.full((N, N), np.inf)
    _fill_costs(X, R, linear, C, 2, band, bounds, np.empty((0, 0)))
    Cb = C.copy()  # the band alone: its optimum U bounds the true one
    lb = C.copy()  # a lower bound of every entry: exact in the band, one middle frame outside
    dX = np.empty(D)
    for i in range(N):
        for j in range(i + band, N):
            Cb[i, j] = np.inf
            for d in range(D):
                dX[d] = X[j, d] - X[i, d]
            lb[i, j] = _frame_cost(X, R, dX, i, j, i + (j - i) // 2, linear)
    U = _dp(Cb, W, band)[0][W, N - 1] * (1.0 + 1e-9)  # feasible: (band - 1) (W - 1) >= N - 1
    head = _dp(lb, W)[0]  # head[w, i] <= least cost of frames 0..i, w keyframes, the last i
    tail = _dp(lb[::-1, ::-1].T.copy(), W)[0]  # the same for frames j..N-1 from the end
    for i in range(N):
        for j in range(i + band, N):
            rest = np.inf  # the least the rest of the clip can cost around segment (i, j)
            for w in range(1, W):
                rest = min(rest, head[w, i] + tail[W - w, N - 1 - j])
            bounds[i, j] = U - rest
    _fill_costs(X, R, linear, C, band, N, bounds, lb)  # lb: their middle frames' costs
    return C * TWO_PI


#: :func:`_optimum_costs` screens with the single-precision matrix when the band of
#: :func:`_banded_costs` spans more than 1 / sqrt(SCREEN_SHARE) of the clip (measured on the 107
#: eval clips, one in two, best of 5, with the single-precision kernel's constant width: the
#: screen 0.24-0.25 ms against the band's 0.26-0.30 ms for W = 7-9, even at W = 10, the band
#: the faster from W = 12: 60-frame clips screen for W <= 9).
SCREEN_SHARE = 25.0

#: Unit roundoff of float32: the rounding error of each of its operations, relative.
_U32 = 2.0**-24


@numba.njit(cache=True)
def _screen_scales(X, R):
    """(A, r): the widest spread of an angle channel of (N, D) ``X`` [turns over frames] and the
    largest rate ``|R|`` [turns/frame]: what bounds every term of the single-precision sums."""
    A = 0.0
    for d in range(X.shape[1]):
        A = max(A, (X[:, d].max() - X[:, d].min()) * TURN)
    return A, np.abs(R).max() * TURN


@numba.njit(cache=True)
def _screenable(X, R):
    """True where :func:`sidql.keyframes.single_costs.single_cost_matrix`'s rounding to the
    nearest integer is exact for every term (terms of magnitude below 2^20 turns)."""
    A, r = _screen_scales(X, R)
    return 2.0 * A + 8.0 / 27.0 * X.shape[0] * r < 2.0**20


@numba.njit(cache=True)
def single_lower_bounds(X, R, C32):
    """(N, N) lower bounds [turns] of the float64 Hermite costs (:func:`_cost_matrix`'s, in
    turns) from the single-precision ones ``C32`` [rad] of
    :func:`sidql.keyframes.single_costs.single_cost_matrix` of the same (N, D) ``X``, ``R``.

    Each of the (L - 1) D terms of entry (i, j), ``|wrap(e_n - h01 e_j + h10 L r_i + h11 L
    r_j)|``, is a 1-Lipschitz function of its argument, which float32 gets wrong by at most
    13 roundings of its magnitude ``M <= 2 A + 8/27 L r`` (|h01| <= 1, |h10|, |h11| <= 4/27;
    A, r: :func:`_screen_scales`); the sums of the non-negative terms add at most L + 12
    roundings relative. The bound takes 16 and L + 16 (room for float64's own rounding, 2^-29
    of these), and is clamped at 0."""
    N, D = X.shape
    A, r = _screen_scales(X, R)
    lb = np.zeros((N, N))
    for i in range(N):
        for j in range(i + 2, N):
            L = j - i
            terms = (L - 1) * D * 16.0 * _U32 * (2.0 * A + 8.0 / 27.0 * L * r)
            c = C32[i, j] * TURN
            lb[i, j] = max(0.0, c - terms - (L + 16) * _U32 * (c + terms))
    return lb


@numba.njit(cache=True, fastmath=_FAST)  # the flags of the kernels it shares
def _screened_costs(X, R, H, W):
    """:func:`optimum_cost_matrix` (Hermite) screened by the single-precision matrix: its
    programme's path, summed exactly, gives U; its lower bounds
    (:func:`single_lower_bounds`) the least the rest of the clip costs around each segment;
    only the segments within U of that are summed exactly (and abandoned once over it). The
    single-precision matrix runs in the processor's widest vectors
    (:mod:`sidql.keyframes.wide_vectors`), over the protocol's 48 channels as a compile-time
    width (its disk cache, like this one's, refreshed by an edit of this file)."""
    N = X.shape[0]
    C32 = single_cost_matrix(X, turn_rates(R), H)
    lb = single_lower_bounds(X, R, C32)
    X, R = X * TURN, R * TURN  # the kernels' unit (turns), back to radians at the end
    C = np.zeros((N, N))
    ruled_out = np.full((N, N), np.inf)  # a known "middle frame" cost of inf: skipped at once
    bounds = np.full((N, N), -np.inf)
    P = _dp(C32, W)[1]
    j = N - 1
    for w in range(W, 1, -1):  # the path the single-precision programme takes, summed exactly
        i = P[w, j]
        ruled_out[i, j] = -1.0
        bounds[i, j] = np.inf
        j = i
    _fill_costs(X, R, False, C, 2, N, bounds, ruled_out)
    U = 0.0
    j = N - 1
    for w in range(W, 1, -1):
        U += C[P[w, j], j]
        j = P[w, j]
    head = _dp(lb, W)[0]  # head[w, i] <= least cost of frames 0..i, w keyframes, the last i
    tail = _dp(lb[::-1, ::-1].T.copy(), W)[0]  # the same for frames j..N-1 from the end
    _rest_bounds(bounds, head, tail, U * (1.0 + 1e-9), W)
    for i in range(N):
        for j in range(i + 2, N):
            keep = lb[i, j] <= bounds[i, j]
            ruled_out[i, j] = -1.0 if keep else np.inf
            bounds[i, j] = bounds[i, j] if keep else -np.inf
    _fill_costs(X, R, False, C, 2, N, bounds, ruled_out)
    return C * TWO_PI


@numba.njit(cache=True)
def _rest_bounds(bounds, head, tail, U, W):
    """``bounds[i, j] = U - rest(i, j)`` for j >= i + 2, ``rest(i, j) = min over w of
    head[w, i] + tail[W - w, N - 1 - j]``: the least the clip costs outside segment (i, j)
    (-inf where nothing can; rows of j, so that the loop over them vectorises)."""
    N = bounds.shape[0]
    tail_at = np.empty(N)  # tail[W - w] indexed by the segment's end j
    bounds[:, :] = -np.inf
    for w in range(1, W):
        for j in range(N):
            tail_at[j] = tail[W - w, N - 1 - j]
        for i in range(N - 2):
            h = head[w, i]
            if h < np.inf:
                b, t = bounds[i, i + 2 :], tail_at[i + 2 :]
                for k in range(N - i - 2):
                    b[k] = max(b[k], U - (h + t[k]))


def optimal_keyframes(
    series: SphericalSeries, W: int, reconstruction: str = "hermite"
) -> np.ndarray:
    """(W,) keyframes minimising Q exactly (eq. 19) under a separable reconstruction."""
    require_type(series, SphericalSeries, "series")
    return optimal_table(series, reconstruction, w_max=W).keyframes(W)


@numba.njit(cache=True)
def _cr_dp(Q, w_max):
    """Exact DP over triples of consecutive keyframes for the Catmull-Rom costs Q."""
    N = Q.shape[1]
    best = np.full(w_max + 1, np.inf)
    last = np.full((w_max + 1, 2), -1, dtype=np.int64)  # (x + 1, y) of the best final state
    back = np.full((w_max + 1, N + 1, N, N), -1, dtype=np.int16)
    G = np.full((N + 1, N, N), np.inf)  # state (x + 1, y, z): the last three keyframes
    for z in range(1, N):
        G[0, 0, z] = 0.0  # two keyframes 0 < z, nothing finalised yet
    for w in range(2, w_max + 1):
        # close the clip: the state's last keyframe must be N - 1
        for xi in range(N + 1):
            for y in range(N - 1):
                g = G[xi, y, N - 1]
                if g < np.inf:
                    v = g + Q[xi, y, N - 1, N]
                    if v < best[w]:
                        best[w] = v
                        last[w, 0] = xi
                        last[w, 1] = y
        if w == w_max:
            break
        H = np.full((N + 1, N, N), np.inf)
        for xi in range(N + 1):
            for y in range(N):
                for z in range(y + 1, N - 1):
                    g = G[xi, y, z]
                    if g == np.inf:
                        continue
                    for n in range(z + 1, N):
                        v = g + Q[xi, y, z, n]
                        if v < H[y + 1, z, n]:
                            H[y + 1, z, n] = v
                            back[w + 1, y + 1, z, n] = xi
        G = H
    return best, last, back


@dataclass(frozen=True, kw_only=True)
class CatmullRomTable(KeyframeTable):
    """Exact optima of Q under Catmull-Rom reconstruction for W = 2..w_max
    (:class:`KeyframeTable`).

    Attributes:
        last: (w_max + 1, 2) the best final state (x + 1, y) per W; back: the DP's back pointers.
    """

    last: np.ndarray
    back: np.ndarray

    def _backtrack(self, W: int) -> np.ndarray:
        N = self.n_frames
        xi, y = int(self.last[W, 0]), int(self.last[W, 1])
        out = [N - 1, y]
        z = N - 1
        w = W
        while xi > 0:  # walk back: state (xi, y, z) at layer w came from (back, xi - 1, y)
            out.append(xi - 1)
            prev = int(self.back[w, xi, y, z])
            xi, y, z = prev, xi - 1, y
            w -= 1
        return np.array(sorted(out), dtype=np.int64)


def catmull_rom_optimal(series: SphericalSeries, w_max: int) -> CatmullRomTable:
    """Exact minima of Q under the Catmull-Rom reconstruction for every W from 2 to ``w_max``.

    A segment's curve depends on four keyframes (its ends and their neighbours), so the programme
    runs over triples of consecutive keyframes: O(N^5 M) for the costs, O(w_max N^4) for the DP.
    About a second per 60-frame clip.
    """
    N = series.n_frames
    if not 2 <= w_max <= N:
        raise UsageError(f"w_max must be in [2, {N}]; got {w_max}")
    Q = catmull_rom_costs(series)
    best, last, back = _cr_dp(Q, w_max)
    return CatmullRomTable(cost=best, n_frames=N, n_bones=series.n_bones, last=last, back=back)
