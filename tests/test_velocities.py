"""True velocities: chain velocities agree with finite differences to second order and recover
analytic motion exactly."""

from __future__ import annotations

import mujoco
import numpy as np

from sim.model.humanoid import humanoid_model
from sim.model.kinematics import point_names, point_parents
from sim.motion.ingest import clip_from_qpos
from sim.motion.synthetic import synthetic_qpos
from sim.motion.velocities import qvel_from_qpos


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
