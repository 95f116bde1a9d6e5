"""A later piece of a BVH file converts its motion alone (``motion_like``): the arrays the whole
conversion (``to_acclaim``, the oracle) gives for those frames, whatever the up axis and unit."""

from __future__ import annotations

import numpy as np
import pytest

from sim.bvh.convert import motion_like, to_acclaim
from sim.bvh.reader import parse_bvh
from sim.bvh.records import Bvh
from sim.bvh.stream import iter_take
from sim.errors import MotionDataError


def _frames(bvh: Bvh, a: int, b: int) -> Bvh:
    return Bvh(bvh.path, bvh.joints, bvh.frame_time, bvh.values[a:b], bvh.motion_line)


@pytest.mark.parametrize("unit, up", [(None, "y"), ("cm", "z"), ("in", "y")])
def test_a_later_pieces_motion_is_the_whole_conversions(walk_bvh, unit, up):
    whole = parse_bvh(walk_bvh)
    first = to_acclaim(_frames(whole, 0, 300), unit=unit, up=up)
    later = _frames(whole, 300, 1000)
    oracle = to_acclaim(later, unit=first.unit, up=up).motion
    got = motion_like(later, first)
    assert np.array_equal(got.root, oracle.root) and list(got.angles) == list(oracle.angles)
    assert all(np.array_equal(got.angles[k], oracle.angles[k]) for k in oracle.angles)
    takes = list(iter_take(walk_bvh, unit=unit, up=up))
    joined = np.concatenate([t.motion.root for t in takes])
    assert np.array_equal(joined, to_acclaim(whole, unit=unit, up=up).motion.root)


def test_a_later_piece_flying_off_is_refused_as_the_whole_conversion_refuses_it(walk_bvh):
    whole = parse_bvh(walk_bvh)
    first = to_acclaim(_frames(whole, 0, 300))
    far = _frames(whole, 300, 400)
    far.values[50, 0] = 1e12  # the root's Xposition, beyond MAX_METRES in any unit
    with pytest.raises(MotionDataError) as oracle:
        to_acclaim(far)
    with pytest.raises(MotionDataError) as got:
        motion_like(far, first)
    assert str(got.value) == str(oracle.value)
