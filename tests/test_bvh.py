"""BVH in and out: files the tests make (``tests/bvh_files.py``) read against an independent
forward kinematics, and CMU trials written as BVH and read back against their AMC."""

from __future__ import annotations

import numpy as np
import pytest
from bvh_files import METRES, bvh_text, creature, forward_kinematics, motion

from sim.bvh.convert import detect_unit, to_acclaim
from sim.bvh.reader import parse_bvh
from sim.bvh.writer import write_bvh
from sim.motion.ingest import load_motion
from sim.motion.trial import read_trial, subject_model


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def assert_same_points(expected: np.ndarray, points: np.ndarray, tol: float) -> None:
    """Every expected joint is a point of the clip and every point an expected joint, frame by
    frame, within ``tol`` [m]."""
    d = np.linalg.norm(expected[:, :, None] - points[:, None], axis=-1)  # (T, J_bvh, J_clip)
    assert d.min(axis=2).max() < tol, d.min(axis=2).max()
    assert d.min(axis=1).max() < tol, d.min(axis=1).max()


@pytest.mark.parametrize(
    ("unit", "up", "fps"),
    [("cm", "y", 60.0), ("m", "z", 120.0), ("in", "y", 30.0), ("mm", "z", 60.0)],
)
def test_every_joint_and_end_site_is_where_an_independent_fk_puts_it(tmp_path, unit, up, fps):
    nodes = creature()
    values = motion(nodes, int(fps * 2), fps)
    path = write(tmp_path, "c.bvh", bvh_text(nodes, values, fps, unit=unit, up=up))
    clip = load_motion(path, fps=fps / 2 if fps > 30 else fps, up=up)
    step = 2 if fps > 30 else 1
    expected = forward_kinematics(nodes, values, unit=unit, up=up)[::step]
    assert clip.fps == (fps / step) and clip.source_fps == fps
    assert_same_points(expected, clip.positions, 1e-6)


def test_a_100_fps_file_is_resampled_onto_120_then_taken_as_an_amc_is(tmp_path):
    nodes = creature()
    values = motion(nodes, 201, 100.0)
    path = write(tmp_path, "c.bvh", bvh_text(nodes, values, 100.0))
    clip = load_motion(path, fps=30.0)
    expected = forward_kinematics(nodes, values)
    assert clip.source_fps == 120.0 and clip.fps == 30.0
    assert len(clip.positions) == 61  # 2 s at 30 fps, both ends included
    # every third clip frame (n/30 s = 10n/3 source frames) falls on a source frame: exact
    assert_same_points(expected[::10], clip.positions[::3], 1e-6)
    # the others are interpolated between source frames 10 ms apart: close to the motion
    oracle = forward_kinematics(nodes, motion(nodes, 241, 120.0), unit="cm")  # same motion at 120
    assert_same_points(oracle[::4][:61], clip.positions, 2e-3)


def test_the_unit_is_detected_from_the_skeletons_size_and_can_be_set(tmp_path):
    nodes = creature()
    values = motion(nodes, 10, 30.0)
    clips = {}
    for unit in METRES:
        path = write(tmp_path, f"{unit}.bvh", bvh_text(nodes, values, 30.0, unit=unit))
        assert detect_unit(parse_bvh(path)) == unit
        clips[unit] = load_motion(path, fps=30.0).positions
    for unit in METRES:
        np.testing.assert_allclose(clips[unit], clips["m"], atol=2e-5)  # 6 decimals of a mm file
    inches = tmp_path / "in.bvh"
    forced = read_trial(inches, unit="cm")[0]  # a setting wins over the detection
    assert forced.length_to_metres == 0.01


def test_each_segment_of_the_built_humanoid_is_an_offset_of_the_file(tmp_path):
    nodes = creature()
    path = write(tmp_path, "c.bvh", bvh_text(nodes, motion(nodes, 5, 30.0), 30.0, unit="cm"))
    skeleton, model = subject_model(path)
    segments = sorted(
        float(np.linalg.norm(model.site(f"{b.name}_end").pos))
        for b in skeleton.bones
        if b.length > 0
    )
    offsets = sorted(float(np.linalg.norm(n.offset)) for n in nodes if n.parent >= 0)
    np.testing.assert_allclose(segments, offsets, atol=1e-8)
    for b in skeleton.bones:
        assert np.linalg.norm(model.site(f"{b.name}_end").pos) == pytest.approx(b.length, abs=1e-9)
    names = skeleton.bone_names
    assert (
        "mixamorig_Hips" == skeleton.name and "Left_Thigh" in names and "Left_Thigh_offset" in names
    )


def test_a_joints_rotation_channels_become_its_bones_dofs_in_application_order(tmp_path):
    nodes = creature()
    path = write(tmp_path, "c.bvh", bvh_text(nodes, motion(nodes, 3, 30.0), 30.0))
    take = to_acclaim(parse_bvh(path))
    bone = take.skeleton.bone("LeftAnkle")  # CHANNELS 3 Yrotation Xrotation Zrotation
    assert bone.dofs == ("rz", "rx", "ry")
    assert take.skeleton.bone("RightKnee").dofs == ("rx", "rz")
    assert take.skeleton.bone("Chest").length == 0  # three children at three OFFSETs


def test_constant_position_channels_on_a_joint_place_it_and_moving_ones_are_refused(tmp_path):
    text = bvh_text(creature(), motion(creature(), 4, 30.0), 30.0)
    six = text.replace(
        "CHANNELS 3 Zrotation Xrotation Yrotation\n\t\tJOINT LeftKnee",
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\t\tJOINT LeftKnee",
    )
    assert six != text
    lines = six.splitlines()
    start = lines.index("MOTION") + 3
    for k in range(start, len(lines)):  # Left Thigh's columns follow the root's six
        v = lines[k].split()
        lines[k] = " ".join(v[:6] + ["10.0", "-5.0", "0.0"] + v[6:])
    path = write(tmp_path, "six.bvh", "\n".join(lines) + "\n")
    take = to_acclaim(parse_bvh(path))
    assert take.skeleton.bone("Left_Thigh_offset").length == pytest.approx(np.hypot(0.1, 0.05))
    lines[start + 2] = lines[start + 2].replace(" 10.0 -5.0 ", " 10.5 -5.0 ")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(Exception, match=r"six\.bvh:\d+: joint 'Left Thigh': Xposition moves"):
        to_acclaim(parse_bvh(path))


# --- CMU trials as BVH ------------------------------------------------------------------------


@pytest.mark.parametrize("trial", ["02_01", "07_12", "05_06", "60_01"])
def test_a_cmu_trial_written_as_bvh_reads_back_to_the_amcs_points(cmu_dir, tmp_path, trial):
    """On the subject's humanoid and on the shared one (there the AMC path copies each bone's
    angles and the BVH path re-expresses each bone's rotation in its ASF frame: the same, as CMU's
    axis frames are the canonical skeleton's; 05_06 and 60_01 bend two-dof bones past 90 degrees
    in their middle axis)."""
    subject = cmu_dir / trial[:2]
    asf, amc = subject / f"{trial[:2]}.asf", subject / f"{trial}.amc"
    skeleton, take, fps = read_trial(asf, amc)
    path = write_bvh(tmp_path / f"{trial}.bvh", skeleton, take, fps)
    for which in ("subject", "humanoid"):
        a = load_motion(asf, amc, skeleton=which, derivatives=False)
        b = load_motion(path, skeleton=which, derivatives=False)
        assert a.names == b.names
        err = np.linalg.norm(a.positions - b.positions, axis=-1).max()
        assert err < 1e-4, (which, err)  # the 0.1 mm; measured < 2e-7 m


def test_the_writer_keeps_the_points_in_other_units_and_z_up(cmu_dir, tmp_path):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    skeleton, take, fps = read_trial(asf, amc)
    a = load_motion(asf, amc)
    for unit, up in (("m", "z"), ("in", "y")):
        path = write_bvh(tmp_path / f"{unit}{up}.bvh", skeleton, take, fps, unit=unit, up=up)
        assert detect_unit(parse_bvh(path)) == unit
        b = load_motion(path, up=up)
        assert np.abs(a.positions - b.positions).max() < 1e-4


def test_cmus_bvh_release_names_map_onto_the_shared_humanoid(cmu_dir, tmp_path):
    from sim.motion.retarget import CMU_BVH_NAMES

    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    skeleton, take, fps = read_trial(asf, amc)
    text = (write_bvh(tmp_path / "a.bvh", skeleton, take, fps)).read_text()
    for bvh_name, bone in CMU_BVH_NAMES.items():
        text = text.replace(f"JOINT {bone}\n", f"JOINT {bvh_name}\n")
    path = write(tmp_path, "cgspeed.bvh", text.replace("ROOT root", "ROOT Hips"))
    a = load_motion(asf, amc, skeleton="humanoid")
    b = load_motion(path, skeleton="humanoid")
    assert np.abs(a.positions - b.positions).max() < 1e-4


def test_a_skeleton_unlike_cmus_cannot_go_onto_the_shared_humanoid(tmp_path):
    nodes = creature()
    path = write(tmp_path, "c.bvh", bvh_text(nodes, motion(nodes, 5, 30.0), 30.0))
    with pytest.raises(Exception, match="cannot retarget to the humanoid"):
        load_motion(path, skeleton="humanoid")
