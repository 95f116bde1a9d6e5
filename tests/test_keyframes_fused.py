"""The optimum's chart and costs in one compiled pass give exactly the two-step results."""

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
        fused = clip_cost_matrix(clip, reconstruction)
        assert np.array_equal(fused, segment_cost_matrix(chart(clip), reconstruction))
        a = clip_optimal_table(clip, reconstruction, w_max=20)
        b = optimal_table(chart(clip), reconstruction, w_max=20)
        assert np.array_equal(a.cost, b.cost) and np.array_equal(a.pointers, b.pointers)


def test_optimal_method_uses_it_and_keeps_its_answers(walk_clip):
    clip = walk_clip.slice(0, 60)
    for W in (5, 12):
        keys = select("optimal", clip, W)
        assert np.array_equal(keys, optimal_table(chart(clip), "hermite", W).keyframes(W))


def test_one_pass_refuses_the_non_separable_reconstruction():
    with pytest.raises(ValueError, match="catmull_rom"):
        clip_cost_matrix(smooth_clip(N=20), "catmull_rom")
