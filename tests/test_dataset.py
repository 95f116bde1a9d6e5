"""Batch ingest: bad files are skipped and reported, good results kept, outputs atomic."""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

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
    code = main(
        ["dataset", "--data", str(mixed_dir), "--out", str(tmp_path / "o"), "--workers", "1"]
    )
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
    np.testing.assert_array_equal(back.derivative_noise, walk_clip.derivative_noise)
    assert back.slice(0, 5).derivative_noise.shape == (5, len(walk_clip.names))
    assert back.names == walk_clip.names and back.joint_names == walk_clip.joint_names
    clips = walk_clip.split(60)
    assert len(clips) == walk_clip.n_frames // 60
    assert clips[0].start_frame == 0
    with pytest.raises(MotionDataError):
        load_npz(tmp_path / "missing.npz")


def test_clip_start_frames_count_source_frames(walk_clip):
    c = walk_clip.slice(10, 20)
    assert c.start_frame == 40 and c.n_frames == 10


# ---------------------------------------------------------------- hostile layouts ----------------


def test_output_paths_are_safe_and_unique(tmp_path):
    from pathlib import PurePosixPath

    from sim.motion.dataset import Trial, output_paths

    def trial(rel, subject, name):
        return Trial(subject=subject, name=name, asf=Path("x.asf"), amc=tmp_path / rel)

    trials = [
        trial("x/.._01.amc", "..", ".._01"),
        trial("x/._01.amc", ".", "._01"),
        trial("a/09/09_06.amc", "09", "09_06"),
        trial("b/09/09_06.amc", "09", "09_06"),
        trial("c/09/09_06.AMC", "09", "09_06"),
        trial("d/09/09_07.amc", "09", "09_07"),
        trial("e/09/09_07.amc", "09", "09_07"),
        trial("f/s/s_<a\\b>.amc", "s", "s_<a\\b>"),
        trial("g/index.json_01.amc", "index.json", "index.json_01"),
        trial("h/" + "x" * 300 + "_01.amc", "x" * 300, "x" * 300 + "_01"),
    ]
    paths = output_paths(trials, tmp_path)
    assert len({str(p).lower() for p in paths}) == len(trials)
    for p in paths:
        assert len(p.parts) == 2 and not p.is_absolute()
        assert all(part not in (".", "..") and not part.startswith(".") for part in p.parts)
        assert all(
            set(part) <= set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.-")
            for part in p.parts
        )
    assert paths[0] == PurePosixPath("_../_.._01.npz")
    assert paths[7] == PurePosixPath("s/s__a_b_.npz")
    assert paths[8].parts[0] == "_index.json"  # never the folder that would shadow index.json
    assert all(len(part) <= 104 for part in paths[9].parts)  # cut, with a hash: fits a file system
    # Colliding trials get different hash suffixes; a trial without a twin keeps its plain name.
    assert {p.parent.name for p in paths[2:7]} == {"09"}
    assert all(re.fullmatch(r"09_0[67]-[0-9a-f]{8}\.npz", p.name) for p in paths[2:7])
    lone = output_paths([trials[2]], tmp_path)
    assert lone == [PurePosixPath("09/09_06.npz")]


def test_dataset_keeps_dotdot_subjects_inside_out_and_twins_apart(tmp_path, cmu_dir):
    src, out = tmp_path / "src", tmp_path / "deep" / "out"
    (src / "x").mkdir(parents=True)
    shutil.copy(cmu_dir / "02" / "02.asf", src / "x" / "02.asf")  # the folder's only ASF
    shutil.copy(cmu_dir / "02" / "02_01.amc", src / "x" / ".._01.amc")
    lines = (cmu_dir / "09" / "09_06.amc").read_text().splitlines()
    frames_b = 120  # b's copy is shorter, so each output can be matched to its input
    body_start = next(i for i, ln in enumerate(lines) if ln.strip() == "1")
    short = lines[: body_start + frames_b * (1 + 29)]
    for sub, text in (("a", "\n".join(lines)), ("b", "\n".join(short))):
        (src / sub / "09").mkdir(parents=True)
        shutil.copy(cmu_dir / "09" / "09.asf", src / sub / "09" / "09.asf")
        (src / sub / "09" / "09_06.amc").write_text(text + "\n")
    s = ingest_directory(src, out, workers=1, progress=False)
    assert not s.skipped, s.skipped
    written = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.npz"))
    assert all(w.startswith("deep/out/") for w in written), written
    index = json.loads((out / "index.json").read_text())
    files = {t["amc"]: t["file"] for t in index["trials"]}
    assert len(files) == 3 and len(set(files.values())) == 3
    assert files["x/.._01.amc"] == "_../_.._01.npz"  # amc: relative to the index's source
    frames = {amc: load_npz(out / f).n_frames for amc, f in files.items()}
    assert frames["b/09/09_06.amc"] == (frames_b + 3) // 4
    assert frames["a/09/09_06.amc"] > frames["b/09/09_06.amc"]


KILL_SCRIPT = """
import multiprocessing as mp, sys, threading, time
from sim.motion.dataset import ingest_directory

def report():
    while len(mp.active_children()) < 2:
        time.sleep(0.01)
    print(" ".join(str(p.pid) for p in mp.active_children()), flush=True)

threading.Thread(target=report, daemon=True).start()
ingest_directory(sys.argv[1], sys.argv[2], workers=2, progress=False)
print("finished", flush=True)
"""


def _running(pid: int) -> bool:
    """True while ``pid`` exists and is not a zombie (an exited process nobody reaped yet)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
def test_workers_exit_when_the_dataset_parent_is_killed(tmp_path, cmu_dir):
    import os
    import signal
    import subprocess
    import sys
    import time

    src = tmp_path / "src" / "01"
    src.mkdir(parents=True)
    shutil.copy(cmu_dir / "01" / "01.asf", src / "01.asf")
    shutil.copy(cmu_dir / "01" / "01_01.amc", src / "01_00.amc")
    for k in range(1, 40):  # ~40 x 2,751 frames: seconds of work, so the kill lands mid-batch
        (src / f"01_{k:02d}.amc").symlink_to(src / "01_00.amc")  # links inside the folder
    repo = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(repo), OMP_NUM_THREADS="1")
    proc = subprocess.Popen(
        [sys.executable, "-c", KILL_SCRIPT, str(tmp_path / "src"), str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        env=env,
        text=True,
    )
    try:
        workers = [int(p) for p in proc.stdout.readline().split()]
        assert len(workers) == 2, workers
        assert proc.poll() is None, "the batch finished before the kill; give it more work"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        deadline = time.monotonic() + 20
        while any(_running(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        alive = [w for w in workers if _running(w)]
        assert not alive, f"workers {alive} outlived their parent"
    finally:
        proc.kill()
        for w in workers if "workers" in locals() else []:
            if _running(w):
                os.kill(w, signal.SIGKILL)
    assert not list((tmp_path / "out").rglob("*.tmp")), "a worker left a partial file"
    assert not (tmp_path / "out" / "index.json").exists()


# ----------------------------------------------- nothing non-finite leaves the ingest -----------


def test_cli_ingest_and_dataset_refuse_a_nan_axis_naming_its_line(tmp_path, cmu_dir, capsys):
    text = (cmu_dir / "02" / "02.asf").read_text()
    bad = text.replace("axis 0 0 20  XYZ", "axis 0 nan 20  XYZ", 1)
    assert bad != text
    src = tmp_path / "src" / "02"
    src.mkdir(parents=True)
    (src / "02.asf").write_text(bad)
    shutil.copy(cmu_dir / "02" / "02_01.amc", src / "02_01.amc")
    code = main(
        ["ingest", str(src / "02.asf"), str(src / "02_01.amc"), "--out", str(tmp_path / "x.npz")]
    )
    err = capsys.readouterr().err
    line = next(i for i, ln in enumerate(bad.splitlines(), 1) if "nan" in ln)
    assert code == 2 and f"02.asf:{line}: non-finite value 'nan' in axis" in err
    assert not (tmp_path / "x.npz").exists()
    s = ingest_directory(tmp_path / "src", tmp_path / "out", workers=1, progress=False)
    assert not s.written and len(s.skipped) == 1 and "non-finite" in s.skipped[0]["error"]


def test_the_velocity_stage_refuses_non_finite_qpos_naming_the_source(walk_clip):
    from sim.model.humanoid import subject_model
    from sim.motion.ingest import clip_from_qpos

    asf = Path(walk_clip.source).with_name("02.asf")
    _, model = subject_model(asf)

    def from_qpos(qpos):
        names, parents = walk_clip.names, walk_clip.parents
        return clip_from_qpos(model, names, parents, qpos, source_fps=30, fps=30, source="walk.amc")

    qpos = walk_clip.qpos.copy()
    qpos[3, 0] = np.nan
    with pytest.raises(MotionDataError, match=r"walk\.amc: non-finite joint positions"):
        from_qpos(qpos)
    qpos[3, 0] = 1e308  # finite, but its differences overflow
    with pytest.raises(MotionDataError, match=r"walk\.amc: non-finite"):
        from_qpos(qpos)


def test_retarget_to_the_humanoid_refuses_zero_length_legs(tmp_path, cmu_dir):
    from sim.motion.ingest import load_motion

    text = (cmu_dir / "02" / "02.asf").read_text()
    lines = text.splitlines()
    for bone in ("lfemur", "ltibia", "rfemur", "rtibia"):
        i = lines.index(f"     name {bone}")
        k = next(j for j in range(i, i + 5) if lines[j].strip().startswith("length"))
        lines[k] = "     length 0"
    (tmp_path / "02.asf").write_text("\n".join(lines) + "\n")
    with pytest.raises(MotionDataError, match="legs 0 m long") as err:
        load_motion(tmp_path / "02.asf", cmu_dir / "02" / "02_01.amc", skeleton="humanoid")
    assert err.value.line is not None


def test_subject_models_follow_a_same_size_rewrite_of_the_asf(tmp_path, cmu_dir):
    from sim.model.humanoid import subject_model

    text = (cmu_dir / "02" / "02.asf").read_text()
    path = tmp_path / "02.asf"
    path.write_text(text)
    first = subject_model(path)[0].bone("lfemur").length
    changed = text.replace("length 7.59371", "length 8.59371", 1)
    assert len(changed) == len(text) and changed != text
    st = path.stat()
    path.write_text(changed)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))  # same size and mtime: only content differs
    assert subject_model(path)[0].bone("lfemur").length > first


def test_bad_dataset_folders_are_motion_data_errors(walk_clip, tmp_path):
    from sim.motion.dataset import load_dataset_clips

    path = save_npz(walk_clip, tmp_path / "02" / "c.npz")
    cut = tmp_path / "02" / "cut.npz"
    cut.write_bytes(path.read_bytes()[:1000])  # a truncated copy: zipfile's BadZipFile
    with pytest.raises(MotionDataError, match="cut.npz: not a clip file"):
        load_npz(cut)
    index = tmp_path / "index.json"
    for text in ('{"trials": [{"subject": "a"}]}', '{"trials": 5}', "[1]", '{"trials": [3]}'):
        index.write_text(text)
        with pytest.raises(MotionDataError, match="index.json"):
            load_dataset_clips(tmp_path)
    index.write_text(json.dumps({"trials": [{"subject": "02", "file": "02/c.npz"}]}))
    clips, subjects = load_dataset_clips(tmp_path)
    assert len(clips) == walk_clip.n_frames // 60 and subjects == ["02"] * len(clips)


def test_on_ray_the_driver_writes_the_outputs(cmu_dir, tmp_path, monkeypatch):
    """Ray tasks may run on another machine, where OUT is another disk (sim.batch: 'the driver
    writes the outputs'); the dataset's workers wrote their .npz where they ran. Simulated here:
    every task sees OUT as another folder."""
    import sim.motion.dataset as dataset
    from sim.batch import run_batch

    elsewhere = tmp_path / "node"

    def on_another_node(fn, items, **kw):
        moved = [(t, str(elsewhere), *rest) for t, _, *rest in items]
        return run_batch(fn, moved, workers=1, progress=False)

    monkeypatch.setattr(dataset, "run_batch", on_another_node)
    src = tmp_path / "cmu" / "02"
    src.mkdir(parents=True)
    for name in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / name, src / name)
    s = dataset.ingest_directory(tmp_path / "cmu", tmp_path / "out", ray="local", progress=False)
    assert [r["file"] for r in s.written] == ["02/02_01.npz"] and not s.skipped
    assert load_npz(tmp_path / "out" / "02" / "02_01.npz").n_frames == s.written[0]["frames"]
    assert not elsewhere.exists()


def test_index_names_inputs_that_resolve_from_any_working_folder(cmu_dir, tmp_path, monkeypatch):
    """'sidql dataset ../shared/cmu --out D' recorded ASF paths relative to the folder it ran in;
    'sidql eval --data D --physics' from anywhere else could not read the skeletons."""
    from sidql.evaluation.cases import load_cases
    from sidql.evaluation.trial_physics import physics_setup

    src = tmp_path / "cmu" / "02"
    src.mkdir(parents=True)
    for name in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / name, src / name)
    monkeypatch.chdir(tmp_path)
    ingest_directory("cmu", "out", workers=1, progress=False)
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    cases, _ = load_cases(tmp_path / "out", progress=False)
    assert cases and all(Path(c.asf).is_file() for c in cases)
    assert len(physics_setup(cases)) == 1
