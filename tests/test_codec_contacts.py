"""The codec's foot-contact section: its bytes as docs/codec.md lays them out, the bits surviving
a round trip, old streams unchanged, hostile sections refused in one line, the decoder pinning
the feet, and the physics-aware keyframes of ``sidql encode --physics``."""

from __future__ import annotations

import struct
import zlib
from dataclasses import replace
from functools import partial

import numpy as np
import pytest
from cli_run import cli, one_line_exit_2
from hypothesis import given, settings
from hypothesis import strategies as st
from keyframe_synth import smooth_clip

from sidql.codec import format as sidq
from sidql.codec.contact_coding import (
    encode_with_contacts,
    foot_pass,
    foot_track,
    streamed_contacts,
    trial_contacts,
)
from sidql.codec.contact_section import FLAG, MAX_SECTION_BYTES, FootContacts
from sidql.codec.decode import decode_to_reconstruction, reconstruct_stream, stream_to_clip
from sidql.codec.encode import encode_files, encode_series
from sidql.codec.sequence import is_sequence, iter_streams
from sidql.keyframes.contact_pinning import pin_feet
from sidql.keyframes.physical_costs import physical_band, physical_costs, segment_inputs
from sidql.keyframes.spherical import chart
from sim.errors import MotionDataError, UnmetTargetError, UsageError
from sim.motion.chunks import stream_clips
from sim.motion.ingest import load_motion

N = 150
FLOOR = np.array([0.01, 0.002, -0.001, 0.004, 0.0])


@pytest.fixture(scope="module")
def plain():
    """A position-coded stream (coding 2) and an angle-coded one (coding 1), without contacts."""
    series = chart(smooth_clip(N=N, fps=30.0, seed=3))
    return (
        encode_series(series, rate=400.0, reconstruction="catmull_rom").stream,
        encode_series(series, rate=600.0, reconstruction="linear", objective="angle").stream,
    )


def _bits(seed: int, n: int = N) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.repeat(rng.random((n // 5 + 1, 2)) < 0.6, 5, axis=0)[:n]


def _runs_by_hand(column: np.ndarray) -> bytes:
    """One foot's runs as docs/codec.md words them (LEB128 varints), written independently."""

    def varint(n):
        out = b""
        while n >= 0x80:
            out, n = out + bytes([n & 0x7F | 0x80]), n >> 7
        return out + bytes([n])

    lengths, state, count = [], column[0], 0
    for b in column:
        if b != state:
            lengths.append(count)
            state, count = b, 0
        count += 1
    lengths.append(count)
    return varint(2 * len(lengths) + int(column[0])) + b"".join(varint(x) for x in lengths[:-1])


@pytest.mark.parametrize("which", [0, 1])
def test_the_section_is_laid_out_as_the_format_page_says(plain, which):
    stream = plain[which]
    old = sidq.to_bytes(stream)
    bits = _bits(1)
    new = sidq.to_bytes(replace(stream, contacts=FootContacts(bits, FLOOR)))
    section = FLOOR.astype("<f4").tobytes() + _runs_by_hand(bits[:, 0]) + _runs_by_hand(bits[:, 1])
    body = old[:4] + bytes([old[4] | 0x80]) + old[5:-4] + section + struct.pack("<I", len(section))
    assert new == body + struct.pack("<I", zlib.crc32(body))
    assert (
        old[4] in (1, 2, 3, 4, 5, 6) and not old[4] & FLAG
    )  # a stream without contacts is as before


@pytest.mark.parametrize("which", [0, 1])
def test_old_streams_still_decode_and_carry_no_contacts(plain, which):
    s = sidq.from_bytes(sidq.to_bytes(plain[which]))
    assert s.contacts is None and s == replace(s, contacts=None)
    assert np.array_equal(s.keyframes, plain[which].keyframes)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([0, 1]))
def test_contact_bits_and_floor_survive_the_round_trip(plain, seed, which):
    rng = np.random.default_rng(seed)
    bits = rng.random((N, 2)) < rng.random()  # from every frame flipping to a single run
    floor = rng.normal(scale=0.05, size=5).astype(np.float32).astype(np.float64)
    stream = replace(plain[which], contacts=FootContacts(bits, floor))
    back = sidq.from_bytes(sidq.to_bytes(stream))
    assert np.array_equal(back.contacts.bits, bits) and np.array_equal(back.contacts.floor, floor)
    assert np.array_equal(back.pose_codes, stream.pose_codes)


def test_the_decoder_pins_the_feet_the_bits_name(plain):
    stream = replace(plain[0], contacts=FootContacts(_bits(2), FLOOR))
    s = sidq.from_bytes(sidq.to_bytes(stream))
    free = reconstruct_stream(replace(s, contacts=None))
    want = pin_feet(free.positions, s.contacts.bits, s.keyframes, s.fps, floor=FLOOR)
    got = reconstruct_stream(s)
    assert np.allclose(got.positions, want, atol=1e-12)
    assert len(s.keyframes) < N / 2 and not np.allclose(got.positions, free.positions)
    clip = stream_to_clip(s)  # the .npz output: the pinned points, angles charted again
    assert np.allclose(clip.positions, got.positions, atol=1e-9)


def _section_of(data: bytes) -> tuple[bytes, int]:
    (n,) = struct.unpack("<I", data[-8:-4])
    return data[: -8 - n], n


def _recrc(raw: bytes) -> bytes:
    return raw + struct.pack("<I", zlib.crc32(raw))


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_hostile_contact_sections_fail_in_one_line(plain, data):
    stream = replace(plain[0], contacts=FootContacts(_bits(3), FLOOR))
    good = sidq.to_bytes(stream)
    head, n = _section_of(good)
    section = bytearray(good[len(head) : len(head) + n])
    kind = data.draw(st.sampled_from(["truncate", "flip", "length", "runs"]))
    if kind == "truncate":  # cut anywhere, checksum made valid again
        raw = _recrc(good[: data.draw(st.integers(5, len(good) - 5))])
    elif kind == "flip":  # a byte of the section changed behind a valid checksum
        section[data.draw(st.integers(0, n - 1))] ^= data.draw(st.integers(1, 255))
        raw = _recrc(head + bytes(section) + struct.pack("<I", n))
    elif kind == "length":  # a length field that lies (up to 4 GiB)
        raw = _recrc(
            head + bytes(section) + struct.pack("<I", data.draw(st.integers(0, 2**32 - 1)))
        )
    else:  # runs for another number of frames, or trailing bytes
        runs = data.draw(st.binary(min_size=0, max_size=40))
        raw = _recrc(head + bytes(section[:20]) + runs + struct.pack("<I", 20 + len(runs)))
    try:
        s = sidq.from_bytes(raw, "hostile.sidq")
    except MotionDataError as e:
        assert "\n" not in str(e) and str(e).startswith("hostile.sidq")
        return
    assert s.contacts is None or s.contacts.bits.shape == (s.n_frames, 2)


def test_the_reader_bounds_the_section_before_slicing(plain):
    good = sidq.to_bytes(replace(plain[0], contacts=FootContacts(_bits(4), FLOOR)))
    head, n = _section_of(good)
    for lie in (MAX_SECTION_BYTES + 1, 2**32 - 1, len(good)):
        raw = _recrc(good[:-8] + struct.pack("<I", lie))
        with pytest.raises(MotionDataError, match="contact section of"):
            sidq.from_bytes(raw, "x.sidq")
    nan = _recrc(head + np.full(5, np.nan, "<f4").tobytes() + good[len(head) + 20 : -4])
    with pytest.raises(MotionDataError, match="floor: non-finite"):
        sidq.from_bytes(nan, "x.sidq")


def test_a_section_on_another_skeleton_is_refused(plain):
    names = ("root", *(f"b{i}" for i in range(22)))
    other = replace(plain[1], names=names, contacts=FootContacts(_bits(6), FLOOR))
    with pytest.raises(MotionDataError, match="other than the protocol"):
        sidq.from_bytes(sidq.to_bytes(other), "o.sidq")


def test_bits_of_another_length_are_refused_when_written(plain):
    with pytest.raises(UsageError, match="cover 10 frames"):
        sidq.to_bytes(replace(plain[0], contacts=FootContacts(_bits(5, 10), FLOOR)))


def test_the_band_is_the_clip_matrix_on_its_diagonals():
    clip = smooth_clip(N=40, fps=30.0, seed=1)
    x = segment_inputs(clip)
    full, band = physical_costs(x), physical_band(x, 12)
    for L in range(13):
        i = np.arange(40 - L)
        assert np.array_equal(band[:, i, L], full[:, i, i + L])
    assert not band[:, 40 - 12 :, 12].any()


@pytest.fixture(scope="module")
def walk(cmu_dir):
    return load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc", fps=30.0)


@pytest.mark.parametrize("physics", [False, True])
def test_encoding_with_contacts_counts_the_section_in_the_rate(walk, physics):
    enc = encode_with_contacts(walk, physics=physics, rate=600.0)
    s = sidq.from_bytes(enc.data)
    assert enc.bytes_per_second <= 600.0 and len(enc.data) == len(sidq.to_bytes(enc.stream))
    assert np.array_equal(s.contacts.bits, trial_contacts(walk).bits)
    assert 10 < s.contacts.bits.sum() < 2 * walk.n_frames  # a walk: both states present
    assert np.isfinite(enc.mean_error_mm) and enc.mean_error_mm < 30


def test_physics_changes_the_keyframes_and_refuses_what_it_cannot_carry(walk):
    a = encode_with_contacts(walk, physics=False, rate=300.0, reconstruction="linear")
    b = encode_with_contacts(walk, physics=True, rate=300.0, reconstruction="linear")
    assert not np.array_equal(a.stream.keyframes, b.stream.keyframes)
    with pytest.raises(UsageError, match="offline"):
        encode_with_contacts(walk, rate=300.0, latency=5)
    with pytest.raises(UsageError, match="physical cost needs"):
        encode_with_contacts(walk, physics=True, rate=300.0, reconstruction="hermite")
    with pytest.raises(UnmetTargetError, match="foot contacts alone"):
        encode_with_contacts(walk, rate=1.0)


def test_encode_command_with_physics_writes_a_stream_that_decodes(cmu_dir, tmp_path):
    trial = [str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")]
    out = tmp_path / "w.sidq"
    res = cli("encode", *trial, "--out", str(out), "--rate", "500", "--physics", timeout=300)
    assert res.returncode == 0 and "foot contacts" in res.stdout, res.stderr
    assert sidq.read(out).contacts is not None
    res = cli("encode", *trial, "--out", str(out), "--rate", "500", "--contacts", "--latency", "5")
    one_line_exit_2(res, "offline")


def test_streamed_contacts_of_one_window_are_the_whole_take_paths_bytes(cmu_dir, tmp_path):
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    enc = encode_files(asf, amc, tmp_path / "s.sidq", rate=600.0, contacts=streamed_contacts)
    whole = encode_files(asf, amc, tmp_path / "w.sidq", rate=600.0, encoder=encode_with_contacts)
    assert enc.streams == whole.streams == 1
    assert (tmp_path / "s.sidq").read_bytes() == (tmp_path / "w.sidq").read_bytes()


def test_streamed_contacts_over_windows_carry_the_whole_takes_floor_and_bits(cmu_dir, tmp_path):
    asf, amc = cmu_dir / "01" / "01.asf", cmu_dir / "01" / "01_01.amc"  # 688 frames at 30 fps
    clip = load_motion(asf, amc, fps=30.0, derivatives=False)
    whole = trial_contacts(clip)
    track = foot_track(stream_clips(asf, amc, fps=30.0, chunk_frames=50))
    assert len(track.names) == 6 and track.n_frames == clip.n_frames
    assert np.array_equal(trial_contacts(track).bits, whole.bits)
    assert np.array_equal(trial_contacts(track).floor, whole.floor)
    out = tmp_path / "s.sidq"
    enc = encode_files(asf, amc, out, rate=900.0, window=200, contacts=streamed_contacts)
    assert is_sequence(out) and enc.streams >= 3 and enc.n_frames == clip.n_frames
    assert out.stat().st_size == enc.n_bytes <= 900.0 * clip.n_frames / 30.0
    bits, start = [], 0
    for stream in iter_streams(out):
        assert np.array_equal(stream.contacts.floor, whole.floor)
        assert np.array_equal(stream.contacts.bits, whole.bits[start : start + stream.n_frames])
        bits.append(stream.contacts.bits[1:] if start else stream.contacts.bits)
        start += stream.n_frames - 1  # consecutive streams share a frame
    assert np.array_equal(np.concatenate(bits), whole.bits)
    rec = decode_to_reconstruction(out)  # pinned stream by stream
    assert rec.positions.shape == (clip.n_frames, 23, 3) and np.isfinite(rec.positions).all()


def test_a_take_read_once_gives_the_windows_the_points_and_bytes_of_a_second_read(
    cmu_dir, tmp_path
):
    asf, amc = cmu_dir / "01" / "01.asf", cmu_dir / "01" / "01_01.amc"  # 688 frames at 30 fps
    again = list(stream_clips(asf, amc, fps=30.0, chunk_frames=50, velocities=False))
    track, kept = foot_pass(stream_clips(asf, amc, fps=30.0, chunk_frames=50), keep=10**6)
    assert foot_pass(stream_clips(asf, amc, fps=30.0, chunk_frames=50), keep=687)[1] is None
    assert len(kept) == len(again) and track.n_frames == sum(c.n_frames for c in again)
    for k, c in zip(kept, again, strict=True):
        idx = [c.names.index(n) for n in k.names]
        assert np.array_equal(k.positions, c.positions[:, idx])
        assert not np.any(k.velocities) and k.start_frame == c.start_frame
    paths = {}
    for keep in (10**6, 100):  # kept whole; too long to keep: read again
        paths[keep] = out = tmp_path / f"k{keep}.sidq"
        enc = encode_files(asf, amc, out, rate=900.0, window=200,
                           contacts=partial(streamed_contacts, keep=keep))  # fmt: skip
        assert enc.streams >= 3
    assert paths[10**6].read_bytes() == paths[100].read_bytes()
