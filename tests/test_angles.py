"""The one angle wrap: into [-pi, pi), the same from numpy and from numba kernels."""

import numba
import numpy as np
import pytest

from sim.model.angles import wrap_angle


def test_wrap_lands_in_the_half_open_interval_on_the_same_point_of_the_circle():
    a = np.array([np.pi, -np.pi, 3 * np.pi, 0.1, -0.1 - 4 * np.pi, 7.0, -7.0, 1e6, 0.0])
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    assert np.allclose(np.cos(w), np.cos(a)) and np.allclose(np.sin(w), np.sin(a))
    assert w[0] == pytest.approx(-np.pi) and w[1] == pytest.approx(-np.pi)
    assert w[3] == 0.1 and w[-1] == 0.0  # inside: untouched


def test_shapes_and_scalars():
    a = np.random.default_rng(0).uniform(-20, 20, (4, 5, 3))
    w = wrap_angle(a)
    assert w.shape == a.shape and w is not a
    ref = np.angle(np.exp(1j * a))  # an independent wrap (complex argument, (-pi, pi])
    assert np.allclose(np.abs(w), np.abs(ref), atol=1e-12)
    assert wrap_angle(2.5 * np.pi) == pytest.approx(0.5 * np.pi)


@numba.njit
def _sum_abs_wrapped(x):
    total = 0.0
    for v in x:
        total += abs(wrap_angle(v))
    return total


def test_kernels_inline_the_same_wrap():
    x = np.random.default_rng(1).uniform(-30, 30, 1000)
    assert _sum_abs_wrapped(x) == pytest.approx(np.abs(wrap_angle(x)).sum(), rel=1e-14)
