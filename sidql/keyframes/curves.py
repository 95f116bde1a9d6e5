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

from sim.errors import UnknownNameError, UsageError

#: The curves, by name. A curve's index here is its code in a ``.sidq`` stream (header byte 5,
#: :mod:`sidql.codec.format`) and its mode in the codec's kernels: append, never reorder.
CURVES: tuple[str, ...] = ("hermite", "linear", "catmull_rom")


def validate_keyframes(keyframes, n_frames: int) -> np.ndarray:
    """Keyframe indices as a sorted (W,) int64 array; ValueError unless they are strictly
    increasing, start at 0, end at ``n_frames - 1`` and W >= 2."""
    k = np.asarray(keyframes)
    if k.ndim != 1 or k.size < 2 or not np.issubdtype(k.dtype, np.integer):
        raise UsageError(f"keyframes must be >= 2 integer indices; got {keyframes!r}")
    k = k.astype(np.int64)
    if k[0] != 0 or k[-1] != n_frames - 1 or np.any(np.diff(k) <= 0):
        raise UsageError(
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
    x, xd, _ = interpolate_derivatives(values, rates, keyframes, dt, curve)
    return x, xd


#: Frames evaluated at a time by :func:`interpolate_derivatives` (a whole trial can be long).
_CHUNK_FRAMES = 4096


def _segment_polynomials(values, rates, k, dt, curve):
    """Per segment ``w`` (between keyframes k[w] and k[w+1]) the curve as a cubic in the time
    ``tau`` [s] since k[w]: coefficients (W-1, 4, D) of 1, tau, tau^2, tau^3."""
    xa, xb = values[k[:-1]], values[k[1:]]
    h = ((k[1:] - k[:-1]) * dt)[:, None]
    c = np.zeros((len(k) - 1, 4, values.shape[1]))
    if curve == "linear":
        c[:, 0], c[:, 1] = xa, (xb - xa) / h
        return c
    if curve == "hermite":
        if rates is None:
            raise UsageError("the hermite curve needs rates")
        m = rates[k]
    else:
        m = keyframe_rates(values, k, dt)
    ma, mb = m[:-1], m[1:]
    c[:, 0] = xa
    c[:, 1] = ma
    c[:, 2] = (3 * (xb - xa) / h - 2 * ma - mb) / h
    c[:, 3] = (2 * (xa - xb) / h + ma + mb) / h**2
    return c


def _eval_cubic(c, tau):
    """Value, first and second derivative of cubics ``c`` (n, 4, D) at ``tau`` (n, 1)."""
    x = c[:, 0] + tau * (c[:, 1] + tau * (c[:, 2] + tau * c[:, 3]))
    v = c[:, 1] + tau * (2 * c[:, 2] + 3 * tau * c[:, 3])
    a = 2 * c[:, 2] + 6 * tau * c[:, 3]
    return x, v, a


def interpolate_derivatives(
    values: np.ndarray,
    rates: np.ndarray | None,
    keyframes,
    dt: float,
    curve: str = "hermite",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`interpolate` with the curve's second derivative.

    Returns:
        (N, D) values, (N, D) rates [u/s] and (N, D) second derivatives [u/s^2], all from the
        curve itself (its piecewise polynomials). At an inner keyframe, where the curve's rate
        ("linear") or second derivative ("hermite", "catmull_rom") jumps, the second derivative
        is the mean of both sides' plus the rate's jump spread over the frame,
        ``(a(t-) + a(t+)) / 2 + (v(t+) - v(t-)) / dt`` (an impulse); the rate there is the mean of
        both sides for "linear" and the (continuous) rate otherwise.
    """
    check_curve(curve)
    values = np.asarray(values, dtype=float)
    N = values.shape[0]
    k = validate_keyframes(keyframes, N)
    n = np.arange(N)
    seg = np.clip(np.searchsorted(k, n, side="right") - 1, 0, len(k) - 2)
    coef = _segment_polynomials(values, rates, k, dt, curve)
    x, v, a = (np.empty_like(values) for _ in range(3))
    for start in range(0, N, _CHUNK_FRAMES):  # chunks bound the (frames, 4, D) temporaries
        part = slice(start, start + _CHUNK_FRAMES)
        tau = ((n[part] - k[seg[part]]) * dt)[:, None]
        x[part], v[part], a[part] = _eval_cubic(coef[seg[part]], tau)
    x[k] = values[k]  # exact at keyframes (no rounding of the polynomial)
    for start in range(1, len(k) - 1, _CHUNK_FRAMES):  # inner keyframes, a chunk at a time
        w = np.arange(start, min(start + _CHUNK_FRAMES, len(k) - 1))  # segments starting there
        inner = k[w]
        _, v_right, a_right = _eval_cubic(coef[w], np.zeros((len(w), 1)))
        h_left = ((inner - k[w - 1]) * dt)[:, None]
        _, v_left, a_left = _eval_cubic(coef[w - 1], h_left)
        a[inner] = 0.5 * (a_left + a_right) + (v_right - v_left) / dt
        if curve == "linear":
            v[inner] = 0.5 * (coef[w - 1, 1] + coef[w, 1])
    return x, v, a
