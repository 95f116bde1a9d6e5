"""Batch ingest: bad files are skipped and reported, good results kept, outputs atomic."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from sidql.commands.main import main
from sim.errors import MotionDataError
from sim.motion.clip import load_npz, save_npz
from sim.motion.dataset import find_trials, ingest_directory


@pytest.fixture()
def mixed_dir(tmp_path, cmu_dir):
    """Two good trials, a corrupt AMC, and an AMC whose skeleton is missing."""
    src = tmp_path / "cmu"
    (src / "02").mkdir(parents=True)
    (src / "99").mkdir()
    for name in ("02.asf", "02_01.amc", "02_02.amc"):
        shutil.copy(cmu_dir / "02" / name, src / "02" / name)
    text = (cmu_dir / "02" / "02_02.amc").read_text().splitlines()
    text[40] = text[40].split()[0] + " 1.0 oops 3.0"
    (src / "02" / "02_03.amc").write_text("\n".join(text))
    shutil.copy(cmu_dir / "02" / "02_01.amc", src / "99" / "99_01.amc")
    return src


def test_find_trials_pairs_amc_with_its_subject_skeleton(cmu_dir):
    trials = find_trials(cmu_dir)
    assert len(trials) == 25
    assert all(t.asf.name == f"{t.subject}.asf" and t.asf.exists() for t in trials)
    assert [t.name for t in trials] == sorted(t.name for t in trials)


def test_batch_skips_bad_files_and_keeps_good_results(mixed_dir, tmp_path):
    out = tmp_path / "out"
    s = ingest_directory(mixed_dir, out, workers=2, progress=False)
    assert sorted(r["trial"] for r in s.written) == ["02_01", "02_02"]
    errors = {r["amc"].rsplit("/", 1)[-1]: r["error"] for r in s.skipped}
    assert set(errors) == {"02_03.amc", "99_01.amc"}
    assert "02_03.amc:41: non-numeric value 'oops'" in errors["02_03.amc"]
    assert "99.asf" in errors["99_01.amc"] and "cannot read file" in errors["99_01.amc"]
    index = json.loads((out / "index.json").read_text())
    assert [t["trial"] for t in index["trials"]] == ["02_01", "02_02"]
    assert len(index["skipped"]) == 2
    clip = load_npz(out / "02" / "02_01.npz")
    assert clip.positions.shape == (clip.n_frames, 31, 3)
    assert not list(out.rglob("*.tmp"))


def test_cli_dataset_reports_the_skipped_files(mixed_dir, tmp_path, capsys):
    code = main(["dataset", str(mixed_dir), "--out", str(tmp_path / "o"), "--workers", "1"])
    text = capsys.readouterr().out
    assert code == 0
    assert "ingested 2 trials" in text and "skipped 2 bad trial(s)" in text
    assert "oops" in text


def test_cli_ingest_writes_the_documented_keys(cmu_dir, tmp_path, capsys):
    out = tmp_path / "walk.npz"
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    assert main(["ingest", str(asf), str(amc), "--out", str(out)]) == 0
    with np.load(out) as z:
        for key in ("names", "parents", "positions", "velocities", "qpos", "qvel", "fps"):
            assert key in z.files
        T = (343 + 3) // 4  # 120 -> 30 fps: every 4th of 343 frames
        assert z["positions"].shape == (T, 31, 3) and z["velocities"].shape == (T, 31, 3)
        assert list(z["names"][:2]) == ["root", "lhipjoint"] and float(z["fps"]) == 30.0


def test_cli_ingest_malformed_file_exits_2_naming_the_line(tmp_path, cmu_dir, capsys):
    bad = tmp_path / "bad.amc"
    lines = (cmu_dir / "02" / "02_01.amc").read_text().splitlines()
    lines[10] = "lfemurX 1 2 3"
    bad.write_text("\n".join(lines))
    code = main(
        ["ingest", str(cmu_dir / "02" / "02.asf"), str(bad), "--out", str(tmp_path / "x.npz")]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert "bad.amc:11: unknown bone 'lfemurX'" in err
    assert not (tmp_path / "x.npz").exists()


def test_npz_round_trip_and_clip_splitting(walk_clip, tmp_path):
    path = save_npz(walk_clip, tmp_path / "c.npz")
    back = load_npz(path)
    np.testing.assert_array_equal(back.positions, walk_clip.positions)
    assert back.names == walk_clip.names and back.joint_names == walk_clip.joint_names
    clips = walk_clip.split(60)
    assert len(clips) == walk_clip.n_frames // 60
    assert clips[0].start_frame == 0
    with pytest.raises(MotionDataError):
        load_npz(tmp_path / "missing.npz")


def test_clip_start_frames_count_source_frames(walk_clip):
    c = walk_clip.slice(10, 20)
    assert c.start_frame == 40 and c.n_frames == 10


def test_atomic_writes_get_ordinary_file_permissions(tmp_path):
    import os

    from sim.motion.clip import write_atomic

    mask = os.umask(0o022)
    try:
        write_atomic(tmp_path / "a.bin", lambda f: f.write(b"data"))
    finally:
        os.umask(mask)
    assert (tmp_path / "a.bin").read_bytes() == b"data"
    assert (tmp_path / "a.bin").stat().st_mode & 0o777 == 0o644
