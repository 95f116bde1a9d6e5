"""BVH files (Biovision hierarchy: Blender, MotionBuilder, CMU's BVH release, LAFAN1) read into a
:class:`~sim.bvh.records.Bvh`, in the file's own units and axes.

The same contract as the Acclaim readers: the file is opened through
:func:`sim.files.open_regular` (a regular file of at most :data:`sim.bvh.records.MAX_BVH_BYTES`) and read
a chunk at a time (:func:`sim.files.text_lines`); every malformed file raises one
:class:`~sim.errors.MotionDataError` naming the file, the line and the problem. Numbers are plain
ASCII decimals (``-12.5``, ``3e-4``: no ``nan``, ``inf``, ``0x``, ``1_0`` or other digits), finite
and within the bounds of :mod:`sim.bvh.records`. The motion table is allocated only once its
size (``Frames`` x channels) is known to fit the file: every value takes at least two bytes of
it, so the table is at most 4x the file's size.

Grammar read (keywords in any capitalisation, tokens split on any blanks)::

    HIERARCHY
    ROOT name { OFFSET x y z  CHANNELS n c1 .. cn  JOINT name { ... } ...  End Site { OFFSET x y z } }
    MOTION
    Frames: N
    Frame Time: seconds
    N lines of C numbers (C: all the joints' channels, in hierarchy order)
"""

from __future__ import annotations

import os
import re
from dataclasses import replace

import numpy as np

from sim.bvh.records import (
    CHANNELS,
    MAX_BVH_BYTES,
    MAX_DEGREES,
    MAX_DEPTH,
    MAX_FRAME_RATE,
    MAX_FRAMES,
    MAX_JOINTS,
    MAX_OFFSET,
    MIN_FRAME_RATE,
    Bvh,
    Joint,
)
from sim.decimals import parse_table
from sim.errors import MotionDataError
from sim.files import excerpt, open_regular, text_lines

#: One strict ASCII decimal number: optional sign, digits with an optional point (or a point and
#: digits), an optional exponent.
NUMBER = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_NUMBER_RE = re.compile(NUMBER + r"\Z")
_CHANNEL = {c.lower(): c for c in CHANNELS}
_NUMBER_CHARS = str.maketrans("", "", "0123456789+-.eE \t")  # deleted: what numbers are made of
MAX_HIERARCHY_CHARS = 1 << 20  # the hierarchy (before MOTION) is read whole; at most this long


def parse_bvh(path: str | os.PathLike, *, motion: bool = True) -> Bvh:
    """Read a BVH file (any joint names and hierarchy, 0 to 6 channels per joint in any order).

    Args:
        motion: False reads the hierarchy only (``values`` has no rows; ``frame_time`` is the
            file's, or 1/120 s when it was not read).

    Returns:
        The file's joints, frame time and motion table, in its own units and axes.

    Raises:
        MotionDataError: a malformed hierarchy, a frame count the file cannot hold or does not
            hold, a frame of the wrong number of values, a number that is not a plain finite
            ASCII decimal or is out of bounds... (one line naming file and line).
    """
    path = str(path)
    with open_regular(path, MAX_BVH_BYTES) as f:  # regular files only, of bounded size
        size = os.fstat(f.fileno()).st_size
        parser = _BvhParser(path, size, motion)
        for first_line, lines in text_lines(f, path, MAX_BVH_BYTES):
            if parser.feed(first_line, lines):
                break
    return parser.finish()


def iter_bvh(path: str | os.PathLike, *, max_bytes: int = MAX_BVH_BYTES):
    """Read a BVH file a chunk of frames at a time: yields :class:`Bvh` pieces (the hierarchy,
    frame time and ``motion_line`` of the file, ``values`` the rows of one text chunk,
    :data:`sim.files.TEXT_CHUNK_BYTES`), frame after frame, with the same bounds, checks and
    one-line errors as :func:`parse_bvh` of the whole file. Memory: one chunk's rows, whatever
    the file's length. A caller that stops early closes the file (a generator).

    Raises:
        MotionDataError: as :func:`parse_bvh` (a defect is raised when its chunk is read: the
            pieces before it have been yielded; a truncated MOTION after the last piece).
    """
    path = str(path)
    with open_regular(path, max_bytes) as f:
        parser = _BvhParser(path, os.fstat(f.fileno()).st_size, True, stream=True)
        for first_line, lines in text_lines(f, path, max_bytes):
            parser.feed(first_line, lines)
            if parser.state == "frames" and parser.row > parser.base:
                yield parser.piece(parser.values[: parser.row - parser.base])
                parser.base = parser.row
    parser.finish()


def number(token: str, path: str, line: int, what: str, bound: float) -> float:
    """``token`` as a finite float of magnitude at most ``bound`` (a strict ASCII decimal)."""
    if not _NUMBER_RE.match(token):
        raise MotionDataError(path, line, f"{what}: {excerpt(token)} is not a plain decimal number")
    value = float(token)
    if not abs(value) <= bound:  # inf (1e999) too
        raise MotionDataError(
            path, line, f"{what}: {excerpt(token, quote=False)} exceeds {bound:g} in magnitude"
        )
    return value


class _BvhParser:
    """The file as a state machine fed a chunk of lines at a time: the hierarchy's tokens are
    gathered until ``MOTION``, then the two header lines, then the frames: a chunk at a time
    by a compiled pass when it converts them all exactly (:mod:`sim.decimals`), else through
    numpy's C reader when it holds nothing but digits, signs, points, ``e``/``E`` and
    blanks (numpy then refuses every token the strict grammar :data:`NUMBER` refuses, tested),
    else line by line, each token matched against :data:`NUMBER`, naming the line."""

    def __init__(self, path: str, size: int, motion: bool, stream: bool = False):
        self.path, self.size, self.want_motion = path, size, motion
        self.stream = stream  # the frames a chunk at a time (:func:`iter_bvh`), never whole
        self.base = 0  # the frame of ``values``' first row
        self.state = "hierarchy"
        self.tokens: list[tuple[str, int]] = []
        self.chars = 0
        self.joints: list[Joint] = []
        self.motion_line = 0
        self.n_frames: int | None = None
        self.frame_time: float | None = None
        self.header_line = 0
        self.values: np.ndarray | None = None
        self.row = 0
        self.last_line = 0
        self.seen_text = False

    def feed(self, first_line: int, lines: list[str]) -> bool:
        """Read a chunk; returns True when nothing more is wanted (hierarchy-only reads)."""
        self.last_line = first_line + len(lines) - 1
        i = 0
        while i < len(lines):
            if self.state == "frames":
                self._frames(first_line + i, lines[i:])
                return False
            ln, text = first_line + i, lines[i]
            i += 1
            if self.state == "hierarchy":
                self._hierarchy_line(ln, text)
            elif self.state == "header":
                self._header_line(ln, text)
            if self.state == "frames" and not self.want_motion:
                return True
        return False

    # -- the hierarchy ---------------------------------------------------------------------------

    def _hierarchy_line(self, ln: int, text: str) -> None:
        words = text.split()
        if not words:
            return
        self.seen_text = True
        if words[0].upper() == "MOTION":
            self.joints = _Hierarchy(self.path, self.tokens).parse()
            self.tokens = []
            self.motion_line, self.state = ln, "header"
            return
        self.chars += len(text)
        if self.chars > MAX_HIERARCHY_CHARS:
            raise MotionDataError(
                self.path, ln, f"hierarchy longer than {MAX_HIERARCHY_CHARS:,} characters"
            )
        self.tokens.extend((w, ln) for w in words)

    def _header_line(self, ln: int, text: str) -> None:
        words = text.replace(":", " : ").split()
        if not words:
            return
        key = [w.lower() for w in words if w != ":"][:2]
        values = [w for w in words if w != ":"]
        if key[:1] == ["frames"] and self.n_frames is None:
            if len(values) != 2 or not values[1].isascii() or not values[1].isdigit():
                raise MotionDataError(self.path, ln, "expected 'Frames: N' (N a whole number)")
            n = int(values[1]) if len(values[1]) <= 12 else MAX_FRAMES + 1
            if not 1 <= n <= MAX_FRAMES:
                raise MotionDataError(self.path, ln, f"Frames: {n}; expected 1 to {MAX_FRAMES:,}")
            self.n_frames, self.header_line = n, ln
        elif key == ["frame", "time"] and self.n_frames is not None:
            if len(values) != 3:
                raise MotionDataError(self.path, ln, "expected 'Frame Time: seconds'")
            t = number(values[2], self.path, ln, "Frame Time", 1e6)
            if not 1.0 / MAX_FRAME_RATE <= t <= 1.0 / MIN_FRAME_RATE:
                raise MotionDataError(
                    self.path, ln, f"Frame Time {t:g} s; expected {1 / MAX_FRAME_RATE:g} to "
                    f"{1 / MIN_FRAME_RATE:g} s",
                )  # fmt: skip
            self.frame_time = t
            self.state = "frames"
            if self.want_motion:
                self._allocate()
        else:
            want = "'Frames: N'" if self.n_frames is None else "'Frame Time: seconds'"
            raise MotionDataError(self.path, ln, f"expected {want}, got {excerpt(text.strip())}")

    def _allocate(self) -> None:
        """The (Frames, C) table, once the file is known to be able to hold it."""
        C = sum(len(j.channels) for j in self.joints)
        N = self.n_frames
        if N * max(C, 1) * 2 > self.size:  # each value: a digit and a blank or line break
            raise MotionDataError(
                self.path,
                self.header_line,
                f"Frames: {N:,} of {C} channels cannot fit in a file of {self.size:,} bytes",
            )
        self.values = np.empty((0 if self.stream else N, C))
        self.bound = np.array(
            [MAX_OFFSET if c.endswith("position") else MAX_DEGREES
             for j in self.joints for c in j.channels]
        )  # fmt: skip

    # -- the frames ------------------------------------------------------------------------------

    def _frames(self, first_line: int, lines: list[str]) -> None:
        if not self.want_motion:
            return
        n, N = len(lines), self.n_frames
        if self.stream:  # this chunk's rows only: at most one a line, none past 'Frames:'
            self.base = self.row
            self.values = np.empty((max(min(n, N - self.row), 0), self.values.shape[1]))
        last = n
        while last > 0 and not lines[last - 1].strip():
            last -= 1  # trailing blank lines (the file's end, or the chunk's)
        if 0 < last and self.row + last <= N:
            block = lines[:last]
            if self._compiled(block):
                return
            if not "".join(block).translate(_NUMBER_CHARS):  # digits, signs, points, e, blanks
                try:  # numpy's C reader: a ragged row or a malformed number raises
                    values = np.loadtxt(block, dtype=np.float64, ndmin=2, comments=None)
                except ValueError:
                    values = None
                if (
                    values is not None
                    and values.shape == (last, self.values.shape[1])
                    and _within(values, self.bound)
                ):
                    self.values[self.row - self.base : self.row - self.base + last] = values
                    self.row += last
                    return
        for k, line in enumerate(lines):
            self._frame_line(first_line + k, line)

    def _compiled(self, block: list[str]) -> bool:
        """Read the rows of ``block`` in one compiled pass (:func:`sim.decimals.parse_table`:
        exact decimals, blanks between them) when it takes them all and they are within bounds;
        whether it did (if not, numpy's reader and then the lines one by one read them)."""
        C = self.values.shape[1]
        values = parse_table("\n".join(block), len(block), C) if C else None
        if values is None or not _within(values, self.bound):
            return False
        self.values[self.row - self.base : self.row - self.base + len(block)] = values
        self.row += len(block)
        return True

    def _frame_line(self, ln: int, line: str) -> None:
        tokens = line.split()
        if not tokens:
            return
        path, C = self.path, self.values.shape[1]
        if self.row >= self.n_frames:
            raise MotionDataError(path, ln, f"more frames than 'Frames: {self.n_frames}' declares")
        if len(tokens) != C:
            raise MotionDataError(
                path,
                ln,
                f"frame {self.row + 1} has {len(tokens)} values; the hierarchy has {C} channels",
            )
        what = f"frame {self.row + 1}"
        self.values[self.row - self.base] = [
            number(t, path, ln, what, b) for t, b in zip(tokens, self.bound, strict=True)
        ]
        self.row += 1

    # -- the result ------------------------------------------------------------------------------

    def finish(self) -> Bvh:
        path = self.path
        if not self.seen_text:
            raise MotionDataError(path, None, "empty file")
        if self.state == "hierarchy":
            raise MotionDataError(path, self.last_line or None, "no MOTION section")
        if self.state == "header":
            want = "'Frames: N'" if self.n_frames is None else "'Frame Time: seconds'"
            raise MotionDataError(path, self.last_line, f"MOTION section ends before {want}")
        values = self.values
        if not self.want_motion or self.stream:
            values = np.zeros((0, sum(len(j.channels) for j in self.joints)))
        if self.want_motion and self.row < self.n_frames:
            raise MotionDataError(
                path,
                self.last_line,
                f"truncated MOTION: {self.row:,} frames of the {self.n_frames:,} that "
                f"'Frames:' (line {self.header_line}) declares",
            )
        return self.piece(values)

    def piece(self, values: np.ndarray) -> Bvh:
        """The file's hierarchy and frame time with the motion table ``values``."""
        return Bvh(
            path=self.path,
            joints=tuple(self.joints),
            frame_time=float(self.frame_time),
            values=values,
            motion_line=self.motion_line,
        )


class _Hierarchy:
    """The hierarchy's tokens (each with its line) read into joints, parents first."""

    def __init__(self, path: str, tokens: list[tuple[str, int]]):
        self.path, self.tokens, self.i = path, tokens, 0
        self.joints: list[Joint] = []
        self.names: list[str] = []

    def next(self, what: str) -> tuple[str, int]:
        if self.i >= len(self.tokens):
            line = self.tokens[-1][1] if self.tokens else None
            raise MotionDataError(self.path, line, f"hierarchy ends before {what}")
        self.i += 1
        return self.tokens[self.i - 1]

    def expect(self, word: str) -> int:
        token, ln = self.next(f"'{word}'")
        if token.upper() != word.upper():
            raise MotionDataError(self.path, ln, f"expected '{word}', got {excerpt(token)}")
        return ln

    def parse(self) -> list[Joint]:
        self.expect("HIERARCHY")
        self.expect("ROOT")
        self._joint(-1, self.tokens[self.i - 1][1], 1)
        if self.i < len(self.tokens):
            token, ln = self.tokens[self.i]
            raise MotionDataError(
                self.path, ln, f"{excerpt(token)} after the ROOT's closing brace (one ROOT only)"
            )
        joints, column = [], 0  # the motion's columns follow the joints in file order
        for j in self.joints:
            joints.append(replace(j, column=column))
            column += len(j.channels)
        if not column:
            raise MotionDataError(self.path, self.tokens[0][1], "no joint has CHANNELS")
        return joints

    def _name(self, ln: int) -> str:
        """The words after ``ROOT``/``JOINT`` on its line (up to a ``{``)."""
        words = []
        while self.i < len(self.tokens) and self.tokens[self.i][1] == ln:
            if self.tokens[self.i][0] == "{":
                break
            words.append(self.tokens[self.i][0])
            self.i += 1
        if not words:
            raise MotionDataError(self.path, ln, "joint without a name")
        return " ".join(words)

    def _joint(self, parent: int, ln: int, depth: int, end_site: bool = False) -> None:
        """One joint block (its keyword just read), its children recursively (depth bounded)."""
        path = self.path
        if depth > MAX_DEPTH:
            raise MotionDataError(path, ln, f"hierarchy more than {MAX_DEPTH} joints deep")
        if len(self.joints) >= MAX_JOINTS:
            raise MotionDataError(path, ln, f"more than {MAX_JOINTS} joints and End Sites")
        name = f"{self.names[parent]} End Site" if end_site else self._name(ln)
        self.expect("{")
        index = len(self.joints)
        self.joints.append(None)  # its place: parents before children
        self.names.append(name)
        offset, channels = None, None
        while True:
            token, tln = self.next("'}'")
            key = token.upper()
            if key == "}":
                break
            if key == "OFFSET" and offset is None:
                offset = np.array(
                    [number(self.next("OFFSET values")[0], path, tln, "OFFSET", MAX_OFFSET)
                     for _ in range(3)]
                )  # fmt: skip
            elif key == "CHANNELS" and channels is None and not end_site:
                channels = self._channels(tln)
            elif key == "JOINT" and not end_site:
                self._joint(index, tln, depth + 1)
            elif key == "END" and not end_site:
                self.expect("Site")
                self._joint(index, tln, depth + 1, end_site=True)
            else:
                raise MotionDataError(
                    path,
                    tln,
                    f"unexpected {excerpt(token)} in {'End Site' if end_site else 'joint'} {excerpt(name)}",
                )
        if offset is None:
            raise MotionDataError(path, ln, f"joint {excerpt(name)} has no OFFSET")
        channels = channels or ()
        self.joints[index] = Joint(
            name=name, parent=parent, offset=offset, channels=channels,
            column=0, line=ln, end_site=end_site,
        )  # fmt: skip

    def _channels(self, ln: int) -> tuple[str, ...]:
        count, cln = self.next("the channel count")
        if not (count.isascii() and count.isdigit() and int(count) <= len(CHANNELS)):
            raise MotionDataError(
                self.path, cln, f"channel count {excerpt(count)}; expected 0 to 6"
            )
        names = []
        for _ in range(int(count)):
            token, tln = self.next("a channel name")
            channel = _CHANNEL.get(token.lower())
            if channel is None and token.upper() in ("JOINT", "END", "}", "OFFSET", "CHANNELS"):
                raise MotionDataError(
                    self.path, tln, f"CHANNELS {count} lists only {len(names)} channels"
                )
            if channel is None:
                raise MotionDataError(
                    self.path,
                    tln,
                    f"unknown channel {excerpt(token)}; known: {', '.join(CHANNELS)}",
                )
            if channel in names:
                raise MotionDataError(self.path, tln, f"channel {channel} listed twice")
            names.append(channel)
        return tuple(names)


def _within(values: np.ndarray, bound: np.ndarray) -> bool:
    """Every value finite and within its column's bound (nan fails the comparisons)."""
    return bool((values.max(axis=0) <= bound).all() and (values.min(axis=0) >= -bound).all())
