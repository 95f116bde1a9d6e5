"""Coding 2's fields of a ``.sidq`` stream (versions 2 to 6): the bone lengths, the quantiser's
parameters and the range-coded block of keyframe residuals, written and read.

Specified in ``docs/codec.md`` ("Versions 2 to 4"); :mod:`sidql.codec.format` reads the rest of
the container (header, points, checksum) and calls these. Version 4 adds the root channels' own
slope weight and codes the D residual channels with contexts shared by kind (theta, phi, root)
and chosen by each integer's expected magnitude (:func:`sidql.codec.entropy.encode_integers`'s
``kinds``); versions 2 and 3 (one context set per channel) are still read. Version 5 drops the
parent-innovation term of the prediction and scales each keyframe's step by how many frames its
value moves (:func:`sidql.codec.quantise.keyframe_steps`, the exponent in one more byte).
Version 6 adds the cones (:mod:`sidql.codec.cones`): bones predicted at a fixed angle to bones
decoded before them.
"""

from __future__ import annotations

import struct

import numpy as np

from sidql.codec.cones import cone_bytes, read_cones
from sidql.codec.entropy import decode_integers, encode_integers, estimate_split
from sidql.codec.quantise import PositionQuantiser
from sim.errors import MotionDataError, UsageError

#: coding 2 as written, and as read (2: no lever exponent byte, 1/2 implied; 2 and 3: no root
#: slope byte, the root predicted like the angles, and one context set per channel; 2 to 4: the
#: parent bone's innovation in the prediction, one step for every keyframe; 2 to 5: no cones)
VERSION_POSITION, POSITION_VERSIONS = 6, (2, 3, 4, 5, 6)
#: the largest gap exponent byte (version 5: the exponent x 4)
MAX_GAP_QUARTERS = 4
#: the largest magnitude a decoded coding-2 keyframe value may have [rad or m].
MAX_DECODED_VALUE = 1e6
#: reconstructions coding 2 carries (no rates are sent).
POSITION_RECONSTRUCTIONS: tuple[str, ...] = ("linear", "catmull_rom")


def length_codes(lengths: np.ndarray) -> tuple[int, np.ndarray]:
    """Coding 2's bone lengths: an exponent e (int8; unit 2^e m, the least power of two with the
    longest bone within 65535 units) and (M,) uint16 multiples of the unit (at most 7 um of
    rounding for bones under 0.9 m). Stored lengths code to themselves."""
    lengths = np.asarray(lengths, dtype=np.float64)
    top = max(float(lengths.max(initial=0.0)), 1e-9)
    e = int(np.clip(np.ceil(np.log2(top / 65535.0)), -127, 127))
    return e, np.clip(np.rint(lengths / 2.0**e), 0, 65535).astype(np.uint16)


def lengths_from_codes(exponent: int, codes: np.ndarray) -> np.ndarray:
    """(M,) bone lengths [m] a coding-2 stream stores (the inverse of :func:`length_codes`)."""
    return np.asarray(codes, dtype=np.float64) * 2.0 ** int(exponent)


def position_lengths(lengths: np.ndarray) -> np.ndarray:
    """The bone lengths [m] a decoder of a coding-2 stream will use for ``lengths``."""
    return lengths_from_codes(*length_codes(lengths))


def channel_kinds(n_bones: int, version: int = VERSION_POSITION) -> np.ndarray | None:
    """(1 + D,) the context kinds of the coded rows (gap changes, then theta, phi, root):
    version 4 shares contexts by kind (-1: the gap row's own, 0 theta, 1 phi, 2 root); None
    (one context set per row) before."""
    if version < 4:
        return None
    M = n_bones
    return np.r_[-1, np.zeros(M), np.ones(M), np.full(3, 2)].astype(np.int64)


def coded_rows(keys: np.ndarray, pose_codes: np.ndarray) -> np.ndarray:
    """(1 + D, W) the integers of the coded block: the gap changes (the first gap 0), then each
    channel's residual codes."""
    k = np.asarray(keys, dtype=np.int64)
    gaps = np.diff(k, prepend=k[:1])
    return np.vstack([np.diff(gaps, prepend=0)[None], np.asarray(pose_codes, np.int64).T])


def estimated_block(keys: np.ndarray, pose_codes: np.ndarray) -> float:
    """``estimate_size(coded_rows(keys, pose_codes))`` [bytes], the same float, with the codes
    (W, D) int64 read in place."""
    k = np.asarray(keys, dtype=np.int64)
    gaps = np.diff(k, prepend=k[:1])
    codes = np.asarray(pose_codes)
    if codes.dtype != np.int64:
        codes = codes.astype(np.int64)
    return estimate_split(np.diff(gaps, prepend=0), codes.T)


def block_bytes(
    keys: np.ndarray, pose_codes: np.ndarray, n_bones: int, version: int = VERSION_POSITION
) -> bytes:
    """The keyframe count (uint32) and the range-coded block of a version-``version`` stream."""
    rows = coded_rows(keys, pose_codes)
    kinds = channel_kinds(n_bones, version)
    return struct.pack("<I", len(keys)) + encode_integers(rows, kinds=kinds)


def quantiser_bytes(q: PositionQuantiser, version: int = VERSION_POSITION) -> bytes:
    """The position step (float32), the slope weight x 8, then (version 3 on) the lever exponent
    x 16, (version 4 on) the root's slope weight x 8 and (version 5 on) the gap exponent x 4,
    uint8 each, then (version 6) the cones (:func:`sidql.codec.cones.cone_bytes`). Older versions are written for tests of the readers only; one that cannot say ``q``
    is refused."""
    if (
        version not in POSITION_VERSIONS
        or (version < 4 and q.root_slope != q.rho)
        or (version < 3 and q.exponent != 0.5)
        or (version < 5 and (q.gap_exponent != 0 or not q.partner))
        or (version >= 5 and q.partner)
        or (version < 6 and q.cones is not None)
    ):
        raise UsageError(f"version {version} cannot carry this quantiser")
    out = struct.pack("<fB", q.step, round(q.rho * 8))
    out += bytes([round(q.exponent * 16)]) if version >= 3 else b""
    out += bytes([round(q.root_slope * 8)]) if version >= 4 else b""
    out += bytes([round(q.gap_exponent * 4)]) if version >= 5 else b""
    return out + (cone_bytes(q.cones) if version >= 6 else b"")


def read_quantiser(take, version: int, where: str, M: int, lengths, parents) -> PositionQuantiser:
    """The quantiser of a version-``version`` stream from its fields (``take(n, what)`` returns
    the next n bytes or refuses a short stream)."""
    step, rho8 = struct.unpack("<fB", take(5, "position step"))
    lever16 = take(1, "lever exponent")[0] if version >= 3 else 8  # version 2: 1/2
    root8 = take(1, "root predictor")[0] if version >= 4 else rho8
    gap4 = take(1, "gap exponent")[0] if version >= 5 else 0
    if (
        not (np.isfinite(step) and step > 0)
        or max(rho8, root8) > 16
        or lever16 > 16
        or gap4 > MAX_GAP_QUARTERS
    ):
        raise MotionDataError(
            where, None, f"bad position step {step}, predictor {rho8}, lever exponent "
            f"{lever16}, root predictor {root8} or gap exponent {gap4}",
        )  # fmt: skip
    cones = read_cones(take, where, M, parents) if version >= 6 else None
    return PositionQuantiser(
        M, lengths, parents, float(step), rho8 / 8.0, exponent=lever16 / 16,
        root_rho=root8 / 8.0 if version >= 4 else None, gap_exponent=gap4 / 4,
        partner=version < 5, cones=cones,
    )  # fmt: skip


def read_block(data: bytes, version: int, M: int, W: int, where: str) -> np.ndarray:
    """(1 + D, W) the coded block's integers (W checked by the caller); a block that runs out is
    refused."""
    rows, used = decode_integers(data, 2 * M + 4, W, kinds=channel_kinds(M, version))
    if used > len(data) + 5:  # the coder reads at most 5 bytes ahead of its data
        raise MotionDataError(where, None, "truncated stream: coded keyframes missing")
    return rows
