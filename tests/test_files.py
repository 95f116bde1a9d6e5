"""Atomic outputs (:mod:`sim.files`)."""

from __future__ import annotations

import os

import pytest

from sim.files import write_atomic


def test_atomic_writes_get_ordinary_file_permissions(tmp_path):
    mask = os.umask(0o022)
    try:
        write_atomic(tmp_path / "a.bin", lambda f: f.write(b"data"))
    finally:
        os.umask(mask)
    assert (tmp_path / "a.bin").read_bytes() == b"data"
    assert (tmp_path / "a.bin").stat().st_mode & 0o777 == 0o644


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    (tmp_path / "a.bin").write_bytes(b"old")

    def half_then_fail(f):
        f.write(b"ne")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError, match="disk on fire"):
        write_atomic(tmp_path / "a.bin", half_then_fail)
    assert (tmp_path / "a.bin").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin"]
