"""Joint position error of decoded keyframes, in one compiled pass (the encoder's measure).

The encoder tries many keyframe plans and step sizes; each needs the mean joint position error of
what the decoder would rebuild. :func:`position_errors` computes it without building the decoded
chart: per frame it evaluates each channel's curve between its keyframes (linear or Catmull-Rom,
exactly as :func:`sidql.keyframes.reconstruct.interpolate`), walks the bone tree (bone b adds
``length_b (sin theta cos phi, sin theta sin phi, cos theta)`` to its parent's point, CMU axes)
and compares with the true points. Numba; O(N D) per call.
"""

from __future__ import annotations

import numba
import numpy as np

from sidql.keyframes.segment_costs import hermite_basis

_MODES = {"linear": 1, "catmull_rom": 2}


@numba.njit(cache=True, nogil=True)
def _errors(P, keys, kv, mode, lengths, parents, out):
    """P: (N, J, 3) true points in CMU axes [m]; keys (W,); kv (W, D) decoded keyframe values;
    out: (N, J) filled with Euclidean errors [m]."""
    N, J, _ = P.shape
    W, D = kv.shape
    M = J - 1
    tan = np.zeros((W, D))
    if mode == 2:
        for w in range(W):
            lo = w - 1 if w > 0 else w
            hi = w + 1 if w < W - 1 else w
            dt = keys[hi] - keys[lo]
            for d in range(D):
                tan[w, d] = (kv[hi, d] - kv[lo, d]) / dt
    x = np.empty(D)
    pts = np.empty((J, 3))
    seg = 0
    for n in range(N):
        while seg < W - 2 and keys[seg + 1] <= n:
            seg += 1
        a = keys[seg]
        b = keys[seg + 1]
        L = b - a
        s = (n - a) / L
        if mode == 1:
            for d in range(D):
                x[d] = kv[seg, d] + s * (kv[seg + 1, d] - kv[seg, d])
        else:
            h00, h01, h10, h11 = hermite_basis(s)
            for d in range(D):
                x[d] = (
                    h00 * kv[seg, d]
                    + h10 * L * tan[seg, d]
                    + h01 * kv[seg + 1, d]
                    + h11 * L * tan[seg + 1, d]
                )
        for c in range(3):
            pts[0, c] = x[2 * M + c]
        for j in range(1, J):
            t = x[j - 1]
            f = x[M + j - 1]
            st = np.sin(t)
            p = parents[j]
            pts[j, 0] = pts[p, 0] + lengths[j - 1] * st * np.cos(f)
            pts[j, 1] = pts[p, 1] + lengths[j - 1] * st * np.sin(f)
            pts[j, 2] = pts[p, 2] + lengths[j - 1] * np.cos(t)
        for j in range(J):
            e0 = pts[j, 0] - P[n, j, 0]
            e1 = pts[j, 1] - P[n, j, 1]
            e2 = pts[j, 2] - P[n, j, 2]
            out[n, j] = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)


def chart_points(values: np.ndarray, lengths: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(N, J, 3) points [m], CMU axes, of (N, 2 M + 3) chart channels [theta | phi | root]."""
    v = np.asarray(values, dtype=np.float64)
    J = len(parents)
    M = J - 1
    st = np.sin(v[:, :M])
    u = np.stack([st * np.cos(v[:, M : 2 * M]), st * np.sin(v[:, M : 2 * M]), np.cos(v[:, :M])], -1)
    P = np.empty((len(v), J, 3))
    P[:, 0] = v[:, 2 * M :]
    for j in range(1, J):
        P[:, j] = P[:, parents[j]] + lengths[j - 1] * u[:, j - 1]
    return P


def position_errors(
    true_points: np.ndarray,
    keys: np.ndarray,
    key_values: np.ndarray,
    reconstruction: str,
    lengths: np.ndarray,
    parents: np.ndarray,
) -> np.ndarray:
    """(N, J) Euclidean error [m] of every point in every frame of the decoded motion.

    Args:
        true_points: (N, J, 3) true points [m] in CMU axes (:func:`chart_points` of the true
            chart gives them).
        keys: (W,) keyframes from 0 to N - 1; key_values: (W, 2 M + 3) the decoded keyframe
            values [theta | phi | root].
        reconstruction: "linear" or "catmull_rom"; lengths: (M,) [m]; parents: (J,).
    """
    P = np.ascontiguousarray(true_points, dtype=np.float64)
    out = np.empty(P.shape[:2])
    _errors(
        P,
        np.ascontiguousarray(keys, dtype=np.int64),
        np.ascontiguousarray(key_values, dtype=np.float64),
        _MODES[reconstruction],
        np.ascontiguousarray(lengths, dtype=np.float64),
        np.ascontiguousarray(parents, dtype=np.int64),
        out,
    )
    return out
