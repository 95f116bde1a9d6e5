"""What every command shares for bad input: one exception, one-line errors and warnings.

Every bad input exits 2 with one line on stderr: ``sidql COMMAND: error: PROBLEM``, for any
:class:`sim.errors.SidqlError` (PROBLEM names the file and line when there is one). Warnings print as
one line ``warning: FILE:LINE: MESSAGE`` (no Python source line).
"""

from __future__ import annotations

import argparse
import sys

from sim.errors import MotionDataWarning, SidqlError


class UsageError(SidqlError):
    """A bad command-line value (e.g. W out of range); exits 2 with one line."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a parse error is one line ``PROG: error: MESSAGE`` (exit 2), no usage dump."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` replacement: ``warning: FILE:LINE: MESSAGE`` on one line.

    A :class:`~sim.errors.MotionDataWarning` already starts with the data file and line it is
    about; any other warning gets the Python file and line that raised it.
    """
    text = str(message).replace("\n", " ")
    if not issubclass(category, MotionDataWarning):
        text = f"{filename}:{lineno}: {text}"
    print(f"warning: {text}", file=sys.stderr if file is None else file)


def positive(kind):
    """An argparse ``type``: ``kind(text)`` that must be > 0 (else a one-line usage error)."""

    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"must be positive: {text!r}")
        return v

    return parse


def cmu_rate(text):
    """An argparse ``type``: an output frame rate that divides CMU's 120 fps (30 takes every 4th
    frame)."""
    v = positive(float)(text)
    if abs(120.0 / v - round(120.0 / v)) > 1e-9:
        raise argparse.ArgumentTypeError(f"must divide 120 (CMU's rate): {text!r}")
    return v
