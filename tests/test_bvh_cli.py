"""BVH on the command line: a ``.bvh`` wherever ``ASF AMC`` goes, ``convert`` both ways and from a
clip, ``decode --out X.bvh``, and folders of trials that hold BVH files beside CMU's layout."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from bvh_files import bvh_text, creature, motion
from test_cli import one_error_line

from sidql.commands import main as cli
from sim.motion.clip import load_npz
from sim.motion.dataset import find_trials
from sim.motion.ingest import load_motion


@pytest.fixture
def cmu_bvh(cmu_dir, tmp_path):
    """Subject 02's walk written as BVH by ``sidql convert``; (asf, amc, bvh)."""
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    bvh = tmp_path / "walk.bvh"
    assert cli.main(["convert", str(asf), str(amc), str(bvh)]) == 0
    return asf, amc, bvh


def test_convert_goes_both_ways_and_keeps_every_point(cmu_bvh, tmp_path):
    asf, amc, bvh = cmu_bvh
    assert cli.main(["convert", str(bvh), str(tmp_path / "back.amc")]) == 0
    a = load_motion(asf, amc)
    for clip in (load_motion(bvh), load_motion(tmp_path / "back.asf", tmp_path / "back.amc")):
        assert np.abs(clip.positions - a.positions).max() < 1e-6


def test_ingest_extract_and_encode_take_a_bvh_alone(cmu_bvh, tmp_path, capsys):
    asf, amc, bvh = cmu_bvh
    assert cli.main(["ingest", str(bvh), "--out", str(tmp_path / "w.npz")]) == 0
    a, b = load_motion(asf, amc), load_npz(tmp_path / "w.npz")
    assert np.abs(a.positions - b.positions).max() < 1e-6 and a.names == b.names
    assert cli.main(["extract", str(bvh), "-W", "5", "--methods", "uniform"]) == 0
    assert "keyframes 0 15 30 44 59" in capsys.readouterr().out
    stream = tmp_path / "w.sidq"
    assert cli.main(["encode", str(bvh), "--rate", "800", "--out", str(stream)]) == 0
    assert (
        cli.main(["decode", str(stream), "--out", str(tmp_path / "d.bvh"), "--asf", str(bvh)]) == 0
    )
    decoded = load_motion(tmp_path / "d.bvh", fps=30.0)
    assert decoded.names == a.names and np.abs(decoded.positions - a.positions).max() < 0.05


def test_a_bvh_with_a_second_file_or_an_asf_alone_is_a_one_line_usage_error(cmu_bvh, capsys):
    asf, amc, bvh = cmu_bvh
    assert cli.main(["ingest", str(bvh), str(amc), "--out", "x.npz"]) == 2
    assert "give it alone" in one_error_line(capsys, "ingest")
    assert cli.main(["ingest", str(asf), "--out", "x.npz"]) == 2
    assert "needs its AMC motion" in one_error_line(capsys, "ingest")
    assert cli.main(["convert", str(bvh), "out.bvh"]) == 2
    assert "converts to .amc" in one_error_line(capsys, "convert")


def test_ingest_reads_a_z_up_file_in_the_unit_it_is_told(tmp_path):
    nodes = creature()
    values = motion(nodes, 8, 30.0)
    rotations = [i for i, c in enumerate(c for n in nodes for c in n.channels) if "rotation" in c]
    values[:, rotations] = 0.0  # the rest pose, written in each file's axes
    (tmp_path / "z.bvh").write_text(bvh_text(nodes, values, 30.0, unit="in", up="z"))
    (tmp_path / "y.bvh").write_text(bvh_text(nodes, values, 30.0, unit="in", up="y"))
    for name, up in (("z", "z"), ("y", "y")):
        argv = ["ingest", str(tmp_path / f"{name}.bvh"), "--up", up, "--unit", "in"]
        assert cli.main([*argv, "--out", str(tmp_path / f"{name}.npz")]) == 0
    z, y = load_npz(tmp_path / "z.npz"), load_npz(tmp_path / "y.npz")
    # the same figure standing up in both: the same points
    assert np.abs(z.positions - y.positions).max() < 1e-6
    assert np.ptp(z.positions[0, :, 2]) > 1.7


def test_a_clip_is_written_as_bvh_on_its_skeleton(cmu_dir, tmp_path):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    npz = tmp_path / "h.npz"
    assert (
        cli.main(["ingest", str(asf), str(amc), "--skeleton", "humanoid", "--out", str(npz)]) == 0
    )
    assert cli.main(["convert", str(npz), str(tmp_path / "h.bvh")]) == 0  # the shared humanoid's
    clip, back = load_npz(npz), load_motion(tmp_path / "h.bvh", fps=30.0)
    assert np.abs(clip.positions - back.positions).max() < 1e-6


def test_folders_find_bvh_files_beside_cmus_layout_and_the_dataset_holds_both(
    cmu_dir, cmu_bvh, tmp_path
):
    data = tmp_path / "data"
    (data / "02").mkdir(parents=True)
    for f in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / f, data / "02" / f)
    (data / "mocap").mkdir()
    shutil.copy(cmu_bvh[2], data / "mocap" / "walk.bvh")
    nodes = creature()
    (data / "mocap" / "c_01.bvh").write_text(bvh_text(nodes, motion(nodes, 130, 60.0), 60.0))
    trials = find_trials(data)
    assert [(t.subject, t.name) for t in trials] == [
        ("02", "02_01"),
        ("c", "c_01"),
        ("mocap", "walk"),
    ]
    assert all(t.asf == t.amc for t in trials if t.amc.suffix == ".bvh")
    out = tmp_path / "out"
    assert cli.main(["dataset", "--data", str(data), "--out", str(out)]) == 0
    index = json.loads((out / "index.json").read_text())
    assert len(index["trials"]) == 3
    from sim.motion.trial import subject_model

    for entry in index["trials"]:  # each skeleton kept as an ASF inside the dataset
        assert entry["asf"].endswith(".asf") and (out / entry["asf"]).is_file()
        clip = load_npz(out / entry["file"])
        model = subject_model(out / entry["asf"])[1]
        assert model.nq == clip.qpos.shape[1]


def test_synths_reference_of_a_bvh_is_the_amcs_at_the_control_rate(cmu_bvh, tmp_path):
    from dataclasses import replace

    from sim.bvh.writer import write_bvh
    from sim.motion.trial import read_trial
    from sim.simulate.reference import trial_qpos

    asf, amc, bvh = cmu_bvh
    a = trial_qpos(asf, amc)
    np.testing.assert_allclose(trial_qpos(bvh, bvh), a, atol=1e-6)
    skeleton, take, _ = read_trial(asf, amc)  # every other frame, as a 60 fps file
    half = replace(take, root=take.root[::2], angles={k: v[::2] for k, v in take.angles.items()})
    sixty = write_bvh(tmp_path / "sixty.bvh", skeleton, half, 60.0)
    b = trial_qpos(sixty, sixty)  # interpolated onto 120 Hz: the source frames kept exactly
    assert len(b) == 2 * half.n_frames - 1
    np.testing.assert_allclose(b[::2], a[::2][: len(b[::2])], atol=1e-6)


def test_a_synthetic_clip_exports_as_bvh_with_its_points(tmp_path):
    from sim.motion.clip import save_npz
    from sim.motion.synthetic import synthetic_motion

    clip = synthetic_motion(2.0, seed=3)
    save_npz(clip, tmp_path / "s.npz")
    assert cli.main(["convert", str(tmp_path / "s.npz"), str(tmp_path / "s.bvh")]) == 0
    back = load_motion(tmp_path / "s.bvh", fps=clip.fps)
    assert back.names == clip.names
    assert np.abs(back.positions - clip.positions).max() < 1e-6


def test_the_hierarchy_alone_reads_without_the_motion(tmp_path):
    from sim.bvh.reader import parse_bvh

    nodes = creature()
    (tmp_path / "c.bvh").write_text(bvh_text(nodes, motion(nodes, 9, 30.0), 30.0))
    whole, head = parse_bvh(tmp_path / "c.bvh"), parse_bvh(tmp_path / "c.bvh", motion=False)
    assert head.values.shape == (0, whole.values.shape[1]) and head.fps == whole.fps == 30.0
    assert [j.name for j in head.joints] == [j.name for j in whole.joints]
