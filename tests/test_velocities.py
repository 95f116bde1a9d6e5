"""True velocities: chain velocities agree with finite differences to second order and recover
analytic motion exactly."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import humanoid_model
from sim.model.kinematics import point_names, point_parents
from sim.motion.ingest import clip_from_qpos
from sim.motion.synthetic import synthetic_qpos
from sim.motion.velocities import (
    body_rotation_steps,
    kin_related,
    point_derivatives,
    pose_jumps,
    qvel_from_qpos,
)


def test_constant_rate_hinge_sweep_is_recovered_exactly():
    skel, model = humanoid_model()
    rate, omega = 120.0, 1.7  # [1/s], [rad/s]
    T = 40
    qpos = np.tile(model.qpos0, (T, 1))
    qpos[:, 2] = 1.0
    hinge = model.joint("rhumerus_rx").qposadr[0]
    qpos[:, hinge] = omega * np.arange(T) / rate
    clip = clip_from_qpos(
        model, point_names(skel), point_parents(skel), qpos, source_fps=rate, fps=rate
    )
    dof = model.joint("rhumerus_rx").dofadr[0]
    np.testing.assert_allclose(clip.qvel[:, dof], omega, atol=1e-12)
    others = np.delete(clip.qvel, dof, axis=1)
    np.testing.assert_allclose(others, 0.0, atol=1e-12)
    # A point on the swept chain moves as omega x r about the hinge axis.
    data = mujoco.MjData(model)
    j = clip.index("rradius")
    body = model.body("rhumerus").id
    for t in (0, T // 2, T - 1):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        axis = data.xmat[body].reshape(3, 3) @ np.array([1.0, 0.0, 0.0])
        r = clip.positions[t, j] - data.xpos[body]
        np.testing.assert_allclose(clip.velocities[t, j], omega * np.cross(axis, r), atol=1e-9)
        # Bodies below the hinge turn at omega about its axis; bodies elsewhere do not turn.
        np.testing.assert_allclose(clip.angular_velocities[t, j], omega * axis, atol=1e-12)
        np.testing.assert_allclose(clip.angular_velocities[t, clip.index("lradius")], 0, atol=1e-12)


def test_qvel_matches_analytic_hinge_rates_to_second_order():
    _, model = humanoid_model()
    errs = []
    for rate in (120.0, 240.0):
        qpos, dhinge = synthetic_qpos(model, 1.0, seed=3, rate=rate)
        qvel = qvel_from_qpos(model, qpos, rate)
        errs.append(np.abs(qvel[1:-1, 6:] - dhinge[1:-1]).max() / np.abs(dhinge).max())
    assert errs[0] < 5e-3
    assert errs[0] / errs[1] > 3.5  # halving h quarters the error: second order


def test_point_velocities_agree_with_position_differences(walk_clip):
    skel, model = humanoid_model()
    errs = []
    for rate in (120.0, 480.0):
        qpos, _ = synthetic_qpos(model, 1.0, seed=5, rate=rate)
        c = clip_from_qpos(
            model, point_names(skel), point_parents(skel), qpos, source_fps=rate, fps=rate
        )
        fd = (c.positions[2:] - c.positions[:-2]) * rate / 2
        errs.append(np.abs(fd - c.velocities[1:-1]).max())
    assert errs[0] < 0.05
    assert errs[0] / errs[1] > 10  # second order: 4x the rate, ~16x smaller error


def test_real_clip_velocities_are_consistent_with_positions(cmu_dir):
    from sim.motion.ingest import load_motion

    c = load_motion(cmu_dir / "09" / "09.asf", cmu_dir / "09" / "09_06.amc", fps=120)
    fd = (c.positions[2:] - c.positions[:-2]) * 60.0
    err = np.linalg.norm(fd - c.velocities[1:-1], axis=-1)
    speed = np.linalg.norm(c.velocities[1:-1], axis=-1)
    assert np.median(err) < 0.01 * np.median(speed) + 1e-3


def test_euler_flips_in_an_amc_file_change_no_point_and_no_velocity(cmu_dir, tmp_path):
    """A take written with some frames' Euler triples swapped for their twins (three-dof bones)
    and whole turns added (every bone) ingests to the same qpos, points and velocities."""
    from dataclasses import replace

    from sim.acclaim.amc import parse_amc
    from sim.acclaim.asf import parse_asf
    from sim.acclaim.writer import write_amc
    from sim.model.rotations import euler_twin
    from sim.motion.ingest import load_motion

    asf = cmu_dir / "02" / "02.asf"
    skeleton = parse_asf(asf)
    motion = parse_amc(cmu_dir / "02" / "02_01.amc", skeleton)
    motion = replace(motion, root=motion.root[:160], angles={
        k: v[:160] for k, v in motion.angles.items()})  # fmt: skip
    rng = np.random.default_rng(0)
    flipped = {}
    for b in skeleton.bones:
        a = motion.angles.get(b.name)
        if a is None or not b.dofs:
            continue
        a = a.copy()
        if len(b.dofs) == 3:
            a[30:49] = np.degrees(euler_twin(np.radians(a[30:49])))
        a += 360.0 * rng.integers(-2, 3, a.shape) * (rng.random(a.shape) < 0.1)
        flipped[b.name] = a
    write_amc(tmp_path / "plain.amc", skeleton, motion)
    write_amc(tmp_path / "flipped.amc", skeleton, replace(motion, angles=flipped))
    plain = load_motion(asf, tmp_path / "plain.amc")
    jumpy = load_motion(asf, tmp_path / "flipped.amc")
    assert np.abs(np.diff(flipped["lfemur"], axis=0)).max() > 90  # the file does jump
    np.testing.assert_allclose(jumpy.qpos, plain.qpos, atol=1e-9)
    np.testing.assert_allclose(jumpy.positions, plain.positions, atol=1e-9)
    np.testing.assert_allclose(jumpy.velocities, plain.velocities, atol=1e-6)
    assert np.linalg.norm(plain.velocities, axis=-1).max() < 10.0  # a walk


def test_a_pose_jump_stays_in_the_positions_and_out_of_the_velocities():
    """A femur turned half a turn for ten frames (a solver's flip, as in CMU 05_06): the jump is
    found at its two steps, the velocities everywhere are the unbroken motion's to first order,
    and frames away from it keep the central difference exactly."""
    _, model = humanoid_model()
    rate = 120.0
    qpos, _ = synthetic_qpos(model, 1.0, seed=2, rate=rate)
    glitch = qpos.copy()
    hinge = model.joint("rfemur_rz").qposadr[0]
    glitch[50:60, hinge] += np.pi
    femur = model.body("rfemur").id
    related = kin_related(model)
    jumps = pose_jumps(body_rotation_steps(model, glitch), rate, related)
    assert np.flatnonzero(jumps.any(axis=1)).tolist() == [49, 59]
    assert jumps[[49, 59], femur].all()
    assert not pose_jumps(body_rotation_steps(model, qpos), rate, related).any()  # smooth: none

    truth = qvel_from_qpos(model, qpos, rate)
    plain = qvel_from_qpos(model, glitch, rate)
    fixed = qvel_from_qpos(model, glitch, rate, across_jumps=False)
    dof = model.joint("rfemur_rz").dofadr[0]
    assert np.abs(plain[:, dof] - truth[:, dof]).max() > 0.9 * np.pi * rate / 2  # ~188 rad/s
    scale = np.abs(truth).max()
    assert np.abs(fixed - truth).max() < 0.05 * scale  # one-sided: first-order error only
    away = np.r_[0:48, 52:58, 62 : len(qpos)]
    np.testing.assert_array_equal(fixed[away], plain[away])


def test_real_take_with_pose_jumps_keeps_velocities_to_the_points(cmu_dir):
    """CMU 05_06 turns its right femur by ~180 deg in one source frame and back, several times
    (the points jump with it: the knee 39 cm in 1/120 s). Velocities beside those frames stay
    those of the motion; away from them they are the points' finite differences."""
    from sim.motion.ingest import load_motion

    c = load_motion(cmu_dir / "05" / "05.asf", cmu_dir / "05" / "05_06.amc", fps=120)
    knee = c.index("rfemur")
    step = np.linalg.norm(np.diff(c.positions[:, knee], axis=0), axis=-1)
    assert step.max() > 0.3  # the data's own jump [m per frame], kept
    speed = np.linalg.norm(c.velocities, axis=-1)
    assert speed.max() < 30.0  # [m/s]; differenced across the jumps: 165
    fd = (c.positions[2:] - c.positions[:-2]) * 60.0
    err = np.linalg.norm(fd - c.velocities[1:-1], axis=-1)
    near = np.zeros(len(c.positions), dtype=bool)
    for t in np.flatnonzero(step > 0.1):
        near[max(t - 2, 0) : t + 4] = True
    err = err[~near[1:-1]]
    assert np.median(err) < 0.01
    assert np.percentile(err, 99) < 0.5  # [m/s]; the rest: 15-60 deg steps, second order


def test_source_derivatives_are_not_taken_across_a_pose_jump():
    """A point whose data jumps 30 cm (a solver's flip) keeps, on each side of the jump, the
    derivatives of its own smooth path; a point the jump does not move is untouched."""
    rate, T = 120.0, 80
    t = np.arange(T) / rate
    smooth = np.stack([np.sin(3 * t), np.cos(2 * t), 0.1 * t], axis=-1)
    p = np.stack([smooth, smooth], axis=1)  # (T, 2, 3)
    p[40:, 0, 0] += 0.3  # point 0 jumps between samples 39 and 40
    cuts = np.zeros((T - 1, 2), bool)
    cuts[39, 0] = True
    vel, acc = point_derivatives(p, rate, cuts=cuts)
    v_true = np.stack([3 * np.cos(3 * t), -2 * np.sin(2 * t), 0.1 + 0 * t], axis=-1)
    a_true = np.stack([-9 * np.sin(3 * t), -4 * np.cos(2 * t), 0 * t], axis=-1)
    np.testing.assert_allclose(vel[:, 0], v_true, atol=2e-3)
    np.testing.assert_allclose(acc[:, 0], a_true, atol=0.2)
    plain_v, plain_a = point_derivatives(p, rate)
    assert np.abs(plain_a[:, 0] - a_true).max() > 100  # across it: 0.3 m in 8 ms
    np.testing.assert_array_equal(vel[:, 1], plain_v[:, 1])
    np.testing.assert_array_equal(acc[:, 1], plain_a[:, 1])


def test_edge_windows_differentiate_a_quartic_exactly_and_say_how_much_noise_they_pass():
    """At a take's ends the source window shifts inward: a quartic is still differentiated
    exactly there, but sample noise passes 5.3x as strongly into the first frame's
    acceleration (derivative_noise says so, and seeded noise shows it)."""
    from sim.motion.velocities import SOURCE_WINDOW, derivative_noise, point_derivatives

    fps, T = 120.0, 49
    t = np.arange(T) / fps
    c = np.array([[0.3, -1.2, 4.0, 2.5, -3.0], [1.0, 0.5, -2.0, 6.0, 1.5]])  # (2 points, degree 4)
    pos = np.zeros((T, 2, 3))
    vel = np.zeros_like(pos)
    acc = np.zeros_like(pos)
    for j in range(2):
        for k in range(3):
            cj = c[j] * (k + 1)
            pos[:, j, k] = sum(cj[n] * t**n for n in range(5))
            vel[:, j, k] = sum(n * cj[n] * t ** (n - 1) for n in range(1, 5))
            acc[:, j, k] = sum(n * (n - 1) * cj[n] * t ** (n - 2) for n in range(2, 5))
    frames = np.array([0, 1, 2, 4, 24, T - 3, T - 1])
    v, a = point_derivatives(pos, fps, frames)
    np.testing.assert_allclose(v, vel[frames], atol=1e-8)
    np.testing.assert_allclose(a, acc[frames], atol=1e-6)
    gain = derivative_noise(T, frames, points=2)
    assert gain.shape == (len(frames), 2)
    assert gain[0, 0] == pytest.approx(5.33, abs=0.01)  # read at the window's first sample
    assert gain[-1, 0] == pytest.approx(gain[0, 0])  # and at its last
    assert gain[1, 0] == pytest.approx(3.93, abs=0.01)
    # four samples in: as centred (the two windows' sums agree to rounding, not bit for bit)
    assert gain[3, 0] <= 1.0 + 1e-9 and gain[4, 0] == pytest.approx(1.0)
    # the ratio is what noise does: seeded white noise through both windows
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 1e-3, (4000, T, 1, 3))
    a_edge = np.array([point_derivatives(n, fps, [0, 24])[1] for n in noise[:, :, :, :]])
    ratio = a_edge[:, 0].std() / a_edge[:, 1].std()
    assert ratio == pytest.approx(gain[0, 0], rel=0.05)
    assert SOURCE_WINDOW == 17


def test_derivative_noise_beside_a_pose_jump_is_the_cut_points_own():
    """A pose jump cuts one point's samples: frames whose window it shortens pass more noise
    for that point only; a piece too short for a fit reads its neighbour's, extrapolated (more
    still); a take too short for any fit is not measured at all."""
    from sim.motion.velocities import NO_WINDOW_NOISE, derivative_noise

    T = 80
    cuts = np.zeros((T - 1, 2), dtype=bool)
    cuts[39, 1] = True  # point 1 jumps between samples 39 and 40
    cuts[41, 1] = True  # and back: samples 40, 41 are a piece of two
    g = derivative_noise(T, np.arange(T), cuts=cuts)
    assert np.allclose(g[8 : T - 8, 0], 1.0)  # the other point is untouched
    assert g[39, 1] == pytest.approx(5.33, abs=0.01)  # the last sample before the jump
    assert g[41, 1] > g[40, 1] > g[39, 1]  # two samples: the nearest piece's fit, extrapolated
    assert np.allclose(g[8:30, 1], 1.0) and np.allclose(g[52 : T - 8, 1], 1.0)
    assert (derivative_noise(2, points=3) == NO_WINDOW_NOISE).all()


def _rotations_by_columns(model, qpos):
    """The oracle: each body's joints composed on (T, 4) quaternion columns with
    ``quaternion.mul``, the steps as ``rotation_angle`` of consecutive frames."""
    from sim.model import quaternion as quat

    rot = np.zeros((qpos.shape[0], model.nbody, 4))
    rot[..., 0] = 1.0
    moved = np.zeros(model.nbody, dtype=bool)
    for j in range(model.njnt):
        kind, adr, b = model.jnt_type[j], model.jnt_qposadr[j], model.jnt_bodyid[j]
        if kind == mujoco.mjtJoint.mjJNT_HINGE:
            half = 0.5 * qpos[:, adr]
            local = np.column_stack([np.cos(half), np.sin(half)[:, None] * model.jnt_axis[j]])
        elif kind == mujoco.mjtJoint.mjJNT_BALL:
            local = qpos[:, adr : adr + 4]
        elif kind == mujoco.mjtJoint.mjJNT_FREE:
            local = qpos[:, adr + 3 : adr + 7]
        else:
            continue
        rot[:, b] = quat.mul(rot[:, b], local) if moved[b] else local
        moved[b] = True
    rel = quat.mul(quat.conj(rot[:-1]), rot[1:])
    steps = 2 * np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))
    return rot, steps


@pytest.mark.parametrize("subject, trial", [("05", "05_06"), ("17", "17_10"), ("02", "02_01")])
def test_body_rotations_and_their_steps_equal_quaternion_products_bit_for_bit(
    cmu_dir, subject, trial
):
    from sim.acclaim.amc import parse_amc
    from sim.motion.retarget import motion_to_qpos
    from sim.motion.trial import subject_model
    from sim.motion.velocities import body_joint_rotations

    skeleton, model = subject_model(cmu_dir / subject / f"{subject}.asf")
    qpos = motion_to_qpos(skeleton, parse_amc(cmu_dir / subject / f"{trial}.amc", skeleton), model)
    rot, steps = _rotations_by_columns(model, qpos)
    got = body_joint_rotations(model, qpos)
    assert got.shape == rot.shape and np.array_equal(got, rot)
    got_steps = body_rotation_steps(model, qpos)
    assert got_steps.shape == steps.shape and got_steps.flags.c_contiguous
    assert np.array_equal(got_steps, steps)
