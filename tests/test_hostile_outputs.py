"""Hostile outputs and resume state, one finding at a time: nothing written, deleted or
read outside the folder the user named; the resume journal read as hostile input; memory bounded
by the input; printable messages naming the file read.

(The random search over planted links, devices, FIFOs and crafted journals is
``benchmarks/fuzz_campaign.py``; memory is measured there.)
"""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest
from cli_run import cli, one_line_exit_2
from hostile_outputs import journal_params, kept_entry

import sim.motion.dataset as dataset_module
from sim.errors import MotionDataError, OutputError, UnknownNameError
from sim.files import write_atomic, written_by
from sim.motion.clip import MAX_POINTS, Clip, load_npz, save_npz
from sim.motion.dataset import dataset_clips, find_trials
from sim.simulate.dataset import synthesize
from sim.simulate.journal import JOURNAL, MAX_LINE_BYTES, clip_name

# --- a synth run's journal, crafted by hand (no simulation needed) -------------------------------

SYNTH = dict(kinds=("procedural",), seconds=0.5, seed=0, workers=1, progress=False)


def _journal(out: Path, lines, n: int = 1) -> None:
    out.mkdir(parents=True, exist_ok=True)
    text = "".join((x if isinstance(x, str) else json.dumps(x)) + "\n"
                   for x in [{"params": journal_params(n)}, *lines])  # fmt: skip
    (out / JOURNAL).write_text(text)


def _clip_files(out: Path, *indices) -> None:
    for i in indices:
        (out / clip_name("procedural", i)).parent.mkdir(parents=True, exist_ok=True)
        (out / clip_name("procedural", i)).write_bytes(b"clip")


# 1. synth --resume deletes files outside --out
def test_resume_deletes_only_the_clips_the_run_itself_names(tmp_path):
    """A journal listing more kept clips than --n, with files that leave --out (``..``, an
    absolute path): one line, nothing deleted; a journal the run wrote: only its own surplus
    clip files go (named as the run names them), the index lists the first n."""
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "precious.txt").write_text("keep me")
    out = tmp_path / "out"
    _clip_files(out, 0)
    for planted in ("../victim/precious.txt", str(victim / "precious.txt")):
        _journal(out, [{"index": 0, "kept": kept_entry(0)},
                       {"index": 1, "kept": kept_entry(1, file=planted)}])  # fmt: skip
        with pytest.raises(MotionDataError, match=r"journal.jsonl:3: kept: the file of task 1"):
            synthesize(None, out, 1, resume=True, **SYNTH)
        assert (victim / "precious.txt").read_text() == "keep me"
        assert (out / clip_name("procedural", 0)).exists() and not (out / "index.json").exists()
    _clip_files(out, 0, 1, 2)
    (victim / "link.npz").symlink_to(victim / "precious.txt")
    _journal(out, [{"index": i, "kept": kept_entry(i)} for i in range(3)])
    summary = synthesize(None, out, 1, resume=True, **SYNTH)
    assert [r["file"] for r in summary.written] == ["procedural/procedural_00000.npz"]
    assert sorted(p.name for p in (out / "procedural").iterdir()) == ["procedural_00000.npz"]
    index = json.loads((out / "index.json").read_text())
    assert [t["file"] for t in index["trials"]] == ["procedural/procedural_00000.npz"]
    assert (victim / "precious.txt").read_text() == "keep me"


# 2. an output replaces device nodes and FIFOs
def _special(path: Path, kind: str):
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "socket":
        import socket

        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        return s
    else:
        try:
            os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # a /dev/null of our own
        except PermissionError:
            pytest.skip("making a device node needs CAP_MKNOD")
    return None


@pytest.mark.parametrize("kind", ["fifo", "device", "socket", "directory"])
def test_an_output_never_replaces_a_device_fifo_socket_or_folder(cmu_dir, tmp_path, kind):
    target = tmp_path / "x.npz"
    keep = target.mkdir() if kind == "directory" else _special(target, kind)
    before = target.lstat()
    res = cli("ingest", str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc"),
              "--out", str(target), timeout=300)  # fmt: skip
    one_line_exit_2(res, f"{target}: ", "an output replaces regular files only")
    after = target.lstat()
    assert (after.st_mode, after.st_ino) == (before.st_mode, before.st_ino)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.npz"]  # no temporary left
    if keep is not None:
        keep.close()


# 3. journal.jsonl is written with a plain open()
@pytest.mark.parametrize("kind", ["link", "fifo"])
def test_the_journal_is_never_written_through_a_link_or_into_a_fifo(tmp_path, kind):
    out, victim = tmp_path / "out", tmp_path / "victim.txt"
    out.mkdir()
    victim.write_text("keep me")
    if kind == "link":
        (out / JOURNAL).symlink_to(victim)
    else:
        os.mkfifo(out / JOURNAL)
    res = cli("synth", "--kinds", "procedural", "--n", "1", "--seconds", "0.5", "--out",
              str(out), "--workers", "1", "--quiet", timeout=60)  # fmt: skip
    one_line_exit_2(res, f"{out / JOURNAL}: ", "an output replaces regular files only")
    assert victim.read_text() == "keep me"
    assert (out / JOURNAL).is_symlink() if kind == "link" else (out / JOURNAL).is_fifo()


# 4. a symlinked subfolder of --out is written through
def test_a_linked_subfolder_of_out_is_never_written_through(cmu_dir, tmp_path):
    data, out, elsewhere = tmp_path / "data" / "02", tmp_path / "ds", tmp_path / "elsewhere"
    data.mkdir(parents=True)
    for name in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / name, data / name)
    out.mkdir()
    elsewhere.mkdir()
    (out / "02").symlink_to(elsewhere)
    res = cli("dataset", "--data", str(data.parent), "--out", str(out), "--workers", "1",
              "--quiet", timeout=300)  # fmt: skip
    one_line_exit_2(res, f"{out / '02'}: a symbolic link, not a folder")
    (out / "procedural").symlink_to(elsewhere)
    with pytest.raises(OutputError, match="procedural: a symbolic link, not a folder"):
        synthesize(None, out, 1, **SYNTH)
    assert list(elsewhere.iterdir()) == []


# 5. videos through the writer: no predictable temporary name, no link followed
def test_a_file_another_program_writes_lands_whole_and_only_where_named(tmp_path):
    out, victim = tmp_path / "out", tmp_path / "victim.mp4"
    out.mkdir()
    victim.write_bytes(b"keep me")
    with written_by(out / "clip00_a.mp4", root=out, suffix=".mp4") as path:
        assert str(out) not in path or "/." in path  # a private folder, not a guessable name
        Path(path).write_bytes(b"video")
    assert (out / "clip00_a.mp4").read_bytes() == b"video"
    assert sorted(p.name for p in out.iterdir()) == ["clip00_a.mp4"]
    from sim.replay.video import write_video

    (out / "clip01_a.mp4").symlink_to(victim)
    frames = (np.zeros((32, 32, 3), np.uint8) for _ in range(3))
    with pytest.raises(OutputError, match="a symbolic link; an output replaces regular files"):
        write_video(frames, out / "clip01_a.mp4", 30.0)
    assert victim.read_bytes() == b"keep me"
    assert sorted(p.name for p in out.iterdir()) == ["clip00_a.mp4", "clip01_a.mp4"]


# 6. memory is not bounded by the input's size
def test_an_amc_whose_frames_would_outgrow_the_stated_bound_is_refused_before_building(
    cmu_dir, tmp_path, monkeypatch
):
    import sim.motion.ingest as ingest

    amc = tmp_path / "root.amc"
    amc.write_text(":DEGREES\n" + "".join(f"{i}\nroot 0 0 0 0 0 0\n" for i in range(1, 2001)))
    built = []
    monkeypatch.setattr(ingest, "motion_to_qpos", lambda *a, **k: built.append(1))
    monkeypatch.setattr(ingest, "ARRAY_BYTES_FLOOR", 1 << 20)  # 2,000 frames: ~43 MB > 1 MB
    with pytest.raises(MotionDataError, match=r"root.amc: 2,000 frames of 31 points need ~4"):
        ingest.load_motion(cmu_dir / "02" / "02.asf", amc)
    assert built == []


def test_an_index_listing_one_clip_200_times_reads_it_once(walk_clip, tmp_path, monkeypatch):
    save_npz(walk_clip.slice(0, 60), tmp_path / "a" / "c.npz")
    os.link(tmp_path / "a" / "c.npz", tmp_path / "a" / "hard.npz")
    entries = [{"subject": "02", "file": "a/c.npz"}] * 199 + [{"file": "a/hard.npz"}]
    (tmp_path / "index.json").write_text(json.dumps({"trials": entries}))
    reads = []
    monkeypatch.setattr(dataset_module, "load_npz", lambda p: reads.append(p) or load_npz(p))
    skipped: list = []
    rows = dataset_clips(tmp_path, 60, skipped)
    assert len(reads) == 1 and len(rows) == 1 and len(skipped) == 199
    assert "listed again" in skipped[0]["problem"]


# 7. control characters reach the terminal, and messages name the fake path in `source`
def test_control_characters_in_a_clip_never_reach_the_terminal(walk_clip, tmp_path):
    import dataclasses

    clip = dataclasses.replace(walk_clip.slice(0, 60), source="/fake/\x1b]0;owned\x07\x1b[2J")
    save_npz(clip, tmp_path / "ok.npz")
    names = ("\x1b[2J" + clip.names[0], *clip.names[1:])
    save_npz(dataclasses.replace(clip, names=names), tmp_path / "bad.npz")
    assert load_npz(tmp_path / "ok.npz").source == "/fake/?]0;owned??[2J"
    with pytest.raises(MotionDataError, match=r"bad.npz: names: a name that cannot be printed"):
        load_npz(tmp_path / "bad.npz")
    short = dataclasses.replace(clip, names=tuple(f"p{i}" for i in range(len(clip.names))))
    save_npz(short, tmp_path / "data" / "s.npz")
    (tmp_path / "data" / "index.json").write_text(json.dumps({"trials": [{"file": "s.npz"}]}))
    res = cli("eval", "--data", str(tmp_path / "data"), "--keyframes", "8", "--methods",
              "uniform", "--out", str(tmp_path / "r.json"), "--quiet")  # fmt: skip
    assert "\x1b" not in res.stdout + res.stderr and "\x07" not in res.stdout + res.stderr
    assert f"skipped {tmp_path / 'data' / 's.npz'}: clip lacks protocol point" in res.stderr
    assert "/fake/" not in res.stderr


# 8. a malformed journal gives a traceback; a 150 MB journal line is read whole
@pytest.mark.parametrize(
    "line, problem",
    [('"kept"', "no task index"), ("[1, 2]", "no task index"), ({"kept": kept_entry(0)}, "no task index"),
     ({"index": -1, "kept": kept_entry(0)}, "no task index"), ({"index": 0, "kept": "x.npz"}, "kept: not"),
     ({"index": 0, "kept": kept_entry(0), "rejected": "procedural"}, "not one of"),
     ({"index": 0, "kept": kept_entry(0, frames="15")}, "frames out of range"),
     ({"index": 0, "kept": kept_entry(0, notes=["\x1b[2J"])}, "printable"),
     ({"index": 0, "skipped": {"task": "x"}}, "not of a trial"), ("{not json", "not a JSON line"),
     ("x" * (MAX_LINE_BYTES + 1), "a line of over")],
)  # fmt: skip
def test_a_malformed_journal_is_one_line_and_deletes_nothing(tmp_path, line, problem):
    out = tmp_path / "out"
    _clip_files(out, 0)
    _journal(out, [line, {"index": 1, "kept": kept_entry(1)}])
    with pytest.raises(MotionDataError, match=rf"journal.jsonl:2: .*{problem}") as e:
        synthesize(None, out, 1, resume=True, **SYNTH)
    assert "\n" not in str(e.value) and "\x1b" not in str(e.value)
    assert (out / clip_name("procedural", 0)).exists() and not (out / "index.json").exists()


# 9. 1,500 nested folders end in a RecursionError
def test_deeply_nested_folders_are_walked_without_recursion(cmu_dir, tmp_path):
    (tmp_path / "data").mkdir()
    fd = os.open(tmp_path / "data", os.O_RDONLY)
    for _ in range(1500):  # deeper than a path may be long: made from descriptors
        os.mkdir("d", dir_fd=fd)
        fd, parent = os.open("d", os.O_RDONLY, dir_fd=fd), fd
        os.close(parent)
    os.close(os.open("01_01.amc", os.O_CREAT | os.O_WRONLY, dir_fd=fd))
    os.close(fd)
    near = tmp_path / "data" / "02"
    near.mkdir()
    for name in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / name, near / name)
    skipped: list = []
    try:
        trials = find_trials(tmp_path / "data", skipped)
    finally:
        _remove_nest(tmp_path / "data")  # shutil.rmtree itself recurses
    assert [t.name for t in trials] == ["02_01"]
    assert len(skipped) == 1 and "nested over 64 folders deep" in skipped[0]["error"]


def _remove_nest(folder: Path) -> None:
    """Remove ``folder/d/d/.../01_01.amc`` without recursion (from descriptors)."""
    fds = [os.open(folder, os.O_RDONLY)]
    while "d" in os.listdir(fds[-1]):
        fds.append(os.open("d", os.O_RDONLY, dir_fd=fds[-1]))
    os.unlink("01_01.amc", dir_fd=fds[-1])
    for child, parent in zip(fds[:0:-1], fds[-2::-1], strict=True):
        os.close(child)
        os.rmdir("d", dir_fd=parent)
    os.close(fds[0])


# 11. the tool writes clips its own reader refuses; number strictness; long lists of names
def test_the_writer_refuses_a_clip_its_reader_would_refuse(walk_clip, tmp_path):
    J = MAX_POINTS + 1
    big = Clip(names=tuple(f"p{i}" for i in range(J)), parents=np.arange(-1, J - 1),
               positions=np.zeros((2, J, 3)), velocities=np.zeros((2, J, 3)),
               qpos=np.zeros((2, 7)), qvel=np.zeros((2, 6)), rotations=np.zeros((2, J, 4)),
               fps=30.0)  # fmt: skip
    with pytest.raises(OutputError, match=f"a clip of {J} points; its reader takes at most 512"):
        save_npz(big, tmp_path / "big.npz")
    assert not (tmp_path / "big.npz").exists()
    still = walk_clip.slice(0, 1)
    T = 40_000  # constant frames: deflate shrinks them past the reader's inflation limit
    arrays = {k: np.repeat(getattr(still, k), T, axis=0)
              for k in ("positions", "velocities", "qpos", "qvel", "rotations")}  # fmt: skip
    static = Clip(names=still.names, parents=still.parents, fps=30.0, **arrays)
    save_npz(static, tmp_path / "static.npz")
    assert load_npz(tmp_path / "static.npz").n_frames == T  # its own reader takes it


def test_a_list_of_valid_names_is_cut_short():
    e = UnknownNameError("bone", "x", [f"bone{i:04d}" for i in range(1000)])
    assert len(str(e)) < 400 and str(e).endswith("(1000 in all)")


def test_an_atomic_write_never_goes_through_a_link_below_its_root(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / "a").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(OutputError, match="out/a: a symbolic link, not a folder"):
        write_atomic(tmp_path / "out" / "a" / "b" / "f", lambda f: f.write(b"x"),
                     root=tmp_path / "out")  # fmt: skip
    assert list((tmp_path / "elsewhere").iterdir()) == []


# 10. decode --out x.amc of a 280-byte stream of 32,768 still frames ran past 60 s
def test_the_skeleton_fit_fits_each_distinct_pose_once(cmu_dir, walk_clip, monkeypatch):
    import sidql.codec.skeleton as fit_module
    from sim.acclaim.asf import parse_asf

    skeleton = parse_asf(cmu_dir / "02" / "02.asf")
    poses = walk_clip.positions[[0, 1]]
    fitted = []
    real = fit_module._fit_poses
    monkeypatch.setattr(fit_module, "_fit_poses",
                        lambda s, P, n: fitted.append(len(P)) or real(s, P, n))  # fmt: skip
    once = fit_module.fit_motion(skeleton, poses, walk_clip.names)
    many = fit_module.fit_motion(skeleton, poses[[0, 1, 1, 0, 1] * 200], walk_clip.names)
    assert fitted == [2, 2]
    assert np.array_equal(many.root, once.root[[0, 1, 1, 0, 1] * 200])
    for k, v in once.angles.items():
        assert np.array_equal(many.angles[k], v[[0, 1, 1, 0, 1] * 200])


@pytest.mark.parametrize("token", ["1_0_8", "\u0661\u0660\u0668", "\uff11", "0x1f", "1e5e5"])
def test_acclaim_numbers_are_ascii_decimals_only(cmu_dir, tmp_path, token):
    from sim.acclaim.amc import parse_amc
    from sim.acclaim.asf import parse_asf

    skeleton = parse_asf(cmu_dir / "02" / "02.asf")
    (tmp_path / "x.amc").write_text(f":DEGREES\n1\nroot 0 0 {token} 0 0 0\n", encoding="utf-8")
    with pytest.raises(MotionDataError, match=r"x.amc:3: non-numeric value '[^']*' in bone"):
        parse_amc(tmp_path / "x.amc", skeleton)
