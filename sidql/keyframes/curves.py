"""The curves between keyframes: every frame of a sampled signal rebuilt from its keyframes.

Between consecutive keyframes ``k_w < k_{w+1}`` each of the D coordinates follows one curve, the
same kind for all (:data:`CURVES`):

``"hermite"`` (the paper's eqs. 9-13)
    the cubic that matches value and rate at both ends (cubic Hermite). Needs pose and rates.
``"linear"``
    the straight line between the two end values. Needs the pose only.
``"catmull_rom"``
    the cubic Hermite whose end rates are *estimated* from neighbouring keyframes,
    ``m_w = (x[k_{w+1}] - x[k_{w-1}]) / (t_{w+1} - t_{w-1})`` (one-sided at the clip ends).
    Needs the pose only; a segment's curve depends on four keyframes.

Keyframes are reproduced exactly by every curve. The spherical reconstructions of
:mod:`sidql.keyframes.reconstructions` run one curve per bone angle (theta, phi) and root
coordinate; the ``cartesian`` one runs the Hermite curve on point positions.

Pure numpy over (N, D) arrays of any units u; times in seconds.
"""

from __future__ import annotations

import numpy as np

from sim.errors import UnknownNameError

#: The curves, by name. A curve's index here is its code in a ``.sidq`` stream (header byte 5,
#: :mod:`sidql.codec.format`) and its mode in the codec's kernels: append, never reorder.
CURVES: tuple[str, ...] = ("hermite", "linear", "catmull_rom")


def validate_keyframes(keyframes, n_frames: int) -> np.ndarray:
    """Keyframe indices as a sorted (W,) int64 array; ValueError unless they are strictly
    increasing, start at 0, end at ``n_frames - 1`` and W >= 2."""
    k = np.asarray(keyframes)
    if k.ndim != 1 or k.size < 2 or not np.issubdtype(k.dtype, np.integer):
        raise ValueError(f"keyframes must be >= 2 integer indices; got {keyframes!r}")
    k = k.astype(np.int64)
    if k[0] != 0 or k[-1] != n_frames - 1 or np.any(np.diff(k) <= 0):
        raise ValueError(
            f"keyframes must increase strictly from 0 to {n_frames - 1}; got {k.tolist()}"
        )
    return k


def check_curve(curve: str) -> None:
    """UnknownNameError (listing :data:`CURVES`) unless ``curve`` is one of them."""
    if curve not in CURVES:
        raise UnknownNameError("curve", curve, CURVES)


def keyframe_rates(values: np.ndarray, keyframes: np.ndarray, dt: float) -> np.ndarray:
    """Catmull-Rom rate estimates at the keyframes.

    Args:
        values: (N, D) samples; keyframes: (W,) indices; dt: frame interval [s].

    Returns:
        (W, D) rates [units/s]: central difference over the neighbouring keyframes, one-sided at
        the first and last keyframe.
    """
    k = keyframes
    xk = values[k]
    tk = k * dt
    m = np.empty_like(xk)
    m[1:-1] = (xk[2:] - xk[:-2]) / (tk[2:] - tk[:-2])[:, None]
    m[0] = (xk[1] - xk[0]) / (tk[1] - tk[0])
    m[-1] = (xk[-1] - xk[-2]) / (tk[-1] - tk[-2])
    return m


def interpolate(
    values: np.ndarray,
    rates: np.ndarray | None,
    keyframes,
    dt: float,
    curve: str = "hermite",
) -> tuple[np.ndarray, np.ndarray]:
    """Rebuild every frame of ``values`` from its keyframes.

    Args:
        values: (N, D) samples (any units u).
        rates: (N, D) their time derivatives [u/s]; only read at keyframes, only by "hermite"
            (may be None for the other curves).
        keyframes: (W,) strictly increasing indices from 0 to N-1.
        dt: frame interval [s].
        curve: one of :data:`CURVES`.

    Returns:
        (N, D) reconstructed values and (N, D) their time derivatives [u/s]. For "linear" the
        derivative at an inner keyframe is the mean of the two adjacent slopes.
    """
    check_curve(curve)
    values = np.asarray(values, dtype=float)
    N = values.shape[0]
    k = validate_keyframes(keyframes, N)
    n = np.arange(N)
    seg = np.clip(np.searchsorted(k, n, side="right") - 1, 0, len(k) - 2)
    a, b = k[seg], k[seg + 1]
    h = ((b - a) * dt)[:, None]
    s = ((n - a) / (b - a))[:, None]
    xa, xb = values[a], values[b]
    if curve == "linear":
        slope = (xb - xa) / h
        out = xa + s * (xb - xa)
        rate = slope.copy()
        inner = k[1:-1]
        if len(inner):
            left = (values[inner] - values[k[:-2]]) / ((inner - k[:-2]) * dt)[:, None]
            right = (values[k[2:]] - values[inner]) / ((k[2:] - inner) * dt)[:, None]
            rate[inner] = 0.5 * (left + right)
        return out, rate
    if curve == "hermite":
        if rates is None:
            raise ValueError("the hermite curve needs rates")
        ma, mb = rates[a], rates[b]
    else:
        mk = keyframe_rates(values, k, dt)
        ma, mb = mk[seg], mk[seg + 1]
    s2, s3 = s * s, s * s * s
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
    out = h00 * xa + h10 * h * ma + h01 * xb + h11 * h * mb
    d00, d10, d01, d11 = 6 * s2 - 6 * s, 3 * s2 - 4 * s + 1, -6 * s2 + 6 * s, 3 * s2 - 2 * s
    rate = (d00 * xa + d01 * xb) / h + d10 * ma + d11 * mb
    # The last frame belongs to the last segment at s = 1; the formulas already give x_b, m_b.
    return out, rate
