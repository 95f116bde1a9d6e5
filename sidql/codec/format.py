"""The ``.sidq`` container, versions 1 to 6: bytes <-> :class:`Stream`.

The byte format is specified once, in ``docs/codec.md`` ("The .sidq format"): version 1 carries
codings 0 (fixed-size records, for live streaming) and 1 (packed, LZMA, offline), versions 2
to 6 coding 2, the position coding (its fields: :mod:`sidql.codec.position_format`; values as
:class:`sidql.codec.quantise.PositionQuantiser` rebuilds them). All numbers are little-endian;
the header names the reconstruction (its index in :data:`sidql.keyframes.curves.CURVES`), the
stream rate, the skeleton's hash (:func:`sidql.codec.skeleton.skeleton_hash`) and the points
(J = 0: the CMU protocol's 23, :data:`sidql.keyframes.spherical.POINTS`), and a CRC-32 of every
byte before it ends the file. This module is that specification's reader and writer.

Limits (checked before anything of their size is allocated): at most :data:`MAX_FRAMES` frames
(fewer for skeletons of more than 23 points), a rate in (0, :data:`MAX_FPS`], lengths, origin and
steps within :data:`MAX_METRES` / :data:`MAX_STEP`, an LZMA dictionary within
:data:`LZMA_MEMLIMIT`; the packed keyframes are inflated incrementally, the gaps first.

Any deviation (bad magic, unknown version or reconstruction, short read, a body that is not a
whole number of records, a bad gap, a checksum mismatch) raises :class:`MotionDataError` with one
line naming the file and the problem.
"""

from __future__ import annotations

import lzma
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sidql.codec.contact_section import FootContacts, attach_section, split_section, with_section
from sidql.codec.position_format import (  # noqa: F401 (re-exported: the format's one name)
    MAX_DECODED_VALUE,
    POSITION_RECONSTRUCTIONS,
    POSITION_VERSIONS,
    VERSION_POSITION,
    block_bytes,
    length_codes,
    lengths_from_codes,
    position_lengths,
    quantiser_bytes,
    read_block,
    read_quantiser,
)
from sidql.codec.quantise import BITS, Quantiser
from sidql.keyframes.curves import CURVES
from sidql.keyframes.spherical import POINTS, protocol_parent_indices
from sim.errors import MotionDataError, UsageError
from sim.files import MAX_SIDQ_BYTES, read_regular, write_atomic

MAGIC = b"SIDQ"
VERSION = 1
MAX_GAP = 255


@dataclass(frozen=True)
class Stream:
    """A decoded container: everything needed to rebuild the motion.

    Attributes:
        reconstruction: one of :data:`CURVES`.
        latency: look-ahead [frames] the encoder used (0: offline, whole trial).
        fps: stream frame rate [1/s].
        skeleton_hash: 8 bytes identifying the source skeleton.
        names: (J,) point names; parents: (J,) int64 parent indices (-1 root).
        lengths: (M,) bone lengths [m].
        quantiser: the quantisation parameters.
        keyframes: (W,) frame indices, 0 first, strictly increasing.
        pose_codes: (W, D) uint16; rate_codes: (W, D) int16 or None.
        coding: 0 fixed records, 1 packed (see the module docstring).
        contacts: the optional foot-contact section (:mod:`sidql.codec.contact_section`).
    """

    reconstruction: str
    latency: int
    fps: float
    skeleton_hash: bytes
    names: tuple[str, ...]
    parents: np.ndarray
    lengths: np.ndarray
    quantiser: Quantiser
    keyframes: np.ndarray
    pose_codes: np.ndarray
    rate_codes: np.ndarray | None
    coding: int = 0
    contacts: FootContacts | None = None

    @property
    def n_frames(self) -> int:
        return int(self.keyframes[-1]) + 1


def record_size(reconstruction: str, n_bones: int) -> int:
    """Bytes of one keyframe record."""
    D = 2 * n_bones + 3
    return 1 + 2 * D * (2 if reconstruction == "hermite" else 1)


def header_bytes(stream: Stream, position_version: int = VERSION_POSITION) -> bytes:
    """The header of ``stream`` (everything before the first record); coding 2 as version
    ``position_version`` (older ones for tests of the readers)."""
    J = len(stream.names)
    standard = tuple(stream.names) == POINTS and np.array_equal(
        stream.parents, protocol_parent_indices()
    )
    out = bytearray()
    out += MAGIC
    out += struct.pack(
        "<BBBBHf",
        position_version if stream.coding == 2 else VERSION,
        CURVES.index(stream.reconstruction),
        stream.coding,
        stream.quantiser.bits,
        stream.latency,
        stream.fps,
    )
    out += bytes(stream.skeleton_hash)
    out += struct.pack("<B", 0 if standard else J)
    if not standard:
        for n in stream.names:
            b = n.encode("ascii")
            out += struct.pack("<B", len(b)) + b
        out += np.asarray(stream.parents, dtype=np.int8).tobytes()
    if stream.coding == 2:
        exponent, codes = length_codes(stream.lengths)
        out += struct.pack("<b", exponent) + codes.astype("<u2").tobytes()
        return bytes(out + quantiser_bytes(stream.quantiser, position_version))
    out += np.asarray(stream.lengths, dtype="<f4").tobytes()
    out += np.asarray(stream.quantiser.root_origin, dtype="<f4").tobytes()
    out += np.asarray(stream.quantiser.root_step, dtype="<f4").tobytes()
    if stream.reconstruction == "hermite":
        out += np.asarray(stream.quantiser.rate_step, dtype="<f4").tobytes()
    return bytes(out)


def record_bytes(stream: Stream, start: int = 0, stop: int | None = None) -> bytes:
    """Records ``start..stop`` of ``stream`` as bytes (a live sender emits them one by one)."""
    k = np.asarray(stream.keyframes, dtype=np.int64)
    stop = len(k) if stop is None else stop
    gaps = np.diff(k, prepend=k[:1])[start:stop]
    W = len(gaps)
    D = stream.pose_codes.shape[1]
    fields = [("gap", "u1"), ("pose", "<u2", (D,))]
    if stream.reconstruction == "hermite":
        fields.append(("rate", "<i2", (D,)))
    rec = np.zeros(W, dtype=np.dtype(fields))
    rec["gap"] = gaps
    rec["pose"] = stream.pose_codes[start:stop]
    if stream.reconstruction == "hermite":
        rec["rate"] = stream.rate_codes[start:stop]
    return rec.tobytes()


def to_bytes(stream: Stream, position_version: int = VERSION_POSITION) -> bytes:
    """The whole container: header, records, CRC-32 (coding 2 as ``position_version``)."""
    gaps = np.diff(stream.keyframes)
    if stream.keyframes[0] != 0 or len(stream.keyframes) < 2 or gaps.min() < 1:
        raise UsageError("keyframes must start at 0 and increase strictly (at least 2)")
    if gaps.max() > MAX_GAP:
        raise UsageError(f"gap {int(gaps.max())} exceeds the format's {MAX_GAP}")
    if int(stream.keyframes[-1]) + 1 > frame_limit(len(stream.names)):
        raise UsageError(
            f"{int(stream.keyframes[-1]) + 1} frames exceed the format's limit of "
            f"{frame_limit(len(stream.names))}"
        )
    if stream.coding == 2:
        if stream.reconstruction not in POSITION_RECONSTRUCTIONS:
            raise UsageError(f"coding 2 carries {', '.join(POSITION_RECONSTRUCTIONS)} only")
        body = header_bytes(stream, position_version) + position_bytes(stream, position_version)
    elif stream.coding == 1:
        body = header_bytes(stream) + packed_bytes(stream)
    elif stream.quantiser.bits != 16:
        raise UsageError("coding 0 carries 16-bit codes only")
    else:
        body = header_bytes(stream) + record_bytes(stream)
    body = with_section(body, stream.contacts, stream.n_frames)  # as is without contacts
    return body + struct.pack("<I", zlib.crc32(body))


_LZMA_FILTERS = [
    {"id": lzma.FILTER_LZMA1, "preset": 6, "dict_size": 1 << 20, "lc": 0, "lp": 1, "pb": 1}
]


def _planar(stream: Stream) -> bytes:
    k = np.asarray(stream.keyframes, dtype=np.int64)
    gaps = np.diff(k, prepend=k[:1]).astype(np.uint8)
    codes = stream.pose_codes.astype(np.int64)
    delta = np.mod(np.diff(codes, axis=0, prepend=0), 65536).astype("<u2")
    parts = [gaps.tobytes(), np.ascontiguousarray(delta.T).tobytes()]
    if stream.reconstruction == "hermite":
        parts.append(np.ascontiguousarray(stream.rate_codes.astype("<i2").T).tobytes())
    return b"".join(parts)


def packed_bytes(stream: Stream) -> bytes:
    """The coding-1 body: keyframe count, then the LZMA-packed planar keyframes."""
    W = len(stream.keyframes)
    return struct.pack("<I", W) + lzma.compress(
        _planar(stream), format=lzma.FORMAT_ALONE, filters=_LZMA_FILTERS
    )


def position_bytes(stream: Stream, version: int = VERSION_POSITION) -> bytes:
    """The coding-2 body: keyframe count, then one range-coded block of integers (one channel of
    gap changes, then the D channels' prediction residuals; :mod:`sidql.codec.entropy`)."""
    return block_bytes(stream.keyframes, stream.pose_codes, stream.quantiser.n_bones, version)


def write(stream: Stream, path: str | os.PathLike) -> Path:
    """Write ``stream`` to ``path`` atomically; returns the path."""
    path = Path(path)
    data = to_bytes(stream)
    write_atomic(path, lambda f: f.write(data))
    return path


#: Stated limits of a stream, checked before anything is unpacked (:func:`from_bytes`): its
#: length in frames (1 + the sum of its gaps, hence also its keyframe count) for the protocol's
#: 23 points, 2^15 frames (4.5 minutes at 120 fps, 18 at the default 30), so that decoding any
#: accepted stream (:func:`sidql.codec.decode.stream_to_clip`) peaks at a few hundred MB; a
#: skeleton of J > 23 points may have ``MAX_FRAMES * 23 // J`` frames.
MAX_FRAMES = 1 << 15
#: Frame rate [1/s] at most (a stream's rate is positive).
MAX_FPS = 1000.0
#: Bound [m] on bone lengths and on the root origin; [m or rad, per code step] on the root and
#: rate quantisation steps: far beyond any motion (a trial spans metres, codes steps of mm),
#: so that every decoded value is finite.
MAX_METRES = 1e4
MAX_STEP = 1.0
#: Memory [bytes] the LZMA decoder may use: a stream declaring a larger dictionary is refused
#: (the encoder's is 1 MiB; the format allows up to 4 GiB).
LZMA_MEMLIMIT = 16 << 20


def frame_limit(J: int) -> int:
    """The most frames a stream of a ``J``-point skeleton may have (see :data:`MAX_FRAMES`)."""
    return MAX_FRAMES * len(POINTS) // max(J, len(POINTS))


def _check_gaps(gaps: np.ndarray, fps: float, J: int, where: str) -> None:
    """Refuse a gap list that is malformed or makes the stream longer than its limit
    (:data:`MAX_FRAMES`, fewer for skeletons of more than 23 points)."""
    if gaps[0] != 0 or not gaps[1:].all():
        raise MotionDataError(where, None, "bad keyframe gap (first must be 0, others >= 1)")
    frames = 1 + int(gaps.sum(dtype=np.int64))
    limit = frame_limit(J)
    if frames > limit:
        raise MotionDataError(
            where, None, f"{frames:,} frames exceed the limit of {limit:,} "
            f"({limit / fps:.4g} s at {fps:g} fps, {J} points)",
        )  # fmt: skip


class _Reader:
    def __init__(self, data: bytes, where: str):
        self.data, self.pos, self.where = data, 0, where

    def take(self, n: int, what: str) -> bytes:
        if self.pos + n > len(self.data):
            raise MotionDataError(self.where, None, f"truncated stream: {what} missing")
        out = self.data[self.pos : self.pos + n]
        self.pos += n
        return out


def from_bytes(data: bytes, where: str = "<stream>") -> Stream:
    """Parse a container (see the module docstring); MotionDataError on any defect."""
    data, section = split_section(bytes(data), where)
    return attach_section(_from_plain(data, where), section, where)


def _from_plain(data: bytes, where: str) -> Stream:
    body, r, recon, coding, bits, latency, fps = _header(bytes(data), where)
    skel = r.take(8, "skeleton hash")
    names, parents = _points(r, where)
    J = len(names)
    M = J - 1
    D = 2 * M + 3
    if coding == 2:
        (exponent,) = struct.unpack("<b", r.take(1, "length unit"))
        codes = np.frombuffer(r.take(2 * M, "bone lengths"), dtype="<u2")
        lengths = lengths_from_codes(exponent, codes)
        return _position_stream(r, body, where, recon, latency, fps, skel, names, parents, lengths)
    lengths = _floats(r, M, "bone lengths", 0.0, MAX_METRES)
    origin = _floats(r, 3, "root origin", -MAX_METRES, MAX_METRES)
    step = _floats(r, 3, "root step", -MAX_STEP, MAX_STEP)
    rate_step = _floats(r, D, "rate steps", -MAX_STEP, MAX_STEP) if recon == "hermite" else None
    if coding == 0:
        gaps, pose, rate = _fixed_records(r, body, recon, M, fps)
    else:
        gaps, pose, rate = _packed_records(r, body, recon, M, fps, bits)
    if gaps[0] != 0 or np.any(gaps[1:] == 0):
        raise MotionDataError(where, None, "bad keyframe gap (first must be 0, others >= 1)")
    return Stream(
        reconstruction=recon,
        latency=int(latency),
        fps=float(fps),
        skeleton_hash=skel,
        names=tuple(names),
        parents=parents,
        lengths=lengths.astype(np.float64),
        quantiser=Quantiser(M, origin, step, rate_step, bits),
        keyframes=np.cumsum(gaps),
        pose_codes=pose,
        rate_codes=rate,
        coding=coding,
    )


def _header(data: bytes, where: str):
    """The checked magic, version, checksum and header fields of a container: (body, a reader
    past the header, reconstruction, coding, bits, latency, fps)."""
    if len(data) < 4 or data[:4] != MAGIC:
        raise MotionDataError(where, None, "not a .sidq stream (bad magic)")
    if len(data) < 8:
        raise MotionDataError(where, None, "truncated stream: header missing")
    body, (crc,) = data[:-4], struct.unpack("<I", data[-4:])
    version = data[4]
    if version not in (VERSION, *POSITION_VERSIONS):
        raise MotionDataError(
            where, None, f"unsupported .sidq version {version} (known: 1 to {VERSION_POSITION})"
        )
    if zlib.crc32(body) != crc:
        raise MotionDataError(where, None, "checksum mismatch: the stream is truncated or corrupt")
    r = _Reader(body, where)
    r.take(5, "header")
    kind, coding, bits, latency, fps = struct.unpack("<BBBHf", r.take(9, "header"))
    if kind >= len(CURVES):
        raise MotionDataError(where, None, f"unknown reconstruction code {kind}")
    recon = CURVES[kind]
    if version in POSITION_VERSIONS:
        if coding != 2 or bits != 0 or recon not in POSITION_RECONSTRUCTIONS:
            raise MotionDataError(
                where, None, f"version {version} needs coding 2, 0 bits and linear or catmull_rom;"
                f" got coding {coding}, {bits} bits, {recon}",
            )  # fmt: skip
    elif coding > 1 or bits not in BITS or (coding == 0 and bits != 16):
        raise MotionDataError(where, None, f"unknown coding {coding} with {bits} bits")
    if not (np.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise MotionDataError(where, None, f"frame rate {fps:g} outside (0, {MAX_FPS:g}]")
    return body, r, recon, coding, bits, latency, fps


def _points(r: _Reader, where: str) -> tuple[list[str], np.ndarray]:
    """The point names and parents (J,) of a container (0 points: the protocol's)."""
    (J,) = r.take(1, "point count")
    if J == 1:
        raise MotionDataError(where, None, f"bad point count {J}")
    if J == 0:
        names, parents = list(POINTS), protocol_parent_indices()
        J = len(POINTS)
    else:
        names = []
        for _ in range(J):
            (n,) = r.take(1, "point name")
            try:
                names.append(r.take(n, "point name").decode("ascii"))
            except UnicodeDecodeError:
                raise MotionDataError(where, None, "point name is not ASCII") from None
        parents = np.frombuffer(r.take(J, "parents"), dtype=np.int8).astype(np.int64)
    if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, J)):
        raise MotionDataError(where, None, "bad parent list (each parent must precede its child)")
    return names, parents


def _floats(r: _Reader, n: int, what: str, low: float, high: float) -> np.ndarray:
    """``n`` float32 values, each finite and within [low, high]."""
    v = np.frombuffer(r.take(4 * n, what), dtype="<f4").astype(np.float32)
    if not (np.isfinite(v).all() and (v >= low).all() and (v <= high).all()):
        raise MotionDataError(r.where, None, f"{what} outside [{low:g}, {high:g}]")
    return v


def _fixed_records(r: _Reader, body: bytes, recon: str, M: int, fps: float):
    """Coding 0's records: (gaps (W,), pose codes (W, D), rate codes (W, D) or None)."""
    where, J, D = r.where, M + 1, 2 * M + 3
    size = record_size(recon, M)
    rest = len(body) - r.pos
    if rest % size or rest // size < 2:
        raise MotionDataError(
            where, None, f"body of {rest} bytes is not >= 2 records of {size} bytes"
        )
    fields = [("gap", "u1"), ("pose", "<u2", (D,))]
    if recon == "hermite":
        fields.append(("rate", "<i2", (D,)))
    rec = np.frombuffer(body, dtype=np.dtype(fields), offset=r.pos)
    _check_gaps(rec["gap"], fps, J, where)
    gaps = rec["gap"].astype(np.int64)
    pose = np.array(rec["pose"])
    rate = np.array(rec["rate"]) if recon == "hermite" else None
    return gaps, pose, rate


def _packed_records(r: _Reader, body: bytes, recon: str, M: int, fps: float, bits: int):
    """Coding 1's delta + LZMA records, inflated incrementally and capped: (gaps (W,), pose
    codes (W, D), rate codes (W, D) or None)."""
    where, J, D = r.where, M + 1, 2 * M + 3
    size = record_size(recon, M)
    (W,) = struct.unpack("<I", r.take(4, "keyframe count"))
    if not 2 <= W <= frame_limit(J):  # checked before anything of size W is allocated
        raise MotionDataError(where, None, f"bad keyframe count {W} (2 to {frame_limit(J):,})")
    want = W * size
    dec = lzma.LZMADecompressor(format=lzma.FORMAT_ALONE, memlimit=LZMA_MEMLIMIT)
    try:  # incremental, capped: the gaps first, checked, then the codes they vouch for
        raw = dec.decompress(body[r.pos :], max_length=W)
        if len(raw) == W:
            _check_gaps(np.frombuffer(raw, dtype=np.uint8), fps, J, where)
            raw += dec.decompress(b"", max_length=want - W)
    except lzma.LZMAError as e:
        raise MotionDataError(where, None, f"corrupt packed keyframes: {e}") from None
    if len(raw) != want:
        raise MotionDataError(
            where, None, f"packed keyframes inflate to {len(raw)} bytes, not {want}"
        )
    gaps = np.frombuffer(raw, dtype=np.uint8, count=W).astype(np.int64)
    delta = np.frombuffer(raw, dtype="<u2", count=W * D, offset=W).reshape(D, W).T
    pose = np.cumsum(delta, axis=0, dtype=np.uint16)  # wraps: modulo 2^16
    rate = None
    if recon == "hermite":
        rate = np.frombuffer(raw, dtype="<i2", count=W * D, offset=W + 2 * W * D)
        rate = rate.reshape(D, W).T.copy()
    if np.any(pose[:, :M] >= (1 << bits)) or np.any(pose[:, 2 * M :] >= (1 << bits)):
        raise MotionDataError(where, None, f"pose code beyond {bits} bits")
    return gaps, pose, rate


def _position_stream(r, body, where, recon, latency, fps, skel, names, parents, lengths):
    """The rest of a coding-2 stream after the bone lengths (see :func:`position_bytes`)."""
    J = len(names)
    M = J - 1
    quant = read_quantiser(r.take, body[4], where, M, lengths, parents)
    (W,) = struct.unpack("<I", r.take(4, "keyframe count"))
    if not 2 <= W <= frame_limit(J):  # checked before anything of size W is allocated
        raise MotionDataError(where, None, f"bad keyframe count {W} (2 to {frame_limit(J):,})")
    rows = read_block(body[r.pos :], body[4], M, W, where)
    gaps = np.cumsum(rows[0])
    if np.any(gaps < 0) or np.any(gaps > MAX_GAP):
        raise MotionDataError(where, None, "bad keyframe gap (first must be 0, others 1..255)")
    _check_gaps(gaps, fps, J, where)
    keys = np.cumsum(gaps)
    pose = rows[1:].T.copy()
    with np.errstate(all="ignore"):
        values = quant.decode_keyframes(pose, keys)
    # residuals that make the prediction run away (no encoder writes them): angles and root
    # positions beyond any motion's (a million radians or metres), or overflow
    if not (np.abs(values) <= MAX_DECODED_VALUE).all():
        raise MotionDataError(
            where, None, "coded keyframes decode to non-finite or implausible values"
        )
    return Stream(
        reconstruction=recon,
        latency=int(latency),
        fps=float(fps),
        skeleton_hash=skel,
        names=tuple(names),
        parents=parents,
        lengths=lengths.astype(np.float64),
        quantiser=quant,
        keyframes=keys,
        pose_codes=pose,
        rate_codes=None,
        coding=2,
    )


def read(path: str | os.PathLike) -> Stream:
    """Read and parse a ``.sidq`` file; MotionDataError (naming the file) on any defect."""
    data = read_regular(path, MAX_SIDQ_BYTES)  # regular files only, of bounded size
    return from_bytes(data, str(path))
