"""Rotation helpers against an independent source: scipy's ``Rotation`` (test-only dependency)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim.model import quaternion as quat
from sim.model.rotations import (
    Y_UP_TO_Z_UP,
    axis_rotation,
    euler_angles_deg,
    euler_matrix,
    y_up_to_z_up,
    z_up_to_y_up,
)

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


@pytest.mark.parametrize("order", ORDERS)
def test_euler_matrix_applies_the_first_axis_first_like_scipy_extrinsic(order):
    angles = np.random.default_rng(len(order) + ORDERS.index(order)).uniform(-180, 180, (7, 5, 3))
    expect = Rotation.from_euler(order.lower(), angles.reshape(-1, 3), degrees=True).as_matrix()
    np.testing.assert_allclose(euler_matrix(angles, order), expect.reshape(7, 5, 3, 3), atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_angles_invert_euler_matrix(order):
    rng = np.random.default_rng(20 + ORDERS.index(order))
    angles = rng.uniform(-180, 180, (50, 3))
    angles[:, 1] = rng.uniform(
        -89, 89, 50
    )  # the middle angle's own range: the decomposition is unique
    np.testing.assert_allclose(
        euler_angles_deg(euler_matrix(angles, order), order), angles, atol=1e-9
    )


@pytest.mark.parametrize("order", ["X", "Z", "XZ", "YX"])
def test_euler_matrix_with_fewer_axes(order):
    angles = np.random.default_rng(9).uniform(-90, 90, (4, len(order)))
    expect = Rotation.from_euler(order.lower(), angles, degrees=True).as_matrix()
    np.testing.assert_allclose(euler_matrix(angles, order), expect, atol=1e-12)


@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_axis_rotation_is_the_right_handed_rotation(axis):
    a = np.linspace(-3.0, 3.0, 11)
    expect = Rotation.from_euler(axis.lower(), a[:, None]).as_matrix()
    np.testing.assert_allclose(axis_rotation(axis, a), expect, atol=1e-12)


def test_the_axis_change_is_plus_90_degrees_about_x_and_its_functions_agree():
    np.testing.assert_allclose(
        Y_UP_TO_Z_UP, Rotation.from_euler("x", 90, degrees=True).as_matrix(), atol=1e-15
    )
    v = np.random.default_rng(3).normal(size=(6, 4, 3))
    np.testing.assert_array_equal(y_up_to_z_up(v), v @ Y_UP_TO_Z_UP.T)
    np.testing.assert_array_equal(z_up_to_y_up(v), v @ Y_UP_TO_Z_UP)
    np.testing.assert_array_equal(z_up_to_y_up(y_up_to_z_up(v)), v)
    assert y_up_to_z_up([0.0, 1.0, 0.0]).tolist() == [0.0, 0.0, 1.0]  # up stays up


def test_quaternion_matrices_match_scipy():
    q = np.random.default_rng(4).normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    R = Rotation.from_quat(np.roll(q, -1, axis=-1)).as_matrix()  # scipy: xyzw
    np.testing.assert_allclose(quat.to_matrix(q), R, atol=1e-12)
    back = quat.from_matrix(R)
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=-1)), 1.0, atol=1e-12)
