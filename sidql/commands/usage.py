"""What every command shares for bad input: one exception, one-line errors and warnings.

Every bad input exits 2 with one line on stderr: ``sidql COMMAND: error: PROBLEM``, where PROBLEM
names the file and line when there is one (:class:`sim.errors.MotionDataError`). Warnings print as
one line ``warning: FILE:LINE: MESSAGE`` (no Python source line).
"""

from __future__ import annotations

import argparse
import re
import socket
import sys

from sim.errors import MotionDataWarning
from sim.files import excerpt


class UsageError(Exception):
    """A bad command-line value (e.g. W out of range, an unknown method); exits 2 with one line."""


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


#: Seconds ``--ray HOST:PORT`` waits for the cluster to answer before it is refused.
RAY_CONNECT_TIMEOUT_S = 3.0
_HOST = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252})|\[[0-9A-Fa-f:.]{2,45}\]")


def ray_address(text):
    """An argparse ``type`` for ``--ray ADDRESS``: ``local``, ``auto`` (Ray finds the cluster), or
    ``[ray://]HOST:PORT`` that answers on that port within :data:`RAY_CONNECT_TIMEOUT_S` seconds;
    anything else is a one-line usage error before any work starts (instead of Ray's traceback,
    or its 20 s of retries for an address nobody answers on)."""
    if text in ("local", "auto"):
        return text
    bare = text.removeprefix("ray://")
    host, sep, port = bare.rpartition(":")
    if not (sep and _HOST.fullmatch(host) and port.isascii() and port.isdigit()
            and 1 <= int(port) <= 65535):  # fmt: skip
        raise argparse.ArgumentTypeError(
            f"not a Ray address: {excerpt(text)} (expected local, auto, HOST:PORT or "
            "ray://HOST:PORT)"
        )
    try:
        _answers_grpc(host.strip("[]"), int(port))
    except OSError as e:
        why = e.strerror or str(e) or type(e).__name__
        raise argparse.ArgumentTypeError(
            f"no Ray cluster answers at {excerpt(text)} ({why})"
        ) from None
    return text


def _answers_grpc(host: str, port: int) -> None:
    """Raise OSError unless ``host:port`` answers the HTTP/2 preface with a SETTINGS frame, as
    Ray's gRPC servers (the GCS, the client server) do: an open port alone is not enough (a
    proxy or firewall may accept any connection)."""
    with socket.create_connection((host, port), RAY_CONNECT_TIMEOUT_S) as s:
        s.settimeout(RAY_CONNECT_TIMEOUT_S)
        s.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))
        head = b""
        while len(head) < 9:
            part = s.recv(9 - len(head))
            if not part:
                break
            head += part
    if len(head) < 9 or head[3] != 4:
        raise OSError("it does not speak gRPC")
