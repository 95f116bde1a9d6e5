"""Encoding in bounded memory: the AMC read a chunk at a time, the take retargeted per chunk,
encoded in windows, written as a sequence of ordinary streams and decoded stream by stream."""

from __future__ import annotations

import re
import struct
import zlib

import numpy as np
import pytest

from sidql.codec import format as sidq
from sidql.codec.decode import decode_file, decode_to_reconstruction
from sidql.codec.encode import encode_files, encode_series
from sidql.codec.sequence import MAGIC, SequenceWriter, is_sequence, iter_streams, take_frames
from sidql.codec.skeleton import skeleton_hash
from sidql.codec.windows import cut_frame
from sidql.commands.main import main
from sidql.keyframes.spherical import chart, protocol_indices
from sim.acclaim.amc import iter_amc, parse_amc
from sim.acclaim.asf import parse_asf
from sim.errors import MotionDataError
from sim.motion.chunks import stream_clips
from sim.motion.clip import load_npz
from sim.motion.ingest import load_motion


@pytest.fixture(scope="module")
def trial(cmu_dir):
    """01_01 (2,751 frames at 120 fps: several text chunks, 688 frames at 30 fps)."""
    return cmu_dir / "01" / "01.asf", cmu_dir / "01" / "01_01.amc"


def test_amc_pieces_join_to_the_whole_file(trial):
    asf, amc = trial
    sk = parse_asf(asf)
    whole = parse_amc(amc, sk)
    pieces = list(iter_amc(amc, sk))
    assert len(pieces) > 3
    assert [p.first_frame for p in pieces] == list(
        whole.first_frame + np.cumsum([0] + [p.n_frames for p in pieces[:-1]])
    )
    assert np.array_equal(np.concatenate([p.root for p in pieces]), whole.root)
    for name, a in whole.angles.items():
        assert np.array_equal(np.concatenate([p.angles[name] for p in pieces]), a), name


def test_a_defect_deep_in_the_file_is_one_line_naming_its_line(trial, tmp_path):
    asf, amc = trial
    lines = amc.read_text().splitlines()
    bad = len(lines) - 500  # far past the first text chunk
    assert lines[bad].startswith(("l", "r", "u", "t", "h", "n")), lines[bad]
    lines[bad] = lines[bad].split()[0] + " 1.0 oops 2.0"
    path = tmp_path / "bad.amc"
    path.write_text("\n".join(lines) + "\n")
    sk = parse_asf(asf)
    with pytest.raises(MotionDataError) as whole:
        parse_amc(path, sk)
    with pytest.raises(MotionDataError) as streamed:
        list(iter_amc(path, sk))
    assert str(streamed.value) == str(whole.value)
    assert f":{bad + 1}:" in str(streamed.value) and "\n" not in str(streamed.value)


def test_retargeting_per_chunk_gives_the_whole_takes_points(trial):
    asf, amc = trial
    whole = load_motion(asf, amc, derivatives=False)
    clips = list(stream_clips(asf, amc, chunk_frames=50))
    assert len(clips) > 10
    assert [c.start_frame for c in clips[:3]] == [0, 200, 400]
    for key in ("positions", "velocities", "qpos"):
        joined = np.concatenate([getattr(c, key) for c in clips])
        np.testing.assert_allclose(joined, getattr(whole, key), rtol=0, atol=1e-12, err_msg=key)


def test_a_take_of_one_window_is_the_same_bytes_as_the_whole_chart(cmu_dir, tmp_path):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    enc = encode_files(asf, amc, tmp_path / "w.sidq", rate=600.0)
    whole = encode_series(
        chart(load_motion(asf, amc, derivatives=False)), rate=600.0,
        skel_hash=skeleton_hash(parse_asf(asf)), where=str(amc),
    )  # fmt: skip
    assert enc.streams == 1 and (tmp_path / "w.sidq").read_bytes() == whole.data


def test_a_take_longer_than_a_window_is_a_sequence_that_decodes_every_frame(trial, tmp_path):
    asf, amc = trial
    out = tmp_path / "s.sidq"
    enc = encode_files(asf, amc, out, rate=600.0, window=200)
    truth = load_motion(asf, amc, derivatives=False)
    N = truth.n_frames
    assert is_sequence(out) and enc.streams >= 3 and enc.n_frames == N
    assert out.stat().st_size == enc.n_bytes <= 600.0 * N / truth.fps
    assert take_frames(iter_streams(out)) == N
    rec = decode_to_reconstruction(out)
    assert rec.positions.shape == (N, 23, 3) and np.all(np.diff(rec.keyframes) > 0)
    assert (
        rec.keyframes[0] == 0 and rec.keyframes[-1] == N - 1 and len(rec.keyframes) == enc.keyframes
    )
    err = 1000 * np.linalg.norm(
        rec.positions - truth.positions[:, protocol_indices(truth)], axis=-1
    )
    assert err.mean() == pytest.approx(enc.mean_error_mm, rel=0.05)
    decode_file(out, tmp_path / "s.npz")
    np.testing.assert_array_equal(load_npz(tmp_path / "s.npz").positions, rec.positions)
    decode_file(out, tmp_path / "s.amc", asf=asf)
    back = load_motion(asf, tmp_path / "s.amc", source_fps=truth.fps, derivatives=False)
    assert back.n_frames == N
    refit = np.linalg.norm(back.positions[:, protocol_indices(back)] - rec.positions, axis=-1)
    assert refit.mean() < 1e-3


def test_each_window_meets_an_error_target(trial, tmp_path):
    asf, amc = trial
    out = tmp_path / "e.sidq"
    enc = encode_files(asf, amc, out, max_error=3.0, window=200)
    truth = load_motion(asf, amc, derivatives=False)
    rec = decode_to_reconstruction(out)
    err = 1000 * np.linalg.norm(
        rec.positions - truth.positions[:, protocol_indices(truth)], axis=-1
    )
    assert enc.streams >= 3 and err.mean() <= 3.0


def test_the_command_line_says_it_wrote_a_sequence(trial, tmp_path, capsys):
    asf, amc = trial
    out = tmp_path / "c.sidq"
    args = ["encode", str(asf), str(amc), "--out", str(out), "--max-error", "4", "--window", "200"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert re.search(r"a sequence of [3-5] streams", printed), printed
    assert main(["decode", str(out), "--out", str(tmp_path / "c.npz")]) == 0
    assert load_npz(tmp_path / "c.npz").n_frames == 688


def _sequence(tmp_path, streams: list[bytes], count: int | None = None) -> bytes:
    path = tmp_path / "q.sidq"
    with open(path, "wb") as f:
        w = SequenceWriter(f)
        for s in streams:
            w.add(s)
        w.close()
    data = path.read_bytes()
    if count is not None:  # restate the count, then the checksum
        body = data[:-8] + struct.pack("<I", count)
        data = body + struct.pack("<I", zlib.crc32(body))
    return data


@pytest.fixture(scope="module")
def two_streams(walk_clip):
    s = chart(walk_clip)
    a = encode_series(s.frames(slice(0, 50)), rate=800.0).data
    b = encode_series(s.frames(slice(49, None)), rate=800.0).data
    return a, b


def test_the_sequence_reader_refuses_every_defect_in_one_line(two_streams, tmp_path):
    a, b = two_streams
    good = _sequence(tmp_path, [a, b])
    path = tmp_path / "d.sidq"
    path.write_bytes(good)
    assert good[:4] == MAGIC and len(list(iter_streams(path))) == 2
    rng = np.random.default_rng(0)
    cases = [good[:n] for n in (3, 5, 9, 40, len(good) - 5, len(good) - 1)]
    cases += [_sequence(tmp_path, [a, b], count=3), good + b"x", good[:4] + b"\x07" + good[5:]]
    for _ in range(40):
        bad = bytearray(good)
        bad[int(rng.integers(5, len(good)))] ^= 1 << int(rng.integers(8))
        cases.append(bytes(bad))
    for data in cases:
        path.write_bytes(data)
        with pytest.raises(MotionDataError) as e:
            list(iter_streams(path))
        assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_streams_of_different_rates_are_refused(two_streams, walk_clip, tmp_path):
    a, _ = two_streams
    s = chart(walk_clip.slice(0, 80))
    other = sidq.from_bytes(encode_series(s, rate=800.0).data)
    from dataclasses import replace

    c = sidq.to_bytes(replace(other, fps=other.fps * 2))
    path = tmp_path / "r.sidq"
    path.write_bytes(_sequence(tmp_path, [a, c]))
    with pytest.raises(MotionDataError, match="stream 2 differs"):
        list(iter_streams(path))


def test_a_window_is_cut_where_the_points_bend_most():
    t = np.arange(100, dtype=float)
    P = np.zeros((100, 2, 3))
    P[:, :, 0] = t[:, None]
    P[60:, :, 1] = (t[60:] - 60)[:, None] * 0.5  # a kink at frame 60
    assert cut_frame(P, 40, 90) == 60
    assert cut_frame(P, 70, 90) in range(70, 91)


def test_a_report_takes_a_sequence_and_checks_its_skeleton(trial, cmu_dir, tmp_path):
    from sidql.evaluation.validation import load_stream

    asf, amc = trial
    out = tmp_path / "r.sidq"
    enc = encode_files(asf, amc, out, rate=500.0, window=300)
    decoded = load_stream(out, asf)
    assert enc.streams > 1 and decoded.motion.positions.shape[0] == enc.n_frames
    with pytest.raises(MotionDataError, match="another skeleton"):
        load_stream(out, cmu_dir / "02" / "02.asf")


def test_reading_ahead_keeps_the_order_raises_in_place_and_closes_an_abandoned_source():
    from sidql.codec.windows import read_ahead

    assert list(read_ahead(iter(range(50)))) == list(range(50))
    closed = []

    def source(fail_at=None):
        try:
            for i in range(10):
                if i == fail_at:
                    raise MotionDataError("take.amc", 7, "bad frame")
                yield i
        finally:
            closed.append(True)

    got = []
    with pytest.raises(MotionDataError, match="bad frame"):
        for x in read_ahead(source(fail_at=4)):
            got.append(x)
    assert got == [0, 1, 2, 3]  # every item before the defect, then the defect itself
    it = read_ahead(source())
    assert next(it) == 0
    it.close()  # the caller stops early: the source is closed too
    assert closed == [True, True]


def test_a_sequence_too_long_to_join_in_memory_is_refused_in_one_line(
    two_streams, tmp_path, monkeypatch
):
    a, b = two_streams
    path = tmp_path / "long.sidq"
    path.write_bytes(_sequence(tmp_path, [a, b]))
    frames = len(decode_to_reconstruction(path).positions)
    monkeypatch.setattr(sidq, "frame_limit", lambda J: frames - 1)
    with pytest.raises(MotionDataError, match="cannot be joined") as e:
        decode_to_reconstruction(path)
    assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_a_record_longer_than_the_file_is_refused_before_it_is_allocated(two_streams, tmp_path):
    import tracemalloc

    a, _ = two_streams
    data = bytearray(_sequence(tmp_path, [a]))
    data[5:9] = struct.pack("<I", 60 << 20)  # a record of 60 MiB in a file of a few hundred bytes
    path = tmp_path / "claims.sidq"
    path.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        with pytest.raises(MotionDataError, match="truncated sequence"):
            list(iter_streams(path))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20
