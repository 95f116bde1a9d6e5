"""The optimum screened by the single-precision matrix: its lower bounds hold, and it keeps the
optimum of the full float64 matrix (the banded route and the full table as oracles)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.keyframes.optimal import (
    SCREEN_SHARE,
    _banded_costs,
    _dp,
    _screenable,
    _screened_costs,
    clip_optimal_table,
    single_lower_bounds,
)
from sidql.keyframes.segment_costs import TURN, clip_cost_matrix, clip_stacked
from sidql.keyframes.single_costs import single_costs, weights_of


def _clips(walk_clip):
    other = smooth_clip(N=40, seed=5)
    return [smooth_clip(N=30, seed=2), walk_clip.slice(0, 60), walk_clip.slice(50, 86), other]


def _walk_back(C, W):
    P = _dp(C, W)[1]
    out = [C.shape[0] - 1]
    for w in range(W, 1, -1):
        out.append(int(P[w, out[-1]]))
    return out[::-1]


def test_single_lower_bounds_are_below_the_float64_costs_and_close(walk_clip):
    for clip in _clips(walk_clip):
        X, R = clip_stacked(clip)
        full = clip_cost_matrix(clip) * TURN
        lb = single_lower_bounds(X, R, single_costs(X, R))
        upper = np.triu(np.ones_like(full, bool), 2)
        assert np.all(lb[upper] <= full[upper]) and np.all(lb[~upper] == 0)
        assert np.all(lb >= 0)
        big = upper & (full > 1e-2 * full.max())  # where it screens: tight, not just valid
        assert np.all(lb[big] >= full[big] * (1 - 1e-2))


def test_screened_costs_keep_the_full_optimum_for_every_count(walk_clip):
    for clip in _clips(walk_clip):
        X, R = clip_stacked(clip)
        assert _screenable(X, R)
        full = clip_cost_matrix(clip)
        table = clip_optimal_table(clip, w_max=clip.n_frames)
        H = weights_of(clip.n_frames)
        for W in range(2, clip.n_frames + 1):
            C = _screened_costs(X, R, H, W)
            kept = np.isfinite(C)
            np.testing.assert_allclose(C[kept], full[kept], rtol=1e-12, atol=0)
            keys = _walk_back(C, W)
            assert keys == table.keyframes(W).tolist(), W
            assert keys == _walk_back(_banded_costs(X, R, False, W), W), W
        assert not np.isfinite(_screened_costs(X, R, H, 5)).all()  # it rules entries out


def test_screened_costs_of_a_still_clip_break_ties_as_the_table(walk_clip):
    clip = walk_clip.slice(0, 20)
    still = replace(clip, positions=np.repeat(clip.positions[:1], 20, 0),
                    velocities=np.zeros_like(clip.velocities))  # fmt: skip
    X, R = clip_stacked(still)
    table = clip_optimal_table(still)
    for W in (2, 3, 4, 20):
        assert (
            _walk_back(_screened_costs(X, R, weights_of(20), W), W) == table.keyframes(W).tolist()
        )


def test_the_screen_refuses_angles_too_large_for_single_precision(walk_clip):
    X, R = clip_stacked(walk_clip.slice(0, 20))
    X = X.copy()
    X[5, 0] += 2 * np.pi * 2.0**21  # a term beyond float32's exact rounding to integers
    assert not _screenable(X, R)


@pytest.mark.parametrize("W", [3, 5, 9])
def test_the_optimal_method_takes_the_screen_for_few_keyframes(W, walk_clip):
    from sidql.keyframes.methods import select

    clip = walk_clip.slice(0, 60)
    N = clip.n_frames
    band = min(N, int(np.ceil(1.5 * (N - 1) / (W - 1))) + 1)
    assert band * band * SCREEN_SHARE >= N * N  # the screen's route, W <= 9 on 60 frames
    assert np.array_equal(
        select("optimal", clip, W), clip_optimal_table(clip, w_max=W).keyframes(W)
    )
