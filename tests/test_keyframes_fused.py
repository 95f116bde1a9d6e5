"""The optimum's chart and costs in one compiled pass give the two-step results (to the last bit
of a fastmath kernel) and the same keyframes."""

from __future__ import annotations

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.keyframes.methods import select
from sidql.keyframes.optimal import clip_optimal_table, optimal_table
from sidql.keyframes.segment_costs import clip_cost_matrix, segment_cost_matrix
from sidql.keyframes.spherical import chart


@pytest.mark.parametrize("reconstruction", ["hermite", "linear"])
def test_one_pass_costs_equal_chart_then_costs(reconstruction, walk_clip):
    for clip in (smooth_clip(N=60, seed=4), walk_clip.slice(0, 60)):
        # the same numbers up to the last bit: two fastmath kernels compiled apart (one fresh,
        # one from numba's disk cache) may round differently
        fused = clip_cost_matrix(clip, reconstruction)
        two_step = segment_cost_matrix(chart(clip), reconstruction)
        np.testing.assert_allclose(fused, two_step, rtol=1e-12, atol=0)
        a = clip_optimal_table(clip, reconstruction, w_max=20)
        b = optimal_table(chart(clip), reconstruction, w_max=20)
        np.testing.assert_allclose(a.cost, b.cost, rtol=1e-12, atol=0)
        assert np.array_equal(a.pointers, b.pointers)


def test_optimal_method_uses_it_and_keeps_its_answers(walk_clip):
    clip = walk_clip.slice(0, 60)
    for W in (5, 12):
        keys = select("optimal", clip, W)
        assert np.array_equal(keys, optimal_table(chart(clip), "hermite", W).keyframes(W))


def test_one_pass_refuses_the_non_separable_reconstruction():
    with pytest.raises(ValueError, match="catmull_rom"):
        clip_cost_matrix(smooth_clip(N=20), "catmull_rom")


@pytest.mark.parametrize("reconstruction", ["hermite", "linear"])
def test_optimum_costs_keep_the_optimum_of_the_full_matrix(reconstruction, walk_clip):
    from sidql.keyframes.optimal import clip_optimal_keyframes, optimum_cost_matrix

    for clip in (smooth_clip(N=30, seed=2), walk_clip.slice(0, 60), walk_clip.slice(50, 86)):
        full = clip_cost_matrix(clip, reconstruction)
        table = clip_optimal_table(clip, reconstruction)
        pruned_any = False
        for W in range(2, clip.n_frames + 1):
            C = optimum_cost_matrix(clip, W, reconstruction)
            kept = np.isfinite(C)
            # the entries kept are the same numbers, up to the last bit: two fastmath kernels
            # compiled apart (one fresh, one from numba's disk cache) may round differently
            np.testing.assert_allclose(C[kept], full[kept], rtol=1e-12, atol=0)
            pruned_any |= not kept.all()
            keys = clip_optimal_keyframes(clip, W, reconstruction)
            assert np.array_equal(keys, table.keyframes(W)), W
            assert full[keys[:-1], keys[1:]].sum() == pytest.approx(table.cost[W], rel=1e-12)
        assert pruned_any  # the pruning did something on real motion


def test_optimum_costs_of_a_still_clip_and_bad_counts(walk_clip):
    from dataclasses import replace

    from sidql.keyframes.optimal import clip_optimal_keyframes, optimum_cost_matrix

    clip = walk_clip.slice(0, 20)
    still = replace(clip, positions=np.repeat(clip.positions[:1], 20, 0),
                    velocities=np.zeros_like(clip.velocities))  # fmt: skip
    for c in (still, clip):
        for W in (2, 4, 20):
            assert np.array_equal(clip_optimal_keyframes(c, W), clip_optimal_table(c).keyframes(W))
    for W in (1, 21):
        with pytest.raises(ValueError, match="W must be"):
            optimum_cost_matrix(clip, W)


def test_the_compiled_gather_gives_the_chart_and_refuses_what_chart_refuses(walk_clip):
    from dataclasses import fields, replace

    from sidql.keyframes.segment_costs import clip_stacked, stacked
    from sim.errors import MotionDataError

    for clip in (smooth_clip(N=40, seed=3), walk_clip.slice(10, 70)):
        X, R = clip_stacked(clip)
        want_x, want_r = stacked(chart(clip))
        assert np.array_equal(X, want_x) and np.array_equal(R, want_r)
    clip = walk_clip.slice(0, 30)
    bad = clip.positions.copy()
    bad[7, clip.names.index("lfemur"), 1] = np.nan
    with pytest.raises(MotionDataError, match="non-finite"):
        clip_stacked(replace(clip, positions=bad))
    with pytest.raises(MotionDataError, match="non-finite"):
        chart(replace(clip, positions=bad))
    keep = [i for i, n in enumerate(clip.names) if n != "lhumerus"]
    parents = np.array([keep.index(p) if p in keep else -1 for p in clip.parents[keep]])
    J = len(clip.names)
    per_point = {f.name: getattr(clip, f.name)[:, keep] for f in fields(clip)
                 if isinstance(getattr(clip, f.name), np.ndarray)
                 and getattr(clip, f.name).ndim >= 2 and getattr(clip, f.name).shape[1] == J}  # fmt: skip
    lacking = replace(clip, names=tuple(clip.names[i] for i in keep), parents=parents, **per_point)
    for fn in (clip_stacked, chart):
        with pytest.raises(MotionDataError, match="lhumerus"):
            fn(lacking)
