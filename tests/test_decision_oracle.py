"""The fast decision paths (compiled segment costs, the pruned optimum, the compiled policy on
single-precision costs) take the same decisions as plain reference code on real clips: segment
costs summed in numpy frame by frame, the full programme over them, and the torch network."""

from __future__ import annotations

import numpy as np
import pytest

from sidql.keyframes import methods
from sidql.keyframes.optimal import solve
from sidql.keyframes.segment_costs import clip_cost_matrix, stacked
from sidql.keyframes.spherical import M_BONES, chart


def numpy_costs(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(N, N) Hermite segment costs [rad] of stacked angles X (N, D) [rad] and rates R (N, D)
    [rad/frame]: per segment, the rebuilt frames' |angle error| wrapped by ``remainder``,
    summed over frames and channels (no code shared with the compiled kernels)."""
    N = len(X)
    C = np.zeros((N, N))
    for i in range(N - 2):
        for j in range(i + 2, N):
            L = j - i
            s = (np.arange(i + 1, j) - i)[:, None] / L
            h00, h01 = 2 * s**3 - 3 * s**2 + 1, -2 * s**3 + 3 * s**2
            h10, h11 = s**3 - 2 * s**2 + s, s**3 - s**2
            curve = h00 * X[i] + h01 * X[j] + L * (h10 * R[i] + h11 * R[j])
            err = np.remainder(curve - X[i + 1 : j] + np.pi, 2 * np.pi) - np.pi
            C[i, j] = np.abs(err).sum()
    return C


@pytest.fixture(scope="module")
def clips(cmu_dir):
    from sim.motion.ingest import load_clips

    out = []
    for trial in ("02/02_01", "16/16_24", "35/35_01"):
        amc = cmu_dir / f"{trial}.amc"
        if amc.exists():
            subject = trial.split("/")[0]
            out += [c for c in load_clips(cmu_dir / subject / f"{subject}.asf", amc)[:2]]
    assert len(out) >= 2
    return [c for c in out if c.n_frames == 60]


def test_compiled_segment_costs_equal_a_numpy_sum_on_real_clips(clips):
    for clip in clips:
        want = numpy_costs(*stacked(chart(clip)))
        np.testing.assert_allclose(clip_cost_matrix(clip), want, rtol=1e-11, atol=1e-11)


def test_the_optimum_keyframes_equal_the_full_programme_over_numpy_costs(clips):
    for clip in clips:
        table = solve(numpy_costs(*stacked(chart(clip))), M_BONES)
        for W in (2, 3, 5, 8, 15, 30, 59):
            assert np.array_equal(methods.select("optimal", clip, W), table.keyframes(W)), W


def test_the_dqn_method_decides_as_the_torch_network_over_numpy_costs(clips):
    from sidql.learning.policy import load_policy
    from sidql.learning.tasks import clip_features

    policy = load_policy()
    for clip in clips:
        series = chart(clip)
        feats = clip_features(series)[None].astype(np.float32)
        costs = numpy_costs(*stacked(series))[None]
        for W in (2, 3, 4, 5, 8, 12, 15, 20, 30, 45, 59):
            want = policy.decide_torch(feats, costs, W)[0]
            assert np.array_equal(methods.select("dqn", clip, W), want), W


def test_single_precision_costs_are_the_numpy_sum_to_a_few_parts_in_a_million(clips):
    from sidql.keyframes.single_costs import single_costs

    for clip in clips:
        X, R = stacked(chart(clip))
        want = numpy_costs(X, R)
        got = single_costs(X, R)
        assert got.dtype == np.float64 and got.shape == want.shape
        assert np.array_equal(got == 0, want == 0)  # the same entries are empty
        np.testing.assert_allclose(got, want, rtol=2e-6, atol=0)
        assert not np.array_equal(got, want)  # it is single precision (else this test is moot)


def test_compiled_features_equal_the_numpy_formula_bit_for_bit(clips):
    """The policy's inputs: theta, phi minus its clip mean, the rates, as float32 (numpy here)."""
    from sidql.learning.tasks import stacked_features

    for clip in clips:
        X, R = stacked(chart(clip))
        m = X.shape[1] // 2
        phi = X[:, m:] - X[:, m:].mean(axis=0, keepdims=True)
        want = np.concatenate([X[:, :m], phi, R], axis=1).astype(np.float32)
        got = stacked_features(X, R)
        assert got.dtype == np.float32
        assert np.array_equal(got.view(np.int32), want.view(np.int32))
