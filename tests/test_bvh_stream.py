"""A BVH read a chunk of frames at a time: the pieces join to the whole file, a defect anywhere is
the whole file's one-line error, and a BVH take encodes to the bytes of the whole-file path."""

from __future__ import annotations

import io

import numpy as np
import pytest
from bvh_files import bvh_text, creature, motion

from sidql.codec.encode import encode_files, encode_series
from sidql.codec.skeleton import skeleton_hash
from sidql.codec.windows import encode_windows
from sidql.commands.main import main
from sim.bvh.convert import to_acclaim
from sim.bvh.reader import iter_bvh, parse_bvh
from sim.bvh.stream import first_skeleton, iter_take, read_skeleton
from sim.errors import MotionDataError
from sim.motion.chunks import stream_clips
from sim.motion.ingest import load_motion


def test_bvh_pieces_join_to_the_whole_file_and_convert_as_it_does(walk_bvh):
    whole = parse_bvh(walk_bvh)
    pieces = list(iter_bvh(walk_bvh))
    assert len(pieces) > 3 and all(repr(p.joints) == repr(whole.joints) for p in pieces)
    assert np.array_equal(np.concatenate([p.values for p in pieces]), whole.values)
    take = to_acclaim(whole)
    takes = list(iter_take(walk_bvh))
    assert len(takes) == len(pieces)
    assert np.array_equal(np.concatenate([t.motion.root for t in takes]), take.motion.root)
    for name, a in take.motion.angles.items():
        assert np.array_equal(np.concatenate([t.motion.angles[name] for t in takes]), a), name
    for t in takes:
        assert repr(t.skeleton) == repr(take.skeleton)
    assert repr(read_skeleton(walk_bvh)) == repr(take.skeleton)


def _same_error(path):
    """The whole file's error and the streamed one's, and the pieces yielded before it."""
    with pytest.raises(MotionDataError) as whole:
        to_acclaim(parse_bvh(path))
    yielded = []
    with pytest.raises(MotionDataError) as streamed:
        for take in iter_take(path):
            yielded.append(take)
    assert str(streamed.value) == str(whole.value)
    assert "\n" not in str(streamed.value)
    return str(streamed.value), len(yielded)


def test_a_defect_deep_in_the_file_is_the_whole_files_one_line_error(walk_bvh, tmp_path):
    lines = walk_bvh.read_text().splitlines()
    bad = len(lines) - 300  # far past the first text chunk
    tokens = lines[bad].split()
    lines[bad] = " ".join(tokens[:3] + ["oops"] + tokens[4:])
    path = tmp_path / "bad.bvh"
    path.write_text("\n".join(lines) + "\n")
    message, before = _same_error(path)
    assert f":{bad + 1}:" in message and before > 3

    path.write_text("\n".join(walk_bvh.read_text().splitlines()[:-200]) + "\n")
    message, before = _same_error(path)
    assert "truncated MOTION" in message and before > 3


def test_the_first_chunks_skeleton_is_the_whole_files_and_a_later_defect_still_stops_encode(
    walk_bvh, tmp_path, capsys
):
    assert repr(first_skeleton(walk_bvh)) == repr(read_skeleton(walk_bvh))
    lines = walk_bvh.read_text().splitlines()
    bad = len(lines) - 300  # far past the first text chunk
    lines[bad] = " ".join(lines[bad].split()[:3] + ["oops"] + lines[bad].split()[4:])
    path = tmp_path / "bad.bvh"
    path.write_text("\n".join(lines) + "\n")
    assert skeleton_hash(first_skeleton(path)) == skeleton_hash(read_skeleton(walk_bvh))  # fine
    message, _ = _same_error(path)
    out = tmp_path / "bad.sidq"
    assert main(["encode", str(path), "--out", str(out), "--rate", "942"]) == 2
    assert message in capsys.readouterr().err and not out.exists()
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_a_position_channel_that_drifts_over_chunks_is_refused_as_in_the_whole_file(tmp_path):
    nodes = creature()
    spine = 9
    nodes[spine].channels = ("Yposition",) + nodes[spine].channels
    values = motion(nodes, 3000, 120.0)
    col = sum(len(n.channels) for n in nodes[:spine])
    values[:, col] = 2.0  # [m]: 200 cm, so 1e-6 of it is 0.0002 cm
    path = tmp_path / "drift.bvh"
    path.write_text(bvh_text(nodes, values, 120.0))
    sizes = np.cumsum([p.n_frames for p in iter_bvh(path)])
    assert len(sizes) >= 3
    list(iter_take(path))  # constant: read
    # each piece within 1e-6 of the first frame, the take 1.6e-6 apart: refused
    values[sizes[0] : sizes[1], col] = 2.0000016
    values[sizes[1] : sizes[2], col] = 1.9999984
    path.write_text(bvh_text(nodes, values, 120.0))
    assert np.array_equal(np.cumsum([p.n_frames for p in iter_bvh(path)]), sizes)
    message, before = _same_error(path)
    assert "Yposition moves" in message and before == 2


def test_a_bvh_take_encodes_to_the_bytes_of_the_whole_file_path(walk_bvh, tmp_path):
    clips = list(stream_clips(walk_bvh, walk_bvh, chunk_frames=50, velocities=False))
    whole = load_motion(walk_bvh, derivatives=False)
    assert len(clips) > 10
    np.testing.assert_allclose(
        np.concatenate([c.positions for c in clips]), whole.positions, rtol=0, atol=1e-12
    )
    out = tmp_path / "w.sidq"
    enc = encode_files(walk_bvh, None, out, rate=600.0, window=200)
    f = io.BytesIO()
    skel = skeleton_hash(to_acclaim(parse_bvh(walk_bvh)).skeleton)
    ref = encode_windows(f, [whole], encode_series, rate=600.0, window=200, skel_hash=skel)
    assert enc.streams == ref.streams > 1
    assert out.read_bytes() == f.getvalue()
