"""Feet the simulated body can stand on (soles by default; ``stance_ankles=True`` opt-in):
a sole box from behind the ankle to the ball, ankles stiff enough for a standing body, soles
laid flat in the reference, a floor support whose centre of pressure balances the body."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.feedforward import reference_feedforward
from sim.simulate.model import (
    MIN_DEFLECTION,
    SOLE_HEEL,
    STANCE_MARGIN,
    human_torque_limit,
    sim_model,
    stance_stiffness,
)
from sim.simulate.reference import flat_soles, on_floor, trial_qpos


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton(), soles=True, stance_ankles=True)


@pytest.fixture(scope="module")
def still_pose(cmu_dir, model):
    """2 s of one held frame: 60_01 frame 108, standing still on both feet (root and feet
    slower than 5 cm/s) with the soles 15 and 11 deg toe-up in the captured pose."""
    q = trial_qpos(cmu_dir / "60" / "60.asf", cmu_dir / "60" / "60_01.amc")[108:109]
    return on_floor(model, np.repeat(q, 240, axis=0))


def _sole_corners(model, data, side):
    g = model.geom(f"{side}sole").id
    R = data.geom_xmat[g].reshape(3, 3)
    c = np.array([[i, j, -1.0] for i in (-1, 1) for j in (-1, 1)]) * model.geom_size[g]
    return data.geom_xpos[g] + c @ R.T, R


def test_the_sole_reaches_behind_the_ankle_and_alone_touches_the_floor(model):
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    for side in "lr":
        corners, R = _sole_corners(model, data, side)
        ankle = data.xpos[model.body(f"{side}foot").id]
        along = (corners - ankle) @ R[:, 0]  # along the sole, toes positive
        assert along.min() == pytest.approx(-SOLE_HEEL, abs=1e-6)
        assert along.max() > 0.1  # to the ball of the foot
        capsule = model.geom(f"{side}foot")
        floor = model.geom("floor")
        touches = (capsule.contype & floor.conaffinity) | (floor.contype & capsule.conaffinity)
        assert not touches[0]  # the sole stands in for the foot capsule on the floor
    default = sim_model(canonical_skeleton())
    assert mujoco.mj_name2id(default, mujoco.mjtObj.mjOBJ_GEOM, "lsole") >= 0  # the default body
    capsules = sim_model(canonical_skeleton(), soles=False)
    assert mujoco.mj_name2id(capsules, mujoco.mjtObj.mjOBJ_GEOM, "lsole") < 0


def test_ankles_are_as_stiff_as_a_standing_body_needs_within_the_human_limit(model):
    mgh = stance_stiffness(model) / STANCE_MARGIN
    assert 550 < mgh < 750  # 75 kg, centre of mass ~0.9 m above the ankles
    plain = sim_model(canonical_skeleton())  # stance_ankles off
    for joint in ("lfoot_rx", "rfoot_rx", "lfoot_rz"):
        kp = model.actuator_gainprm[model.actuator(joint).id, 0]
        cap = human_torque_limit(joint) / MIN_DEFLECTION
        assert kp == pytest.approx(min(STANCE_MARGIN * mgh, cap))
        assert plain.actuator_gainprm[plain.actuator(joint).id, 0] < mgh / 10  # the foot's own
    assert model.actuator_gainprm[model.actuator("lfoot_rx").id, 0] > mgh


def test_flat_soles_lay_a_standing_foot_flat_and_the_support_balances_it(model, still_pose):
    data = mujoco.MjData(model)
    flat = flat_soles(model, still_pose)
    for ref, tilted in ((still_pose, True), (flat, False)):
        data.qpos[:] = ref[0]
        mujoco.mj_kinematics(model, data)
        tilt = [np.degrees(np.arccos(_sole_corners(model, data, s)[1][2, 2])) for s in "lr"]
        assert (min(tilt) > 8.0) if tilted else (max(tilt) < 1.0)  # measured 15, 11 -> 0.03
    np.testing.assert_array_equal(flat[:, :7], still_pose[:, :7])  # the body above stays
    _, ff = reference_feedforward(model, flat[:2])
    # the floor alone carries the still body: no residual wrench at the root (measured 0.0;
    # on the tilted soles, only the heels within reach: 31 N and 31 N m)
    assert np.abs(ff[0, :6]).max() < 1.0
    assert np.abs(ff[0, 6:]).max() > 1.0  # and the legs carry it


def test_a_still_standing_pose_held_2s_stays_up_only_on_flat_soles(model, still_pose):
    assert not track(model, flat_soles(model, still_pose), assist_limit=0.0).fell
    assert track(model, still_pose, assist_limit=0.0).fell  # on the heels: it topples
    plain = sim_model(canonical_skeleton(), soles=False)  # capsule feet, ankles sized by the foot
    assert track(plain, on_floor(plain, still_pose[:1].repeat(240, 0)), assist_limit=0.0).fell
