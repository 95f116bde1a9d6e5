"""Hostile files, one attack at a time: sizes and bombs bounded before anything is allocated,
regular files only, nothing read outside the folder named, one line for every bad input.

(The random search over all of them is ``tests/test_fuzz.py`` and
``benchmarks/fuzz_campaign.py``; memory and time are measured there, never here.)
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import lzma
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest
from cli_run import REPO, cli, one_line_exit_2
from hypothesis import given, settings
from hypothesis import strategies as st

import sim.files
from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import parse_asf
from sim.errors import MotionDataError
from sim.files import excerpt, text_lines, write_atomic
from sim.motion.clip import load_npz, save_npz
from sim.motion.dataset import find_trials, load_dataset_clips, read_index

# --- text read a chunk at a time ---------------------------------------------------------------


@settings(max_examples=300, derandomize=True, database=None, deadline=None)
@given(st.lists(st.sampled_from([b"a", b"12", b" ", b"\n", b"\r\n", b"\r", b"\x85", b"\x0b",
                                 b"\xe2\x80\xa8", b"\xc3\xa9", b"\xff", b"\x1c"]), max_size=60),
       st.integers(1, 9))  # fmt: skip
def test_text_lines_split_and_number_lines_as_str_splitlines(pieces, chunk):
    data = b"".join(pieces)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    saved, sim.files.TEXT_CHUNK_BYTES = sim.files.TEXT_CHUNK_BYTES, chunk
    try:
        got, line = [], 1
        for first, lines in text_lines(io.BytesIO(data), "x", 1 << 20):
            assert first == line
            got += lines
            line += len(lines)
    finally:
        sim.files.TEXT_CHUNK_BYTES = saved
    assert got == text.splitlines()


@pytest.mark.filterwarnings("ignore::sim.errors.MotionDataWarning")
def test_amc_read_in_tiny_chunks_equals_the_whole_read(cmu_dir, monkeypatch):
    """Chunk boundaries anywhere (inside frames, between the fast and the checked path) change
    nothing: the same arrays, bit for bit, and the same error line."""
    skeleton = parse_asf(cmu_dir / "07" / "07.asf")
    whole = parse_amc(cmu_dir / "07" / "07_12.amc", skeleton)  # ends in an incomplete frame
    monkeypatch.setattr(sim.files, "TEXT_CHUNK_BYTES", 997)
    chunked = parse_amc(cmu_dir / "07" / "07_12.amc", skeleton)
    assert np.array_equal(whole.root, chunked.root) and whole.notes == chunked.notes
    assert all(np.array_equal(whole.angles[k], chunked.angles[k]) for k in whole.angles)


def test_bones_an_amc_never_mentions_are_shared_read_only_zeros(cmu_dir, tmp_path):
    skeleton = parse_asf(cmu_dir / "02" / "02.asf")
    (tmp_path / "root.amc").write_text(":DEGREES\n1\nroot 1 2 3 4 5 6\n2\nroot 1 2 3 4 5 6\n")
    motion = parse_amc(tmp_path / "root.amc", skeleton)
    lfemur = motion.angles["lfemur"]
    assert lfemur.shape == (2, 3) and not lfemur.any() and not lfemur.flags.writeable


def test_an_amc_with_no_line_break_is_refused_naming_its_line(cmu_dir, tmp_path):
    skeleton = parse_asf(cmu_dir / "02" / "02.asf")
    (tmp_path / "x.amc").write_bytes(b":DEGREES\n1\nroot " + b"1 " * (sim.files.MAX_LINE_BYTES))
    with pytest.raises(MotionDataError, match=r"x.amc:3: no line break"):
        parse_amc(tmp_path / "x.amc", skeleton)


def test_error_excerpts_are_short_and_printable():
    assert excerpt("\x1b[2J" + "a" * 100) == "'?[2J" + "a" * 36 + "...'"
    assert excerpt(b"\xff\x00ok", quote=False) == "??ok"


# --- regular files only ------------------------------------------------------------------------


def test_ingest_refuses_dev_zero_and_a_fifo_as_the_skeleton_at_once(cmu_dir, tmp_path):
    amc = str(cmu_dir / "02" / "02_01.amc")
    one_line_exit_2(cli("ingest", "/dev/zero", amc, "--out", str(tmp_path / "o.npz")),
                    "/dev/zero: not a regular file (a character device)")  # fmt: skip
    os.mkfifo(tmp_path / "s.asf")
    one_line_exit_2(cli("ingest", str(tmp_path / "s.asf"), amc, "--out", str(tmp_path / "o.npz")),
                    "s.asf: not a regular file (a FIFO")  # fmt: skip


def test_a_dataset_lists_fifos_and_links_out_of_the_folder_instead_of_reading_them(
    cmu_dir, tmp_path
):
    src = tmp_path / "src" / "02"
    src.mkdir(parents=True)
    (src / "02.asf").write_bytes((cmu_dir / "02" / "02.asf").read_bytes())
    os.mkfifo(src / "02_01.amc")
    (tmp_path / "secret.txt").write_text("root:CANARY\n")
    os.symlink(tmp_path / "secret.txt", src / "02_02.amc")
    (src / "02_03\x1b[2J.amc").write_bytes(b"")
    skipped = []
    assert find_trials(tmp_path / "src", skipped) == []
    problems = " | ".join(r["error"] for r in skipped)
    assert "02_01.amc: not a regular file (a FIFO)" in problems
    assert "02_02.amc: a symbolic link to a file outside" in problems
    assert "cannot be printed" in problems and "\x1b" not in problems
    assert "CANARY" not in problems


# --- folder confinement and index.json -----------------------------------------------------------


@pytest.fixture()
def dataset(walk_clip, tmp_path):
    folder = tmp_path / "d"
    save_npz(walk_clip, folder / "02" / "a.npz")
    index = {"skeleton": "humanoid", "trials": [{"subject": "02", "file": "02/a.npz"}]}
    (folder / "index.json").write_text(json.dumps(index))
    return folder, index


@pytest.mark.parametrize(
    ("name", "problem"),
    [("/etc/passwd", "is absolute"), ("../../x.npz", "leaves the dataset folder"),
     ("02/\x1b[2J.npz", "cannot be printed"), ("02/out.npz", "leaves the dataset folder")],
)  # fmt: skip
def test_index_entries_stay_inside_the_folder(dataset, tmp_path, name, problem):
    folder, index = dataset
    (tmp_path / "secret.npz").write_text("CANARY")
    os.symlink(tmp_path / "secret.npz", folder / "02" / "out.npz")
    index["trials"][0]["file"] = name
    (folder / "index.json").write_text(json.dumps(index))
    with pytest.raises(MotionDataError, match=problem) as e:
        load_dataset_clips(folder)
    assert "CANARY" not in str(e.value) and "\x1b" not in str(e.value)


def test_an_index_that_would_parse_into_gigabytes_is_refused_before_parsing(tmp_path):
    (tmp_path / "index.json").write_text('{"trials": [' + ",".join(["{}"] * 2_500_000) + "]}")
    with pytest.raises(MotionDataError, match="parsing would take"):
        read_index(tmp_path / "index.json")
    (tmp_path / "index.json").write_text("[" * 50_000 + "]" * 50_000)
    with pytest.raises(MotionDataError, match="nested too deeply"):
        read_index(tmp_path / "index.json")


# --- clip files -----------------------------------------------------------------------------------


def _rewrite(path: Path, change) -> None:
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    np.savez_compressed(path, **arrays)


def test_a_clip_file_that_inflates_past_its_limit_is_refused_at_its_directory(walk_clip, tmp_path):
    path = tmp_path / "c.npz"
    save_npz(walk_clip, path)
    with zipfile.ZipFile(path, "a", zipfile.ZIP_DEFLATED) as z:
        info = zipfile.ZipInfo("sim_bomb.npy")
        info.compress_type = zipfile.ZIP_DEFLATED
        with z.open(info, "w", force_zip64=True) as f:
            for _ in range(80):
                f.write(bytes(1 << 20))
    assert path.stat().st_size < 1 << 20
    with pytest.raises(MotionDataError, match="inflate to"):
        load_npz(path)


def test_clip_arrays_are_checked_from_their_headers(walk_clip, tmp_path):
    path = tmp_path / "c.npz"
    cases = {
        "velocities: shape": lambda a: a.update(velocities=a["velocities"][:, :3]),
        "dtype 'object' refused": lambda a: a.update(names=np.array([1, None], dtype=object)),
        "non-finite values in velocities": lambda a: a["velocities"].__setitem__(0, np.nan),
        "parents: not a tree": lambda a: a["parents"].__setitem__(3, 99),
        "no array 'qpos'": lambda a: a.pop("qpos"),
    }
    for problem, change in cases.items():
        save_npz(walk_clip, path)
        _rewrite(path, change)
        with pytest.raises(MotionDataError, match=problem):
            load_npz(path)


# --- .sidq ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def stream(cmu_dir):
    from sidql.codec.encode import encode_clip
    from sim.motion.ingest import load_motion

    clip = load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc").slice(0, 30)
    return encode_clip(clip, rate=4000, reconstruction="linear").stream


def test_an_lzma_bomb_declaring_ten_million_keyframes_is_refused_before_inflating(stream):
    from sidql.codec import format as sidq

    head = sidq.header_bytes(stream)
    body = head + struct.pack("<I", 10**7) + lzma.compress(
        bytes(1 << 22), format=lzma.FORMAT_ALONE, filters=sidq._LZMA_FILTERS
    )  # fmt: skip
    with pytest.raises(MotionDataError, match="bad keyframe count 10000000"):
        sidq.from_bytes(body + struct.pack("<I", zlib.crc32(body)))


def test_streams_are_bounded_in_frames_rate_and_values(stream):
    from sidql.codec import format as sidq

    limit = sidq.frame_limit(23)
    at = dataclasses.replace(
        stream, keyframes=np.arange(limit), pose_codes=np.full((limit, 47), 9, np.uint16)
    )
    assert sidq.from_bytes(sidq.to_bytes(at)).n_frames == limit  # the limit itself decodes
    over = dataclasses.replace(at, keyframes=np.r_[np.arange(limit - 1), limit])
    with pytest.raises(ValueError, match="limit"):  # the writer refuses what readers refuse
        sidq.to_bytes(over)
    data = bytearray(sidq.to_bytes(stream))
    data[10:14] = struct.pack("<f", 1e9)  # the frame rate
    body = bytes(data[:-4])
    with pytest.raises(MotionDataError, match="frame rate 1e\\+09 outside"):
        sidq.from_bytes(body + struct.pack("<I", zlib.crc32(body)))


# --- policy and checkpoint files -----------------------------------------------------------------


def test_a_policy_archive_with_compressed_members_is_refused_before_loading(tmp_path):
    from sidql.learning.files import ModelFileError
    from sidql.learning.policy import DEFAULT_POLICY, load_policy

    src = zipfile.ZipFile(DEFAULT_POLICY)
    with zipfile.ZipFile(tmp_path / "p.pt", "w", zipfile.ZIP_DEFLATED) as z:
        for name in src.namelist():
            z.writestr(name, src.read(name))
    with pytest.raises(ModelFileError, match="is not stored"):
        load_policy(tmp_path / "p.pt")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny real training run: its Args and checkpoint payload."""
    import torch

    from sidql.learning.dqn import train
    from sidql.learning.settings import Args

    out = tmp_path_factory.mktemp("run") / "p.pt"
    args = Args(
        out=str(out), steps=24, synthetic_tasks=8, keyframe_counts=(4,), batch_size=8, buffer_size=40,
        learning_starts=8, n_envs=2, demo_episodes=2, eval_every=24, progress=False, hidden=8,
    )  # fmt: skip
    train(args)
    return args, torch.load(f"{out}.ckpt", weights_only=True)


@pytest.mark.parametrize(
    ("tamper", "problem"),
    [
        (lambda c, t: c.pop("net"), "net: not the weights"),
        (lambda c, t: c.update(rng={"bit_generator": "PCG64", "state": {"state": "x"}}), "rng"),
        (lambda c, t: c.update(torch_rng=t.zeros(5056, dtype=t.uint8)), "torch_rng"),
        (lambda c, t: c["memory"].update(mask=t.zeros(3, 3, dtype=t.bool)), "memory.mask"),
        (lambda c, t: c["memory"].update(pos=10**12), "memory: position"),
        (lambda c, t: c["memory"]["action"].__setitem__(0, 999), "memory.action: values"),
        (lambda c, t: c.update(log=[{"step": 0}]), "log\\[0\\]"),
        (lambda c, t: c.update(step="7"), "step 7 is not a count"),
    ],
)  # fmt: skip
def test_a_tampered_checkpoint_with_matching_settings_is_one_line(run, tamper, problem):
    import torch

    from sidql.learning.dqn import train
    from sidql.learning.files import ModelFileError, save_payload

    args, payload = run
    ck = {k: (dict(v) if isinstance(v, dict) else v) for k, v in payload.items()}
    ck["memory"] = {k: (v.clone() if isinstance(v, torch.Tensor) else v)
                    for k, v in payload["memory"].items()}  # fmt: skip
    tamper(ck, torch)
    save_payload(f"{args.out}.ckpt", ck)
    try:
        with pytest.raises(ModelFileError, match=f"cannot resume from it: {problem}"):
            train(dataclasses.replace(args, resume=True, steps=48))
    finally:
        save_payload(f"{args.out}.ckpt", payload)


# --- command-line values and outputs -----------------------------------------------------------


def test_train_refuses_a_batch_of_zero_before_reading_anything(tmp_path):
    one_line_exit_2(cli("train", "--data", str(tmp_path), "--batch-size", "0", "--out",
                        str(tmp_path / "p.pt")), "--batch-size must be")  # fmt: skip
    assert not (tmp_path / "p.pt").exists()


def test_ray_addresses_are_checked_before_any_work(tmp_path):
    from sidql.commands.usage import ray_address

    one_line_exit_2(cli("dataset", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--ray",
                        "bogus::address"), "not a Ray address")  # fmt: skip
    mute = socket.create_server(("127.0.0.1", 0))  # accepts, never answers: not a cluster
    grpc = socket.create_server(("127.0.0.1", 0))  # answers the HTTP/2 preface like Ray's GCS

    def answer():
        conn, _ = grpc.accept()
        conn.recv(33)
        conn.sendall(bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))
        conn.close()

    threading.Thread(target=answer, daemon=True).start()
    try:
        with pytest.raises(argparse.ArgumentTypeError, match="no Ray cluster answers"):
            ray_address(f"127.0.0.1:{mute.getsockname()[1]}")
        assert ray_address(f"ray://127.0.0.1:{grpc.getsockname()[1]}").startswith("ray://")
    finally:
        mute.close()
        grpc.close()


def test_a_writer_killed_mid_write_leaves_no_temporary_file(tmp_path):
    """SIGKILL while the data are being written: no half file, no ``.tmp`` beside it."""
    code = (
        "import sys, time; sys.path.insert(0, sys.argv[2]); from sim.files import write_atomic\n"
        "def slow(f):\n    f.write(b'x' * 1000); f.flush(); print('writing', flush=True); "
        "time.sleep(60)\n"
        "write_atomic(sys.argv[1], slow)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "index.json"), str(REPO)],
                            stdout=subprocess.PIPE, text=True)  # fmt: skip
    assert proc.stdout.readline().strip() == "writing"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert list(tmp_path.iterdir()) == []
    write_atomic(tmp_path / "index.json", lambda f: f.write(b"{}"))
    assert [p.name for p in tmp_path.iterdir()] == ["index.json"]
