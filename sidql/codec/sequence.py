"""A sequence of ``.sidq`` streams: one take longer than a stream may be, written and read one
stream at a time (bounded memory, any length).

The byte format is specified in ``docs/codec.md`` ("A sequence of streams"): the magic
:data:`MAGIC`, a version byte, then records ``uint32 n`` + ``n`` bytes of one ordinary stream
(:mod:`sidql.codec.format`, its own CRC-32), a record of ``n = 0`` ending them, the stream count
(``uint32``) and a CRC-32 of every byte before it. Every stream has the first one's rate, skeleton
hash and points; each stream after the first starts at the frame where the one before it ends
(its frame 0 is that frame again, and a decoder outputs it once, from the earlier stream).

Any defect is one line naming the file (:class:`~sim.errors.MotionDataError`).
"""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np

from sidql.codec import format as sidq
from sim.errors import MotionDataError, UsageError
from sim.files import MAX_SIDQ_BYTES, open_regular

MAGIC = b"SIDM"
VERSION = 1
#: Largest sequence file read [bytes]: it is read one stream (at most ``MAX_SIDQ_BYTES``) at a
#: time, so memory does not grow with it; the limit bounds only the time a read takes.
MAX_SEQUENCE_BYTES = 16 << 30
_HEADER = MAGIC + bytes([VERSION])


def is_sequence(path: str | os.PathLike) -> bool:
    """Whether the file at ``path`` starts with the sequence magic (False if unreadable)."""
    try:
        with open_regular(path, MAX_SEQUENCE_BYTES) as f:
            return f.read(4) == MAGIC
    except MotionDataError:
        return False


class SequenceWriter:
    """Writes a sequence to the binary file object ``f``, one stream at a time."""

    def __init__(self, f):
        self.f, self.count, self.crc, self.size = f, 0, 0, 0
        self._write(_HEADER)

    def _write(self, data: bytes) -> None:
        self.f.write(data)
        self.crc = zlib.crc32(data, self.crc)
        self.size += len(data)

    def add(self, data: bytes) -> None:
        """Append one ordinary ``.sidq`` stream's bytes."""
        if not 0 < len(data) <= MAX_SIDQ_BYTES:
            raise UsageError(f"a stream of {len(data)} bytes (1 to {MAX_SIDQ_BYTES:,})")
        self._write(struct.pack("<I", len(data)) + data)
        self.count += 1

    def close(self) -> None:
        """End the sequence: the end record, the stream count and the CRC-32."""
        if self.count < 1:
            raise UsageError("a sequence needs at least one stream")
        self._write(struct.pack("<II", 0, self.count))
        self.f.write(struct.pack("<I", self.crc))
        self.size += 4


#: Bytes a sequence adds to its streams: the header, a length per stream, the end record, the
#: count and the CRC.
def overhead_bytes(streams: int) -> int:
    return len(_HEADER) + 4 * streams + 12


def iter_streams(path: str | os.PathLike):
    """Yield the :class:`~sidql.codec.format.Stream` of each record of the sequence at ``path``
    in order, one at a time (the whole file's CRC is checked after the last).

    Raises:
        MotionDataError: not a sequence, a bad record length, a stream that differs from the
            first in rate, skeleton or points, a bad stream (:func:`sidql.codec.format.from_bytes`),
            a truncated file or a checksum mismatch.
    """
    where = str(path)
    with open_regular(path, MAX_SEQUENCE_BYTES) as f:
        head = f.read(len(_HEADER))
        if head[:4] != MAGIC:
            raise MotionDataError(where, None, "not a .sidq sequence (bad magic)")
        if head[4:] != bytes([VERSION]):
            raise MotionDataError(where, None, f"unknown sequence version {head[4:]!r}")
        crc, count, first = zlib.crc32(head), 0, None
        while True:
            raw = _take(f, 4, where, "record length")
            crc = zlib.crc32(raw, crc)
            (n,) = struct.unpack("<I", raw)
            if n == 0:
                break
            if n > MAX_SIDQ_BYTES:
                raise MotionDataError(where, None, f"record of {n:,} bytes exceeds the limit")
            data = _take(f, n, where, f"stream {count + 1}")
            crc = zlib.crc32(data, crc)
            stream = sidq.from_bytes(data, f"{where}: stream {count + 1}")
            first = stream if first is None else first
            _check_same(first, stream, where, count + 1)
            count += 1
            yield stream
        tail = _take(f, 4, where, "stream count")
        crc = zlib.crc32(tail, crc)
        (declared,) = struct.unpack("<I", tail)
        (stored,) = struct.unpack("<I", _take(f, 4, where, "checksum"))
        if declared != count or count < 1:
            raise MotionDataError(where, None, f"stream count {declared}; the file holds {count}")
        if stored != crc or f.read(1):
            raise MotionDataError(
                where, None, "checksum mismatch: the sequence is truncated or corrupt"
            )


def _take(f, n: int, where: str, what: str) -> bytes:
    """The next ``n`` bytes of ``f``, refused before anything is allocated when the file does not
    hold them (a record length may claim up to 64 MiB)."""
    if n > os.fstat(f.fileno()).st_size - f.tell():
        raise MotionDataError(where, None, f"truncated sequence: {what} missing")
    data = f.read(n)
    if len(data) != n:
        raise MotionDataError(where, None, f"truncated sequence: {what} missing")
    return data


def _check_same(first: sidq.Stream, s: sidq.Stream, where: str, k: int) -> None:
    """Refuse stream ``k`` if its rate, skeleton or points differ from the first stream's."""
    same = (
        s.fps == first.fps
        and s.skeleton_hash == first.skeleton_hash
        and tuple(s.names) == tuple(first.names)
        and np.array_equal(s.parents, first.parents)
    )
    if not same:
        raise MotionDataError(
            where, None, f"stream {k} differs from stream 1 in rate, skeleton or points"
        )


def take_frames(streams) -> int:
    """Frames of the take a sequence of streams holds (each after the first shares its first
    frame with the one before)."""
    total, count = 0, 0
    for s in streams:
        total += s.n_frames
        count += 1
    return total - max(count - 1, 0)
