"""Velocities and accelerations of every reconstruction come from its curve, and agree with finite
differences of the same curve sampled densely.

The same curve at a higher rate: a clip whose keyframe frames are the coarse clip's keyframes,
``m`` frames apart, rebuilt by the same reconstruction, is the coarse curve sampled every ``dt / m``
(every reconstruction reads only its keyframes' values and rates, and times in seconds). Central
differences of its positions and velocities at ``h = dt / m`` must match its analytic velocities
and accelerations inside segments; at an inner keyframe the acceleration is the mean of both
sides' plus the velocity's jump spread over the frame, ``(a- + a+) / 2 + (v+ - v-) / dt``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sidql.keyframes import pitch, reconstructions
from sidql.keyframes.curves import interpolate_derivatives
from sidql.keyframes.spherical import M_BONES
from sidql.keyframes.unchart import clip_from_chart

FPS, N, M = 30.0, 31, 20
KEYS = np.array([0, 7, 16, 22, 30])


def smooth_clip(fps: float = FPS, n: int = N, seed: int = 0):
    """A 23-point clip from a smooth chart (angles away from the poles), exact rates."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fps
    f = rng.uniform(0.5, 2.0, (1, M_BONES))
    ph = rng.uniform(0, 2 * np.pi, (1, M_BONES))
    theta = 1.4 + 0.6 * np.sin(2 * np.pi * f * t[:, None] + ph)
    dtheta = 0.6 * 2 * np.pi * f * np.cos(2 * np.pi * f * t[:, None] + ph)
    phi = 0.5 + 0.8 * np.sin(np.pi * f * t[:, None])
    dphi = 0.8 * np.pi * f * np.cos(np.pi * f * t[:, None])
    root = np.stack([0.5 * t, 0.9 + 0.05 * np.sin(4 * t), 0.2 * t**2], axis=1)
    root_v = np.stack([0.5 + 0 * t, 0.2 * np.cos(4 * t), 0.4 * t], axis=1)
    lengths = rng.uniform(0.1, 0.4, M_BONES)
    return clip_from_chart(theta, phi, dtheta, dphi, root, root_v, lengths, fps)


def denser(clip, m: int):
    """The clip with every frame repeated so that its frame ``m n`` is the clip's frame ``n`` at
    ``m`` times the rate (keyframe values and rates are the clip's)."""
    idx = np.arange(m * (clip.n_frames - 1) + 1) // m
    return dataclasses.replace(
        clip, positions=clip.positions[idx], velocities=clip.velocities[idx],
        qpos=clip.qpos[idx], qvel=clip.qvel[idx], rotations=clip.rotations[idx],
        fps=clip.fps * m,
    )  # fmt: skip


def central(x: np.ndarray, h: float, i: np.ndarray) -> np.ndarray:
    """Five-point central difference at ``i`` (exact for polynomials up to degree 4)."""
    return (x[i - 2] - 8 * x[i - 1] + 8 * x[i + 1] - x[i + 2]) / (12 * h)


def keyframe_acceleration(v, a, j, h, dt):
    """``(a- + a+) / 2 + (v+ - v-) / dt`` at dense frame ``j``, each side's limit extrapolated
    from the two dense frames on that side (a linear, v quadratic)."""
    a_minus, a_plus = 2 * a[j - 1] - a[j - 2], 2 * a[j + 1] - a[j + 2]
    jerk_minus, jerk_plus = (a[j - 1] - a[j - 2]) / h, (a[j + 2] - a[j + 1]) / h
    v_minus = v[j - 1] + h * a_minus - 0.5 * h * h * jerk_minus
    v_plus = v[j + 1] - h * a_plus - 0.5 * h * h * jerk_plus
    return 0.5 * (a_minus + a_plus) + (v_plus - v_minus) / dt


def interior(n: int, keys: np.ndarray) -> np.ndarray:
    """Indices whose five-point stencil lies inside one segment (no keyframe within 2)."""
    near = np.zeros(n, dtype=bool)
    for d in range(-2, 3):
        near[np.clip(keys + d, 0, n - 1)] = True
    return np.flatnonzero(~near)


@pytest.mark.parametrize("reconstruction", ["hermite", "linear", "catmull_rom"])
def test_channel_curves_second_derivative_matches_finite_differences(reconstruction):
    rng = np.random.default_rng(1)
    values = rng.normal(size=(N, 5))
    rates = rng.normal(size=(N, 5))
    dense_v = np.zeros((M * (N - 1) + 1, 5))
    dense_r = np.zeros_like(dense_v)
    dense_v[M * KEYS], dense_r[M * KEYS] = values[KEYS], rates[KEYS]
    dt, h = 1 / FPS, 1 / (FPS * M)
    x, v, a = interpolate_derivatives(dense_v, dense_r, M * KEYS, h, reconstruction)
    xc, vc, ac = interpolate_derivatives(values, rates, KEYS, dt, reconstruction)
    np.testing.assert_allclose(x[::M], xc, atol=1e-9)  # the same curve
    inside = interior(len(x), M * KEYS)
    np.testing.assert_allclose(central(x, h, inside), v[inside], rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(central(v, h, inside), a[inside], rtol=1e-7, atol=1e-6)
    # inner keyframes: both sides' mean plus the velocity's jump over the frame
    for kf in KEYS[1:-1]:
        np.testing.assert_allclose(ac[kf], keyframe_acceleration(v, a, M * kf, h, dt), rtol=1e-4)


@pytest.mark.parametrize(
    "reconstruction", ["hermite", "linear", "catmull_rom", "cartesian", "slerp"]
)
def test_point_accelerations_of_every_reconstruction_match_finite_differences(reconstruction):
    clip = smooth_clip()
    dense = denser(clip, M)
    h = 1 / dense.fps
    if reconstruction == "slerp":  # the rig is fitted to all frames: fit it once, on the clip
        rig, _ = pitch.fit_rig(*pitch.protocol_rotations(clip))
        coarse, fine = (
            reconstructions.points_reconstruction(
                *slerp[:2], slerp[3], keys, "slerp", c.fps, slerp[2]
            )
            for c, keys in ((clip, KEYS), (dense, M * KEYS))
            for slerp in [pitch.slerp_points(c, keys, rig)]
        )
    else:
        coarse = reconstructions.rebuild(reconstruction, clip, KEYS)
        fine = reconstructions.rebuild(reconstruction, dense, M * KEYS)
    assert coarse.accelerations is not None and coarse.accelerations.shape == coarse.positions.shape
    np.testing.assert_allclose(fine.positions[::M], coarse.positions, atol=1e-9)
    P, V, A = fine.positions, fine.velocities, fine.accelerations
    i = interior(len(P), M * KEYS)
    scale = np.abs(A[i]).max()
    np.testing.assert_allclose(central(P, h, i), V[i], atol=1e-6 * np.abs(V[i]).max())
    np.testing.assert_allclose(central(V, h, i), A[i], atol=1e-5 * scale)
    np.testing.assert_allclose(fine.accelerations[::M][1:-1][~np.isin(np.arange(1, N - 1), KEYS)],
                               coarse.accelerations[1:-1][~np.isin(np.arange(1, N - 1), KEYS)],
                               atol=1e-6 * scale)  # fmt: skip
    if reconstruction in ("cartesian", "slerp"):  # point curves: the keyframe rule at the points
        for kf in KEYS[1:-1]:  # (one-sided limits extrapolated from the dense samples: 2 %)
            want = keyframe_acceleration(V, A, M * kf, h, 1 / FPS)
            np.testing.assert_allclose(coarse.accelerations[kf], want, rtol=1e-2, atol=2e-2 * scale)


def test_a_motion_the_curve_represents_has_its_true_acceleration():
    """Root on a parabola, every bone still: Hermite from exact keyframes reproduces the
    constant root acceleration at every frame (keyframes included)."""
    clip = smooth_clip()
    rec = reconstructions.rebuild("hermite", clip, KEYS)
    # the smooth clip's root moves 0.5 t, 0.9 + 0.05 sin 4t, 0.2 t^2 in CMU axes; its z (CMU)
    # channel is quadratic: acceleration 0.4 everywhere; world y = -z_cmu
    np.testing.assert_allclose(rec.accelerations[:, 0, 1], -0.4, atol=1e-9)
