"""Li et al. 2015: quaternion distances, the threshold rule, slerp reconstruction by FK."""

import numpy as np
import pytest
from keyframe_synth import assert_velocities_match_differences, smooth_clip
from scipy.spatial.transform import Rotation

from sidql.keyframes import pitch, reconstructions
from sidql.keyframes.metrics import bone_vectors
from sidql.keyframes.spherical import POINTS
from sim.model import quaternion as quat


def random_quats(rng, shape):
    q = rng.normal(size=shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def angle(a, b):
    """Rotation angle [rad] from a to b by scipy (independent of sim.model.quaternion)."""
    a, b = np.broadcast_arrays(a, b)
    ra = Rotation.from_quat(np.roll(a, -1, axis=-1).reshape(-1, 4))  # scipy: xyzw
    rb = Rotation.from_quat(np.roll(b, -1, axis=-1).reshape(-1, 4))
    return (ra.inv() * rb).magnitude().reshape(a.shape[:-1])


def test_pitch_distance_is_the_summed_rotation_angle_and_ignores_sign():
    rng = np.random.default_rng(0)
    local = random_quats(rng, (6, 23))
    flipped = local * rng.choice([-1.0, 1.0], size=(6, 23, 1))
    expect = angle(local[:, None], local[None]).sum(-1)
    assert np.allclose(pitch.pitch_distances(local), expect, atol=1e-6)
    assert np.allclose(pitch.pitch_distances(flipped), expect, atol=1e-6)


def test_slerp_takes_the_shorter_arc_at_constant_rate():
    rng = np.random.default_rng(1)
    a, b = random_quats(rng, (2, 20))
    s = np.linspace(0, 1, 11)
    path = quat.slerp(a[:, None], b[:, None], s[None, :])
    total = angle(a, b)
    assert np.allclose(angle(a[:, None], path), total[:, None] * s[None, :])
    assert np.allclose(angle(path[:, -1], b), 0, atol=1e-7)


def brute_threshold(D, tau):
    keys = [0]
    for n in range(1, len(D)):
        if D[n, keys[-1]] > tau:
            keys.append(n)
    if keys[-1] != len(D) - 1:
        keys.append(len(D) - 1)
    return keys


def test_threshold_rule_and_count_search():
    clip = smooth_clip(60, 30.0, seed=31)
    _, local, _ = pitch.protocol_rotations(clip)
    D = pitch.pitch_distances(local)
    assert np.allclose(D, D.T) and np.allclose(np.diag(D), 0, atol=1e-6)
    for tau in np.quantile(D, [0.05, 0.2, 0.5]):
        assert pitch.threshold_keyframes(D, tau).tolist() == brute_threshold(D, tau)
    for W in (2, 4, 9, 17, 60):
        k, tau = pitch.keyframes_for_count(D, W)
        assert len(k) == W and k[0] == 0 and k[-1] == 59 and np.all(np.diff(k) > 0)
        if len(brute_threshold(D, tau)) == W:  # exact count reached: it is the threshold rule
            assert k.tolist() == brute_threshold(D, tau)


@pytest.mark.parametrize("source", ["synthetic", "real walk"])
def test_forward_kinematics_rebuilds_synthetic_and_real_clips(source, request):
    if source == "real walk":
        clip = request.getfixturevalue("walk_clip").slice(0, 60)
    else:
        clip = smooth_clip(30, 30.0, seed=32)
    pos, local, parents = pitch.protocol_rotations(clip)
    rig, worst = pitch.fit_rig(pos, local, parents)
    assert worst < 1e-9
    P, _ = pitch.forward(rig, pos[:, 0], local)
    assert np.allclose(P, pos, atol=1e-9)


def slerp_motion(keys, N, fps, seed):
    """A clip whose local rotations are slerps between keyframes and root linear: pitch's own
    interpolant, built through sidql's forward kinematics on a real-looking rig."""
    base = smooth_clip(N, fps, seed=seed)
    pos, local, parents = pitch.protocol_rotations(base)
    rig, _ = pitch.fit_rig(pos, local, parents)
    rng = np.random.default_rng(seed)
    kq = random_quats(rng, (len(keys), 23))
    kr = rng.normal(size=(len(keys), 3))
    n = np.arange(N)
    seg = np.clip(np.searchsorted(keys, n, side="right") - 1, 0, len(keys) - 2)
    s = (n - keys[seg]) / (keys[seg + 1] - keys[seg])
    loc = quat.slerp(kq[seg], kq[seg + 1], s[:, None])
    root = kr[seg] + s[:, None] * (kr[seg + 1] - kr[seg])
    P, _ = pitch.forward(rig, root, loc)
    from dataclasses import replace

    return replace(base, positions=P, velocities=np.zeros_like(P), rotations=loc)


def test_pitch_reconstruction_is_exact_on_slerp_motion():
    keys = np.array([0, 9, 25, 59])
    clip = slerp_motion(keys, 60, 30.0, seed=33)
    rec = reconstructions.rebuild("slerp", clip, keys)
    assert np.allclose(rec.positions, clip.positions, atol=1e-9)
    assert pitch.pitch_error(clip.positions, rec.positions) == pytest.approx(0.0, abs=1e-9)


def test_pitch_reconstruction_keeps_lengths_keyframes_and_velocity_is_the_derivative():
    N = 301
    clip = smooth_clip(N, 300.0, seed=34)
    keys = np.array([0, 80, 200, 300])
    rec = reconstructions.rebuild("slerp", clip, keys)
    assert rec.names == POINTS and rec.reconstruction == "slerp"
    assert np.allclose(rec.positions[keys], clip.positions[keys], atol=1e-12)
    L = np.linalg.norm(bone_vectors(rec.positions, rec.parents), axis=-1)
    L0 = np.linalg.norm(bone_vectors(clip.positions, rec.parents), axis=-1)
    assert np.abs(L - L0).max() < 1e-9
    assert_velocities_match_differences(rec, keys)
    assert pitch.pitch_error(clip.positions, rec.positions) > 0


def test_count_search_tops_up_when_no_threshold_gives_w():
    """All distances equal: thresholds give 4 or 2 keyframes, never 3; the fall-back adds the
    frame farthest from its preceding keyframe (the first on ties)."""
    D = np.ones((4, 4)) - np.eye(4)
    assert sorted({len(pitch.threshold_keyframes(D, t)) for t in (-1.0, 0.5, 1.0, 2.0)}) == [2, 4]
    k, tau = pitch.keyframes_for_count(D, 3)
    assert k.tolist() == [0, 1, 3]
