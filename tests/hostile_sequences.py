"""Hostile sequences of ``.sidq`` streams (the ``SIDM`` container, :mod:`sidql.codec.sequence`).

One file type of ``tests/hostile_inputs.py`` (kind ``"sidm"``), kept here so that module does not
grow. Seeds are sequences of the real ``.sidq`` seeds (offline and live streams of one short
clip: the same rate, skeleton and points, so the sequence is valid). Mutations: bytes anywhere;
a record's length (0, off by one, past the stream limit, 2^32 - 1); the stream count; the magic
and version; one stream damaged by the ``.sidq`` mutations (its record length kept true); a
stream of another rate or skeleton; streams stretched to the frame limit (a take too long to
join, from a small file); thousands of records of one small stream; a cut or a tail. Eight in
ten get their checksum fixed so the damage reaches the readers behind it.

The reader (:func:`read_sidm`) is the decoder's: the first stream (rate, skeleton), each stream
reconstructed one at a time (``sidql decode`` to ``.npz`` or ``.amc``), and the whole take
joined (:func:`sidql.codec.decode.decode_to_reconstruction`, ``sidql report``).
"""

from __future__ import annotations

import dataclasses
import struct
import zlib

import numpy as np
from hostile_inputs import Case, _long_stream, _pick, _sidq_case, _stream_case

U32 = (0, 1, 2, 23, 255, 1 << 16, (64 << 20) + 1, (1 << 31) - 1, (1 << 32) - 1)


def sequence_bytes(streams: list[bytes], count: int | None = None) -> bytes:
    """A sequence of the streams' bytes (``count``: the stream count it states)."""
    from sidql.codec.sequence import MAGIC, VERSION

    body = MAGIC + bytes([VERSION])
    for s in streams:
        body += struct.pack("<I", len(s)) + s
    body += struct.pack("<II", 0, len(streams) if count is None else count)
    return body + struct.pack("<I", zlib.crc32(body))


def sidm_seeds(seeds) -> list[bytes]:
    """Valid sequences of the ``.sidq`` seeds: two streams, and all of them."""
    return [sequence_bytes(seeds.sidq[1:3]), sequence_bytes(list(seeds.sidq))]


def _records(data: bytes) -> list[tuple[int, int]]:
    """(offset of the length field, length) of each record of a valid sequence."""
    out, at = [], 5
    while True:
        (n,) = struct.unpack("<I", data[at : at + 4])
        if n == 0:
            return out
        out.append((at, n))
        at += 4 + n


def _streams(data: bytes) -> list[bytes]:
    return [data[at + 4 : at + 4 + n] for at, n in _records(data)]


def _other(stream: bytes, rng) -> bytes:
    """``stream`` at another rate or with another skeleton hash."""
    from sidql.codec import format as sidq

    s = sidq.from_bytes(stream)
    if rng.randrange(2):
        s = dataclasses.replace(s, fps=float(np.float32(s.fps * _pick(rng, (0.5, 2.0, 1.001)))))
    else:
        s = dataclasses.replace(s, skeleton_hash=bytes(8 - len(b"other")) + b"other")
    return sidq.to_bytes(s)


def sidm_case(seeds, rng) -> Case:
    """A random hostile sequence (deterministic in the choices of ``rng``)."""
    data = _pick(rng, sidm_seeds(seeds))
    streams = _streams(data)
    op = _pick(rng, ("bytes", "length", "count", "header", "stream", "stream", "other", "long",
                     "many", "cut"))  # fmt: skip
    ops = [op]
    if op == "bytes":
        from acclaim_mutations import mutate

        new, m = mutate(data, rng)
        ops += m
    elif op == "length":
        at, n = _pick(rng, _records(data))
        value = _pick(rng, (*U32, n - 1, n + 1))
        new = data[:at] + struct.pack("<I", value) + data[at + 4 :]
    elif op == "count":
        new = data[:-8] + struct.pack("<I", _pick(rng, (*U32, len(streams) + 1))) + data[-4:]
    elif op == "header":
        b = bytearray(data)
        b[rng.randrange(5)] = _pick(rng, (0, 1, 2, 0x4D, 0xFF))
        new = bytes(b)
    elif op == "stream":  # one stream damaged as a .sidq file would be
        k = rng.randrange(len(streams))
        case = _sidq_case(dataclasses.replace(seeds, sidq=[streams[k]]), rng)
        bad = case.files["s.sidq"]
        if isinstance(bad, bytes) and bad:
            streams[k] = bad
        new = sequence_bytes(streams)
        ops += case.ops
    elif op == "other":  # a stream of another rate or skeleton
        k = 1 + rng.randrange(len(streams) - 1)
        streams[k] = _other(streams[k], rng)
        new = sequence_bytes(streams)
    elif op == "long":  # streams at the frame limit: small, but too long to join
        long = [_long_stream(streams[0], rng) for _ in range(1 + rng.randrange(5))]
        new = sequence_bytes(long)
    elif op == "many":  # many records of one small stream
        new = sequence_bytes([streams[0]] * _pick(rng, (2, 50, 1000, 5000)))
    else:  # cut, or a tail
        cut = rng.randrange(len(data))
        new = data[:cut] if rng.randrange(2) else data + bytes(1 + rng.randrange(64))
    return _stream_case(rng, "sidm", new, ops, fixable=len(new) > 4)


def read_sidm(path, folder, _args) -> list:
    """Read a sequence as the decoder does: the first stream, each stream's reconstruction one
    at a time (only its finiteness kept), then the whole take joined."""
    from sidql.codec.decode import _sequence_reconstructions as per_stream
    from sidql.codec.decode import decode_to_reconstruction, first_stream

    first_stream(path)
    finite = [bool(np.isfinite(r.positions).all() and np.isfinite(r.velocities).all())
              for r in per_stream(path)]  # fmt: skip
    rec = decode_to_reconstruction(path)
    return [np.array([0.0 if all(finite) else np.nan]), rec.positions, rec.velocities]
