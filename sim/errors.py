"""The project's one error hierarchy: every error raised on purpose derives from :class:`SidqlError`.

* :class:`BadFileError`: a file that cannot be used; names the file, the line (when known) and
  the problem. Its kinds: :class:`MotionDataError` (ASF/AMC files, clips, ``.sidq`` streams,
  dataset indexes), :class:`ModelFileError` (policy and checkpoint files) and
  :class:`OutputError` (an output that cannot go where it was asked for).
* :class:`UnmetTargetError`: a request that cannot be met by any answer (e.g. a byte rate too low
  for the trial).
* :class:`UnknownNameError`: an unknown name of a method, reconstruction, kind, ...; the message
  lists the valid ones.
* :class:`AllFailedError`: a batch job whose every item failed on bad input (each one listed);
  a job that keeps any good result lists the bad items and does not raise.
* :class:`UsageError`: an argument value outside what a function or command accepts (a keyframe
  count W out of range, frame rates that do not divide); the message names the argument, what is
  valid and the value given: also an array of the wrong shape or a value that is not finite. Its
  kind :class:`ArgumentTypeError` is an argument of the wrong type.

The command line prints any :class:`SidqlError` as one line and exits 2; a batch job lists the
item it failed on and keeps every good result. Every error a public function raises on purpose
is one of these (``tests/test_errors.py`` calls each public function with bad arguments); any
other exception is a bug.
"""

from __future__ import annotations

from collections.abc import Iterable


class SidqlError(Exception):
    """Base of every error the project raises for bad input or an impossible request."""


class BadFileError(SidqlError, ValueError):
    """A file that cannot be used: names the file, the line (when known) and the problem.

    A ``ValueError`` too, so generic callers can still catch it; code in this project raises one
    of its kinds for malformed input, never a bare IndexError/KeyError/ValueError from deep inside.
    """

    MAX_PROBLEM = 1000  # characters; a hostile token (a 100,000-character name) is cut short

    def __init__(self, path: str | None, line: int | None, problem: str):
        self.path = None if path is None else str(path)
        self.line = line
        if len(problem) > self.MAX_PROBLEM:  # cut to at most MAX_PROBLEM: pickling is stable
            problem = problem[: self.MAX_PROBLEM - 40] + f"... ({len(problem)} characters)"
        self.problem = problem
        where = self.path or "<input>"
        if line is not None:
            where = f"{where}:{line}"
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):
        # Worker processes send errors back pickled; rebuild from the three fields.
        return (type(self), (self.path, self.line, self.problem))


class MotionDataError(BadFileError):
    """Bad motion data: an ASF/AMC file, a clip, a ``.sidq`` stream or a dataset index."""


class ModelFileError(BadFileError):
    """A policy or checkpoint file that is refused: not a plain tensor file (e.g. a pickle that
    would construct arbitrary objects), unreadable, of another format or version, or of other
    settings."""


class OutputError(BadFileError):
    """An output that cannot be written where it was asked for: below the folder the user named
    there is a symbolic link, or the target is a directory, FIFO, device or socket (outputs only
    ever replace regular files), or a clip its own reader would refuse."""


class UnmetTargetError(SidqlError, ValueError):
    """A target no answer meets, e.g. a byte rate too low for the trial's fewest keyframes."""


class UnknownNameError(SidqlError, KeyError, ValueError):
    """An unknown name (of a method, reconstruction, clip kind, point, ...); the message lists the
    valid ones: ``unknown method 'x'; known: random, uniform, ...``.

    A ``KeyError`` and a ``ValueError`` too, so the caller of a plain lookup catches it as either.

    Attributes:
        what: what was looked up ("method", "reconstruction", ...); name: the name given;
        known: the valid names, in their order.
    """

    MAX_KNOWN = 300  # characters of the list of valid names

    def __init__(self, what: str, name, known: Iterable[str]):
        self.what, self.name, self.known = what, name, tuple(str(k) for k in known)
        shown = repr(name) if len(repr(name)) <= 200 else repr(name)[:200] + "..."
        listed = ", ".join(self.known) or "none"
        if len(listed) > self.MAX_KNOWN:  # a 1,000-bone skeleton: the first names and a count
            listed = (
                listed[: self.MAX_KNOWN].rsplit(", ", 1)[0] + f", ... ({len(self.known)} in all)"
            )
        super().__init__(f"unknown {what} {shown}; known: {listed}")

    def __str__(self) -> str:  # KeyError would print the message quoted
        return str(self.args[0])

    def __reduce__(self):
        return (type(self), (self.what, self.name, self.known))


class AllFailedError(SidqlError):
    """A batch job whose every item failed on bad input: nothing to keep. The message lists each
    item and its error (a job that keeps any good result lists the bad items and goes on)."""


class UsageError(SidqlError, ValueError):
    """An argument value a function or command does not accept (e.g. W outside [2, N], an output
    rate that does not divide the source rate); the message names the argument, what would be
    valid and the value given. A ``ValueError`` too, as for any bad argument value."""


class ArgumentTypeError(UsageError, TypeError):
    """An argument of the wrong kind (e.g. a float where a frame count is an integer); a
    ``TypeError`` too, as Python's own for a wrong type."""


class MotionDataWarning(UserWarning):
    """Input that was repaired rather than rejected (e.g. an incomplete final AMC frame dropped)."""


def require_type(value, kind: type | tuple[type, ...], what: str):
    """``value`` itself if it is an instance of ``kind``; otherwise an :class:`ArgumentTypeError`
    naming the argument, the kind it must be and the kind given."""
    if not isinstance(value, kind):
        kinds = kind if isinstance(kind, tuple) else (kind,)
        want = " or ".join(k.__name__ for k in kinds)
        raise ArgumentTypeError(f"{what} must be a {want}; got {type(value).__name__}")
    return value


def require_positive(value, what: str) -> float:
    """``value`` as a float if it is finite and > 0; otherwise a :class:`UsageError`."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{what} must be a number; got {type(value).__name__}") from None
    if not (v > 0 and v < float("inf")):
        raise UsageError(f"{what} must be positive and finite; got {value!r}")
    return v
