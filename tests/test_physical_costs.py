"""Physics-aware keyframes: the physical segment cost against a direct computation, its optimum."""

from itertools import combinations

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.keyframes import methods
from sidql.keyframes.curves import interpolate_derivatives
from sidql.keyframes.optimal import clip_optimal_table
from sidql.keyframes.physical_costs import (
    GRAVITY,
    MU,
    SegmentInputs,
    cone_residual,
    physical_costs,
    physics_table,
    point_masses,
    scaled,
    segment_inputs,
)
from sidql.keyframes.segment_costs import clip_cost_matrix
from sidql.keyframes.spherical import POINTS


def _ray_distance(f, supported):
    """Distance from the friction cone by projecting onto its boundary ray in the (|f_h|, f_z)
    half-plane (an independent construction of the same set)."""
    out = []
    for v, s in zip(f, supported, strict=True):
        if not s:
            out.append(np.linalg.norm(v))
            continue
        p = np.array([np.hypot(v[0], v[1]), v[2]])
        d = np.array([MU, 1.0]) / np.hypot(MU, 1.0)
        inside = p[0] <= MU * p[1]
        out.append(0.0 if inside else np.linalg.norm(p - max(0.0, p @ d) * d))
    return np.array(out)


def test_cone_residual_is_the_distance_from_the_friction_cone():
    rng = np.random.default_rng(0)
    f = rng.normal(size=(500, 3)) * 10
    sup = rng.random(500) < 0.7
    assert np.allclose(cone_residual(f, sup), _ray_distance(f, sup), atol=1e-12)
    # standing still needs g upwards: the floor supplies it, nothing does in the air
    up = np.array([[0.0, 0.0, GRAVITY]])
    assert cone_residual(up, np.array([True]))[0] == 0.0
    assert cone_residual(up, np.array([False]))[0] == pytest.approx(GRAVITY)


def test_point_masses_lump_de_leva_segments_at_the_bone_ends():
    w = point_masses()
    assert w.sum() == pytest.approx(1.0) and np.all(w > 0)
    for k, name in enumerate(POINTS):  # left and right alike
        if name[0] == "l" and name != "lowerback" and name != "lowerneck":
            assert w[k] == pytest.approx(w[POINTS.index("r" + name[1:])])
    # de Leva 1996 (male): the knee holds half the thigh and half the shank, the ball half the foot
    assert w[POINTS.index("lfemur")] == pytest.approx((14.16 + 4.33) / 200)
    assert w[POINTS.index("lfoot")] == pytest.approx(1.37 / 200)


def _inputs(N=14, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 30.0
    wave = lambda a, w: a * np.sin(w * t + rng.uniform(0, 6))[:, None]  # noqa: E731
    com = np.hstack([wave(0.3, 3), wave(0.2, 4), 0.9 + wave(0.05, 9)])
    com_vel = np.gradient(com, 1 / 30.0, axis=0)
    S = 0.02 + rng.normal(size=(N, 2, 2, 3)).cumsum(axis=0) * 0.01
    SV = np.gradient(S, 1 / 30.0, axis=0)
    contact = rng.random((N, 2)) < 0.6
    return SegmentInputs(
        com, com_vel, S, SV, np.array([0.02, 0.025]), rng.normal(size=(N, 2)) * 0.005, contact,
        rng.normal(size=(N, 2)) * 0.01, rng.normal(size=(N, 2, 2)) * 0.1,
        np.abs(rng.normal(size=N)) * 0.05, 1 / 30.0,
    )  # fmt: skip


def _direct(x: SegmentInputs, i: int, j: int) -> np.ndarray:
    """The three terms of segment (i, j) from the Hermite curves of sidql.keyframes.curves."""
    n = np.arange(i, j + 1)
    keys = np.array([0, j - i])
    N = len(n)
    p, v, _ = interpolate_derivatives(
        x.spheres[n].reshape(N, -1), x.sphere_vel[n].reshape(N, -1), keys, x.dt
    )
    p, v = p.reshape(N, 2, 2, 3), v.reshape(N, 2, 2, 3)
    _, _, a = interpolate_derivatives(x.com[n], x.com_vel[n], keys, x.dt)
    skate = height = res = 0.0
    for m in range(1, N - 1):
        t = n[m]
        for f in range(2):
            k = np.argmin(p[m, f, :, 2])
            h = p[m, f, k, 2] - x.radius[f] - x.floor[t, f]
            if x.contact[t, f]:
                skate += np.linalg.norm(v[m, f, k, :2] - x.vel0[t, f])
                height += abs(h - x.height0[t, f])
            else:
                height += max(0.0, max(0.0, -h) - max(0.0, -x.height0[t, f]))
        f_ = a[m] + [0, 0, GRAVITY]
        r = _ray_distance(f_[None], [x.contact[t].any()])[0] / GRAVITY
        res += max(0.0, r - x.residual0[t])
    return np.array([skate, height, res])


def test_physical_costs_equal_a_direct_computation_on_every_segment():
    x = _inputs()
    T = physical_costs(x)
    N = len(x.com)
    for i in range(N):
        for j in range(i + 1, N):
            want = _direct(x, i, j) if j > i + 1 else np.zeros(3)
            assert np.allclose(T[:, i, j], want, rtol=1e-9, atol=1e-9), (i, j)
    assert np.all(T[:, np.tril_indices(N)[0], np.tril_indices(N)[1]] == 0)


@pytest.fixture(scope="module")
def clip():
    return smooth_clip(14, 30.0, seed=3)


def test_physics_keyframes_are_the_exact_minimum_of_q_plus_the_weighted_cost(clip):
    terms = physical_costs(segment_inputs(clip))
    C = clip_cost_matrix(clip) + 0.7 * scaled(terms)
    N, W = clip.n_frames, 4
    best = min(
        (sum(C[a, b] for a, b in zip(k[:-1], k[1:], strict=True)), k)
        for inner in combinations(range(1, N - 1), W - 2)
        for k in [(0, *inner, N - 1)]
    )
    table = physics_table(clip, weight=0.7, w_max=W, terms=terms)
    got = table.keyframes(W)
    assert sum(C[a, b] for a, b in zip(got[:-1], got[1:], strict=True)) == pytest.approx(best[0])


def test_weight_zero_is_the_q_optimum_and_the_method_declares_contacts(clip):
    for W in (3, 5):
        assert np.array_equal(
            physics_table(clip, weight=0.0, w_max=W).keyframes(W),
            clip_optimal_table(clip, w_max=W).keyframes(W),
        )
    assert methods.reconstruction_of("physics") == "contacts"
    k = methods.select("physics", clip, 5, memo={"w_max": 6})
    assert k[0] == 0 and k[-1] == clip.n_frames - 1 and len(k) == 5
