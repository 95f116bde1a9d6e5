"""Atomic outputs (a file is either wholly written or not there at all) and checked inputs
(regular files only, of bounded size, read without blocking on a FIFO or device).

Pure standard library (no numpy, no MuJoCo), so every room of ``sim`` and ``sidql`` can write its
outputs through it.
"""

from __future__ import annotations

import codecs
import os
import secrets
import shutil
import stat
import tempfile
import zipfile
from pathlib import Path

from sim.errors import MotionDataError


def write_atomic(path: str | os.PathLike, write) -> None:
    """Call ``write(fileobj)`` on a temporary file beside ``path``, then rename it into place.

    A crash never leaves a half-written ``path`` behind. Where the system offers unnamed
    temporary files (Linux ``O_TMPFILE``), the data are written to a file with no name at all,
    which is linked in only once complete: a process killed while writing (SIGKILL included)
    leaves nothing behind. Elsewhere the temporary file is named ``.<name>.<random>.tmp`` and
    removed on any exception.
    """
    path = Path(path)
    fd = _unnamed_file(path.parent)
    if fd is None:
        _write_named(path, write)
        return
    with os.fdopen(fd, "w+b") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
        os.fchmod(f.fileno(), 0o666 & ~_umask())
        try:
            tmp = _link_unnamed(f.fileno(), path)
        except OSError:  # /proc lacks the link (a sandbox): copy into a named temporary file
            f.seek(0)
            _write_named(path, lambda g: shutil.copyfileobj(f, g))
            return
    try:
        os.replace(tmp, path)
    except BaseException:
        _unlink(tmp)
        raise


def _unnamed_file(folder: Path) -> int | None:
    """A descriptor of an unnamed, writable file in ``folder`` (``O_TMPFILE``), or None where the
    system or file system has none (then :func:`write_atomic` uses a named temporary file)."""
    flag = getattr(os, "O_TMPFILE", 0)
    if not flag or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(folder, flag | os.O_RDWR | getattr(os, "O_CLOEXEC", 0), 0o600)
    except FileNotFoundError:
        raise
    except OSError:  # EOPNOTSUPP, EISDIR (old kernels), EINVAL: the file system lacks it
        return None


def _link_unnamed(fd: int, path: Path) -> Path:
    """Give the unnamed file ``fd`` a fresh hidden name beside ``path``; returns that name.

    ``linkat(/proc/self/fd/N, AT_SYMLINK_FOLLOW)`` (``os.link`` calls plain ``link`` unless given
    a directory descriptor, and ``link`` would not follow the descriptor's link)."""
    proc = os.open("/proc/self/fd", os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        for _ in range(100):
            tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
            try:
                os.link(str(fd), tmp, src_dir_fd=proc, follow_symlinks=True)
                return tmp
            except FileExistsError:
                continue
        raise FileExistsError(f"no free temporary name beside {path}")
    finally:
        os.close(proc)


def _write_named(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w+b") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        _unlink(tmp)
        raise


def _unlink(path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: Size limits [bytes] of the inputs read through :func:`read_regular` (one per kind of file).
#: A real CMU AMC is at most ~20 MB (5 minutes at 120 Hz); ASF skeletons are a few KB.
MAX_ASF_BYTES = 1 << 20
MAX_AMC_BYTES = 64 << 20
MAX_BVH_BYTES = 64 << 20  # a BVH holds the skeleton and the motion: as large as an AMC
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


def excerpt(text: str | bytes, limit: int = 40, *, quote: bool = True) -> str:
    """A short printable quotation of ``text`` for an error message: at most ``limit``
    characters of it, anything but printable ASCII shown as ``?``, ``...`` when cut, in quotes
    (``repr``) unless not ``quote``.

    An error about hostile input quotes it only through this, so a message stays one short line
    and never carries control characters (terminal escapes) or a file's content at length."""
    if isinstance(text, bytes):
        text = text.decode("latin-1")
    cut = len(text) > limit
    shown = "".join(ch if " " <= ch <= "~" else "?" for ch in text[:limit])
    shown += "..." if cut else ""
    return repr(shown) if quote else shown


#: Text files are decoded and split into lines this many bytes at a time (bounded memory).
TEXT_CHUNK_BYTES = 1 << 18
#: A text input with no line break (LF or CR) in this many bytes is refused.
MAX_LINE_BYTES = 1 << 20


def text_encoding(f) -> str:
    """``"utf-8"`` if the file ``f`` (binary, at its start) is valid UTF-8 (ASCII included), else
    ``"latin-1"`` (every byte a character); reads it through in chunks, then rewinds it."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    encoding = "utf-8"
    try:
        while block := f.read(TEXT_CHUNK_BYTES):
            if not (block.isascii() and not decoder.getstate()[0]):
                decoder.decode(block)  # the text is dropped: only validity matters here
        decoder.decode(b"", final=True)
    except UnicodeDecodeError:
        encoding = "latin-1"
    f.seek(0)
    return encoding


def text_lines(f, path: str, max_bytes: int):
    """Yield ``(first line number, lines)`` of the text file ``f`` (binary, at its start) a chunk
    at a time: lines split as ``str.splitlines`` splits the whole decoded file (LF, CRLF, CR, and
    the other Unicode line breaks), numbered from 1 the same way.

    Memory is bounded by :data:`TEXT_CHUNK_BYTES`, whatever the file's size: each chunk ends at
    an LF or CR (never inside a CRLF), so no line straddles two chunks. The file is decoded as
    UTF-8 when it all is, else as Latin-1 (:func:`text_encoding`).

    Raises:
        MotionDataError: no line break in :data:`MAX_LINE_BYTES` bytes (naming that line), or the
            file grew past ``max_bytes`` while being read.
    """
    encoding = text_encoding(f)
    carry, line, total = b"", 1, 0
    while True:
        try:
            block = f.read(TEXT_CHUNK_BYTES)
        except OSError as e:
            raise MotionDataError(path, None, f"cannot read file: {e.strerror or e}") from None
        total += len(block)
        if total > max_bytes:
            raise MotionDataError(path, None, f"file exceeds the limit of {max_bytes:,} bytes")
        data = carry + block
        if not block:
            if data:
                yield line, data.decode(encoding).splitlines()
            return
        end = max(data.rfind(b"\n"), data.rfind(b"\r"))
        if end == len(data) - 1 and data[end] == 13:  # a CR whose LF may come in the next read
            end = max(data.rfind(b"\n", 0, end), data.rfind(b"\r", 0, end))
        if end < 0:
            if len(data) > MAX_LINE_BYTES:
                raise MotionDataError(
                    path, line, f"no line break (LF or CR) in {MAX_LINE_BYTES:,} bytes"
                )
            carry = data
            continue
        lines = data[: end + 1].decode(encoding).splitlines()
        carry = data[end + 1 :]
        yield line, lines
        line += len(lines)


def check_zip(zf, size: int, path: str, *, max_members: int, max_inflated: int, stored_only: bool):
    """Check the directory of the opened ``zipfile.ZipFile`` ``zf`` (a file of ``size`` bytes)
    before any member is read, and return its members.

    Refused: more than ``max_members`` members, repeated names, encrypted members, a compression
    other than none (or deflate, unless ``stored_only``), members whose data overlap or run past
    the end of the file (the overlapping-member zip bomb) and members inflating to more than
    ``max_inflated`` bytes in all (the deflate bomb).

    Raises:
        MotionDataError: one line naming the file and the problem.
    """
    infos = zf.infolist()
    if len(infos) > max_members:
        raise MotionDataError(path, None, f"{len(infos):,} zip members; at most {max_members:,}")
    if len({i.filename for i in infos}) != len(infos):
        raise MotionDataError(path, None, "repeated zip member names")
    methods = (zipfile.ZIP_STORED,) if stored_only else (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED)
    inflated = 0
    for info in infos:
        if info.flag_bits & 0x1:
            raise MotionDataError(path, None, f"zip member {excerpt(info.filename)} is encrypted")
        if info.compress_type not in methods:
            kind = "stored (uncompressed)" if stored_only else "stored or deflated"
            raise MotionDataError(path, None, f"zip member {excerpt(info.filename)} is not {kind}")
        if info.compress_type == zipfile.ZIP_STORED and info.compress_size != info.file_size:
            raise MotionDataError(path, None, f"zip member {excerpt(info.filename)}: bad size")
        inflated += info.file_size
    if inflated > max_inflated:
        raise MotionDataError(
            path, None, f"zip members inflate to {inflated:,} bytes; at most {max_inflated:,}"
        )
    end = 0
    for info in sorted(infos, key=lambda i: i.header_offset):
        if info.header_offset < end:
            raise MotionDataError(path, None, "zip members overlap")
        end = info.header_offset + 30 + len(info.filename.encode()) + info.compress_size
        if end > size:
            raise MotionDataError(path, None, "zip member runs past the end of the file")
    return infos
