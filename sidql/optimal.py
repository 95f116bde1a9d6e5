"""The exact minimum of Q over all keyframe sets, for every keyframe count at once.

Q separates over segments (see :mod:`sidql.segment_costs`), so with ``D[w, j]`` the least cost of
covering frames ``0..j`` with ``w`` keyframes of which the last is ``j``::

    D[1, 0] = 0,   D[w, j] = min_{i < j} D[w - 1, i] + C[i, j]

and the optimum for W keyframes is ``D[W, N - 1]``. One table answers every W from 2 to N in
O(N^3) (O(W N^2) per W). Ties go to the smallest predecessor index, so results are deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from .segment_costs import segment_cost_matrix
from .spherical import SphericalSeries


@numba.njit(cache=True)
def _dp(C, w_max):
    N = C.shape[0]
    D = np.full((w_max + 1, N), np.inf)
    P = np.full((w_max + 1, N), -1, dtype=np.int64)
    D[1, 0] = 0.0
    for w in range(2, w_max + 1):
        for j in range(w - 1, N):
            best = np.inf
            arg = -1
            for i in range(w - 2, j):
                v = D[w - 1, i] + C[i, j]
                if v < best:
                    best = v
                    arg = i
            D[w, j] = best
            P[w, j] = arg
    return D, P


@dataclass(frozen=True)
class OptimalTable:
    """Exact optima of a segment-cost matrix for every keyframe count.

    Attributes:
        cost: (w_max + 1,) least total segment cost [rad] for W keyframes (inf for W < 2).
        pointers: (w_max + 1, N) predecessor of keyframe j in the best W-keyframe cover of 0..j.
        n_frames: N; n_bones: M (the normaliser of Q is N * M).
    """

    cost: np.ndarray
    pointers: np.ndarray
    n_frames: int
    n_bones: int

    def keyframes(self, W: int) -> np.ndarray:
        """(W,) sorted optimal keyframe indices, 0 and N-1 included."""
        if not 2 <= W < len(self.cost):
            raise ValueError(f"W must be in [2, {len(self.cost) - 1}]; got {W}")
        out = [self.n_frames - 1]
        for w in range(W, 1, -1):
            out.append(int(self.pointers[w, out[-1]]))
        return np.array(out[::-1], dtype=np.int64)

    def q(self, W: int) -> float:
        """The optimal Q [rad] for W keyframes."""
        return float(self.cost[W] / (self.n_frames * self.n_bones))


def solve(C: np.ndarray, n_bones: int, w_max: int | None = None) -> OptimalTable:
    """Exact optima of an (N, N) segment-cost matrix for all W from 2 to ``w_max`` (default N)."""
    C = np.ascontiguousarray(C, dtype=np.float64)
    N = C.shape[0]
    w_max = N if w_max is None else int(w_max)
    if not 2 <= w_max <= N:
        raise ValueError(f"w_max must be in [2, {N}]; got {w_max}")
    D, P = _dp(C, w_max)
    return OptimalTable(cost=D[:, N - 1].copy(), pointers=P, n_frames=N, n_bones=n_bones)


def optimal_table(
    series: SphericalSeries, variant: str = "hermite", w_max: int | None = None
) -> OptimalTable:
    """Exact optima of Q (eq. 18) for ``series`` under a separable variant, all W at once."""
    return solve(segment_cost_matrix(series, variant), series.n_bones, w_max)


def optimal_keyframes(series: SphericalSeries, W: int, variant: str = "hermite") -> np.ndarray:
    """(W,) keyframes minimising Q exactly (eq. 19) under a separable variant."""
    return optimal_table(series, variant, w_max=W).keyframes(W)
