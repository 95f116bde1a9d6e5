"""The position coding's searches work out each coded plan's estimated size once: the same
floats, so the same choices and bytes, as working it out every time it is asked for."""

from __future__ import annotations

import numpy as np
import pytest
from keyframe_synth import smooth_clip

import sidql.codec.position_coding as pc
from sidql.codec.encode import encode_series
from sidql.codec.position_format import estimated_block
from sidql.keyframes.spherical import chart


@pytest.fixture(scope="module")
def series():
    return chart(smooth_clip(N=240, fps=30.0, seed=11))


def _every_time(self, keys, codes):  # the oracle: the size model asked afresh on every call
    return self.header + estimated_block(keys, codes)


@pytest.mark.parametrize("target", [{"rate": 400.0}, {"rate": 1500.0}, {"max_error": 1.0}])
def test_a_remembered_size_changes_no_choice_and_no_byte(series, target, monkeypatch):
    memo = encode_series(series, **target)
    monkeypatch.setattr(pc._PositionSearch, "estimate", _every_time)
    fresh = encode_series(series, **target)
    assert memo.data == fresh.data and memo.candidates == fresh.candidates


def test_each_coded_plan_is_sized_once_per_search(series, monkeypatch):
    sized = []

    def counted(keys, codes):
        sized.append((id(codes), codes.tobytes(), keys.tobytes()))
        return estimated_block(keys, codes)

    monkeypatch.setattr(pc, "estimated_block", counted)
    monkeypatch.setattr(pc.os, "cpu_count", lambda: 1)  # one search after the other
    asked = []
    plain = pc._PositionSearch.estimate

    def asking(self, keys, codes):
        asked.append(self)
        return plain(self, keys, codes)

    monkeypatch.setattr(pc._PositionSearch, "estimate", asking)
    encode_series(series, rate=800.0)
    contents = [(c, k) for _, c, k in sized]
    searches = len(set(map(id, asked)))
    assert len(asked) > len(sized)  # asked again about plans already sized
    # a plan is sized again only by the other reconstruction's search, or after it was dropped
    assert len(sized) <= searches * len(set(contents))


def test_a_new_plan_in_a_dropped_plan_s_place_is_sized_afresh(series):
    search = pc._PositionSearch(
        series, "linear", 30, pc._builder(series, "linear", 30.0, bytes(8))
    )  # fmt: skip
    keys, _, codes, _ = search.code(pc._LAM_LO, 1e-3)
    first = search.estimate(keys, codes)
    assert first == search.header + estimated_block(keys, codes)
    other = np.zeros_like(codes)  # other contents, maybe at the address the old ones had
    (remembered,) = search.sized.values()
    search.sized[id(other)] = remembered  # as if the plan had been freed and replaced
    assert search.estimate(keys, other) == search.header + estimated_block(keys, other)
