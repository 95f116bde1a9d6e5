"""The whole-body QP controller (``sim.simulate.wholebody``): its solution is physical (floor
forces inside the friction pyramid, torques within the human limits, the floating base's
equations of motion hold), nothing but the joints and scripted pushes acts on the body, and the
same reference gives the same simulation bit for bit."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import Push, Weakening
from sim.simulate.model import CONTROL_HZ, SUBSTEPS, sim_model
from sim.simulate.reference import contact_consistent, flat_soles, lowest_foot_point, on_floor
from sim.simulate.wholebody import (
    WholeBodyGains,
    qp_tick,
    track_wholebody,
    wholebody_reference,
)
from sim.simulate.wholebody_reference import SMOOTH_S


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton(), actuators="motor")


@pytest.fixture(scope="module")
def walk_ref(trial_on_floor, model):
    ref = on_floor(model, trial_on_floor(model, "02_01")[:90], lift=0.0)
    return contact_consistent(model, flat_soles(model, ref))


def test_the_contact_consistent_reference_stands_on_the_floor(model, walk_ref):
    low = lowest_foot_point(model, walk_ref)
    stance = low <= 0.03
    assert stance.mean() > 0.5  # a walk stands most of the time
    # in stance the lower sole touches z = 0 (within the smoothing of the shift: millimetres)
    assert np.abs(low[stance]).max() < 0.01
    assert np.median(np.abs(low[stance])) < 0.002


def test_qp_forces_lie_in_the_friction_pyramid_and_torques_within_limits(model, walk_ref):
    """Each tick's solution, checked against MuJoCo's own quantities (not the QP's): the
    planned forces push, inside the pyramid; the torques are within the limits; and the root's
    six equations of motion hold with the planned accelerations and forces."""
    gains = WholeBodyGains()
    ref = wholebody_reference(model, walk_ref)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = walk_ref[0], ref.qvel[0]
    lim = model.actuator_ctrlrange[:, 1]
    s = gains.friction / np.sqrt(2.0)
    scratch: dict = {}
    M = np.zeros((model.nv, model.nv))
    jacp = np.zeros((3, model.nv))
    contacts = 0
    for k in range(60):
        mujoco.mj_forward(model, data)
        res = qp_tick(model, data, ref, k, gains, lim, scratch)
        assert res.status == 1
        f = res.forces
        assert np.all(f[:, 2] >= -1e-6)
        assert np.all(np.abs(f[:, :2]) <= s * f[:, 2:3] + 1e-6)
        assert np.all(np.abs(res.tau) <= lim + 1e-9)
        mujoco.mj_fullM(model, data, M)
        generalised = np.zeros(model.nv)
        for p, force in zip(res.points, f, strict=True):
            # the point's body: the geom nearest to it among the feet's (recomputed here)
            body = _body_at(model, data, p)
            mujoco.mj_jac(model, data, jacp, None, p, body)
            generalised += jacp.T @ force
        root = M[:6] @ res.qdd + data.qfrc_bias[:6] - data.qfrc_passive[:6] - generalised[:6]
        assert np.abs(root).max() < 1e-6 * max(1.0, np.abs(generalised).max())
        contacts += len(f) > 0
        data.ctrl[:] = res.tau
        mujoco.mj_step(model, data, nstep=SUBSTEPS)
    assert contacts > 30  # the checks above met real contact


def _body_at(model, data, p):
    """The body of the foot geom (sole or toe box) whose surface is nearest point ``p``."""
    best, body = np.inf, -1
    for n in ("lsole", "rsole", "ltoesole", "rtoesole"):
        g = model.geom(n).id
        local = data.geom_xmat[g].reshape(3, 3).T @ (p - data.geom_xpos[g])
        d = np.linalg.norm(np.maximum(np.abs(local) - model.geom_size[g], 0.0))
        if d < best:
            best, body = d, int(model.geom_bodyid[g])
    return body


def test_only_scripted_pushes_act_from_outside(model, walk_ref, monkeypatch):
    """Every physics step of a tracking: ``qfrc_applied`` is zero and ``xfrc_applied`` is the
    push on its body during its window, zero elsewhere and at other times."""
    push = Push(body="thorax", start=0.2, duration=0.1, force=(80.0, 0.0, 0.0))
    thorax = model.body("thorax").id
    seen = []
    step = mujoco.mj_step

    def checked_step(m, d, nstep=1):
        for _ in range(nstep):
            assert not d.qfrc_applied.any()
            other = np.delete(d.xfrc_applied, thorax, axis=0)
            assert not other.any()
            seen.append(d.xfrc_applied[thorax, 0])
            step(m, d)

    monkeypatch.setattr(mujoco, "mj_step", checked_step)
    r = track_wholebody(model, walk_ref[:48], pushes=(push,))
    seen = np.array(seen)
    assert r.assistance.max() == 0.0 and not r.assist_wrench.any()
    k = np.arange(len(seen)) // SUBSTEPS / CONTROL_HZ  # each step's control tick time
    on = (k >= push.start) & (k < push.start + push.duration)
    np.testing.assert_array_equal(seen[on], 80.0)
    np.testing.assert_array_equal(seen[~on], 0.0)


def test_torques_within_limits_and_same_reference_same_simulation(model, walk_ref):
    a = track_wholebody(model, walk_ref)
    b = track_wholebody(model, walk_ref)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.joint_torque, b.joint_torque)
    lim = model.actuator_forcerange[:, 1]
    assert np.all(np.abs(a.joint_torque) <= lim * (1 + 1e-12))
    assert np.abs(a.joint_torque).max() > 10.0  # it did act


def test_a_weakening_to_s_bounds_the_torque_at_s_of_the_limit_not_s_squared(model, walk_ref):
    """The QP's bound is what acts: the actuators are not also weakened (which made s act as
    s^2 of the limit)."""
    s = 0.5
    weak = track_wholebody(model, walk_ref, weakenings=(Weakening(0.0, 10.0, s),), record_every=1)
    share = np.abs(weak.joint_torque) / model.actuator_forcerange[:, 1]
    assert share.max() <= s * (1 + 1e-9)
    assert share.max() > 0.9 * s  # some joint used (nearly) all it was left, more than s^2


def test_it_needs_torque_actuators():
    with pytest.raises(ValueError, match="motor"):
        track_wholebody(sim_model(canonical_skeleton()), np.zeros((2, 63)))


def test_forward_validation_builds_the_body_its_controller_needs():
    from sim.simulate.validate import DEFAULT_CONTROLLER, ForwardValidation, forward_validation

    skeleton = canonical_skeleton()
    names = ("root", "lfoot", "head")
    default = forward_validation(skeleton, names)
    assert default.controller == DEFAULT_CONTROLLER
    qp = forward_validation(skeleton, names, controller="wholebody")
    assert not qp.model.actuator_biasprm[:, 1].any()  # torque actuators
    sampled = forward_validation(skeleton, names, samples=8)
    assert sampled.controller == "sampling" and sampled.samples == 8
    assert sampled.model.actuator_biasprm[:, 1].any()  # position actuators
    with pytest.raises(ValueError, match="motor"):
        ForwardValidation(sampled.model, names, controller="wholebody")
    with pytest.raises(ValueError, match="known"):
        ForwardValidation(sampled.model, names, controller="pid")


def test_skating_is_measured_on_one_reference_whatever_the_controller(trial_on_floor):
    """The skating's reference of the sampler (the lifted reference, its yardstick)
    and of the QP (contact-consistent already) stand alike: stance soles on z = 0 (the
    simulated floor), where the lifted reference's soles hover and the contact threshold
    would pick other frames; the two differ only by the ankles ``flat_soles`` turned (a sole
    1 cm higher is turned less), so their roots agree within millimetres."""
    from sim.simulate.reference import FLOOR_LIFT
    from sim.simulate.validate import SKATE_CONTACT, forward_validation

    skeleton = canonical_skeleton()
    names = ("root", "lfoot", "head")
    sampled = forward_validation(skeleton, names, controller="sampling")
    qp = forward_validation(skeleton, names, controller="wholebody")
    qpos = trial_on_floor(sampled.model, "02_01")[:360:4]  # 3 s at 30 fps
    floor = sampled.floor_of(qpos.repeat(4, axis=0)[: 4 * len(qpos) - 3])
    a = sampled.skating_reference(sampled.reference(qpos, 30.0, floor, contact=False))
    b = qp.skating_reference(qp.reference(qpos, 30.0, floor))
    assert np.median(np.abs(a[:, 2] - b[:, 2])) < 0.003
    for ref in (a, b):
        low = lowest_foot_point(sampled.model, ref)
        stance = low <= 0.03
        assert stance.mean() > 0.5 and np.median(np.abs(low[stance])) < 0.002  # on the floor
    lifted = lowest_foot_point(sampled.model, sampled.reference(qpos, 30.0, floor, contact=False))
    assert np.median(lifted[stance]) > FLOOR_LIFT / 2  # the lifted one hovers
    assert (low <= SKATE_CONTACT).sum() > (lifted <= SKATE_CONTACT).sum()


def test_the_soles_angular_velocity_is_their_orientations_rate(model, trial_on_floor):
    """``sole_angvel`` (for ``WholeBodyGains.swing_feedforward``) against MuJoCo's own rotation
    between consecutive ticks (``mju_subQuat``) smoothed as the reference's velocities are
    (``SMOOTH_S``), on 2 s of a walk: the same (measured: 0.01 rad/s median, 0.09 at most,
    against a median speed of 2.7 rad/s)."""
    ref_qpos = on_floor(model, trial_on_floor(model, "02_01")[:240], lift=0.0)
    ref = wholebody_reference(model, ref_qpos)
    data = mujoco.MjData(model)
    quats = np.empty((len(ref_qpos), 2, 4))
    for t, q in enumerate(ref_qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for s in range(2):
            mujoco.mju_mat2Quat(quats[t, s], ref.sole_mat[t, s].ravel())
    rate = np.empty((len(ref_qpos) - 1, 2, 3))
    for t in range(len(ref_qpos) - 1):
        for s in range(2):
            mujoco.mju_subQuat(rate[t, s], quats[t + 1, s], quats[t, s])  # in the sole's frame
            rate[t, s] = ref.sole_mat[t, s] @ rate[t, s] * CONTROL_HZ  # world frame
    mid = 0.5 * (ref.sole_angvel[1:] + ref.sole_angvel[:-1])
    err = np.linalg.norm(
        mid - gaussian_filter1d(rate, SMOOTH_S * CONTROL_HZ, axis=0, mode="nearest"), axis=-1
    )
    assert np.median(np.linalg.norm(rate, axis=-1)) > 1.0  # the feet do turn
    assert np.median(err) < 0.05 and err.max() < 0.3
    off = track_wholebody(model, contact_consistent(model, flat_soles(model, ref_qpos[:120])))
    on = track_wholebody(
        model,
        contact_consistent(model, flat_soles(model, ref_qpos[:120])),
        gains=WholeBodyGains(swing_feedforward=True),
    )
    assert not np.array_equal(off.qpos, on.qpos)  # the option acts
