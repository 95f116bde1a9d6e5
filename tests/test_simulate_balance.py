"""The balance feedback (``sim.simulate.balance``): zero on the reference, the pelvis moment the
stance hips make is the one asked for, the ankles push a leaning centre of mass back, and a
sampled rollout with it is replayed state for state."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from sim.errors import SidqlError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.balance import Balance, balance_plan, balance_torques
from sim.simulate.controller import track
from sim.simulate.feedforward import reference_feedforward
from sim.simulate.model import G, sim_model, total_mass
from sim.simulate.sampling import search_offsets


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


@pytest.fixture(scope="module")
def walk(trial_on_floor, model):
    """(ref_qpos, ref_qvel): 1 s of the walk 07_01 on the canonical body, on the floor."""
    ref = trial_on_floor(model, "07_01")[:120]
    qvel, _ = reference_feedforward(model, ref, mujoco.MjData(model))
    return ref, qvel


def _stance_tick(plan, both: bool) -> int:
    ticks = np.flatnonzero(plan.stance.all(axis=1) if both else plan.stance.sum(axis=1) == 1)
    assert ticks.size, "the walk has such ticks"
    return int(ticks[0])


def _legs_lean(model, data, tau: np.ndarray, direction: np.ndarray) -> dict[str, tuple]:
    """Per side: how far the moment ``tau`` puts on that leg's hinges turns the centre of mass
    along ``direction`` (3,), and the scale ``|moment| |com - foot|`` to compare it with."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    out = {}
    for side in "lr":
        ids = [a for a in np.flatnonzero(tau) if model.actuator(int(a)).name.startswith(side)]
        on_leg = -sum(tau[a] * data.xaxis[model.actuator_trnid[a, 0]] for a in ids)
        r = data.subtree_com[1] - data.xpos[model.body(f"{side}foot").id]
        out[side] = (np.cross(on_leg, r) @ direction, np.linalg.norm(on_leg) * np.linalg.norm(r))
    return out


def test_no_torque_on_the_reference_itself(model, walk):
    ref, qvel = walk
    plan = balance_plan(model, ref, qvel, Balance())
    assert plan.stance.any(axis=1).mean() > 0.8  # a walk stands most of the time
    data = mujoco.MjData(model)
    out = np.zeros(model.nu)
    for k in range(0, len(ref), 7):
        data.qpos[:], data.qvel[:] = ref[k], qvel[k]
        np.testing.assert_allclose(balance_torques(model, data, plan, k, out), 0.0, atol=1e-6)


def test_stance_hips_make_the_pelvis_moment_asked_for(model, walk):
    """A pelvis turned by a small rotation about world x: the moment the hips' torques put on
    the pelvis (each hinge pushes its parent by -tau times its world axis, the axis computed
    here from the parent's frame and the joint's local axis) is -k_rot times the error, the
    ankles get nothing from it (no centre-of-mass error asked for with k_com 0)."""
    ref, qvel = walk
    gains = Balance(k_rot=1.0, d_rot=0.0, k_com=0.0, d_com=0.0)
    plan = balance_plan(model, ref, qvel, gains)
    k = _stance_tick(plan, both=False)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref[k], qvel[k]
    turn = np.zeros(4)
    mujoco.mju_axisAngle2Quat(turn, np.array([1.0, 0.0, 0.0]), 0.05)
    mujoco.mju_mulQuat(data.qpos[3:7], turn, ref[k, 3:7].copy())  # world-frame turn
    tau = balance_torques(model, data, plan, k, np.zeros(model.nu))
    mujoco.mj_forward(model, data)
    moment = np.zeros(3)
    for a in np.flatnonzero(tau):  # -tau times the dof's world axis, from the child's Jacobian
        j = model.actuator_trnid[a, 0]
        jacr = np.zeros((3, model.nv))
        mujoco.mj_jacBody(model, data, None, jacr, model.jnt_bodyid[j])
        moment -= tau[a] * jacr[:, model.jnt_dofadr[j]]
    mgh = total_mass(model) * G
    np.testing.assert_allclose(moment, [-0.05 * mgh, 0.0, 0.0], atol=1e-3 * mgh)
    names = [model.actuator(int(a)).name for a in np.flatnonzero(tau)]
    assert names and all("femur" in n for n in names)


def test_ankles_push_a_forward_centre_of_mass_back(model, walk):
    """A root moving faster than the reference along the walk (the ankle's flexion axis lies
    across it) gets ankle torques whose moment on each stance leg turns the centre of mass
    back (the moment crossed with the centre of mass's lever from the ankle points against
    the walk)."""
    ref, qvel = walk
    gains = Balance(k_rot=0.0, d_rot=0.0, k_com=1.0, d_com=0.3)
    plan = balance_plan(model, ref, qvel, gains)
    k = _stance_tick(plan, both=True)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref[k], qvel[k]
    ahead = np.append(qvel[k, :2] / np.linalg.norm(qvel[k, :2]), 0.0)
    data.qvel[:3] += 0.5 * ahead  # [m/s] too fast
    tau = balance_torques(model, data, plan, k, np.zeros(model.nu))
    assert all("foot" in model.actuator(int(a)).name for a in np.flatnonzero(tau))
    for turn, scale in _legs_lean(model, data, tau, ahead).values():
        assert turn < -0.2 * scale


def test_a_search_with_balance_is_replayed_state_for_state(model, walk):
    """Rollouts and replay add the same feedback of the same states: ``track`` with the offsets
    found passes through the states the search reached; without the feedback it would not."""
    ref = walk[0][:48]
    gains = Balance()
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=3, balance=gains)
    offsets, reached = search_offsets(model, ref, **kw)
    r = track(model, ref, assist_limit=0.0, offsets=offsets, record_every=1, balance=gains)
    np.testing.assert_allclose(r.qpos[12::12], reached[:-1], rtol=0, atol=1e-9)
    bare = track(model, ref, assist_limit=0.0, offsets=offsets, record_every=1)
    assert np.abs(bare.qpos[12::12] - reached[:-1]).max() > 1e-3


def test_torques_are_held_between_updates_and_windows_must_start_on_one(model, walk):
    """``every`` 2: at an odd tick the torques are the previous even tick's, whatever the state
    now; a search whose windows would start between two updates is refused (its rollouts could
    not start where the replay holds a torque computed before them)."""
    from sim.simulate.balance import held_torques

    ref, qvel = walk
    plan = balance_plan(model, ref, qvel, Balance(every=2))
    k = 2 * (_stance_tick(plan, both=False) // 2)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref[k], qvel[k]
    data.qvel[:3] += 0.3
    out = np.zeros(model.nu)
    first = held_torques(model, data, plan, k, out).copy()
    assert np.abs(first).max() > 1.0
    data.qvel[:3] -= 0.6  # another state: an update would differ
    assert np.array_equal(held_torques(model, data, plan, k + 1, out), first)
    assert not np.allclose(held_torques(model, data, plan, k + 2, out), first)
    with pytest.raises(SidqlError, match="multiple"):
        search_offsets(model, ref[:24], samples=2, window=9, balance=Balance(every=2))
    with pytest.raises(SidqlError, match="positive"):
        Balance(every=0)


def test_swing_foot_placement_moves_the_swing_ankle_by_the_offset_asked_for(model, walk):
    """Single stance, the root 0.1 m/s too fast along x and -0.05 along y: the placement term
    alone (c_v 0.3 s) turns only the swing hip, and its targets (torque over stiffness) applied
    as hinge angles move the swing ankle by about dp = 0.3 * (0.1, -0.05) m horizontally (by
    forward kinematics, the lever of a thigh that is not vertical and a finite turn allowed
    for), nothing in double stance, nothing on the reference, and nothing by default."""
    ref, qvel = walk
    assert balance_plan(model, ref, qvel, Balance()).step is None
    gains = Balance(k_rot=0.0, d_rot=0.0, k_com=0.0, d_com=0.0, c_d=1.0, c_v=0.3)
    plan = balance_plan(model, ref, qvel, gains)
    kp = model.actuator_gainprm[:, 0]
    dv = np.array([0.1, -0.05])
    data = mujoco.MjData(model)
    single = np.flatnonzero(plan.stance.sum(axis=1) == 1)
    for k in single[:: max(1, single.size // 6)]:
        data.qpos[:], data.qvel[:] = ref[k], qvel[k]
        assert np.abs(balance_torques(model, data, plan, k, np.zeros(model.nu))).max() < 1e-6
        data.qvel[:2] += dv
        tau = balance_torques(model, data, plan, k, np.zeros(model.nu))
        side = "lr"[int(np.argmin(plan.stance[k]))]
        moved = np.flatnonzero(tau)
        assert moved.size and all(
            model.actuator(int(a)).name.startswith(side + "femur") for a in moved
        )
        foot = model.body(side + "foot").id
        mujoco.mj_kinematics(model, data)
        before = data.xpos[foot, :2].copy()
        for a in moved:
            data.qpos[model.jnt_qposadr[model.actuator_trnid[a, 0]]] += tau[a] / kp[a]
        mujoco.mj_kinematics(model, data)
        shift, want = data.xpos[foot, :2] - before, 0.3 * dv
        assert np.linalg.norm(shift - want) < 0.25 * np.linalg.norm(want)
    k = _stance_tick(plan, both=True)
    data.qpos[:], data.qvel[:] = ref[k], qvel[k]
    data.qvel[:2] += dv
    assert np.abs(balance_torques(model, data, plan, k, np.zeros(model.nu))).max() == 0.0


def test_swing_foot_placement_follows_the_centre_of_mass_offset(model, walk):
    """c_d alone: a reference whose centre of mass sits 0.04 m less far along y from its stance
    foot than the body's (the body's offset 0.04 m too large) moves the swing ankle about
    c_d * 0.04 = 0.02 m along y; the whole body translated asks for nothing (the offset is taken
    from the stance foot)."""
    ref, qvel = walk
    gains = Balance(k_rot=0.0, d_rot=0.0, k_com=0.0, d_com=0.0, c_d=0.5, c_v=0.0)
    plan = balance_plan(model, ref, qvel, gains)
    k = _stance_tick(plan, both=False)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref[k], qvel[k]
    data.qpos[:2] += [0.3, -0.2]  # a translation: no error
    np.testing.assert_allclose(
        balance_torques(model, data, plan, k, np.zeros(model.nu)), 0, atol=1e-6
    )
    shifted = dataclasses.replace(plan, com_off=plan.com_off - [0.0, 0.04])
    tau = balance_torques(model, data, shifted, k, np.zeros(model.nu))
    foot = model.body("lr"[int(np.argmin(plan.stance[k]))] + "foot").id
    mujoco.mj_kinematics(model, data)
    before = data.xpos[foot, :2].copy()
    for a in np.flatnonzero(tau):
        data.qpos[model.jnt_qposadr[model.actuator_trnid[a, 0]]] += (
            tau[a] / model.actuator_gainprm[a, 0]
        )
    mujoco.mj_kinematics(model, data)
    want = np.array([0.0, 0.02])
    assert np.linalg.norm(data.xpos[foot, :2] - before - want) < 0.25 * np.linalg.norm(want)


def test_drift_term_leads_the_velocity_target_by_the_root_position_error(model, walk):
    """``k_drift``: zero on the reference; a body translated by ``d`` off the reference's path
    (no other error) gets nothing from the feedback without the term (it reads the centre of
    mass against the feet only), and with it the torques a root velocity ``k_drift d`` faster
    slower would get without it (``v - (v_ref + k_drift (p_ref - p))``); a translation longer than ``drift_max`` acts as one of that length;
    a body behind the walk has its centre of mass turned forward."""
    ref, qvel = walk
    gains = Balance(k_rot=0.0, d_rot=0.0, k_com=1.0, d_com=0.3, k_drift=2.0, drift_max=0.2)
    plain = Balance(k_rot=0.0, d_rot=0.0, k_com=1.0, d_com=0.3)
    plan, plan0 = balance_plan(model, ref, qvel, gains), balance_plan(model, ref, qvel, plain)
    k = _stance_tick(plan, both=True)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref[k], qvel[k]
    np.testing.assert_allclose(balance_torques(model, data, plan, k, np.zeros(model.nu)), 0.0,
                               atol=1e-6)  # fmt: skip
    ahead = qvel[k, :2] / np.linalg.norm(qvel[k, :2])
    d = -0.1 * ahead  # [m] 10 cm behind the reference's root
    data.qpos[:2] += d
    np.testing.assert_allclose(balance_torques(model, data, plan0, k, np.zeros(model.nu)), 0.0,
                               atol=1e-6)  # fmt: skip
    tau = balance_torques(model, data, plan, k, np.zeros(model.nu))
    data.qpos[:2], data.qvel[:2] = ref[k, :2], qvel[k, :2] + 2.0 * d  # v_ref - k_drift (-d)
    np.testing.assert_allclose(tau, balance_torques(model, data, plan0, k, np.zeros(model.nu)),
                               rtol=1e-9, atol=1e-9)  # fmt: skip
    data.qpos[:2], data.qvel[:2] = ref[k, :2] + 5.0 * d, qvel[k, :2]  # 50 cm: clipped to 20
    far = balance_torques(model, data, plan, k, np.zeros(model.nu))
    data.qpos[:2] = ref[k, :2] + 2.0 * d
    np.testing.assert_allclose(far, balance_torques(model, data, plan, k, np.zeros(model.nu)),
                               rtol=1e-9, atol=1e-9)  # fmt: skip
    for turn, scale in _legs_lean(model, data, tau, np.append(ahead, 0.0)).values():
        assert turn > 0.2 * scale
    with pytest.raises(SidqlError, match="k_drift"):
        Balance(k_drift=-1.0)


def test_drift_lead_is_clipped_and_has_a_dead_zone():
    """``sim.simulate.drift.drift_lead``, by hand: the error (reference less simulated) times
    the rate; longer than ``max_len``: that long; ``dead``: shortened by it, nothing within."""
    from sim.simulate.drift import drift_lead

    ref, sim = np.zeros(2), np.array([0.3, 0.4])  # error (-0.3, -0.4), 0.5 m long
    np.testing.assert_allclose(drift_lead(ref, sim, 2.0, 1.0), [-0.6, -0.8])
    np.testing.assert_allclose(drift_lead(ref, sim, 2.0, 0.25), [-0.3, -0.4])
    np.testing.assert_allclose(drift_lead(ref, sim, 2.0, 1.0, dead=0.1), [-0.48, -0.64])
    np.testing.assert_allclose(drift_lead(ref, sim, 2.0, 0.35, dead=0.1), [-0.3, -0.4])
    np.testing.assert_array_equal(drift_lead(ref, sim, 2.0, 1.0, dead=0.6), [0.0, 0.0])
    np.testing.assert_array_equal(drift_lead(ref, sim, 0.0, 1.0), [0.0, 0.0])


def test_drift_at_the_feet_reads_where_the_stance_feet_stand(model, walk):
    """``drift_feet``: the lead reads the stance feet's mid-point against the reference's
    instead of the root. Zero on the reference; a translated body gets the root's lead; a body
    whose root stays on the reference's but whose left hip turns (both feet in stance) gets none
    from the root's and, from the feet's, the torques the plain feedback gives at a root
    velocity ``k_drift`` times the feet's offset faster (the offset computed here from the
    feet's positions)."""
    ref, qvel = walk
    base = dict(k_rot=0.0, d_rot=0.0, k_com=1.0, d_com=0.3)
    feet = Balance(**base, k_drift=2.0, drift_max=1.0, drift_feet=True)
    root = Balance(**base, k_drift=2.0, drift_max=1.0)
    plans = {g: balance_plan(model, ref, qvel, g) for g in (feet, root, Balance(**base))}
    k = _stance_tick(plans[feet], both=True)
    data = mujoco.MjData(model)

    def tau(gains, q, v):
        data.qpos[:], data.qvel[:] = q, v
        return balance_torques(model, data, plans[gains], k, np.zeros(model.nu))

    def mid(q):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        return data.xpos[[model.body("lfoot").id, model.body("rfoot").id], :2].mean(axis=0)

    np.testing.assert_allclose(tau(feet, ref[k], qvel[k]), 0.0, atol=1e-6)
    moved = ref[k].copy()
    moved[:2] += (0.05, -0.08)
    np.testing.assert_allclose(tau(feet, moved, qvel[k]), tau(root, moved, qvel[k]), atol=1e-9)
    bent = ref[k].copy()
    bent[model.jnt_qposadr[model.joint("lfemur_rx").id]] += 0.3
    offset = mid(bent) - mid(ref[k])
    assert np.linalg.norm(offset) > 0.03  # the feet moved, the root did not
    plain = Balance(**base)
    faster = qvel[k].copy()
    faster[:2] += 2.0 * offset
    np.testing.assert_allclose(tau(root, bent, qvel[k]), tau(plain, bent, qvel[k]), atol=1e-9)
    np.testing.assert_allclose(tau(feet, bent, qvel[k]), tau(plain, bent, faster), atol=1e-9)
    assert np.abs(tau(feet, bent, qvel[k]) - tau(root, bent, qvel[k])).max() > 1.0
