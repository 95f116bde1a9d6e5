"""Mutations of real ASF/AMC files and the one property the readers must keep under them.

Shared by ``tests/test_fuzz.py`` (hypothesis drives the choices) and ``benchmarks/fuzz_campaign.py``
(a seeded ``random.Random`` drives them). A mutator takes the file's bytes and a source of choices
with ``randrange(n)`` (``random.Random`` has it; the tests wrap hypothesis's ``data.draw``) and
returns new bytes.

The property (:func:`check_outcome`): reading a mutated input either raises
:class:`~sim.errors.MotionDataError` naming one of the two files (and, when it gives a line, a line
that exists), or returns values that are all finite, bone names within the grammar.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from sim.acclaim.amc import parse_amc
from sim.acclaim.asf import check_bone_name, parse_asf
from sim.acclaim.records import Motion, Skeleton
from sim.errors import MotionDataError, MotionDataWarning
from sim.motion.clip import Clip
from sim.motion.ingest import load_motion

SEED_FRAMES = 30  # seeds are the real AMC files cut after this many frames (keeps inputs small)

SPECIAL_NUMBERS = (
    b"nan", b"-nan", b"NaN", b"inf", b"-inf", b"Infinity", b"1e308", b"-1e308", b"1e309",
    b"1e-320", b"9223372036854775808", b"18446744073709551616", b"7" * 5000, b"-0", b"0x10",
    b"1_000", b"1e", b".", b"--1", b"+", b"\xc2\xb2", b"\xd9\xa1\xd9\xa2", b"\xef\xbc\x95",
    b"1e400", b"123456789012345678901234567890", b"0", b"1", b"2", b"",
    # near the reader's bounds (1e5 degrees; 1e4 m, i.e. ~177,165 in CMU length units)
    b"99999", b"-100001", b"1e5", b"177000", b"-178000", b"1e-300", b"4.9e-324", b"1e-9",
)  # fmt: skip
SPECIAL_NAMES = (
    b'kn"ee', b"<b>", b"a&b", b"x'y", b"k\xc3\xa9", b"root", b"world", b"floor", b"12", b"(0",
    b"begin", b"end", b":name", b"#", b"lfemur", b"rtibia", b"a" * 300,
)  # fmt: skip
LINE_ENDS = (b"\n", b"\r\n", b"\r", b"\x85", b"\xe2\x80\xa8", b"\x0b", b"\x0c", b"")
_TOKEN = re.compile(rb"[^ \t\r\n]+")
_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def seed_amc(text: bytes, frames: int = SEED_FRAMES) -> bytes:
    """The header and first ``frames`` frames of a real AMC (a frame starts at a number line)."""
    lines = text.splitlines(keepends=True)
    starts = [i for i, ln in enumerate(lines) if ln.strip().isdigit()]
    if len(starts) <= frames:
        return text
    return b"".join(lines[: starts[frames]])


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def _pick(rng, seq):
    return seq[rng.randrange(len(seq))]


def byte_flip(data: bytes, rng) -> bytes:
    b = bytearray(data)
    for _ in range(1 + rng.randrange(4)):
        if b:
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
    return bytes(b)


def byte_set(data: bytes, rng) -> bytes:
    b = bytearray(data)
    for _ in range(1 + rng.randrange(4)):
        if b:
            b[rng.randrange(len(b))] = _pick(rng, (0, 0xFF, 0x0D, 0x0A, 0x20, 0x23, 0x28, 0x3A))
    return bytes(b)


def delete_lines(data: bytes, rng) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    n = 1 + rng.randrange(3)
    return b"".join(lines[:i] + lines[i + n :])


def duplicate_lines(data: bytes, rng) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    n = 1 + rng.randrange(3)
    return b"".join(lines[: i + n] + lines[i : i + n] + lines[i + n :])


def swap_lines(data: bytes, rng) -> bytes:
    lines = _lines(data)
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    lines[i], lines[j] = lines[j], lines[i]
    return b"".join(lines)


def _tokens(data: bytes, pattern=_TOKEN) -> list[tuple[int, int]]:
    return [m.span() for m in pattern.finditer(data)]


def _replace(data: bytes, span: tuple[int, int], new: bytes) -> bytes:
    return data[: span[0]] + new + data[span[1] :]


def swap_tokens(data: bytes, rng) -> bytes:
    spans = _tokens(data)
    if len(spans) < 2:
        return data
    a, b = sorted((_pick(rng, spans), _pick(rng, spans)))
    if a == b or a[1] > b[0]:
        return data
    return data[: a[0]] + data[b[0] : b[1]] + data[a[1] : b[0]] + data[a[0] : a[1]] + data[b[1] :]


def delete_token(data: bytes, rng) -> bytes:
    spans = _tokens(data)
    return _replace(data, _pick(rng, spans), b"") if spans else data


def duplicate_token(data: bytes, rng) -> bytes:
    spans = _tokens(data)
    if not spans:
        return data
    s = _pick(rng, spans)
    return _replace(data, s, data[s[0] : s[1]] + b" " + data[s[0] : s[1]])


def special_number(data: bytes, rng) -> bytes:
    """Replace one number, or every number of one line, by nan/inf/1e308/huge ints/unicode digits."""
    new = _pick(rng, SPECIAL_NUMBERS)
    if rng.randrange(4) == 0:  # the same value in every line that starts like a random line
        lines = _lines(data)
        head = lines[rng.randrange(len(lines))].split(b" ")[0]
        out = []
        for ln in lines:
            if ln.split(b" ")[0] == head:
                spans = _tokens(ln, _NUMBER)
                if spans:
                    ln = _replace(ln, spans[rng.randrange(len(spans))], new)
            out.append(ln)
        return b"".join(out)
    spans = _tokens(data, _NUMBER)
    return _replace(data, _pick(rng, spans), new) if spans else data


def special_name(data: bytes, rng) -> bytes:
    """Replace one word (bone names, keywords) by a hostile or confusing name."""
    spans = [s for s in _tokens(data) if data[s[0] : s[0] + 1].isalpha()]
    return _replace(data, _pick(rng, spans), _pick(rng, SPECIAL_NAMES)) if spans else data


def truncate(data: bytes, rng) -> bytes:
    return data[: rng.randrange(len(data) + 1)]


def long_line(data: bytes, rng) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    unit = _pick(rng, (b"1 ", b"9", b"x", b"lfemur 1 2 3 ", b"(0 1) ", b"\t"))
    filler = unit * (1000 * (1 + rng.randrange(200)))
    if rng.randrange(2):
        lines.insert(i, filler + b"\n")
    else:
        lines[i] = lines[i].rstrip(b"\r\n") + b" " + filler + b"\n"
    return b"".join(lines)


def line_ends(data: bytes, rng) -> bytes:
    """Mix line ends: some LF/CRLF become CR, CRLF, LF, NEL, U+2028, VT, FF or vanish."""
    lines = _lines(data)
    new = _pick(rng, LINE_ENDS)
    every = 1 + rng.randrange(8)
    start = rng.randrange(len(lines))
    out = []
    for k, ln in enumerate(lines):
        if k >= start and (k - start) % every == 0:
            ln = ln.rstrip(b"\r\n") + new
        out.append(ln)
    return b"".join(out)


def insert_bytes(data: bytes, rng) -> bytes:
    i = rng.randrange(len(data) + 1)
    junk = _pick(rng, (b"\x00", b"\xff\xfe", b"\xe2\x80\x8b", b"\xc3", b"#", b"(", b":", b" - "))
    return data[:i] + junk + data[i:]


MUTATORS = (
    byte_flip, byte_set, delete_lines, duplicate_lines, swap_lines, swap_tokens, delete_token,
    duplicate_token, special_number, special_name, truncate, long_line, line_ends, insert_bytes,
)  # fmt: skip
# Value changes are the ones a strict format lets through to the numerics: drawn three times as often.
WEIGHTED = MUTATORS + (special_number, special_number)


def mutate(data: bytes, rng, n: int | None = None) -> tuple[bytes, list[str]]:
    """``n`` (default 1 to 3) random mutations of ``data``; returns the bytes and their names."""
    names = []
    for _ in range(1 + rng.randrange(3) if n is None else n):
        m = _pick(rng, WEIGHTED)
        data = m(data, rng)
        names.append(m.__name__)
    return data, names


# ------------------------------------------------------------------------------------ property


def non_finite(value) -> list[str]:
    """Names of the arrays inside a Skeleton, Motion or Clip that hold a non-finite value."""
    bad = []

    def check(name, a):
        if a is not None and not np.isfinite(np.asarray(a, dtype=np.float64)).all():
            bad.append(name)

    if isinstance(value, Skeleton):
        check("length_to_metres", value.length_to_metres)
        check("root_orientation", value.root_orientation)
        for b in value.bones:
            for f in ("direction", "length", "axis", "limits"):
                check(f"{b.name}.{f}", getattr(b, f))
    elif isinstance(value, Motion):
        check("root", value.root)
        for k, v in value.angles.items():
            check(f"angles[{k}]", v)
    elif isinstance(value, Clip):
        for f in ("positions", "velocities", "qpos", "qvel", "rotations", "angular_velocities"):
            check(f, getattr(value, f))
    return bad


def line_count(path: Path) -> int:
    """Lines as the reader counts them (``str.splitlines`` of the decoded text), plus one for a
    problem found at the end of the file."""
    data = path.read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return len(text.splitlines()) + 1


def read_all(asf: Path, amc: Path, *, full: bool, skeleton: str = "subject") -> list:
    """Parse (and with ``full``, build the model, retarget and take velocities); the values made."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MotionDataWarning)
        skel = parse_asf(asf)
        motion = parse_amc(amc, skel)
        out = [skel, motion]
        if full:
            out.append(load_motion(asf, amc, skeleton=skeleton, fps=30))
    return out


class Breach(AssertionError):
    """The property failed: ``kind`` is ``"non-finite"``, ``"bad-error"`` or ``"bad-name"``."""

    def __init__(self, kind: str, message: str):
        super().__init__(f"{kind}: {message}")
        self.kind = kind


def check_outcome(asf: Path, amc: Path, *, full: bool, skeleton: str = "subject") -> str:
    """Run :func:`read_all`; return ``"error"`` or ``"ok"``, or raise AssertionError on a breach.

    Any exception other than MotionDataError propagates (the caller reports it as foreign); a
    breach of the property raises :class:`Breach`.
    """
    try:
        values = read_all(asf, amc, full=full, skeleton=skeleton)
    except MotionDataError as e:
        named = e.path is not None and Path(e.path).resolve() in (asf.resolve(), amc.resolve())
        if not named:
            raise Breach("bad-error", f"error names neither file: {e}") from e
        if e.line is not None and not 1 <= e.line <= line_count(Path(e.path)):
            raise Breach("bad-error", f"line out of range: {e}") from e
        return "error"
    bad = [n for v in values for n in non_finite(v)]
    if bad:
        raise Breach("non-finite", f"non-finite values in {', '.join(bad)}")
    names = [problem for b in values[0].bones if (problem := check_bone_name(b.name))]
    if names:
        raise Breach("bad-name", "; ".join(names))
    return "ok"
