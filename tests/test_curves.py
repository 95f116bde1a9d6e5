"""The curves between keyframes and the spherical reconstructions: exact on representable
motion, constant bone lengths, exact keyframes, velocities that are the derivatives of the
positions."""

import numpy as np
import pytest
from keyframe_synth import assert_velocities_match_differences, piecewise_clip, smooth_clip

from sidql.keyframes.curves import CURVES, interpolate, keyframe_rates
from sidql.keyframes.metrics import bone_vectors, q_error
from sidql.keyframes.reconstructions import RECONSTRUCTIONS, reconstruct, reconstruct_series
from sidql.keyframes.spherical import POINTS, chart
from sim.errors import UnknownNameError

KEYS = np.array([0, 7, 19, 20, 33, 59])


def truth(clip):
    idx = [clip.index(p) for p in POINTS]
    return clip.positions[:, idx], clip.velocities[:, idx]


@pytest.mark.parametrize("curve", ["hermite", "linear"])
def test_motion_of_the_curves_own_curves_is_rebuilt_exactly(curve):
    clip = piecewise_clip(KEYS, 60, 30.0, seed=4, curve=curve)
    rec = reconstruct(clip, KEYS, curve)
    pos, vel = truth(clip)
    assert np.allclose(rec.positions, pos, atol=1e-9)
    s = chart(clip)
    assert np.allclose(rec.theta, s.theta, atol=1e-9) and np.allclose(rec.phi, s.phi, atol=1e-9)
    assert q_error(s, KEYS, curve) == pytest.approx(0.0, abs=1e-10)
    if curve == "hermite":  # linear velocities are one-sided at keyframes
        assert np.allclose(rec.velocities, vel, atol=1e-8)


def test_catmull_rom_is_exact_on_motion_linear_in_the_chart():
    N, M = 60, 22
    t = np.arange(N)[:, None] / 30.0
    rng = np.random.default_rng(5)
    a, b = rng.uniform(-0.4, 0.4, (2, M))
    theta, phi = 1.3 + a * t, rng.uniform(-3, 3, M) + b * t
    from sidql.keyframes.unchart import clip_from_chart

    root = 0.5 * t * np.ones(3)
    clip = clip_from_chart(
        theta, phi, a + 0 * t, b + 0 * t, root, 0.5 + 0 * root, rng.uniform(0.1, 0.4, M), fps=30.0
    )
    rec = reconstruct(clip, KEYS, "catmull_rom")
    assert np.allclose(rec.positions, truth(clip)[0], atol=1e-9)


def test_catmull_rom_rates_are_central_differences_over_neighbour_keyframes():
    x = np.random.default_rng(6).normal(size=(60, 4))
    m = keyframe_rates(x, KEYS, 0.1)
    w = 2
    assert np.allclose(
        m[w], (x[KEYS[w + 1]] - x[KEYS[w - 1]]) / ((KEYS[w + 1] - KEYS[w - 1]) * 0.1)
    )
    assert np.allclose(m[0], (x[KEYS[1]] - x[0]) / (KEYS[1] * 0.1))


@pytest.mark.parametrize("curve", CURVES)
def test_bone_lengths_are_constant_and_keyframes_exact(curve):
    clip = smooth_clip(60, 30.0, seed=7)
    rec = reconstruct(clip, np.array([0, 11, 40, 59]), curve)
    lengths = np.linalg.norm(bone_vectors(rec.positions, rec.parents), axis=-1)
    assert np.abs(lengths - chart(clip).lengths).max() < 1e-9
    keys = rec.keyframes
    assert np.allclose(rec.positions[keys], truth(clip)[0][keys], atol=1e-12)
    assert rec.names == POINTS and rec.positions.shape == (60, 23, 3)


@pytest.mark.parametrize("curve", CURVES)
def test_velocities_are_the_derivative_of_positions(curve):
    """At 600 fps, central differences of the rebuilt positions match the reported velocities
    away from keyframes (where linear and Catmull-Rom have kinks)."""
    N = 601
    clip = smooth_clip(N, 600.0, seed=8)
    keys = np.array([0, 150, 420, 600])
    rec = reconstruct(clip, keys, curve)
    assert_velocities_match_differences(rec, keys)


def test_all_frames_as_keyframes_reproduce_the_clip_and_q_is_zero():
    clip = smooth_clip(30, 30.0, seed=9)
    rec = reconstruct(clip, np.arange(30))
    pos, vel = truth(clip)
    assert np.allclose(rec.positions, pos, atol=1e-12) and np.allclose(rec.velocities, vel)
    assert q_error(chart(clip), np.arange(30)) == 0.0


def test_bad_keyframes_and_curves_are_rejected():
    clip = smooth_clip(10)
    for bad in ([1, 9], [0, 5, 5, 9], [0, 8], [0], [0.0, 9.0]):
        with pytest.raises(ValueError):
            reconstruct(clip, bad)
    with pytest.raises(UnknownNameError, match="unknown reconstruction 'spline'; known: hermite"):
        reconstruct(clip, [0, 9], "spline")
    with pytest.raises(UnknownNameError, match="unknown curve 'spline'; known: hermite, linear"):
        interpolate(np.zeros((10, 2)), None, [0, 9], 0.1, "spline")


def test_every_curve_is_a_spherical_reconstruction_of_its_name():
    clip = smooth_clip(30)
    keys = [0, 11, 29]
    for curve in CURVES:
        assert curve in RECONSTRUCTIONS
        rec = reconstruct(clip, keys, curve)
        direct = reconstruct_series(chart(clip), keys, curve)
        assert rec.reconstruction == direct.reconstruction == curve
        assert np.array_equal(rec.positions, direct.positions)


def test_interpolate_hermite_reproduces_cubics_on_any_grid():
    t = np.arange(25) * 0.05
    x = (1.0 - 2.0 * t + 0.5 * t**2 - 0.3 * t**3)[:, None]
    xd = (-2.0 + t - 0.9 * t**2)[:, None]
    rec, rate = interpolate(x, xd, [0, 24], 0.05, "hermite")
    assert np.allclose(rec, x) and np.allclose(rate, xd)


@pytest.mark.parametrize("curve", CURVES)
def test_long_signals_are_evaluated_in_chunks_with_the_same_result(curve, monkeypatch):
    """A trial longer than a chunk (and keyframes across chunk borders) gives exactly what one
    pass over every frame gives."""
    from sidql.keyframes import curves

    rng = np.random.default_rng(3)
    N, D = 2 * curves._CHUNK_FRAMES + 123, 5
    values, rates = rng.normal(size=(N, D)), rng.normal(size=(N, D))
    keys = np.unique(np.r_[0, rng.choice(N, 3000, replace=False), N - 1])
    chunked = curves.interpolate_derivatives(values, rates, keys, 1 / 30, curve)
    monkeypatch.setattr(curves, "_CHUNK_FRAMES", 10 * N)
    whole = curves.interpolate_derivatives(values, rates, keys, 1 / 30, curve)
    for a, b in zip(chunked, whole, strict=True):
        np.testing.assert_array_equal(a, b)
