"""Reconstruction of a clip from its keyframes in the spherical chart.

Between consecutive keyframes ``k_w < k_{w+1}`` every bone's ``theta(t)`` and ``phi(t)`` and the
root position (Cartesian, CMU axes) follow one curve per coordinate, chosen by ``variant``:

``"hermite"`` (the paper's eqs. 9-13)
    the cubic that matches value and rate at both ends (cubic Hermite). Needs pose and rates.
``"linear"``
    the straight line between the two end values. Needs the pose only.
``"catmull_rom"``
    the cubic Hermite whose end rates are *estimated* from neighbouring keyframes,
    ``m_w = (x[k_{w+1}] - x[k_{w-1}]) / (t_{w+1} - t_{w-1})`` (one-sided at the clip ends).
    Needs the pose only; a segment's curve depends on four keyframes.

Points are then rebuilt down the 23-point tree with the fixed bone lengths, so every bone keeps its
length exactly. Keyframes are reproduced exactly by every variant.

Pure numpy. Units: metres, seconds, radians; output positions in world axes (z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sidql.keyframes.spherical import (
    POINTS,
    SphericalSeries,
    accelerations_from_chart,
    angles_and_rates,
    chart,
    positions_from_chart,
    split_channels,
    world_to_chart,
)
from sim.motion.clip import Clip
from sim.motion.points import PointMotion

SPHERICAL_CURVES: tuple[str, ...] = ("hermite", "linear", "catmull_rom")


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


def _check_variant(variant: str) -> None:
    if variant not in SPHERICAL_CURVES:
        raise ValueError(f"unknown variant {variant!r}; known: {', '.join(SPHERICAL_CURVES)}")


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
    variant: str = "hermite",
) -> tuple[np.ndarray, np.ndarray]:
    """Rebuild every frame of ``values`` from its keyframes.

    Args:
        values: (N, D) samples (any units u).
        rates: (N, D) their time derivatives [u/s]; only read at keyframes, only by "hermite"
            (may be None for the other variants).
        keyframes: (W,) strictly increasing indices from 0 to N-1.
        dt: frame interval [s].
        variant: one of :data:`SPHERICAL_CURVES`.

    Returns:
        (N, D) reconstructed values and (N, D) their time derivatives [u/s]. For "linear" the
        derivative at an inner keyframe is the mean of the two adjacent slopes.
    """
    x, xd, _ = interpolate_derivatives(values, rates, keyframes, dt, variant)
    return x, xd


def _segment_polynomials(values, rates, k, dt, variant):
    """Per segment ``w`` (between keyframes k[w] and k[w+1]) the curve as a cubic in the time
    ``tau`` [s] since k[w]: coefficients (W-1, 4, D) of 1, tau, tau^2, tau^3."""
    xa, xb = values[k[:-1]], values[k[1:]]
    h = ((k[1:] - k[:-1]) * dt)[:, None]
    c = np.zeros((len(k) - 1, 4, values.shape[1]))
    if variant == "linear":
        c[:, 0], c[:, 1] = xa, (xb - xa) / h
        return c
    if variant == "hermite":
        if rates is None:
            raise ValueError("the hermite variant needs rates")
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
    variant: str = "hermite",
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
    _check_variant(variant)
    values = np.asarray(values, dtype=float)
    N = values.shape[0]
    k = validate_keyframes(keyframes, N)
    n = np.arange(N)
    seg = np.clip(np.searchsorted(k, n, side="right") - 1, 0, len(k) - 2)
    coef = _segment_polynomials(values, rates, k, dt, variant)
    tau = ((n - k[seg]) * dt)[:, None]
    x, v, a = _eval_cubic(coef[seg], tau)
    x[k] = values[k]  # exact at keyframes (no rounding of the polynomial)
    inner = k[1:-1]
    if len(inner):
        w = np.searchsorted(k, inner)  # segment starting at each inner keyframe
        _, v_right, a_right = _eval_cubic(coef[w], np.zeros((len(inner), 1)))
        h_left = ((inner - k[w - 1]) * dt)[:, None]
        _, v_left, a_left = _eval_cubic(coef[w - 1], h_left)
        a[inner] = 0.5 * (a_left + a_right) + (v_right - v_left) / dt
        if variant == "linear":
            v[inner] = 0.5 * (coef[w - 1, 1] + coef[w, 1])
    return x, v, a


@dataclass(frozen=True, kw_only=True)
class Reconstruction(PointMotion):
    """A clip rebuilt from keyframes: the 23 protocol points, ready to replay (a
    :class:`~sim.motion.points.PointMotion`, so replay and render take it as it is).

    Attributes (besides the point motion's names, parents, positions, fps, velocities):
        positions: (N, 23, 3) point positions [m], world axes (z up).
        velocities: (N, 23, 3) point velocities [m/s], world axes (derivative of the curves).
        names: (23,) point names (:data:`sidql.keyframes.spherical.POINTS`); parents: (23,).
        theta: (N, 22) polar angles [rad] of the rebuilt bones; phi: (N, 22) azimuths [rad].
        keyframes: (W,) keyframe indices used.
        variant: the reconstruction (a name in :mod:`sidql.keyframes.reconstructions`).
        accelerations: (N, 23, 3) point accelerations [m/s^2], world axes, from the curves
            themselves (:func:`interpolate_derivatives`: at an inner keyframe the mean over the
            frame's interval); None where a reconstruction does not provide them.
    """

    theta: np.ndarray
    phi: np.ndarray
    keyframes: np.ndarray
    variant: str
    accelerations: np.ndarray | None = None

    @property
    def dt(self) -> float:
        """Frame interval [s]."""
        return 1.0 / self.fps


def points_reconstruction(
    positions: np.ndarray,
    velocities: np.ndarray,
    parents: np.ndarray,
    keyframes: np.ndarray,
    variant: str,
    fps: float,
    accelerations: np.ndarray | None = None,
) -> Reconstruction:
    """A reconstruction rebuilt as points rather than in the chart (``slerp``, ``cartesian``):
    the 23 protocol points' positions (N, 23, 3) [m], velocities [m/s] and accelerations
    [m/s^2], world axes (z up), with their (23,) ``parents``; its bones' theta/phi (N, 22) [rad]
    are measured from the points."""
    child = np.arange(1, len(parents))
    bones = positions[:, child] - positions[:, parents[child]]
    theta, phi, _, _ = angles_and_rates(world_to_chart(bones))
    return Reconstruction(
        positions=positions,
        velocities=velocities,
        names=POINTS,
        parents=parents.copy(),
        theta=theta,
        phi=phi,
        keyframes=keyframes,
        variant=variant,
        fps=fps,
        accelerations=accelerations,
    )


def reconstruct_series(
    series: SphericalSeries, keyframes, variant: str = "hermite"
) -> Reconstruction:
    """Reconstruct a chart from its keyframes (see the module docstring).

    Args:
        series: the true motion's chart (N frames, M bones).
        keyframes: (W,) strictly increasing indices from 0 to N-1.
        variant: one of :data:`SPHERICAL_CURVES`.
    """
    _check_variant(variant)
    k = validate_keyframes(keyframes, series.n_frames)
    M = series.n_bones
    values, rates = series.channels()
    x, xd, xdd = interpolate_derivatives(values, rates, k, series.dt, variant)
    theta, phi, root = split_channels(x, M)
    dtheta, dphi, root_vel = split_channels(xd, M)
    ddtheta, ddphi, root_acc = split_channels(xdd, M)
    P, V = positions_from_chart(
        root, root_vel, theta, phi, dtheta, dphi, series.lengths, series.parents
    )
    A = accelerations_from_chart(
        root_acc, theta, phi, dtheta, dphi, ddtheta, ddphi, series.lengths, series.parents
    )
    return Reconstruction(
        positions=P,
        velocities=V,
        names=POINTS,
        parents=series.parents.copy(),
        theta=theta,
        phi=phi,
        keyframes=k,
        variant=variant,
        fps=1.0 / series.dt,
        accelerations=A,
    )


def reconstruct(clip: Clip, keyframes, variant: str = "hermite") -> Reconstruction:
    """Reconstruct ``clip``'s 23 protocol points from its keyframes.

    Args:
        clip: the true motion (names must include :data:`sidql.keyframes.spherical.POINTS`).
        keyframes: (W,) strictly increasing indices from 0 to clip.n_frames - 1.
        variant: "hermite" (paper), "linear" or "catmull_rom".

    Returns:
        A :class:`Reconstruction`: positions/velocities (N, 23, 3) world z-up [m, m/s].
    """
    return reconstruct_series(chart(clip), keyframes, variant)
