"""The Hamilton product over arrays: the formula term for term (the oracle: each component
stacked, as written in any textbook), bit for bit, for every broadcast of its operands."""

from __future__ import annotations

import numpy as np
import pytest

from sim.model import quaternion as quat


def _written_out(a, b):
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw],
                    axis=-1)  # fmt: skip


@pytest.mark.parametrize(
    "sa, sb",
    [((4,), (4,)), ((7, 4), (7, 4)), ((4,), (7, 4)), ((5, 1, 4), (1, 3, 4)), ((2, 3, 4), (4,))],
)
def test_the_product_is_the_formula_bit_for_bit(sa, sb):
    rng = np.random.default_rng(len(sa) * 10 + len(sb))
    a, b = rng.normal(size=sa), rng.normal(size=sb)
    got = quat.mul(a, b)
    assert got.shape == _written_out(a, b).shape
    assert np.array_equal(got, _written_out(a, b))


def test_lists_and_integers_are_taken_as_floats():
    assert np.array_equal(quat.mul([1, 0, 0, 0], [0, 1, 0, 0]), [0.0, 1.0, 0.0, 0.0])
    assert quat.mul([1, 0, 0, 0], [0, 1, 0, 0]).dtype == np.float64
