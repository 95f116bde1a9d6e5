"""Acclaim AMC motions (the CMU database's format), read into a :class:`~sim.acclaim.records.Motion`
for the :class:`~sim.acclaim.records.Skeleton` of their ASF file (:mod:`sim.acclaim.asf`).

Root translations are converted to metres, rotations kept in degrees (see
:mod:`sim.acclaim.records` for the units and the bounds). Malformed input raises
:class:`~sim.errors.MotionDataError` naming the file, the line and the problem; nothing deeper
leaks out. Frame numbers are ASCII digits (at most 12). Lines are split as ``str.splitlines``
splits them (LF, CRLF, lone CR, ...); error line numbers count the same way.
"""

from __future__ import annotations

import os
import re
import warnings

import numpy as np

from sim.acclaim.frames import read_run
from sim.acclaim.records import MAX_DEGREES, MAX_METRES, ROOT_CHANNELS, Motion, Skeleton
from sim.acclaim.tokens import float_list, known_names
from sim.errors import MotionDataError, MotionDataWarning
from sim.files import MAX_AMC_BYTES, excerpt, open_regular, text_lines

#: Largest AMC file :func:`iter_amc` reads [bytes]: it holds one chunk of frames at a time, so
#: its memory does not grow with the file; the limit only bounds the time a read can take
#: (16 GiB is ~20 million frames, two days at 120 fps).
MAX_STREAMED_AMC_BYTES = 16 << 30

_FRAME_NUMBER_RE = re.compile(r"[0-9]{1,12}\Z")


def parse_amc(path: str | os.PathLike, skeleton: Skeleton, *, strict: bool = False) -> Motion:
    """Read an AMC motion for ``skeleton`` (``:FULLY-SPECIFIED``, ``:DEGREES``; LF or CRLF).

    A file that ends part-way through its final frame (whole lines missing, as in CMU's own
    07_12.amc) loses that frame with a :class:`MotionDataWarning` and a note in ``Motion.notes``,
    unless ``strict``, where it is an error like any other truncated frame.

    Bounded memory: the file is read a chunk at a time (:func:`sim.files.text_lines`) and each
    chunk's values go straight into arrays, so the peak is the motion's own arrays (8 bytes per
    value the file spells out, at least 2 characters each, so at most 4x the file's size) plus a
    chunk. Bones the file never mentions share one read-only row of zeros.

    Returns:
        The motion with root translations in metres and rotations in degrees.

    Raises:
        MotionDataError: truncated frame, unknown bone, wrong number of values, non-numeric token,
            no frames...
    """
    path = str(path)
    parser = _AmcParser(path, skeleton, strict)
    with open_regular(path, MAX_AMC_BYTES) as f:  # regular files only, of bounded size
        for first_line, lines in text_lines(f, path, MAX_AMC_BYTES):
            parser.feed(first_line, lines)
    motion = parser.finish()
    for note in motion.notes:
        warnings.warn(note, MotionDataWarning, stacklevel=2)
    return motion


def iter_amc(
    path: str | os.PathLike,
    skeleton: Skeleton,
    *,
    strict: bool = False,
    max_bytes: int = MAX_STREAMED_AMC_BYTES,
):
    """Read an AMC motion a chunk of frames at a time: yields :class:`Motion` pieces, frame after
    frame (``first_frame`` of each: the file's number of its first frame), the same values,
    checks, notes and one-line errors (file and line) as :func:`parse_amc` of the whole file.

    Bounded memory whatever the file's length: each piece holds the frames of one text chunk
    (:data:`sim.files.TEXT_CHUNK_BYTES`, at most ~4x its size in arrays); the file may be as
    large as ``max_bytes``. A caller that stops early closes the file (a generator).

    Raises:
        MotionDataError: as :func:`parse_amc` (a defect is raised when its chunk is read: the
            pieces before it have been yielded).
    """
    path = str(path)
    parser = _AmcParser(path, skeleton, strict)
    with open_regular(path, max_bytes) as f:
        for first_line, lines in text_lines(f, path, max_bytes):
            parser.feed(first_line, lines)
            if parser.n - parser.taken > 0 and not parser.in_header:
                yield parser.take()
    motion = parser.finish()
    for note in motion.notes:
        warnings.warn(note, MotionDataWarning, stacklevel=2)
    if motion.n_frames:
        yield motion


def _is_frame_number(token: str) -> bool:
    return _FRAME_NUMBER_RE.match(token) is not None


def _frame_number_line(raw: str) -> bool:
    """Whether ``raw`` is a line holding one token of digits (a frame number, valid or not)."""
    tokens = raw.split()
    return len(tokens) == 1 and tokens[0].isdigit()


class _AmcParser:
    """The AMC body as a state machine fed a chunk of lines at a time.

    Frames go to per-bone arrays: runs of frames laid out exactly like the first frame are
    converted a chunk at a time (the fast path: one compiled pass, :mod:`sim.acclaim.frames`,
    where it converts every value exactly, else numpy's reader, bone by bone); anything else goes line by line (the
    checked path), which names the offending line. Both accept the same files and give the same
    values: the fast path only takes what it can verify, and hands any doubt to the checked path.
    """

    ROWS = 256  # frames of the checked path held as Python lists before they become arrays

    def __init__(self, path: str, skeleton: Skeleton, strict: bool):
        self.path, self.skeleton, self.strict = path, skeleton, strict
        self.layout = {b.name: len(b.dofs) for b in skeleton.bones}
        self.layout["root"] = 6
        self.in_deg = skeleton.angles_in_degrees
        self.in_header, self.seen_text = True, False
        self.bounds: dict[str, list[float]] = {}
        self.first: int | None = None  # the file's number of its first frame
        self.n = 0  # frames closed
        self.names: tuple[str, ...] | None = None  # the first frame's bones, in file order
        self.current: dict | None = None  # the frame being read (checked path)
        self.current_line = 0
        self.rows: list[list] = []  # closed frames of the checked path, not yet arrays
        self.columns: dict[str, list[np.ndarray]] = {}  # bone -> (frames, dofs) pieces
        self.notes: list[str] = []
        self.taken = 0  # frames already handed out by :meth:`take`
        self.held: list[str] = []  # the last frame-number line of a chunk and the lines after it
        self.held_from = 0  # the number of held[0]

    # -- feeding ---------------------------------------------------------------------------------

    def feed(self, first_line: int, lines: list[str]) -> None:
        """Read the next chunk of lines; ``first_line``: the number of ``lines[0]``. The chunk's
        last frame may go on in the next chunk: its lines wait for it (:attr:`held`), so that
        frame is read with the next ones, by the fast path where it can."""
        if self.held:  # the lines just before these
            first_line, lines = self.held_from, self.held + lines
            self.held = []
        i = 0
        if self.in_header:
            i = self._header(lines)
            if self.in_header:
                return
        last = len(lines) - 1
        while last > i and not _frame_number_line(lines[last]):
            last -= 1
        if last > i:
            self.held, self.held_from = lines[last:], first_line + last
            lines = lines[:last]
        self._lines(first_line, lines, i, last)

    def _lines(self, first_line: int, lines: list[str], i: int, last: int) -> None:
        """Read ``lines[i:]``: runs of whole frames before ``last`` by the fast path where they
        are regular, the rest line by line."""
        fast = True
        while i < len(lines):
            if fast and self.names is not None and i < last and _frame_number_line(lines[i]):
                self._close(None)
                done = self._fast(lines, i, last)
                if done > i:
                    i = done
                    continue
                fast = False  # irregular: the rest of this chunk goes line by line
            self._line(first_line + i, lines[i])
            i += 1

    def _header(self, lines: list[str]) -> int:
        """Skip blank lines, comments and ``:`` flags; returns the index of the first body line
        (the header ends there) or ``len(lines)``."""
        for i, raw in enumerate(lines):
            text = raw.strip()
            if text:
                self.seen_text = True
            if not text or text.startswith("#"):
                continue
            if text.startswith(":"):
                flag = text.split()[0].upper()
                if flag == ":DEGREES":
                    self.in_deg = True
                elif flag == ":RADIANS":
                    self.in_deg = False
                continue
            self.in_header = False
            self._set_bounds()
            return i
        return len(lines)

    def _set_bounds(self) -> None:
        """Bounds in the file's units: |translation| <= MAX_METRES, |angle| <= MAX_DEGREES."""
        angle = MAX_DEGREES if self.in_deg else float(np.deg2rad(MAX_DEGREES))
        self.bounds = {n: [angle] * k for n, k in self.layout.items()}
        for c in ("tx", "ty", "tz"):
            self.bounds["root"][self.skeleton.root_order.index(c)] = (
                MAX_METRES / self.skeleton.length_to_metres
            )

    # -- the checked path ------------------------------------------------------------------------

    def _line(self, ln: int, raw: str) -> None:
        path = self.path
        tokens = raw.split()
        if not tokens:
            return
        if len(tokens) == 1 and tokens[0].isdigit():
            if not _is_frame_number(tokens[0]):
                raise MotionDataError(
                    path, ln, f"frame number {excerpt(tokens[0], 20)} is not 1 to 12 ASCII digits"
                )
            self._close(None)
            number = int(tokens[0])
            if self.first is None:
                self.first = number
            elif number != self.first + self.n:
                raise MotionDataError(
                    path, ln, f"frame number {number}; expected {self.first + self.n}"
                )
            self.current, self.current_line = {}, ln
            return
        if self.current is None:
            raise MotionDataError(path, ln, f"expected a frame number, got {excerpt(tokens[0])}")
        name = tokens[0]
        if name not in self.layout:
            raise MotionDataError(
                path, ln, f"unknown bone {excerpt(name)}; known: {known_names(sorted(self.layout))}"
            )
        if name in self.current:
            raise MotionDataError(path, ln, f"bone {name!r} appears twice in one frame")
        if len(tokens) - 1 != self.layout[name]:
            raise MotionDataError(
                path, ln, f"bone {name!r} needs {self.layout[name]} values, got {len(tokens) - 1}"
            )
        self.current[name] = float_list(tokens[1:], path, ln, f"bone {name!r}", self.bounds[name])

    def _close(self, at_end: int | None) -> None:
        """Close the frame being read: check it has the first frame's bones, queue its values.

        ``at_end``: the file's last line when this is its final frame (an incomplete final frame
        is dropped with a note unless ``strict``)."""
        current = self.current
        if current is None:
            return
        self.current = None
        if self.names is None:
            if "root" not in current:
                raise MotionDataError(self.path, self.current_line, "frame has no 'root' line")
            self.names = tuple(current)
            self.columns = {name: [] for name in self.names}
        missing = set(self.names) - set(current)
        if missing:
            problem = (
                f"truncated frame {self.first + self.n}: missing {known_names(sorted(missing))}"
            )
            if at_end is not None and not self.strict and self.n >= 1:
                where = f"{self.path}:{self.current_line}"
                self.notes.append(f"{where}: {problem}; dropped the incomplete final frame")
                return
            raise MotionDataError(self.path, self.current_line, problem)
        extra = set(current) - set(self.names)
        if extra:
            raise MotionDataError(
                self.path, self.current_line,
                f"frame has bones the first frame lacks: {known_names(sorted(extra))}",
            )  # fmt: skip
        self.rows.append([current[name] for name in self.names])
        self.n += 1
        if len(self.rows) >= self.ROWS:
            self._flush()

    def _flush(self) -> None:
        """The checked path's queued frames as arrays, one per bone."""
        if not self.rows:
            return
        for k, name in enumerate(self.names):
            values = np.array([row[k] for row in self.rows], dtype=np.float64)
            self.columns[name].append(values.reshape(len(self.rows), self.layout[name]))
        self.rows = []

    # -- the fast path ---------------------------------------------------------------------------

    def _fast(self, lines: list[str], start: int, stop: int) -> int:
        """Convert the frames of ``lines[start:stop]`` (``start`` and ``stop`` frame-number
        lines) in one go when every one is laid out exactly like the first frame, their numbers
        follow on and every value is finite and within bounds; returns ``stop``, or ``start``
        (nothing done) so that the checked path reads them and names any problem."""
        names = self.names
        L = len(names) + 1
        if (stop - start) % L:
            return start
        if self._compiled(lines[start:stop]):
            return stop
        T = (stop - start) // L
        number_lines = lines[start:stop:L]
        digits = "".join(number_lines)
        if not (digits.isascii() and digits.replace(" ", "").replace("\t", "").isdigit()):
            return start  # signs, underscores, unicode digits, other blanks: the checked path
        try:
            numbers = [int(x) for x in number_lines]
        except ValueError:
            return start
        expected = self.first + self.n
        if numbers != list(range(expected, expected + T)) or any(
            len(x.strip()) > 12 for x in number_lines
        ):
            return start
        block = {}
        for k, name in enumerate(names, start=1):
            count = self.layout[name]
            slot = lines[start + k : stop : L]
            prefix = name + " " if count else name
            joined = "\n".join(slot)
            if not joined.startswith(prefix) or joined.count("\n" + prefix) != T - 1:
                return start
            if count == 0:
                if any(line != name for line in slot):
                    return start
                continue
            if not _counted(joined, T * count):
                return start
            try:  # numpy's C reader, the name column skipped; a bad token or a short line raises
                values = np.loadtxt(
                    slot, dtype=np.float64, ndmin=2, comments=None, usecols=range(1, count + 1)
                )
            except (ValueError, IndexError):
                return start
            if values.shape != (T, count) or not _within(values, self.bounds[name]):
                return start
            block[name] = values
        self._flush()
        for name, values in block.items():
            self.columns[name].append(values)
        self.n += T
        return stop

    def _compiled(self, run: list[str]) -> bool:
        """Read the frames of ``run`` in one compiled pass (:func:`sim.acclaim.frames.read_run`)
        when it takes them and every value is within bounds; whether it did."""
        counts = tuple(self.layout[name] for name in self.names)
        values = read_run(run, self.names, counts, self.first + self.n)
        if values is None:
            return False
        bounds = [b for name, k in zip(self.names, counts, strict=True) if k
                  for b in self.bounds[name]]  # fmt: skip
        if not _within(values, bounds):
            return False
        self._flush()
        col = 0
        for name, k in zip(self.names, counts, strict=True):
            if k:
                self.columns[name].append(values[:, col : col + k])
                col += k
        self.n += len(values)
        return True

    # -- the result ------------------------------------------------------------------------------

    def take(self) -> Motion:
        """The closed frames not yet taken, as a motion (the frame being read stays open)."""
        self._flush()
        motion = self._motion()
        self.columns = {name: [] for name in self.names}
        return motion

    def finish(self) -> Motion:
        """The frames not yet taken (all of them unless :meth:`take` ran), the file ended."""
        path = self.path
        if not self.seen_text:
            raise MotionDataError(path, None, "empty file")
        if self.in_header:
            raise MotionDataError(path, None, "no frames")
        if self.held:  # the file's last frame
            held, self.held = self.held, []
            self._lines(self.held_from, held, 0, 0)
        had_frame = self.current is not None or self.n > 0
        self._close(at_end=True)
        if not had_frame:
            raise MotionDataError(path, None, "no frames")
        self._flush()
        return self._motion()

    def _motion(self) -> Motion:
        """The frames closed since the last :meth:`take`, emptying the column pieces."""
        path = self.path
        T = self.n - self.taken
        first = self.first + self.taken
        self.taken = self.n
        skeleton = self.skeleton
        columns = self.columns
        order = [skeleton.root_order.index(c) for c in ROOT_CHANNELS]
        root = _concatenate(columns.pop("root"), T, 6, order)
        root[:, :3] *= skeleton.length_to_metres
        if not self.in_deg:
            np.rad2deg(root[:, 3:], out=root[:, 3:])
        angles = {}
        for b in skeleton.bones:
            if not b.dofs:
                continue
            pieces = columns.pop(b.name, None)
            if pieces is None:  # never mentioned: zeros, one shared read-only row
                angles[b.name] = np.broadcast_to(np.zeros(len(b.dofs)), (T, len(b.dofs)))
                continue
            a = _concatenate(pieces, T, len(b.dofs))
            del pieces
            if not self.in_deg:
                np.rad2deg(a, out=a)
            angles[b.name] = a
        # Finite: every value passed its bound (finite, bounded), and rad2deg of a bounded value
        # is finite; the zeros of unmentioned bones are too.
        return Motion(
            path=path, root=root, angles=angles, first_frame=first, notes=tuple(self.notes)
        )


def _concatenate(pieces: list[np.ndarray], T: int, k: int, order=None) -> np.ndarray:
    """(T, k) float64 of ``pieces`` stacked (columns in ``order`` when given), emptying the list
    as they are copied, so that at most one piece is held twice."""
    out = np.empty((T, k))
    row = 0
    pieces.reverse()
    while pieces:
        piece = pieces.pop()
        out[row : row + len(piece)] = piece if order is None else piece[:, order]
        row += len(piece)
    return out


def _within(values: np.ndarray, bound: list[float]) -> bool:
    """Every value of ``values`` (frames, channels) finite and within its channel's bound."""
    if not len(values):
        return True
    b = np.asarray(bound)
    # min/max reduce without temporaries; nan propagates
    return bool((values.max(axis=0) <= b).all() and (values.min(axis=0) >= -b).all())


def _counted(joined: str, spaces: int) -> bool:
    """Whether the lines of ``joined`` are ASCII with spaces as their only blanks (no tab or unit
    separator: inside a line, the other ASCII characters ``str.split`` and numpy split on) and
    ``spaces`` spaces in all. Such a line has at least as many spaces as tokens less one, so when
    numpy finds at least ``1 + count`` tokens on each of ``T`` lines and they hold ``T count``
    spaces, every line has exactly ``1 + count`` tokens: its name and ``count`` values."""
    return (
        joined.isascii() and "\t" not in joined and "\x1f" not in joined
        and joined.count(" ") == spaces
    )  # fmt: skip
