"""Retargeting: MuJoCo's bodies on the subject's own model equal an independent FK
(``tests/acclaim_fk.py``: scipy rotations, no code shared with the model builder)."""

from __future__ import annotations

import warnings

import mujoco
import numpy as np
import pytest
from acclaim_fk import acclaim_points

from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import parse_asf
from sim.errors import MotionDataWarning
from sim.model.humanoid import HUMANOID_XML, build_mjcf, canonical_skeleton
from sim.model.kinematics import point_names
from sim.motion.ingest import load_motion

TRIALS = ["01/01_01", "05/05_06", "07/07_12", "17/17_10", "60/60_01"]


@pytest.mark.parametrize("trial", TRIALS)
def test_mujoco_bodies_match_numpy_forward_kinematics(cmu_dir, trial):
    subject = trial.split("/")[0]
    asf, amc = cmu_dir / subject / f"{subject}.asf", cmu_dir / f"{trial}.amc"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MotionDataWarning)
        clip = load_motion(asf, amc, fps=30)
        skel = parse_asf(asf)
        expected = acclaim_points(skel, parse_amc(amc, skel))[::4]
    assert clip.names == point_names(skel)
    np.testing.assert_allclose(clip.positions, expected, atol=1e-6)


def test_bone_lengths_are_constant_and_equal_the_asf(walk_clip, cmu_dir):
    skel = parse_asf(cmu_dir / "02" / "02.asf")
    lengths = np.linalg.norm(walk_clip.bone_vectors(), axis=-1)
    for j, name in enumerate(walk_clip.names[1:], start=1):
        np.testing.assert_allclose(lengths[:, j], skel.bone(name).length, atol=1e-9)


def test_world_frame_is_z_up_with_feet_near_the_floor(walk_clip):
    head = walk_clip.positions[:, walk_clip.index("head"), 2]
    feet = walk_clip.positions[:, [walk_clip.index("lfoot"), walk_clip.index("rfoot")], 2]
    assert head.min() > 1.3  # a standing adult's head
    assert np.abs(feet.min()) < 0.1


def test_shared_humanoid_is_the_generated_canonical_model():
    assert HUMANOID_XML.read_text() == build_mjcf(canonical_skeleton(), model_name="cmu_humanoid")
    model = mujoco.MjModel.from_xml_path(str(HUMANOID_XML))
    assert model.nbody == 32 and model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert model.camera("follow").mode == mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM


def test_humanoid_retarget_copies_angles_and_scales_the_root(cmu_dir):
    from sim.motion.retarget import leg_length

    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    own = load_motion(asf, amc)
    shared = load_motion(asf, amc, skeleton="humanoid")
    assert own.joint_names == shared.joint_names  # both are CMU 30-bone skeletons
    np.testing.assert_allclose(own.qpos[:, 7:], shared.qpos[:, 7:])
    np.testing.assert_allclose(own.qpos[:, 3:7], shared.qpos[:, 3:7])
    ratio = leg_length(canonical_skeleton()) / leg_length(parse_asf(asf))
    np.testing.assert_allclose(shared.qpos[:, :3], own.qpos[:, :3] * ratio)
    lengths = np.linalg.norm(shared.bone_vectors(), axis=-1)
    canon = canonical_skeleton()
    np.testing.assert_allclose(lengths[:, shared.index("ltibia")], canon.bone("ltibia").length)


def test_local_rotations_compose_back_to_world_orientations(walk_clip):
    from sim.model.quaternion import mul as quat_mul

    world = {}
    for j, p in enumerate(walk_clip.parents):
        q = walk_clip.rotations[:, j]
        world[j] = q if p < 0 else quat_mul(world[p], q)
    # The bone vector in its body frame is constant when composed orientations are right.
    j = walk_clip.index("ltibia")
    body = world[j]
    v = walk_clip.bone_vectors()[:, j]
    w, xyz = body[:, :1], body[:, 1:]
    # rotate v by the inverse of body: v_local = q* v q
    t = 2 * np.cross(-xyz, v)
    local = v + w * t + np.cross(-xyz, t)
    np.testing.assert_allclose(local, np.broadcast_to(local[0], local.shape), atol=1e-9)
