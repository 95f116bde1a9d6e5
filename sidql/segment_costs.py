"""The segment-cost matrix: the error of eq. 18 split over the segments between keyframes.

For the "hermite" and "linear" variants the curve between keyframes ``i < j`` depends on those two
frames only, so the error of eq. 18 separates::

    Q(K) = sum_w C[k_w, k_{w+1}] / (N * M)

    C[i, j] = sum over frames n with i < n < j, over bones m, of
              |wrap(theta~[n, m] - theta[n, m])| + |wrap(phi~[n, m] - phi[n, m])|

(keyframes themselves are reproduced exactly and cost nothing). Entries with ``i >= j`` or
``j = i + 1`` are 0. The kernels are compiled with numba (cached on disk); one (N, N) matrix costs
O(N^3 M / 6) operations.

The "catmull_rom" variant does not separate this way (a segment's curve depends on four
keyframes); see :func:`sidql.optimal.catmull_rom_optimal`.
"""

from __future__ import annotations

import numba
import numpy as np

from .spherical import SphericalSeries

SEPARABLE_VARIANTS: tuple[str, ...] = ("hermite", "linear")


_TWO_PI = 2.0 * np.pi
_INV_TWO_PI = 1.0 / _TWO_PI


@numba.njit(cache=True, fastmath=True)
def _cost_matrix(X, R, linear):
    """X: (N, D) angles [rad]; R: (N, D) rates times dt [rad/frame]; linear: bool.

    Wrapping is branch-free (``v - 2 pi floor(v / 2 pi + 1/2)``) so the inner loop vectorises.
    """
    N, D = X.shape
    C = np.zeros((N, N))
    for i in range(N):
        for j in range(i + 2, N):
            L = j - i
            total = 0.0
            for n in range(i + 1, j):
                s = (n - i) / L
                if linear:
                    h00 = 1.0 - s
                    h01 = s
                    h10 = 0.0
                    h11 = 0.0
                else:
                    s2 = s * s
                    s3 = s2 * s
                    h00 = 2.0 * s3 - 3.0 * s2 + 1.0
                    h01 = -2.0 * s3 + 3.0 * s2
                    h10 = (s3 - 2.0 * s2 + s) * L
                    h11 = (s3 - s2) * L
                for d in range(D):
                    v = h00 * X[i, d] + h01 * X[j, d] + h10 * R[i, d] + h11 * R[j, d] - X[n, d]
                    v = v - _TWO_PI * np.floor(v * _INV_TWO_PI + 0.5)
                    total += abs(v)
            C[i, j] = total
    return C


def stacked(series: SphericalSeries) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2M) angles [theta | phi] [rad] and (N, 2M) rates times dt [rad per frame], C-ordered."""
    X = np.ascontiguousarray(np.concatenate([series.theta, series.phi], axis=1))
    R = np.ascontiguousarray(np.concatenate([series.dtheta, series.dphi], axis=1) * series.dt)
    return X, R


def segment_cost_matrix(series: SphericalSeries, variant: str = "hermite") -> np.ndarray:
    """The (N, N) segment-cost matrix C [rad] of ``series`` (see the module docstring).

    Args:
        series: a chart with N frames and M bones.
        variant: "hermite" (cubic Hermite with transmitted rates) or "linear".

    Returns:
        (N, N) float64; ``Q(K) = sum_w C[k_w, k_{w+1}] / (N * M)``.
    """
    if variant not in SEPARABLE_VARIANTS:
        raise ValueError(
            f"variant {variant!r} has no (N, N) segment-cost matrix; separable variants: "
            f"{', '.join(SEPARABLE_VARIANTS)} (catmull_rom: see sidql.optimal.catmull_rom_optimal)"
        )
    X, R = stacked(series)
    return _cost_matrix(X, R, variant == "linear")
