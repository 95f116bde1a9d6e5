"""Atomic outputs (a file is either wholly written or not there at all) and checked inputs
(regular files only, of bounded size, read without blocking on a FIFO or device).

Pure standard library (no numpy, no MuJoCo), so every room of ``sim`` and ``sidql`` can write its
outputs through it.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from sim.errors import MotionDataError


def write_atomic(path: str | os.PathLike, write) -> None:
    """Call ``write(fileobj)`` on a temporary file beside ``path``, then rename it into place.

    A crash never leaves a half-written ``path`` behind.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: Size limits [bytes] of the inputs read through :func:`read_regular` (one per kind of file).
#: A real CMU AMC is at most ~20 MB (5 minutes at 120 Hz); ASF skeletons are a few KB.
MAX_ASF_BYTES = 1 << 20
MAX_AMC_BYTES = 64 << 20
MAX_SIDQ_BYTES = 64 << 20
MAX_INDEX_BYTES = 64 << 20
MAX_NPZ_BYTES = 256 << 20
MAX_POLICY_BYTES = 64 << 20
MAX_CHECKPOINT_BYTES = 1 << 30

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def open_regular(path: str | os.PathLike, max_bytes: int):
    """Open ``path`` for binary reading if it is a regular file of at most ``max_bytes`` bytes.

    The check is made on the opened descriptor (``fstat``), so the file cannot be swapped between
    check and read; the open itself never blocks (``O_NONBLOCK``: a FIFO with no writer does not
    hang it). A symbolic link is followed to its target, which must itself be a regular file
    (batch inputs are confined to their folder separately, :func:`inside`).

    Returns:
        A binary file object positioned at the start (the caller closes it).
    Raises:
        MotionDataError: missing or unreadable file, a directory, FIFO, device or socket, or a
            file larger than ``max_bytes`` (one line naming the file).
    """
    name = os.fspath(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(name, flags)
    except OSError as e:
        raise MotionDataError(str(name), None, f"cannot read file: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = next((w for test, w in _KINDS if test(st.st_mode)), "not a regular file")
            raise MotionDataError(str(name), None, f"not a regular file ({kind})")
        if st.st_size > max_bytes:
            raise MotionDataError(
                str(name), None, f"file of {st.st_size:,} bytes exceeds the limit of {max_bytes:,}"
            )
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | os.PathLike, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` (at most ``max_bytes``; see :func:`open_regular`).

    A file that grows past ``max_bytes`` while being read is refused as well."""
    with open_regular(path, max_bytes) as f:
        try:
            data = f.read(max_bytes + 1)
        except OSError as e:
            raise MotionDataError(str(path), None, f"cannot read file: {e.strerror or e}") from None
    if len(data) > max_bytes:
        raise MotionDataError(str(path), None, f"file exceeds the limit of {max_bytes:,} bytes")
    return data


def inside(path: str | os.PathLike, folder: str | os.PathLike) -> bool:
    """Whether ``path``, with every symbolic link resolved, lies within ``folder`` (resolved)."""
    try:
        real = os.path.realpath(path)
        base = os.path.realpath(folder)
    except (OSError, ValueError):
        return False
    return os.path.commonpath([real, base]) == base
