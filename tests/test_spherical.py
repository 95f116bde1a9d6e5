"""The spherical chart: axes, eqs. 6-7 against finite differences, unwrapping, poles."""

import numpy as np
import pytest
from keyframe_synth import smooth_chart, smooth_clip

from sidql.keyframes.reconstructions import reconstruct
from sidql.keyframes.spherical import (
    BONES,
    POINTS,
    SIN_EPS,
    angles_and_rates,
    chart,
    chart_to_world,
    world_to_chart,
)
from sidql.keyframes.unchart import clip_from_chart
from sim.errors import MotionDataError
from sim.model.angles import wrap_angle


def test_points_are_the_protocol_23_parents_first():
    excluded = {"lhand", "rhand", "lfingers", "rfingers", "lthumb", "rthumb", "ltoes", "rtoes"}
    assert len(POINTS) == 23 and POINTS[0] == "root" and len(BONES) == 22
    assert not excluded & set(POINTS)
    clip = smooth_clip(5)
    s = chart(clip)
    assert all(s.parents[j] < j for j in range(1, 23)) and s.parents[0] == -1


def test_axes_follow_cmu_y_up():
    # world +z (up) is CMU +y; world -y is CMU +z.
    assert np.allclose(world_to_chart([0, 0, 1]), [0, 1, 0])
    assert np.allclose(world_to_chart([0, -1, 0]), [0, 0, 1])
    v = np.random.default_rng(0).normal(size=(7, 3))
    assert np.allclose(chart_to_world(world_to_chart(v)), v)
    # an upward bone: theta = pi/2 (perpendicular to CMU z), phi = pi/2 (along CMU y)
    theta, phi, _, _ = angles_and_rates(world_to_chart(np.array([[[0.0, 0.0, 0.3]]])))
    assert np.allclose([theta[0, 0], phi[0, 0]], [np.pi / 2, np.pi / 2])


def test_rates_are_the_derivatives_of_the_angles():
    """Eqs. 6-7 against central differences of eq. 1 along b + t v."""
    rng = np.random.default_rng(1)
    b = rng.normal(size=(200, 1, 3))
    v = rng.normal(size=(200, 1, 3))
    keep = np.linalg.norm(b[..., :2], axis=-1)[:, 0] > 0.2  # away from the poles
    b, v = b[keep], v[keep]
    # constant length: take only the tangential part of v, as for a rigid bone
    v = v - b * (np.sum(b * v, -1, keepdims=True) / np.sum(b * b, -1, keepdims=True))
    theta, phi, dtheta, dphi = angles_and_rates(b, v)
    eps = 1e-6
    tp, pp, _, _ = angles_and_rates(b + eps * v)
    tm, pm, _, _ = angles_and_rates(b - eps * v)
    assert np.allclose(dtheta, (tp - tm) / (2 * eps), atol=1e-6)
    assert np.allclose(dphi, wrap_angle(pp - pm) / (2 * eps), atol=1e-6)


def test_chart_recovers_the_angles_a_clip_was_built_from():
    theta, phi, dtheta, dphi, root, root_vel, lengths = smooth_chart(60, 30.0, seed=2)
    s = chart(clip_from_chart(theta, phi, dtheta, dphi, root, root_vel, lengths, fps=30.0))
    assert np.allclose(s.theta, theta, atol=1e-12)
    # phi is unwrapped from its value at frame 0 in (-pi, pi] (atan2's range)
    offset = phi[0] - np.arctan2(np.sin(phi[0]), np.cos(phi[0]))
    assert np.allclose(s.phi, phi - offset, atol=1e-12)
    assert np.allclose(s.dtheta, dtheta, atol=1e-10)
    assert np.allclose(s.dphi, dphi, atol=1e-10)
    assert np.allclose(s.lengths, lengths, atol=1e-12)
    assert np.allclose(s.root_pos, root) and np.allclose(s.root_vel, root_vel)
    assert s.dt == pytest.approx(1 / 30)


def test_phi_is_unwrapped_along_time():
    N = 90
    t = np.arange(N) / 30.0
    theta = np.full((N, 22), 1.3)
    phi = np.tile(6.0 * t[:, None], (1, 22))  # three turns in 3 s
    zero = np.zeros((N, 22))
    clip = clip_from_chart(
        theta,
        phi,
        zero,
        np.full((N, 22), 6.0),
        np.zeros((N, 3)),
        np.zeros((N, 3)),
        np.full(22, 0.2),
        fps=30.0,
    )
    s = chart(clip)
    assert np.all(np.diff(s.phi, axis=0) > 0) and np.allclose(s.phi, phi, atol=1e-12)


def test_poles_give_finite_rates_and_exact_keyframes():
    """A bone through the chart pole (CMU +z): everything stays finite, keyframes stay exact."""
    N = 31
    t = np.arange(N) / 30.0
    theta, phi, dtheta, dphi, root, root_vel, lengths = smooth_chart(N, 30.0, seed=3)
    theta[:, 0] = np.abs(1.5 * (t - 0.5))  # passes exactly through theta = 0 at frame 15
    dtheta[:, 0] = 1.5 * np.sign(t - 0.5)
    phi[:, 0], dphi[:, 0] = 0.4, 0.0
    clip = clip_from_chart(theta, phi, dtheta, dphi, root, root_vel, lengths, fps=30.0)
    s = chart(clip)
    assert np.isfinite(s.dphi).all() and np.isfinite(s.dtheta).all()
    assert s.theta[15, 0] == pytest.approx(0.0, abs=1e-7)
    # |phi rate| is bounded by |v| / (r SIN_EPS)
    v = np.linalg.norm(clip.velocities[:, 2] - clip.velocities[:, 1], axis=-1)
    assert np.all(np.abs(s.dphi[:, 0]) <= v / (lengths[0] * SIN_EPS) + 1e-9)
    keys = np.array([0, 15, 30])
    rec = reconstruct(clip, keys)
    assert np.isfinite(rec.positions).all() and np.isfinite(rec.velocities).all()
    assert np.allclose(rec.positions[keys], clip.positions[keys], atol=1e-9)


def test_missing_point_is_a_motion_data_error():
    clip = smooth_clip(4)
    from dataclasses import replace

    names = tuple("lfoot_x" if n == "lfoot" else n for n in clip.names)
    with pytest.raises(MotionDataError, match="lfoot"):
        chart(replace(clip, names=names))


def test_chart_of_real_walk_rebuilds_its_points(walk_clip):
    clip = walk_clip.slice(0, 60)
    rec = reconstruct(clip, np.arange(60))
    idx = [clip.index(p) for p in POINTS]
    assert np.allclose(rec.positions, clip.positions[:, idx], atol=1e-9)
    assert np.allclose(rec.velocities, clip.velocities[:, idx], atol=1e-9)


def test_rates_of_real_walk_match_differences_of_its_angles(cmu_dir):
    """Eqs. 6-7 on real data against central differences of theta at the full 120 fps."""
    from sim.motion.ingest import load_motion

    clip = load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc", fps=120.0)
    s = chart(clip)
    fd = (s.theta[2:] - s.theta[:-2]) / (2 * s.dt)
    err = np.abs(fd - s.dtheta[1:-1])
    assert np.median(err) < 0.01 * np.median(np.abs(s.dtheta))


@pytest.mark.parametrize("source", ["synthetic", "real walk"])
def test_compiled_chart_agrees_with_the_vectorised_formulas(source, request):
    if source == "real walk":
        clip = request.getfixturevalue("walk_clip").slice(0, 60)
    else:
        clip = smooth_clip(40, 30.0, seed=4)
    s = chart(clip)
    idx = [clip.index(p) for p in POINTS]
    P, V = world_to_chart(clip.positions[:, idx]), world_to_chart(clip.velocities[:, idx])
    child = np.arange(1, 23)
    parent = s.parents[child]
    theta, phi, dtheta, dphi = angles_and_rates(
        P[:, child] - P[:, parent], V[:, child] - V[:, parent]
    )
    assert np.allclose(s.theta, theta, atol=1e-12) and np.allclose(s.phi, phi, atol=1e-12)
    assert np.allclose(s.dtheta, dtheta, atol=1e-10) and np.allclose(s.dphi, dphi, rtol=1e-9)


def test_non_finite_motion_is_a_motion_data_error():
    from dataclasses import replace

    clip = smooth_clip(6)
    pos = clip.positions.copy()
    pos[3, 5, 1] = np.nan
    with pytest.raises(MotionDataError, match="non-finite"):
        chart(replace(clip, positions=pos))
