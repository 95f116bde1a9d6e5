"""Rotation helpers against an independent source: scipy's ``Rotation`` (test-only dependency)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim.model import quaternion as quat
from sim.model.rotations import (
    EULER_BREAK,
    Y_UP_TO_Z_UP,
    axis_rotation,
    continuous_euler,
    euler_angles_deg,
    euler_matrix,
    euler_twin,
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


def smooth_euler(T: int, k: int, seed: int) -> np.ndarray:
    """(T, k) smooth angles [rad] that leave the principal ranges: the middle one swings past
    +-90 deg (where a decomposition would flip to the twin), the others past +-180 deg."""
    t = np.linspace(0.0, 4.0, T)[:, None]
    rng = np.random.default_rng(seed)
    amp = np.array([2.2, 1.9, 3.4])[:k]
    return amp * np.sin(rng.uniform(0.6, 1.6, k) * t + rng.uniform(0, 2 * np.pi, k))


def with_flips(angles: np.ndarray, seed: int) -> np.ndarray:
    """``angles`` as a file might hold them: twins on some stretches (three axes), whole turns
    added to single angles of random frames."""
    rng = np.random.default_rng(seed)
    out = angles.copy()
    T, k = out.shape
    if k == 3:
        for start in rng.choice(T - 20, 4, replace=False):
            n = rng.integers(1, 20)
            out[start : start + n] = euler_twin(out[start : start + n])
        out[:3] = euler_twin(out[:3])  # the take may even start flipped
    out += 2 * np.pi * rng.integers(-3, 4, out.shape) * (rng.random(out.shape) < 0.15)
    return out


@pytest.mark.parametrize("order", ORDERS)
def test_the_euler_twin_is_the_same_rotation(order):
    a = np.random.default_rng(31 + ORDERS.index(order)).uniform(-4, 4, (50, 3))
    np.testing.assert_allclose(
        euler_matrix(np.degrees(euler_twin(a)), order), euler_matrix(np.degrees(a), order),
        atol=1e-12,
    )  # fmt: skip
    np.testing.assert_allclose(euler_twin(euler_twin(a)), a + [2 * np.pi, 0, 2 * np.pi])


@pytest.mark.parametrize("order", ORDERS + ["X", "ZX", "YZ"])
def test_continuous_euler_recovers_a_smooth_motion_given_with_flips(order):
    k = len(order)
    truth = smooth_euler(400, k, seed=ORDERS.index(order) if k == 3 else k)
    flipped = with_flips(truth, seed=7 + k)
    assert np.abs(np.diff(flipped, axis=0)).max() > 3.0  # the file does jump
    out = continuous_euler(flipped, order)
    np.testing.assert_allclose(out, truth, atol=1e-9)  # exact recovery
    assert np.abs(np.diff(out, axis=0)).max() < 0.1  # continuous
    np.testing.assert_allclose(  # the same rotations, frame by frame
        euler_matrix(np.degrees(out), order), euler_matrix(np.degrees(flipped), order),
        atol=1e-12,
    )  # fmt: skip
    unflipped = np.all(np.abs(flipped - truth) < 1e-9, axis=1)
    np.testing.assert_array_equal(out[unflipped], flipped[unflipped])  # untouched exactly


def test_continuous_euler_leaves_smooth_angles_alone_and_cuts_at_a_real_jump():
    a = smooth_euler(200, 3, seed=3)
    a[:, 1] *= 0.4  # inside +-90 deg: no twin nearer than the frame itself
    np.testing.assert_array_equal(continuous_euler(a, "XYZ"), a)
    # A rotation that jumps by a half turn (a solver's flip, not a change of representation):
    # nothing can make it continuous, and each side keeps the file's own numbers.
    jumped = a.copy()
    jumped[120:, 0] += np.pi
    assert np.abs(np.diff(jumped, axis=0)).max() > EULER_BREAK
    np.testing.assert_array_equal(continuous_euler(jumped, "XYZ"), jumped)
    # Twin stretches after the jump still come back.
    flipped = jumped.copy()
    flipped[150:160] = euler_twin(flipped[150:160])
    np.testing.assert_allclose(continuous_euler(flipped, "XYZ"), jumped, atol=1e-12)


def test_continuous_euler_shapes():
    assert continuous_euler(np.zeros((0, 3)), "XYZ").shape == (0, 3)
    np.testing.assert_array_equal(continuous_euler(np.ones((1, 2)), "XZ"), np.ones((1, 2)))
    with pytest.raises(ValueError, match=r"\(T, 3\)"):
        continuous_euler(np.zeros((4, 2)), "XYZ")
