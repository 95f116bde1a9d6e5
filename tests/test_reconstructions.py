"""The registry of reconstructions: every reconstruction's contract, one Q, and the cartesian one."""

from dataclasses import replace
from itertools import combinations

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.keyframes import methods, reconstructions
from sidql.keyframes.contact_pinning import LEGS
from sidql.keyframes.metrics import bone_vectors, q_error, q_from_angles
from sidql.keyframes.optimal import optimal_table
from sidql.keyframes.segment_costs import segment_cost_matrix
from sidql.keyframes.spherical import POINTS, chart, protocol_indices


@pytest.fixture(scope="module")
def clip():
    return smooth_clip(24, 30.0, seed=7)


@pytest.mark.parametrize("name", list(reconstructions.RECONSTRUCTIONS))
def test_every_reconstruction_reproduces_its_keyframes_with_finite_velocities(clip, name):
    keys = np.array([0, 5, 11, 23])
    rec = reconstructions.rebuild(name, clip, keys)
    idx = protocol_indices(clip)
    assert rec.names == POINTS and rec.reconstruction == name
    assert rec.positions.shape == rec.velocities.shape == (24, len(POINTS), 3)
    spec = reconstructions.get(name)
    kept = np.ones(len(POINTS), bool)  # contacts: the pinned legs may leave later keyframes
    if not spec.exact_keyframes:
        kept[[j for leg in LEGS for j in leg[1:]]] = False
    assert np.allclose(rec.positions[keys][:, kept], clip.positions[keys][:, idx[kept]], atol=1e-9)
    assert np.isfinite(rec.velocities).all()
    assert reconstructions.get(name).payload_bytes > reconstructions.INDEX_BYTES


def test_methods_declare_registered_reconstructions():
    assert methods.reconstruction_of("pitch") == "slerp"
    for name in methods.available():
        assert methods.reconstruction_of(name) in reconstructions.RECONSTRUCTIONS
    with pytest.raises(ValueError, match="unknown reconstruction"):
        reconstructions.get("nope")


def test_payloads_count_floats_of_what_each_reconstruction_sends():
    P = {n: v.payload_bytes - 1 for n, v in reconstructions.RECONSTRUCTIONS.items()}
    pose = 4 * (2 * 22 + 3)
    assert P["linear"] == P["catmull_rom"] == pose and P["hermite"] == 2 * pose
    assert P["slerp"] == 4 * (23 * 4 + 3) and P["cartesian"] == 4 * 23 * 3 * 2


@pytest.mark.parametrize(
    "name", [n for n, v in reconstructions.RECONSTRUCTIONS.items() if v.cost_matrix is not None]
)
def test_cost_kernel_and_optimum_are_q_error(clip, name):
    """One Q: the segment-cost matrix, the optimum table's q and its rebuilt angles all equal
    q_error (the definition), and the optimum is the brute-force minimum."""
    series = chart(clip)
    v = reconstructions.get(name)
    C = v.cost_matrix(series)
    N, M = series.n_frames, series.n_bones
    table = v.optimum(series, w_max=4)
    best = min(
        q_error(series, np.array([0, *inner, N - 1]), name)
        for inner in combinations(range(1, N - 1), 2)
    )
    keys = table.keyframes(4)
    assert table.q(4) == pytest.approx(best, rel=1e-9)
    assert table.q(4) == pytest.approx(q_error(series, keys, name), rel=1e-9)
    assert sum(C[a, b] for a, b in zip(keys[:-1], keys[1:], strict=True)) / (
        N * M
    ) == pytest.approx(q_error(series, keys, name), rel=1e-9)
    rec = v.rebuild(clip, keys, series)
    assert q_from_angles(series, rec.theta, rec.phi) == pytest.approx(q_error(series, keys, name))


def test_optimal_table_q_is_q_error_for_every_w(clip):
    series = chart(clip)
    table = optimal_table(series, "hermite")
    C = segment_cost_matrix(series, "hermite")
    assert C.shape == (24, 24)
    for W in range(2, 25):
        assert table.q(W) == pytest.approx(q_error(series, table.keyframes(W)), rel=1e-9, abs=1e-15)


def cubic_clip(N=40, fps=30.0, seed=3):
    """A clip whose protocol points move on cubic polynomials in xyz (exact velocities)."""
    base = smooth_clip(N, fps, seed)
    rng = np.random.default_rng(seed)
    t = (np.arange(N) / fps)[:, None, None]
    J = len(base.names)
    c = rng.normal(size=(4, J, 3))
    pos = c[0] + c[1] * t + c[2] * t**2 + c[3] * t**3
    vel = c[1] + 2 * c[2] * t + 3 * c[3] * t**2 + 0 * t
    return replace(base, positions=pos, velocities=vel)


def test_cartesian_recovers_motion_cubic_in_xyz_exactly():
    clip = cubic_clip()
    keys = np.array([0, 7, 19, 39])
    rec = reconstructions.rebuild("cartesian", clip, keys)
    idx = protocol_indices(clip)
    assert np.allclose(rec.positions, clip.positions[:, idx], atol=1e-10)
    assert np.allclose(rec.velocities, clip.velocities[:, idx], atol=1e-10)


def test_cartesian_bone_lengths_drift_on_rotating_bones_where_hermite_keeps_them(clip):
    keys = np.array([0, 12, 23])
    true_len = np.linalg.norm(
        bone_vectors(clip.positions[:, protocol_indices(clip)], chart(clip).parents), axis=-1
    )
    for name, drifts in (("cartesian", True), ("hermite", False)):
        rec = reconstructions.rebuild(name, clip, keys)
        L = np.linalg.norm(bone_vectors(rec.positions, rec.parents), axis=-1)
        drift = np.abs(L - true_len).max()
        assert (drift > 1e-3) if drifts else (drift < 1e-9), (name, drift)
