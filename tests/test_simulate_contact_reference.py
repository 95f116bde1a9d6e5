"""The reference the plain tracker and the sampler track (``sim.simulate.validate.
ForwardValidation(contact_reference=...)``): the lifted one by default, unchanged; the
contact-consistent one on request, its stance soles on the simulated floor (z = 0), while every
figure is still measured against the lifted reference's points."""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

import sim.simulate.validate as validate
from sim.model.humanoid import canonical_skeleton
from sim.simulate.model import CONTROL_HZ
from sim.simulate.reference import FLOOR_LIFT, flat_soles, lowest_foot_point, time_warp

NAMES = ("root", "lfoot", "rfoot", "head")


@pytest.fixture(scope="module")
def bodies():
    """(lifted, contact): the plain tracker's forward validation without and with
    ``contact_reference`` (the reference is the same for the sampler; the plain tracker is cheap)."""
    skeleton = canonical_skeleton()
    return (
        validate.forward_validation(skeleton, NAMES, controller="plain"),
        validate.forward_validation(skeleton, NAMES, controller="plain", contact_reference=True),
    )


@pytest.fixture(scope="module")
def walk(trial_on_floor, bodies):
    """(qpos (T, nq) at 30 fps: 3 s of the walk 02_01, floor (T',) under it at the control rate)."""
    qpos = trial_on_floor(bodies[0].model, "02_01")[:360:4]
    return qpos, bodies[0].floor_of(time_warp(bodies[0].model, qpos, 30.0, 1.0, CONTROL_HZ))


def _stance(model, ref) -> np.ndarray:
    """(T,) the lowest sole point [m] of ``ref`` and whether it stands (within 3 cm)."""
    low = lowest_foot_point(model, ref)
    return low, low <= 0.03


def test_the_default_reference_is_the_lifted_one_unchanged(bodies, walk):
    """The default: resampled, lowered by the floor, lifted 1 cm, soles laid flat (built here
    from its parts), and its stance soles hover about the lift above z = 0."""
    lifted, _ = bodies
    qpos, floor = walk
    ref = lifted.reference(qpos, 30.0, floor)
    expected = time_warp(lifted.model, qpos, 30.0, 1.0, CONTROL_HZ)
    expected[:, 2] -= floor - FLOOR_LIFT
    np.testing.assert_array_equal(ref, flat_soles(lifted.model, expected))
    low, stance = _stance(lifted.model, ref)
    assert stance.mean() > 0.5 and np.median(low[stance]) > FLOOR_LIFT / 2


def test_the_contact_reference_stands_its_stance_soles_on_the_floor(bodies, walk):
    """With ``contact_reference`` the stance soles touch z = 0 (within 2 mm, where the lifted
    ones hover about 1 cm); only the height and the ankles (laid flat 1 cm lower) differ from
    the lifted reference, and the height by the lift and the floor estimate's error (cm)."""
    lifted, contact = bodies
    qpos, floor = walk
    a, b = lifted.reference(qpos, 30.0, floor), contact.reference(qpos, 30.0, floor)
    low, stance = _stance(contact.model, b)
    assert stance.mean() > 0.5 and np.median(np.abs(low[stance])) < 0.002
    ankles = [contact.model.jnt_qposadr[contact.model.joint(f"{s}foot_{a}").id]
              for s in "lr" for a in ("rx", "rz")]  # fmt: skip
    same = np.setdiff1d(np.arange(qpos.shape[1]), [2, *ankles])
    np.testing.assert_array_equal(a[:, same], b[:, same])
    dz = a[:, 2] - b[:, 2]
    assert 0.5 * FLOOR_LIFT < np.median(dz) < 3 * FLOOR_LIFT and np.abs(dz).max() < 0.05
    # the contact reference asked of the lifted body gives the same
    np.testing.assert_array_equal(lifted.reference(qpos, 30.0, floor, contact=True), b)


def test_figures_are_measured_against_the_lifted_points_whatever_is_tracked(
    bodies, walk, monkeypatch
):
    """A tracker that ends exactly in the lifted reference's states has no error whichever
    reference it was given: the errors and the skating's reference do not move with the
    option. The tracked contact-consistent reference of a reconstruction 3 cm too low is
    lowered by the original's shift: it stays 3 cm below the original's (its own height error
    kept, as the floor track keeps it)."""
    qpos, _ = walk
    tracked = {}

    def perfect(model, ref, *, assist_limit, record_every):
        tracked["ref"] = ref
        lift = bodies[0].reference(tracked["qpos"], 30.0, tracked["floor"], contact=False)
        states = lift[::record_every]
        return SimpleNamespace(qpos=states, fell=False, fall_frame=-1, unstable=False,
                               joint_torque=np.zeros((len(states), model.nu)))  # fmt: skip

    monkeypatch.setattr(validate, "track", perfect)
    low_recon = qpos.copy()
    low_recon[:, 2] -= 0.03
    figures, refs = [], []
    for body in bodies:
        for motion in (qpos, low_recon):
            orig = time_warp(body.model, qpos, 30.0, 1.0, CONTROL_HZ)
            tracked.update(qpos=motion, floor=body.floor_of(orig))
            figures.append(body.run(motion, 30.0, original_qpos=qpos))
            refs.append(tracked["ref"])
    for f in figures:
        assert f["sim_error_mm"] == pytest.approx(0.0, abs=1e-9)
        assert f["sim_error_local_mm"] == pytest.approx(0.0, abs=1e-9)
    assert figures[0]["sim_error_original_mm"] == pytest.approx(0.0, abs=1e-9)
    assert figures[1]["sim_error_original_mm"] == pytest.approx(30.0, abs=0.5)
    for i in range(2):  # the same figures with the option
        assert figures[i] == figures[i + 2]
    np.testing.assert_allclose(refs[1][:, 2] - refs[0][:, 2], -0.03, atol=1e-12)  # lifted
    np.testing.assert_allclose(refs[3][:, 2] - refs[2][:, 2], -0.03, atol=1e-12)  # contact
    low, stance = _stance(bodies[1].model, refs[2])
    assert np.median(np.abs(low[stance])) < 0.002  # the original's tracked soles on z = 0


def test_the_option_goes_to_other_processes(bodies):
    import pickle

    lifted, contact = bodies
    assert not pickle.loads(pickle.dumps(lifted)).contact
    assert pickle.loads(pickle.dumps(contact)).contact


def test_the_floor_bound_keeps_every_sole_above_the_floor(bodies, walk):
    """A stamp as the IK fits of the Russian dances have (a foot dipping 12 cm through the
    floor within 0.1 s, put here into the walk by lowering the root over 4 frames at 30 fps):
    the contact-consistent shift smoothed alone leaves a sole centimetres under the floor; with
    ``floor_bound`` it lifts the body over the stamp, so no sole box corner (each box's corners
    computed here from its pose and half sizes) is below z = 0 in any tick, and the stance
    soles elsewhere still touch the floor."""
    from sim.simulate.reference import contact_shift

    _, contact = bodies
    qpos, floor = walk
    stamped = qpos.copy()
    stamped[40:44, 2] -= np.array([0.06, 0.12, 0.12, 0.06])
    model = contact.model
    ref = time_warp(model, stamped, 30.0, 1.0, CONTROL_HZ)
    ref[:, 2] -= floor
    ref = flat_soles(model, ref)  # as ForwardValidation.reference lays it before the shift
    data = mujoco.MjData(model)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    soles = [model.geom(n).id for n in ("lsole", "rsole", "ltoesole", "rtoesole")]

    def lowest(shift):
        out = np.empty(len(ref))
        for t, q in enumerate(ref):
            data.qpos[:] = q
            data.qpos[2] -= shift[t]
            mujoco.mj_kinematics(model, data)
            z = [(data.geom_xpos[g] + (signs * model.geom_size[g]) @ data.geom_xmat[g].reshape(3, 3).T)[:, 2].min()
                 for g in soles]  # fmt: skip
            out[t] = min(z)
        return out

    assert lowest(contact_shift(model, ref)).min() < -0.02  # smoothing alone: under the floor
    bound = lowest(contact_shift(model, ref, floor_bound=True))
    assert bound.min() > -1e-9
    stance = bound <= 0.03
    assert stance.mean() > 0.5 and np.median(bound[stance]) < 0.002


def test_a_flight_that_floats_is_stance_and_a_jump_stays_a_flight():
    """``supported``: a 0.4 s flight whose root follows free fall (z = v t - g t^2 / 2) stays a
    flight; the same 0.4 s with the root hovering at one height, or rising steadily, cannot be
    a flight (nothing holds a body up but the floor) and becomes stance; a 0.1 s hover (a
    run's flight, too short to judge) is kept."""
    from sim.simulate.reference import supported

    rate = 120.0
    t = np.arange(48) / rate  # 0.4 s
    stance = np.ones(120, bool)
    stance[30:78] = False
    jump = np.full(120, 0.9)
    jump[30:78] += 1.96 * t - 9.81 * t**2 / 2  # take-off at 1.96 m/s: lands after 0.4 s
    np.testing.assert_array_equal(supported(jump, stance, rate), stance)
    hover = np.full(120, 0.9)
    assert supported(hover, stance, rate).all()
    rising = 0.9 + 0.3 * np.arange(120) / rate
    assert supported(rising, stance, rate).all()
    short = np.ones(120, bool)
    short[30:42] = False
    np.testing.assert_array_equal(supported(hover, short, rate), short)


def test_eval_sets_a_floating_reference_on_the_floor(bodies, walk, monkeypatch):
    """``validate.DEFAULT_FLOATING`` (an option, off by default): the walk with its body lifted 10 cm for 0.6 s (a steady
    hover, no free fall) is set back on the floor by ``ForwardValidation.reference``: in the
    middle of the hover its lowest sole is within 1 cm of z = 0, where the reference without
    the option hovers about 10 cm up."""
    from sim.simulate.reference import contact_shift

    _, contact = bodies
    qpos, floor = walk
    lifted = qpos.copy()
    lifted[30:48, 2] += 0.10
    monkeypatch.setattr(validate, "DEFAULT_FLOATING", True)
    ref = contact.reference(lifted, 30.0, floor)
    mid = slice(40 * 4, 44 * 4)  # control ticks in the hover's middle
    assert lowest_foot_point(contact.model, ref[mid]).max() < 0.01
    plain = time_warp(contact.model, lifted, 30.0, 1.0, CONTROL_HZ)
    plain[:, 2] -= floor
    plain = flat_soles(contact.model, plain)
    plain[:, 2] -= contact_shift(contact.model, plain)
    assert lowest_foot_point(contact.model, plain[mid]).min() > 0.05


def _body_positions(model, qpos) -> np.ndarray:
    """(T, nbody, 3) every body's world position [m] by MuJoCo's kinematics of ``qpos``."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), model.nbody, 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out[t] = data.xpos
    return out


def test_hinges_whole_turns_off_their_range_are_wrapped_to_the_same_pose(bodies, trial_on_floor):
    """CMU's 60_01 holds the left foot's rx near 6.3 rad and a thumb at 20 rad, whole turns
    outside their ranges: ``wrap_hinges`` brings every limited hinge's median within half a
    turn of its range's middle with no jump of half a turn between frames, leaves a hinge
    already there bit for bit, and the bodies stand where they stood (MuJoCo's kinematics of
    both); ``time_warp`` tracks the wrapped angles."""
    from sim.simulate.reference import wrap_hinges

    model = bodies[0].model
    qpos = trial_on_floor(model, "60_01")[:2400:4]
    hinge = (model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE) & (model.jnt_limited != 0)
    adr, mid = model.jnt_qposadr[hinge], model.jnt_range[hinge].mean(axis=1)
    assert np.abs(qpos[:, adr] - mid).max() > 2 * np.pi  # the trial does hold such angles
    wrapped = wrap_hinges(model, qpos)
    assert np.abs(np.median(wrapped[:, adr], axis=0) - mid).max() <= np.pi + 1e-12
    assert np.abs(np.diff(wrapped[:, adr], axis=0)).max() <= np.pi
    near = (np.abs(qpos[:, adr] - mid) < np.pi).all(axis=0)  # hinges never a half turn out
    near &= (np.abs(np.diff(qpos[:, adr], axis=0)) < np.pi).all(axis=0)
    assert near.sum() > 30 and (wrapped[:, adr[near]] == qpos[:, adr[near]]).all()
    turns = (wrapped - qpos) / (2 * np.pi)
    assert np.allclose(turns, np.round(turns), atol=1e-9)
    assert np.abs(_body_positions(model, wrapped) - _body_positions(model, qpos)).max() < 1e-9
    warped = time_warp(model, qpos, 30.0, 1.0, CONTROL_HZ)
    assert np.abs(np.median(warped[:, adr], axis=0) - mid).max() <= np.pi + 1e-12


def test_a_turn_between_two_frames_does_not_sweep_the_limb_round(bodies):
    """A hinge that reads just inside its range in one frame and the same angle plus a turn in
    the next is the same pose twice: the frames between them stay there too."""
    model = bodies[0].model
    j = next(j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
             and model.jnt_limited[j])  # fmt: skip
    q = np.tile(model.qpos0, (2, 1))
    angle = model.jnt_range[j].mean()
    q[:, model.jnt_qposadr[j]] = angle, angle + 2 * np.pi
    warped = time_warp(model, q, 30.0, 1.0, CONTROL_HZ)
    assert np.allclose(warped[:, model.jnt_qposadr[j]], angle, atol=1e-9)
