"""Replay checks: MuJoCo's collision figures against brute-force geometry, and exact invariants."""

from __future__ import annotations

import numpy as np
import pytest

from sidql.evaluation.validation import validate_clip
from sim.model.capsules import adjacent_pairs, bone_poses, bones_of
from sim.replay.checks import (
    CollisionScene,
    PointMotion,
    excess,
    finite_velocity,
    from_clip,
    from_reconstruction,
    joint_limit_violation,
    replay,
    summarise,
)

# A small stick figure (z up, metres): pelvis, two legs with feet, a spine, a head, two arms.
_FIGURE = {
    "root": (None, (0.0, 0.0, 1.0)),
    "lhipjoint": ("root", (0.0, 0.1, 0.95)),
    "lfemur": ("lhipjoint", (0.0, 0.1, 0.55)),
    "ltibia": ("lfemur", (0.0, 0.1, 0.12)),
    "lfoot": ("ltibia", (0.15, 0.1, 0.04)),
    "rhipjoint": ("root", (0.0, -0.1, 0.95)),
    "rfemur": ("rhipjoint", (0.0, -0.1, 0.55)),
    "rtibia": ("rfemur", (0.0, -0.1, 0.12)),
    "rfoot": ("rtibia", (0.15, -0.1, 0.04)),
    "lowerback": ("root", (0.0, 0.0, 1.2)),
    "thorax": ("lowerback", (0.0, 0.0, 1.45)),
    "head": ("thorax", (0.0, 0.0, 1.75)),
    "lhumerus": ("thorax", (0.0, 0.3, 1.45)),
    "lradius": ("lhumerus", (0.0, 0.7, 1.45)),
    "rhumerus": ("thorax", (0.0, -0.45, 1.45)),
    "rradius": ("rhumerus", (0.0, -0.75, 1.45)),
}
NAMES = tuple(_FIGURE)
PARENTS = np.array([-1 if p is None else NAMES.index(p) for p, _ in _FIGURE.values()])
POSE = np.array([xyz for _, xyz in _FIGURE.values()])


def figure(T=30, fps=30.0, velocity=(0.0, 0.0, 0.0)) -> PointMotion:
    """The figure translating at constant ``velocity`` [m/s]."""
    t = np.arange(T)[:, None, None] / fps
    pos = POSE[None] + t * np.asarray(velocity)
    return PointMotion(NAMES, PARENTS, pos, fps)


def seg_dist(p0, p1, q0, q1) -> float:
    """Distance between segments p0p1 and q0q1 by dense brute-force sampling and refinement."""
    s = np.linspace(0, 1, 401)
    P = p0 + s[:, None] * (p1 - p0)
    Q = q0 + s[:, None] * (q1 - q0)
    D = np.linalg.norm(P[:, None] - Q[None], axis=-1)
    i, j = np.unravel_index(np.argmin(D), D.shape)
    # refine around the best pair with a fine local grid
    si = np.clip(s[i] + np.linspace(-0.005, 0.005, 201), 0, 1)
    sj = np.clip(s[j] + np.linspace(-0.005, 0.005, 201), 0, 1)
    P = p0 + si[:, None] * (p1 - p0)
    Q = q0 + sj[:, None] * (q1 - q0)
    return float(np.linalg.norm(P[:, None] - Q[None], axis=-1).min())


def test_bone_poses_turn_z_onto_every_bone_direction():
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(5, len(NAMES), 3))
    pos[0, 1] = pos[0, 0] - np.array([0, 0, 0.3])  # a bone pointing straight down (-z)
    bones = bones_of(NAMES, PARENTS)
    centre, quat, half = bone_poses(bones, pos)
    w, x, y, z = np.moveaxis(quat, -1, 0)
    # third column of the rotation matrix of q = q applied to +z
    ez = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=-1)
    v = pos[:, bones.child] - pos[:, bones.parent]
    np.testing.assert_allclose(ez * 2 * half[..., None], v, atol=1e-12)
    np.testing.assert_allclose(centre, 0.5 * (pos[:, bones.child] + pos[:, bones.parent]))


def test_adjacent_pairs_are_bones_sharing_a_point():
    bones = bones_of(NAMES, PARENTS)
    bn = bones.bone_names
    one = {(bn[a], bn[b]) for a, b in adjacent_pairs(bones, 1)}
    assert ("lfemur", "ltibia") in one  # parent/child
    assert ("lhipjoint", "rhipjoint") in one  # siblings at the root
    assert ("lhumerus", "rhumerus") in one and ("head", "lhumerus") in one  # siblings at the thorax
    assert ("lfemur", "lfoot") not in one and ("lradius", "head") not in one
    two = {(bn[a], bn[b]) for a, b in adjacent_pairs(bones, 2)}
    assert one < two and ("lfemur", "lfoot") in two and ("lradius", "head") not in two


def test_clip_replayed_against_itself_has_zero_error_and_its_own_penetrations():
    m = figure(T=12, velocity=(0.5, 0.0, 0.0))
    pos = m.positions.copy()
    # from frame 5 the left forearm (same length) swings in towards the lower back
    elbow, hand = NAMES.index("lhumerus"), NAMES.index("lradius")
    u = np.array([0.03, -0.22, -0.30]) / np.linalg.norm([0.03, -0.22, -0.30])
    pos[5:, hand] = pos[5:, elbow] + np.linalg.norm(POSE[hand] - POSE[elbow]) * u
    m = PointMotion(NAMES, PARENTS, pos, 30.0)
    c = replay(m, m)
    assert c.mpjpe.max() == 0.0 and c.velocity_error.max() == 0.0
    assert c.bone_drift.max() < 1e-12
    # self-penetration against brute-force capsule geometry, pair by pair
    bones = bones_of(NAMES, PARENTS)
    scene = CollisionScene(bones)
    for t in (0, 8):
        expected = {}
        for a, b in scene.pairs:
            p, q = (
                pos[t, [bones.parent[a], bones.child[a]]],
                pos[t, [bones.parent[b], bones.child[b]]],
            )
            depth = bones.radius[a] + bones.radius[b] - seg_dist(p[0], p[1], q[0], q[1])
            if depth > 0:
                expected[(a, b)] = depth
        _, pen = scene.measure(pos[t])
        got = {(a, b): d for a, b, d in pen}
        assert got.keys() == expected.keys()
        for k in got:
            assert got[k] == pytest.approx(expected[k], abs=1e-5)
        assert c.self_count[t] == len(expected)
        assert c.self_depth[t] == pytest.approx(max(expected.values(), default=0.0), abs=1e-5)
    assert c.self_count[8] > 0 and c.self_count[0] == 0


def test_pose_pushed_5cm_into_the_floor_reports_5cm():
    bones = bones_of(NAMES, PARENTS)
    low = np.minimum(POSE[bones.parent, 2], POSE[bones.child, 2]) - bones.radius
    pos = POSE - [0, 0, low.min()]  # lowest capsule surface exactly on the floor
    frames = np.stack([pos, pos - [0, 0, 0.05], pos + [0, 0, 0.3]])
    c = replay(PointMotion(NAMES, PARENTS, frames, 30.0))
    assert c.floor_depth[0] == pytest.approx(0.0, abs=1e-9)
    assert c.floor_depth[1] == pytest.approx(0.05, abs=1e-9)
    assert c.floor_depth[2] == 0.0
    # every capsule whose lowest point is under the floor after the push is counted
    assert c.floor_bones[1] == int(np.sum(low - low.min() - 0.05 < 0))
    assert summarise(c)["floor_frames"] == 1


def test_foot_skating_is_the_horizontal_speed_of_feet_in_floor_contact():
    """The replay's foot contacts are sim.physics.contacts' (the one definition): soles resting
    on the floor plane are in contact, lifted 5 cm they are not; skating is the horizontal speed
    of a foot in contact."""
    from sim.physics.feet import sole

    v = (0.3, 0.4, 0.0)  # 0.5 m/s horizontally
    m = figure(T=10, velocity=v)
    s = sole(m.positions, NAMES)
    low = (s.centres[..., 2] - s.radius).min()
    pos = m.positions - [0, 0, low]  # the soles' lowest point on the floor z = 0
    c = replay(PointMotion(NAMES, PARENTS, pos, 30.0))
    assert c.foot_names == ("l", "r")
    assert c.foot_contact.any(axis=1).all()
    np.testing.assert_allclose(c.skate_speed, 0.5, rtol=1e-9)
    lifted = replay(PointMotion(NAMES, PARENTS, pos + [0, 0, 0.05], 30.0))
    assert not lifted.foot_contact.any() and lifted.skate_speed.max() == 0.0


def test_errors_against_a_reference_match_direct_computation():
    rng = np.random.default_rng(1)
    ref = figure(T=20, velocity=(1.0, 0.0, 0.0))
    noise = 0.01 * rng.normal(size=ref.positions.shape)
    rec = PointMotion(NAMES, PARENTS, ref.positions + noise, 30.0)
    c = replay(rec, ref)
    np.testing.assert_allclose(c.mpjpe, np.linalg.norm(noise, axis=-1).mean(axis=1))
    dv = finite_velocity(noise, 30.0)
    np.testing.assert_allclose(c.velocity_error, np.linalg.norm(dv, axis=-1).mean(axis=1))
    L = np.linalg.norm(ref.positions[0, 1:] - ref.positions[0, PARENTS[1:]], axis=-1)
    Lr = np.linalg.norm(rec.positions[:, 1:] - rec.positions[:, PARENTS[1:]], axis=-1)
    np.testing.assert_allclose(c.bone_drift, np.abs(Lr - L).max(axis=1), atol=1e-12)


def test_finite_velocity_is_exact_for_quadratic_motion_inside():
    t = np.arange(10)[:, None, None] / 30.0
    pos = np.broadcast_to(3 * t**2 + t, (10, 2, 3))
    expected = np.broadcast_to(6 * t + 1, pos.shape)
    np.testing.assert_allclose(finite_velocity(pos, 30.0)[1:-1], expected[1:-1])


def test_restrict_reparents_to_the_nearest_kept_ancestor():
    m = figure(T=2)
    r = m.restrict(["root", "lfemur", "lfoot", "thorax"])
    assert r.parents.tolist() == [-1, 0, 1, 0]
    np.testing.assert_array_equal(r.positions[:, 2], m.positions[:, NAMES.index("lfoot")])
    with pytest.raises(KeyError, match="known: root"):
        m.restrict(["root", "nose"])


def test_joint_limit_violation_measures_distance_outside_the_range():
    q = np.zeros((3, 9))
    q[1, 7] = 1.1  # above hi = 1.0 by 0.1
    q[2, 8] = -0.7  # below lo = -0.5 by 0.2
    worst, count = joint_limit_violation(q, ("a", "b"), {"a": (-1.0, 1.0), "b": (-0.5, 0.5)})
    np.testing.assert_allclose(worst, [0.0, 0.1, 0.2])
    assert count.tolist() == [0, 1, 1]


def test_excess_is_the_difference_to_the_baseline():
    m = figure(T=5)
    base = summarise(replay(m))
    sunk = PointMotion(NAMES, PARENTS, m.positions - [0, 0, 0.2], 30.0)
    s = summarise(replay(sunk, m))
    e = excess(s, base)
    assert e["floor_depth_max_mm"] == pytest.approx(
        s["floor_depth_max_mm"] - base["floor_depth_max_mm"]
    )
    assert e["floor_frames"] == 5 - base["floor_frames"]


def test_synthetic_clip_against_itself_and_hermite_keeps_bone_lengths():
    from sidql.keyframes.methods import select
    from sidql.keyframes.reconstructions import reconstruct
    from sim.motion.synthetic import synthetic_motion

    clip = synthetic_motion(2.0, seed=3)
    full = from_clip(clip)
    own = replay(full, full)
    assert own.mpjpe.max() == 0.0 and own.velocity_error.max() == 0.0
    assert own.bone_drift.max() < 1e-9
    rec = reconstruct(clip, select("uniform", clip, 6))
    c = replay(from_reconstruction(rec, clip.fps), full)
    assert c.bone_drift.max() < 1e-9  # spherical Hermite rebuilds points with the true lengths
    assert c.mpjpe[rec.keyframes].max() < 1e-9  # keyframes are reproduced exactly
    assert c.mpjpe.max() > 1e-4  # and in between it is a reconstruction, not a copy


def test_real_walk_hermite_reconstruction_keeps_bone_lengths(walk_clip):
    from sidql.keyframes.methods import select
    from sidql.keyframes.reconstructions import reconstruct

    clip = walk_clip.slice(0, 60)
    rec = reconstruct(clip, select("optimal", clip, 5))
    c = replay(from_reconstruction(rec, clip.fps), from_clip(clip))
    assert c.bone_drift.max() < 1e-9
    assert np.isfinite(c.floor_depth).all() and np.isfinite(c.skate_speed).all()


def test_one_scene_per_clip_gives_the_figures_of_a_fresh_scene_per_replay():
    from dataclasses import astuple

    from sidql.keyframes.methods import select
    from sidql.keyframes.reconstructions import rebuild
    from sidql.keyframes.spherical import POINTS
    from sim.motion.synthetic import synthetic_motion

    clip = synthetic_motion(1.0, seed=4)
    full = from_clip(clip)
    orig = full.restrict(POINTS)
    scene = CollisionScene.for_reference(orig)
    motions = [orig] + [
        from_reconstruction(rebuild(v, clip, select("uniform", clip, 5)), clip.fps)
        for v in ("hermite", "cartesian", "hermite")
    ]
    for m in motions:  # reused scene (state left by the previous motion) == a new one
        shared, fresh = astuple(replay(m, full, scene=scene)), astuple(replay(m, full))
        for a, b in zip(shared, fresh, strict=True):
            np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="other bones or floor settings"):
        replay(orig, full, scene=scene, hops=1)
    with pytest.raises(ValueError, match="other bones or floor settings"):
        replay(full, full, scene=scene)


def test_the_cartesian_baseline_stretches_bones_that_the_chart_keeps(walk_clip):
    """The ``cartesian`` method (uniform keyframes, points interpolated in xyz) is the one the
    bone-drift check exists for: under its own reconstruction bones change length by millimetres,
    under the spherical Hermite (same keyframes) they do not."""
    v = validate_clip(walk_clip.slice(0, 60), ["cartesian"], 5)
    runs = {r.label: r for r in v.runs}
    assert set(runs) == {"cartesian+hermite", "cartesian"}
    assert runs["cartesian+hermite"].summary["bone_drift_max_mm"] < 1e-6
    assert runs["cartesian"].summary["bone_drift_max_mm"] > 5.0
    np.testing.assert_array_equal(runs["cartesian"].keyframes, [0, 15, 30, 44, 59])


def test_a_hermite_row_another_method_already_shows_is_not_repeated(walk_clip):
    v = validate_clip(walk_clip.slice(0, 60), ["uniform", "cartesian", "pitch"], 5)
    assert [r.label for r in v.runs] == ["uniform", "cartesian", "pitch", "pitch+slerp"]
