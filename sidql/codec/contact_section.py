"""The optional foot-contact section of a ``.sidq`` stream, and the decoder's pinning from it.

A stream may carry, beside its keyframes, the sender's per-frame foot-contact bits and the floor
it labelled them on (:class:`FootContacts`); the decoder then pins each foot in contact where it
touched down (:func:`sidql.keyframes.contact_pinning.pin_feet`, the ``contacts`` reconstruction's
receiver) after rebuilding the curves. The byte layout is specified in ``docs/codec.md`` ("The
foot-contact section"): bit 7 of the version byte (:data:`FLAG`) says that the section is
present; it then ends the stream just before the CRC-32, followed by its length (uint32):

* 5 float32: the floor's height at the world origin [m], its slopes dz/dx and dz/dy, each foot's
  (``l``, ``r``) stance offset [m] (:func:`sidql.keyframes.contact_pinning.encode_floor`);
* per foot the contact bits run-length coded (:func:`sidql.keyframes.contact_pinning.encode_runs`:
  a LEB128 varint ``2 * runs + first state``, then the varint length of every run but the last),
  exactly the stream's frames.

The CRC covers the section too. A reader (:func:`split_section`, :func:`parse_section`) bounds
the section's length before slicing it (:data:`MAX_SECTION_BYTES`, and the bytes there are) and
allocates the (frames, 2) bits only for the frame count the stream's own limits have accepted;
any defect is one line (:class:`sim.errors.MotionDataError`) naming the file.

Units: metres, seconds; positions (N, 23, 3) in world axes (z up).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, replace

import numpy as np

from sidql.keyframes.contact_pinning import (
    correction_derivatives,
    decode_floor,
    decode_runs,
    encode_runs,
    pin_feet,
)
from sidql.keyframes.spherical import POINTS, chart_arrays, protocol_parent_indices
from sidql.keyframes.unchart import clip_from_chart
from sim.errors import MotionDataError, UsageError
from sim.motion.clip import Clip
from sim.physics.feet import SIDES

#: Bit of the version byte (offset 4) set when the stream carries a foot-contact section.
FLAG = 0x80
#: Bytes of the floor (5 float32).
FLOOR_BYTES = 20
#: Bytes of the section's length field (uint32, just before the CRC).
LENGTH_BYTES = 4
#: The largest section any stream may carry: the floor and, per foot, a 3-byte head and one
#: 3-byte varint per frame (2^15 frames at most, :data:`sidql.codec.format.MAX_FRAMES`).
MAX_SECTION_BYTES = FLOOR_BYTES + len(SIDES) * 3 * (1 + (1 << 15))
#: Bytes of the smallest stream body before its section (magic, header, hash, point count).
_MIN_BODY = 23
#: Bound [m, m/m] on the floor's parameters: far beyond any capture volume.
_MAX_FLOOR = 1e4


@dataclass(frozen=True)
class FootContacts:
    """A stream's foot-contact side information.

    Attributes:
        bits: (N, 2) bool, per frame whether each foot (``l``, ``r``) is in contact.
        floor: (5,) float64 (float32 values): the floor's height at the world origin [m], its
            slopes dz/dx, dz/dy [m/m], each foot's stance offset [m]; world axes, z up.
    """

    bits: np.ndarray
    floor: np.ndarray

    def __post_init__(self):
        b, f = np.asarray(self.bits), np.asarray(self.floor)
        if b.ndim != 2 or b.shape[1] != len(SIDES) or b.shape[0] < 1 or f.shape != (5,):
            raise UsageError(
                f"contact bits must be (N, 2) and the floor (5,); got {b.shape}, {f.shape}"
            )
        if not (np.isfinite(f).all() and (np.abs(f) <= _MAX_FLOOR).all()):
            raise UsageError(f"floor parameters must be finite and within {_MAX_FLOOR:g}")

    def to_bytes(self) -> bytes:
        """The section's bytes (floor, then the run-length coded bits; no length field)."""
        return np.asarray(self.floor, dtype="<f4").tobytes() + encode_runs(self.bits)

    @property
    def n_bytes(self) -> int:
        """What the section adds to a stream [bytes], its length field included."""
        return len(self.to_bytes()) + LENGTH_BYTES


def with_section(body: bytes, contacts: FootContacts | None, n_frames: int) -> bytes:
    """``body`` (a stream's bytes before its CRC) with the section appended and :data:`FLAG` set
    in its version byte (``body`` itself when ``contacts`` is None); the caller appends the CRC
    of the result."""
    if contacts is None:
        return body
    if contacts.bits.shape[0] != n_frames:
        raise UsageError(
            f"contact bits cover {contacts.bits.shape[0]} frames; the stream has {n_frames}"
        )
    section = contacts.to_bytes()
    return body[:4] + bytes([body[4] | FLAG]) + body[5:] + section + struct.pack("<I", len(section))


def split_section(data: bytes, where: str) -> tuple[bytes, bytes | None]:
    """A stream's bytes without its foot-contact section (version byte cleared, CRC recomputed)
    and the section's bytes; ``(data, None)`` when :data:`FLAG` is not set. The whole stream's
    CRC is checked first; the length is bounded before anything is sliced."""
    if len(data) < 5 or not data[4] & FLAG:
        return data, None
    body, crc = data[:-4], data[-4:]
    if len(data) < 8 or zlib.crc32(body) != struct.unpack("<I", crc)[0]:
        raise MotionDataError(where, None, "checksum mismatch: the stream is truncated or corrupt")
    if len(body) < _MIN_BODY + LENGTH_BYTES:
        raise MotionDataError(where, None, "truncated stream: contact section missing")
    (n,) = struct.unpack("<I", body[-LENGTH_BYTES:])
    room = min(MAX_SECTION_BYTES, len(body) - LENGTH_BYTES - _MIN_BODY)
    if not FLOOR_BYTES + 2 <= n <= room:
        raise MotionDataError(
            where, None, f"contact section of {n} bytes (at least {FLOOR_BYTES + 2}, "
            f"at most {room} here)",
        )  # fmt: skip
    end = len(body) - LENGTH_BYTES
    inner = body[:4] + bytes([body[4] & ~FLAG]) + body[5 : end - n]
    return inner + struct.pack("<I", zlib.crc32(inner)), body[end - n : end]


def attach_section(stream, section: bytes | None, where: str):
    """``stream`` (a :class:`sidql.codec.format.Stream` parsed without its section) with the
    :class:`FootContacts` of ``section`` (itself when None)."""
    if section is None:
        return stream
    if tuple(stream.names) != POINTS:  # the pinning knows the protocol's legs only
        raise MotionDataError(
            where, None, "contact section on a skeleton other than the protocol's"
        )
    return replace(stream, contacts=parse_section(section, stream.n_frames, where))


def parse_section(section: bytes, n_frames: int, where: str) -> FootContacts:
    """The :class:`FootContacts` of a section of a stream of ``n_frames`` frames."""
    try:
        floor = decode_floor(section[:FLOOR_BYTES])
        bits = decode_runs(section[FLOOR_BYTES:], n_frames, len(SIDES))
        return FootContacts(bits, floor)
    except (MotionDataError, UsageError) as e:
        problem = e.problem if isinstance(e, MotionDataError) else str(e)
        raise MotionDataError(where, None, f"contact section: {problem}") from None


def pin_decoded(
    contacts: FootContacts,
    names,
    keyframes: np.ndarray,
    fps: float,
    P: np.ndarray,
    V: np.ndarray,
    A: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The decoded points (N, 23, 3) ``P`` [m], ``V`` [m/s], ``A`` [m/s^2] (world axes z up)
    with each foot pinned on its contact frames (:func:`~sidql.keyframes.contact_pinning.pin_feet`
    on the stream's keyframes and floor); velocities and accelerations gain the central
    differences of the correction (as the ``contacts`` reconstruction's)."""
    if tuple(names) != POINTS:
        raise MotionDataError(None, None, "contact bits need the CMU protocol's 23 points")
    pinned = pin_feet(P, contacts.bits, keyframes, fps, floor=contacts.floor)
    dV, dA = correction_derivatives(pinned - P, fps)
    return pinned, V + dV, A + dA


def pinned_clip(rec, lengths: np.ndarray, fps: float, source: str = "") -> Clip:
    """A 23-point :class:`Clip` of decoded, pinned points ``rec`` (a reconstruction: positions
    and velocities (N, 23, 3), world axes z up), charted again so that its angles, ``qpos`` and
    rotations agree with its points (the pinning keeps every bone's length)."""
    s = chart_arrays(rec.positions, rec.velocities, protocol_parent_indices(), 1.0 / fps)
    return clip_from_chart(
        s.theta, s.phi, s.dtheta, s.dphi, s.root_pos, s.root_vel, lengths, fps, source=source
    )
