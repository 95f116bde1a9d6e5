"""A frame that a text chunk cuts in two waits for the next chunk and is read with it: the same
values, notes and errors as reading every frame line by line (the reader's checked path, the
oracle here), and only the file's first and last frames are read line by line."""

from __future__ import annotations

import numpy as np
import pytest

import sim.acclaim.amc as amc_module
import sim.files
from sim.acclaim.amc import iter_amc, parse_amc
from sim.acclaim.asf import parse_asf
from sim.errors import MotionDataError


def _line_by_line(monkeypatch):
    monkeypatch.setattr(amc_module._AmcParser, "_fast", lambda self, lines, start, stop: start)


@pytest.fixture
def walk(cmu_dir):
    return parse_asf(cmu_dir / "01" / "01.asf"), cmu_dir / "01" / "01_01.amc"


@pytest.mark.parametrize("chunk", [997, 4096, 65536])
def test_chunked_pieces_are_the_frames_read_line_by_line(walk, chunk, monkeypatch):
    skeleton, path = walk
    monkeypatch.setattr(sim.files, "TEXT_CHUNK_BYTES", chunk)
    pieces = list(iter_amc(path, skeleton))
    with monkeypatch.context() as m:
        _line_by_line(m)
        oracle = parse_amc(path, skeleton)
    assert np.array_equal(np.concatenate([p.root for p in pieces]), oracle.root)
    for name, a in oracle.angles.items():
        assert np.array_equal(np.concatenate([p.angles[name] for p in pieces]), a), name
    assert sum(p.n_frames for p in pieces) == oracle.n_frames


def test_only_the_first_and_last_frames_are_read_line_by_line(walk, monkeypatch):
    skeleton, path = walk
    monkeypatch.setattr(sim.files, "TEXT_CHUNK_BYTES", 4096)  # ~70 chunk boundaries
    read = []
    line = amc_module._AmcParser._line
    monkeypatch.setattr(
        amc_module._AmcParser, "_line", lambda self, ln, raw: (read.append(ln), line(self, ln, raw))
    )  # fmt: skip
    motion = parse_amc(path, skeleton)
    lines = path.read_text().splitlines()
    per_frame = (len(lines) - 3) // motion.n_frames  # a number line, then a line per bone
    # the first two frames (the first is closed, its layout known, when the second's number
    # is read) and the last
    start, end = 3 + 2 * per_frame, len(lines) - per_frame
    assert motion.n_frames > 500 and read and all(ln <= start or ln > end for ln in read)


@pytest.mark.filterwarnings("ignore::sim.errors.MotionDataWarning")
def test_a_cut_frame_s_defect_and_a_truncated_last_frame_read_as_line_by_line(
    cmu_dir, tmp_path, monkeypatch
):
    skeleton = parse_asf(cmu_dir / "07" / "07.asf")
    path = cmu_dir / "07" / "07_12.amc"  # ends in an incomplete frame: dropped with a note
    monkeypatch.setattr(sim.files, "TEXT_CHUNK_BYTES", 997)
    chunked = parse_amc(path, skeleton)
    with monkeypatch.context() as m:
        _line_by_line(m)
        oracle = parse_amc(path, skeleton)
    assert chunked.notes == oracle.notes and len(chunked.notes) == 1
    assert np.array_equal(chunked.root, oracle.root)
    lines = path.read_text().splitlines()
    for bad in (len(lines) // 3, len(lines) // 2 + 7):  # somewhere; a chunk may well cut it
        broken = lines.copy()
        broken[bad] = broken[bad].split()[0] + " 1.0 oops"
        (tmp_path / "bad.amc").write_text("\n".join(broken) + "\n")
        with pytest.raises(MotionDataError) as streamed:
            list(iter_amc(tmp_path / "bad.amc", skeleton))
        with monkeypatch.context() as m, pytest.raises(MotionDataError) as oracle_error:
            _line_by_line(m)
            parse_amc(tmp_path / "bad.amc", skeleton)
        assert str(streamed.value) == str(oracle_error.value)
        assert f":{bad + 1}:" in str(streamed.value)
