"""The codec end to end on real CMU data: commands, .npz and .amc outputs, clean failures."""

from __future__ import annotations

import json

import numpy as np
import pytest
from acclaim_fk import acclaim_points

from sidql.codec import format as sidq
from sidql.codec.decode import decode_to_reconstruction
from sidql.codec.skeleton import fit_motion, skeleton_hash
from sidql.commands.main import main
from sidql.keyframes.spherical import POINTS, protocol_indices
from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import parse_asf
from sim.acclaim.writer import write_amc
from sim.model.kinematics import point_names
from sim.motion.clip import load_npz
from sim.motion.ingest import load_motion


def test_amc_writer_round_trips_through_the_reader(cmu_dir, tmp_path):
    sk = parse_asf(cmu_dir / "02" / "02.asf")
    m = parse_amc(cmu_dir / "02" / "02_01.amc", sk)
    write_amc(tmp_path / "w.amc", sk, m, comment="round trip")
    back = parse_amc(tmp_path / "w.amc", sk)
    assert np.allclose(back.root, m.root, atol=1e-5)
    for name, a in m.angles.items():
        assert np.allclose(back.angles[name], a, atol=1e-5), name


def test_fit_motion_rebuilds_true_points(cmu_dir, walk_clip):
    """Angles fitted to the true protocol points reproduce them through the independent
    ASF/AMC forward kinematics (twist is free, so only the limited-dof chains carry error)."""
    sk = parse_asf(cmu_dir / "02" / "02.asf")
    pts = walk_clip.positions[:, protocol_indices(walk_clip)]
    P = acclaim_points(sk, fit_motion(sk, pts, POINTS))
    names = point_names(sk)
    err = np.linalg.norm(P[:, [names.index(p) for p in POINTS]] - pts, axis=-1)
    assert err.mean() < 0.5e-3 and err.max() < 5e-3


def test_skeleton_hash_names_the_subject(cmu_dir):
    a = skeleton_hash(parse_asf(cmu_dir / "02" / "02.asf"))
    assert a == skeleton_hash(parse_asf(cmu_dir / "02" / "02.asf"))
    assert a != skeleton_hash(parse_asf(cmu_dir / "01" / "01.asf")) and len(a) == 8


def test_encode_decode_commands_end_to_end(cmu_dir, tmp_path, capsys):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    out = tmp_path / "w.sidq"
    assert main(["encode", str(asf), str(amc), "--out", str(out), "--rate", "900"]) == 0
    clip = load_motion(asf, amc)
    assert out.stat().st_size <= 900 * clip.n_frames / clip.fps
    rec = decode_to_reconstruction(out)
    truth = clip.positions[:, protocol_indices(clip)]
    assert rec.positions.shape == truth.shape
    mm = 1000 * np.linalg.norm(rec.positions - truth, axis=-1).mean()
    assert mm < 40.0
    # .npz in the ingest format
    assert main(["decode", str(out), "--out", str(tmp_path / "w.npz")]) == 0
    z = load_npz(tmp_path / "w.npz")
    assert z.names == POINTS and z.fps == 30.0
    assert np.allclose(z.positions, rec.positions, atol=1e-9)
    assert np.allclose(z.velocities, rec.velocities, atol=1e-9)
    # .amc on the source skeleton, read back by the project's own reader at the stream rate
    assert main(["decode", str(out), "--out", str(tmp_path / "w.amc"), "--asf", str(asf)]) == 0
    back = load_motion(asf, tmp_path / "w.amc", fps=30.0, source_fps=30.0)
    assert back.n_frames == clip.n_frames
    err = np.linalg.norm(back.positions[:, protocol_indices(back)] - rec.positions, axis=-1)
    assert err.mean() < 3e-3
    # deterministic: the same bytes twice
    first = out.read_bytes()
    assert main(["encode", str(asf), str(amc), "--out", str(out), "--rate", "900"]) == 0
    assert out.read_bytes() == first


@pytest.mark.parametrize(
    "argv_tail, problem",
    [
        (["--rate", "800", "--fps", "7"], "must divide"),
        (["--rate", "20"], "rate too low"),
    ],
)
def test_encode_bad_input_exits_2_with_one_line(cmu_dir, tmp_path, capsys, argv_tail, problem):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    rc = main(["encode", str(asf), str(amc), "--out", str(tmp_path / "x.sidq"), *argv_tail])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and problem in err and "\n" not in err
    assert not (tmp_path / "x.sidq").exists()


def test_decode_bad_streams_exit_2_with_one_line(cmu_dir, tmp_path, capsys):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    good = tmp_path / "g.sidq"
    assert main(["encode", str(asf), str(amc), "--out", str(good), "--max-q", "0.05"]) == 0
    data = good.read_bytes()
    cases = {
        "t.sidq": data[: len(data) // 2],
        "c.sidq": data[:100] + bytes([data[100] ^ 0x40]) + data[101:],
        "e.sidq": b"",
    }
    for name, blob in cases.items():
        (tmp_path / name).write_bytes(blob)
        capsys.readouterr()
        rc = main(["decode", str(tmp_path / name), "--out", str(tmp_path / "o.npz")])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and name in err and "\n" not in err, err
    capsys.readouterr()
    wrong = cmu_dir / "01" / "01.asf"
    rc = main(["decode", str(good), "--out", str(tmp_path / "o.amc"), "--asf", str(wrong)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "does not match" in err
    assert main(["decode", str(tmp_path / "missing.sidq"), "--out", str(tmp_path / "o.npz")]) == 2


def test_live_encoding_from_the_command_line(cmu_dir, tmp_path):
    """--latency gives a fixed-record (coding 0) stream with gaps within the look-ahead."""
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    out = tmp_path / "live.sidq"
    argv = ["encode", str(asf), str(amc), "--out", str(out), "--rate", "3000", "--latency", "12"]
    assert main([*argv, "--reconstruction", "linear"]) == 0
    s = sidq.read(out)
    assert s.coding == 0 and s.latency == 12 and np.diff(s.keyframes).max() <= 12
    assert main(["decode", str(out), "--out", str(tmp_path / "live.npz")]) == 0
    assert load_npz(tmp_path / "live.npz").n_frames == s.n_frames


def test_report_takes_a_decoded_stream_like_a_method(cmu_dir, tmp_path, capsys):
    """A .sidq among --methods is replayed and checked on its clip's frames: its MPJPE in
    checks.json is the decoded points' distance from the original clip's, computed here."""
    asf, amc = cmu_dir / "05" / "05.asf", cmu_dir / "05" / "05_01.amc"
    stream = tmp_path / "walk.sidq"
    assert main(["encode", str(asf), str(amc), "--out", str(stream), "--rate", "600"]) == 0
    out = tmp_path / "rep"
    argv = ["report", str(asf), str(amc), "--methods", "uniform", str(stream), "--clips", "1"]
    assert main([*argv, "-W", "6", "--out", str(out), "--no-video"]) == 0
    doc = json.loads((out / "checks.json").read_text())
    (clip,) = doc["clips"]
    runs = {r["method"]: r for r in clip["methods"]}
    assert set(runs) == {"uniform", "walk.sidq"}
    rec = decode_to_reconstruction(stream)
    c = load_motion(asf, amc, fps=30).split(60)[1]
    pts = c.positions[:, protocol_indices(c)]
    want = 1e3 * np.linalg.norm(rec.positions[60:120] - pts, axis=-1).mean()
    assert runs["walk.sidq"]["summary"]["mpjpe_mm"] == pytest.approx(want, rel=1e-4)
    keys = np.asarray(rec.keyframes)
    assert runs["walk.sidq"]["indices"] == [int(k) - 60 for k in keys if 60 <= k < 120]
    capsys.readouterr()
    other = cmu_dir / "01" / "01.asf"
    assert main(["report", str(other), str(cmu_dir / "01" / "01_01.amc"), "--methods",
                 str(stream), "--out", str(tmp_path / "bad"), "--no-video"]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another skeleton" in err[0]


def test_report_refuses_a_stream_of_another_trial_of_the_subject(cmu_dir, tmp_path, capsys):
    """The skeleton hash matches every trial of a subject: a stream of 02_02 shown as a method
    on 02_01 compared another motion frame by frame (MPJPE ~270 mm) without a word."""
    asf = cmu_dir / "02" / "02.asf"
    stream = tmp_path / "other.sidq"
    argv = ["encode", str(asf), str(cmu_dir / "02" / "02_02.amc"), "--out", str(stream)]
    assert main([*argv, "--max-q", "0.05"]) == 0
    capsys.readouterr()
    out = tmp_path / "rep"
    argv = ["report", str(asf), str(cmu_dir / "02" / "02_01.amc"), "--methods", str(stream)]
    assert main([*argv, "--out", str(out), "--no-video"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "other.sidq" in err[0] and "02_01.amc has 86" in err[0]
    assert not out.exists()
