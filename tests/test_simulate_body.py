"""The simulated body's strength and the controller's honesty: every joint's applied torque stays
within its human limit when driven against it, assistance needs the floor, and ``track`` leaves
the model as it found it."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import ActuatorEdits, Weakening, track
from sim.simulate.model import (
    CONTROL_HZ,
    HUMAN_PEAK_TORQUE,
    MIN_DEFLECTION,
    SUBSTEPS,
    TARGET_SPEED,
    Gains,
    human_torque_limit,
    sim_model,
)

#: stiffer controllers than the default: a smaller stiffness cap, and a higher bandwidth too
STIFF = [Gains(min_deflection=0.05), Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)]


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


@pytest.fixture(scope="module")
def lean_model():
    return sim_model(canonical_skeleton(), lean=True)


@pytest.fixture(scope="module")
def walk_ref(trial_on_floor, model):
    return trial_on_floor(model, "02_01")[:120]


def test_limits_are_the_human_table_scaled_by_mass():
    heavy = sim_model(canonical_skeleton(), body_mass_kg=150.0)
    plain = sim_model(canonical_skeleton())
    for i in range(plain.nu):
        name = plain.actuator(i).name
        bone, axis = name.rsplit("_", 1)
        bone = bone[1:] if bone[1:] in HUMAN_PEAK_TORQUE else bone
        assert plain.actuator_forcerange[i, 1] == pytest.approx(HUMAN_PEAK_TORQUE[bone][axis])
        assert heavy.actuator_forcerange[i, 1] == pytest.approx(2 * human_torque_limit(name))
        assert plain.actuator_forcelimited[i]
        # human stiffness: the peak torque needs at least MIN_DEFLECTION of angle error
        assert (
            plain.actuator_gainprm[i, 0] <= plain.actuator_forcerange[i, 1] / MIN_DEFLECTION + 1e-9
        )
    assert (
        human_torque_limit("lfemur_rx")
        > human_torque_limit("lradius_rx")
        > human_torque_limit("lfingers_rx")
    )


@pytest.mark.parametrize("factor", [0.6, 1.0, 1.5, 4.0])
def test_torque_limits_are_the_human_table_whatever_the_gain(factor):
    """A stiffer or softer controller is no stronger or weaker body: with the hinge gains scaled
    by ``factor`` (synth's ``gain``) the limits are the human table's, the stiffness changes,
    and the torque applied when driven far past the limit stays within it."""
    plain = sim_model(canonical_skeleton())
    scaled = sim_model(canonical_skeleton(), gains=Gains().scaled(factor))
    table = np.array([human_torque_limit(scaled.actuator(i).name) for i in range(scaled.nu)])
    np.testing.assert_array_equal(scaled.actuator_forcerange[:, 1], table)
    np.testing.assert_array_equal(scaled.actuator_forcerange[:, 0], -table)
    if factor != 1.0:
        assert not np.allclose(scaled.actuator_gainprm[:, 0], plain.actuator_gainprm[:, 0])
    data = mujoco.MjData(scaled)
    data.qpos[2] = 2.0
    kp = scaled.actuator_gainprm[:, 0]
    for _ in range(20):
        data.ctrl[:] = data.qpos[7:] + 3.0 + 10 * table / kp
        mujoco.mj_step(scaled, data)
        assert np.all(np.abs(data.actuator_force) <= table * (1 + 1e-12))
    assert np.abs(data.actuator_force).max() > 0.999 * table.min()


@pytest.mark.parametrize("gains", [Gains(), *STIFF])
def test_stiffness_is_the_bandwidth_capped_at_the_limit_over_the_deflection(model, gains):
    """kp = min(omega^2 I, limit / min_deflection) per hinge (I: the hinge's reflected inertia
    at rest, the mass matrix's diagonal, read off the default body, whose armature is the
    plain model's), kv = 2 zeta sqrt(kp I) (the damping ratio kept under the cap), armature at
    least kp h^2, and the control range the joint's widened by (limit + kv TARGET_SPEED) / kp;
    the default gains are the default body, bit for bit."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    inertia = np.diag(M)[6:]
    body = sim_model(canonical_skeleton(), gains=gains)
    lim = body.actuator_forcerange[:, 1]
    kp = body.actuator_gainprm[:, 0]
    kv = -body.actuator_biasprm[:, 2]
    np.testing.assert_allclose(kp, np.minimum(gains.omega**2 * inertia, lim / gains.min_deflection))
    np.testing.assert_allclose(kv, 2 * gains.zeta * np.sqrt(kp * inertia))
    h = 1.0 / (CONTROL_HZ * SUBSTEPS)
    assert np.all(body.dof_armature[6:] >= kp * h**2 * (1 - 1e-12))
    reach = (lim + kv * TARGET_SPEED) / kp
    jrange = body.jnt_range[body.actuator_trnid[:, 0]]
    np.testing.assert_allclose(body.actuator_ctrlrange[:, 0], jrange[:, 0] - reach)
    np.testing.assert_allclose(body.actuator_ctrlrange[:, 1], jrange[:, 1] + reach)
    if gains == Gains():
        for field in ("actuator_gainprm", "actuator_biasprm", "actuator_ctrlrange",
                      "dof_armature", "actuator_forcerange"):  # fmt: skip
            np.testing.assert_array_equal(getattr(body, field), getattr(model, field))
        assert gains.min_deflection == MIN_DEFLECTION
    else:  # stiffer where the cap held: the hips and the trunk
        stiffer = kp > model.actuator_gainprm[:, 0] * 1.5
        assert {"lfemur_rx", "lowerback_rx"} <= {
            body.actuator(i).name for i in np.where(stiffer)[0]
        }


def test_a_stiffness_cap_must_be_a_positive_angle():
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(UsageError):
            Gains(min_deflection=bad)


@pytest.mark.parametrize("gains", STIFF)
def test_a_stiffer_controller_applies_at_most_the_human_limit(gains):
    """A stiffer controller is no stronger body: every joint driven past its limit (both signs,
    a target far beyond the stiffness's reach) applies at most the human table's torque, and
    reaches it."""
    body = sim_model(canonical_skeleton(), gains=gains)
    table = np.array([human_torque_limit(body.actuator(i).name) for i in range(body.nu)])
    np.testing.assert_array_equal(body.actuator_forcerange[:, 1], table)
    data = mujoco.MjData(body)
    kp = body.actuator_gainprm[:, 0]
    dof = body.jnt_dofadr[body.actuator_trnid[:, 0]]
    reached = np.zeros(body.nu)
    for sign in (1.0, -1.0):
        mujoco.mj_resetData(body, data)
        data.qpos[2] = 2.0  # in the air
        for _ in range(60):
            data.ctrl[:] = data.qpos[7:] + sign * (3.0 + 10 * table / kp)
            mujoco.mj_step(body, data)
            assert np.all(np.abs(data.actuator_force) <= table * (1 + 1e-12))
            assert np.all(np.abs(data.qfrc_actuator[dof]) <= table * (1 + 1e-9))
            reached = np.maximum(reached, np.abs(data.actuator_force) / table)
        assert np.all(np.isfinite(data.qpos))
    assert reached.min() > 0.999


def test_motor_actuators_clamp_torque_to_the_human_limit():
    """``actuators="motor"``: ``ctrl`` is the torque, clamped to the same human limits."""
    motor = sim_model(canonical_skeleton(), actuators="motor")
    table = np.array([human_torque_limit(motor.actuator(i).name) for i in range(motor.nu)])
    np.testing.assert_array_equal(motor.actuator_ctrlrange[:, 1], table)
    data = mujoco.MjData(motor)
    data.qpos[2] = 2.0
    for sign in (1.0, -1.0):
        data.ctrl[:] = sign * 5 * table
        mujoco.mj_step(motor, data)
        np.testing.assert_allclose(data.actuator_force, sign * table)
    data.ctrl[:] = 0.3 * table
    mujoco.mj_step(motor, data)
    np.testing.assert_allclose(data.actuator_force, 0.3 * table)


@pytest.mark.parametrize("body", ["model", "lean_model"])
def test_every_joint_driven_past_its_limit_applies_at_most_the_limit(body, request):
    """Each control asks for several times the joint's peak torque (a target 3 rad off plus a
    huge feed-forward, both signs); the torque MuJoCo applies (``actuator_force`` and the
    actuator part of ``qfrc_actuator``) reaches the limit and never exceeds it (the lean body
    too)."""
    model = request.getfixturevalue(body)
    data = mujoco.MjData(model)
    lim = model.actuator_forcerange[:, 1]
    kp = model.actuator_gainprm[:, 0]
    dof = model.jnt_dofadr[model.actuator_trnid[:, 0]]
    reached = np.zeros(model.nu)
    for sign in (1.0, -1.0):
        mujoco.mj_resetData(model, data)
        data.qpos[2] = 2.0  # in the air: no floor contact
        for _ in range(60):
            data.ctrl[:] = data.qpos[7:] + sign * (3.0 + 10 * lim / kp)
            mujoco.mj_step(model, data)
            f = data.actuator_force
            assert np.all(np.abs(f) <= lim * (1 + 1e-12))
            assert np.all(np.abs(data.qfrc_actuator[dof]) <= lim * (1 + 1e-9))
            reached = np.maximum(reached, np.abs(f) / lim)
    assert reached.min() > 0.999  # every joint was pushed to its limit


def test_tracking_torques_stay_within_limits_a_weakening_lowers_them_and_the_model_is_kept(
    model, walk_ref
):
    """A weakening scales the controller's effort, never the body: the torques stay within the
    human limits before and during it, are smaller while it lasts than the same ticks of an
    unweakened run, and the model is left as it was (a dataset replays on the model it
    stores)."""
    before = (model.actuator_gainprm.copy(), model.actuator_biasprm.copy(),
              model.actuator_forcerange.copy(), int(model.opt.disableflags))  # fmt: skip
    r = track(model, walk_ref, assist_limit=0.5, weakenings=(Weakening(0.2, 10.0, 0.3),))
    full = track(model, walk_ref, assist_limit=0.5)
    lim = np.array([human_torque_limit(model.actuator(i).name) for i in range(model.nu)])
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-12))
    assert np.abs(r.joint_torque[:6]).max() > 0.5 * lim.max()  # the limits are not idle
    # weakened from 0.2 s on (recorded frame 6 = tick 24 = 0.2 s): leg and trunk torques shrink
    legs = [i for i in range(model.nu) if model.actuator(i).name[1:6] in ("femur", "tibia")]
    weak, strong = (
        np.abs(r.joint_torque[7:, legs]).mean(),
        np.abs(full.joint_torque[7:, legs]).mean(),
    )
    assert weak < 0.85 * strong  # (the sagging body asks more of each joint than 0.3 of it)
    after = (model.actuator_gainprm, model.actuator_biasprm, model.actuator_forcerange,
             int(model.opt.disableflags))  # fmt: skip
    for a, b in zip(before[:3], after[:3], strict=True):
        assert np.array_equal(a, b)
    assert before[3] == after[3]


def test_model_edits_are_restored_when_tracking_raises(model):
    flags = int(model.opt.disableflags)
    with pytest.raises(RuntimeError), ActuatorEdits(model) as edits:
        edits.without_contacts()
        assert int(model.opt.disableflags) != flags
        raise RuntimeError("interrupted")
    assert int(model.opt.disableflags) == flags


def test_no_assistance_without_floor_contact(model, walk_ref):
    """The walk lifted 50 cm for 0.3 s: nothing touches the floor, so no assistance acts and the centre of
    mass falls freely (its height a parabola of curvature -g: internal torques cannot change
    it); with ``assist_in_flight`` the same controller holds the body up."""
    lifted = walk_ref[:36].copy()
    lifted[:, 2] += 0.5
    r = track(model, lifted, assist_limit=3.0)
    assert r.assistance.max() == 0.0 and np.abs(r.assist_wrench).max() == 0.0
    data = mujoco.MjData(model)
    t = np.arange(len(r.qpos)) * SUBSTEPS / 120.0
    com = []
    for q in r.qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        com.append(data.subtree_com[0, 2])
    a = np.polyfit(t, com, 2)[0]
    assert a == pytest.approx(-9.81 / 2, rel=0.02)
    held = track(model, lifted, assist_limit=3.0, assist_in_flight=True)
    assert held.assistance.mean() > 0.5


def test_foot_forces_and_assistance_carry_the_body_weight(trial_on_floor):
    """Momentum balance over a 2 s walk: the mean vertical floor force on the feet plus the
    vertical assistance equals the body weight (the body's vertical momentum returns near its
    start); contact labels are where the force is. On capsule feet: the sole boxes' landings
    are spikier than every 4th tick's first step samples (measured on this walk: 0.58 body
    weight sampled, 0.70 over every physics step), which this test is not about."""
    from sim.simulate.model import total_mass

    model = sim_model(canonical_skeleton(), soles=False)
    r = track(model, trial_on_floor(model, "02_01")[:240], assist_limit=0.5)
    weight = total_mass(model) * 9.81
    assert not r.fell
    support = (r.foot_force[:, :, 2].sum(axis=1) + r.assist_wrench[:, 2]) / weight
    momentum = total_mass(model) * (r.qvel[-1, 2] - r.qvel[0, 2]) / (len(r.qpos) * 4 / 120)
    # sampled at every 4th tick's first step: landings make the sample mean noisy (measured 5 %)
    assert support.mean() - momentum / weight == pytest.approx(1.0, abs=0.08)
    assert np.all(r.foot_force[:, :, 2] >= 0)  # the floor only pushes
    both_off = (r.foot_force[:, :, 2] == 0).all(axis=1)
    assert both_off.mean() < 0.3  # a walk has a foot down most of the time


def test_max_assistance_keeps_only_clips_within_the_budget(tmp_path):
    """The same plan with and without the filter: the kept clips are exactly the plan's clips
    within the budget, in plan order, bit for bit, and the rejected count is the others tried."""
    import json

    from sim.simulate.dataset import synthesize

    kw = dict(kinds=("procedural",), seconds=0.5, seed=2, workers=1, progress=False)
    full = synthesize(None, tmp_path / "all", 6, **kw)
    means = [max(r["mean_assistance"], r["mean_assist_torque"]) for r in full.written]
    budget = float(np.median(means))
    inside = [r for r, m in zip(full.written, means, strict=True) if m <= budget]
    assert 0 < len(inside) < len(means)
    keep = len(inside)  # up to the plan's last clip within the budget
    kept = synthesize(None, tmp_path / "kept", keep, max_assistance=budget, **kw)
    assert [r["trial"] for r in kept.written] == [r["trial"] for r in inside[:keep]]
    assert all(max(r["mean_assistance"], r["mean_assist_torque"]) <= budget for r in kept.written)
    last = int(kept.written[-1]["trial"].split("_")[-1])
    rejected = sum(m > budget for m in means[: last + 1])
    assert kept.rejected == ({"procedural": rejected} if rejected else {})
    index = json.loads((tmp_path / "kept" / "index.json").read_text())
    assert index["synthetic"]["rejected"] == kept.rejected
    for r in kept.written:
        with (
            np.load(tmp_path / "kept" / r["file"]) as a,
            np.load(tmp_path / "all" / r["file"]) as b,
        ):
            assert all(np.array_equal(a[k], b[k]) for k in a.files)


@pytest.mark.parametrize("body", ["model", "lean_model"])
def test_non_adjacent_bodies_collide_and_near_ones_do_not(body, request):
    """Legs driven to cross stop at each other: the shins' and thighs' overlap in the simulation
    stays at the contact softness, while the pose they were driven to overlaps by several cm;
    in the rest pose nothing touches (pairs meeting at a joint are excluded). The lean body
    too."""
    from sim.simulate.model import self_collision_exclusions

    model = request.getfixturevalue(body)
    data = mujoco.MjData(model)
    data.qpos[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]
    data.qpos[2] = 2.0
    mujoco.mj_forward(model, data)
    assert data.ncon == 0  # the upright rest pose, in the air: no self-contact
    names = {n for pair in self_collision_exclusions(model) for n in pair}
    assert ("ltibia", "rtibia") not in self_collision_exclusions(model) and "ltibia" in names
    legs = {model.geom(n).id for n in ("lfemur", "rfemur", "ltibia", "rtibia")}

    def leg_overlap(d) -> float:
        depth = [-d.contact.dist[c] for c in range(d.ncon) if set(d.contact.geom[c]) <= legs]
        return max(depth, default=0.0)

    crossed = data.qpos.copy()
    for side, sign in (("l", 1.0), ("r", -1.0)):  # both thighs adducted across the midline
        j = model.joint(f"{side}femur_rz")
        crossed[model.jnt_qposadr[j.id]] = np.clip(sign * -0.8, *model.jnt_range[j.id])
    target = mujoco.MjData(model)
    target.qpos[:] = crossed
    mujoco.mj_forward(model, target)
    assert leg_overlap(target) > 0.05  # the pose asked for puts a leg through the other
    model.opt.gravity[2] = 0.0
    try:
        deepest = 0.0
        for _ in range(240):  # 0.5 s of the position servos pulling the legs across
            data.ctrl[:] = crossed[7:]
            mujoco.mj_step(model, data)
            deepest = max(deepest, leg_overlap(data))
    finally:
        model.opt.gravity[2] = -9.81
    assert 0.0 < deepest < 0.5 * leg_overlap(target)  # they met and stopped at each other


def test_a_fallen_body_stays_down_without_help(model, trial_on_floor):
    """Pushed hard with the joints weakened, the walker falls; from the fall on there is no
    assistance and the joints hold the pose of the fall: the root stays near the floor."""
    from sim.simulate.controller import Push

    ref = trial_on_floor(model, "02_01")[:336]
    r = track(model, ref, assist_limit=0.5, pushes=(Push("thorax", 0.5, 0.2, (700.0, 0, 0)),),
              weakenings=(Weakening(0.5, 0.8, 0.1),))  # fmt: skip
    assert r.fell and r.fall_frame > 0
    after = r.fall_frame + 15  # half a second after the fall was detected
    assert after < len(r.qpos) - 15
    assert r.qpos[after:, 2].max() < 0.35  # standing, the root is at ~0.9 m
    assert np.abs(r.assist_wrench[r.fall_frame + 1 :]).max() == 0.0


def test_leg_gains_of_their_own_leave_the_rest_stiff_and_the_limits_human():
    """``Gains(legs=...)``: the leg hinges (femur, tibia, foot, toes) take the legs' gains, every
    other hinge the stiffer ones; the torque limits are the same in both."""
    from sim.simulate.model import Gains

    sk = canonical_skeleton()
    stiff = Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)
    default, all_stiff = sim_model(sk), sim_model(sk, gains=stiff)
    upper = sim_model(sk, gains=Gains(min_deflection=0.1, omega=2 * np.pi * 12.0, legs=Gains()))
    names = [default.actuator(a).name for a in range(default.nu)]
    leg = np.array([n[1:].split("_")[0] in ("femur", "tibia", "foot", "toes") for n in names])
    assert leg.sum() == 14  # 2 x (femur 3, tibia 1, foot 2, toes 1)
    kp = upper.actuator_gainprm[:, 0]
    np.testing.assert_array_equal(kp[leg], default.actuator_gainprm[leg, 0])
    np.testing.assert_array_equal(kp[~leg], all_stiff.actuator_gainprm[~leg, 0])
    np.testing.assert_array_equal(upper.actuator_biasprm[leg, 2], default.actuator_biasprm[leg, 2])
    assert (kp[~leg] > default.actuator_gainprm[~leg, 0]).all()
    np.testing.assert_array_equal(upper.actuator_forcerange, default.actuator_forcerange)
