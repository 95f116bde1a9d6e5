"""The fall definition (``sim.simulate.falls``): a part other than the feet on the floor where the
reference has none, or the head below half the reference's; never root height alone."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.falls import fall_cause, fall_reference, first_fall, geom_bottoms
from sim.simulate.model import sim_model


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


def _quat(axis, angle):
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * np.asarray(axis, float)])


def _mul(a, b):
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


UPRIGHT = _quat([1, 0, 0], np.pi / 2)  # the skeleton's y up turned to z up


def _pose(model, turn, lowest=-0.002):
    """The rest pose turned by ``turn`` (quaternion, world frame) after standing it upright,
    lowered so its lowest geom is at ``lowest`` [m] (slightly into the floor: touching)."""
    data = mujoco.MjData(model)
    q = model.qpos0.copy()
    q[3:7] = _mul(turn, UPRIGHT)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    q[2] += lowest - geom_bottoms(model, data).min()
    return q


def _state(model, q):
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)  # contacts at this pose
    return data


def test_standing_on_the_feet_is_not_a_fall(model):
    stand = _pose(model, _quat([0, 0, 1], 0.0))
    ref = fall_reference(model, stand[None])
    data = _state(model, stand)
    assert data.ncon > 0  # the soles touch the floor
    assert fall_cause(model, data, ref, 0) is None


def test_upside_down_is_a_fall_though_the_root_stays_high(model):
    stand = _pose(model, _quat([0, 0, 1], 0.0))
    ref = fall_reference(model, stand[None])
    upside = _pose(model, _quat([0, 1, 0], np.pi))  # on its head
    assert upside[2] > 0.5 * stand[2]  # the root-height rule would not have seen it
    data = _state(model, upside)
    assert fall_cause(model, data, ref, 0).startswith("contact:")
    lifted = upside.copy()
    lifted[2] += 0.3  # held upside down in the air: no contact, the head rule alone
    data = _state(model, lifted)
    assert data.ncon == 0 or not (data.contact.geom[: data.ncon] == 0).any()
    assert fall_cause(model, data, ref, 0) == "head"


def test_lying_down_is_a_fall_unless_the_reference_lies_too(model):
    stand = _pose(model, _quat([0, 0, 1], 0.0))
    lying = _pose(model, _quat([0, 1, 0], np.pi / 2))  # on its side
    data = _state(model, lying)
    cause = fall_cause(model, data, fall_reference(model, stand[None]), 0)
    assert cause is not None and cause != "contact:lsole" and cause != "contact:rsole"
    # the reference lies there itself (a motion performed on the floor): the same parts touch,
    # the head is as low as the reference's: not a fall
    assert fall_cause(model, data, fall_reference(model, lying[None]), 0) is None


def test_a_body_without_strength_collapses_and_is_seen_falling(model):
    """A simulated clip: the standing pose tracked with every torque limit at zero (set here on
    purpose) collapses; the fall is found, in the controller and from the recorded motion."""
    stand = _pose(model, _quat([0, 0, 1], 0.0), lowest=0.0)
    ref = np.repeat(stand[None], 240, axis=0)
    weak = sim_model(canonical_skeleton())
    weak.actuator_forcerange[:] = 0.0
    r = track(weak, ref, assist_limit=0.0)
    assert r.fell and 0 < r.fall_frame < len(r.qpos) - 1
    assert first_fall(weak, r.qpos, ref[::4]) >= 0
    strong = track(model, ref, assist_limit=0.0)
    assert first_fall(model, strong.qpos[:10], ref[::4][:10]) == -1


def _kneel(model):
    """Both knees on the floor: thighs upright, shins flat behind, the shins' lowest point 2 mm
    into the floor (the feet, allowed anyway, may reach lower)."""
    q = _pose(model, _quat([0, 0, 1], 0.0))
    for side in "lr":
        q[model.jnt_qposadr[model.joint(f"{side}tibia_rx").id]] = np.pi / 2
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    shins = [model.geom(f"{s}tibia").id for s in "lr"]
    q[2] -= geom_bottoms(model, data)[shins].min() + 0.002
    return q


def _stance_reference(model):
    """The standing pose with its soles 2.5 cm into the floor, as the IK fits of motion capture
    stand (their shins' ankle ends 3-5 cm above the floor in stance)."""
    return _pose(model, _quat([0, 0, 1], 0.0), lowest=-0.025)


def test_a_knee_on_the_floor_is_a_fall_where_the_reference_stands_on_that_leg(model):
    """The reference's shin counts as on the floor by its lowest point (the ankle end, a few cm
    up in stance), but the simulated body touches with the knee end, which the reference holds
    half a metre up: a fall (the head, well above half the reference's, does not say so)."""
    stand = _stance_reference(model)
    kneel = _kneel(model)
    ref = fall_reference(model, stand[None])
    shins = [model.geom(f"{s}tibia").id for s in "lr"]
    assert ref.on_floor[0, shins].all()  # the whole-geom rule would excuse the shins
    data = _state(model, kneel)
    touching = {model.geom(g).name for pair in data.contact.geom[: data.ncon] for g in pair}
    assert touching & {"ltibia", "rtibia"}
    head = model.geom("head").id
    assert data.geom_xpos[head, 2] > 0.5 * ref.head_z[0]
    assert fall_cause(model, data, ref, 0) in ("contact:ltibia", "contact:rtibia")
    # the reference kneels too: the same parts on the floor, not a fall
    assert fall_cause(model, data, fall_reference(model, kneel[None]), 0) is None


def test_a_shin_touching_at_the_ankle_where_the_reference_stands_is_no_fall(model):
    """The standing pose 4 cm lower (soles into the floor): the shins' ankle ends touch the
    floor where the reference's ankle ends are within the gap: no fall."""
    stand = _stance_reference(model)
    ref = fall_reference(model, stand[None])
    low = stand.copy()
    data = _state(model, low)
    shins = [model.geom(f"{s}tibia").id for s in "lr"]
    low[2] -= geom_bottoms(model, data)[shins].min() + 0.002
    data = _state(model, low)
    touching = {model.geom(g).name for pair in data.contact.geom[: data.ncon] for g in pair}
    assert touching & {"ltibia", "rtibia"}
    assert fall_cause(model, data, ref, 0) is None


def test_on_a_real_walk_the_stance_shin_is_excused_at_the_ankle_only(model, cmu_dir):
    """The walk 02_01 as eval tracks it (on its floor, soles laid flat, stance soles on z = 0):
    in its stance frames the shin's lowest point is within the allowance (so the whole-shin rule
    excused a knee), while the cross-section through the knee (the tibia body's origin, the knee
    joint) lies a capsule radius below the knee, half a metre up, and the one through the ankle
    (the foot body's origin) within the allowance."""
    from sim.simulate.falls import REFERENCE_GAP, section_bottom
    from sim.simulate.reference import contact_consistent, flat_soles, on_floor, trial_qpos

    q = trial_qpos(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc")[:360:4]
    ref_qpos = contact_consistent(
        model, flat_soles(model, on_floor(model, q, 30.0, lift=0.0)), 30.0
    )
    ref = fall_reference(model, ref_qpos)
    g = model.geom("ltibia").id
    r = model.geom_size[g, 0]
    stance = np.flatnonzero(ref.on_floor[:, g])
    assert len(stance) > 10
    data = mujoco.MjData(model)
    for k in stance[:: max(1, len(stance) // 5)]:
        data.qpos[:] = ref_qpos[k]
        mujoco.mj_kinematics(model, data)
        knee, ankle = data.xpos[model.body("ltibia").id], data.xpos[model.body("lfoot").id]
        at_knee = section_bottom(model, data, ref, k, g, knee)
        assert at_knee > 0.3 and abs(at_knee - (knee[2] - r)) < 0.03
        at_ankle = section_bottom(model, data, ref, k, g, ankle)
        assert at_ankle <= REFERENCE_GAP + 0.01 and abs(at_ankle - (ankle[2] - r)) < 0.03
