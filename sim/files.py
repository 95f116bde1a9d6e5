"""Outputs written only inside the folder the user named, whole or not at all, and checked inputs
(regular files only, of bounded size, read without blocking on a FIFO or device). Pure standard
library, so every room of ``sim`` and ``sidql`` writes through it.

The one writer: every file the project writes goes through :func:`write_atomic` (or, for a file
another program writes, :func:`written_by`; for the synth journal, :func:`open_append`). Each
takes the target and ``root``, the folder the user named (default: the target's own folder). The
writer opens ``root`` (following any link in the path the user typed), then walks to the target's
folder one name at a time from the parent's descriptor with ``O_NOFOLLOW`` (``openat``), creating
missing folders with ``mkdirat``: a symbolic link anywhere below ``root`` is refused, never
followed. The target must be absent or a regular file (never a link, directory, FIFO, device or
socket: :class:`~sim.errors.OutputError`, one line). Data go to a temporary file in the target's
folder (``O_TMPFILE``; elsewhere a fresh random name made with ``O_CREAT | O_EXCL |
O_NOFOLLOW``, as ``mkstemp`` makes it) and are renamed over the target (``renameat`` between
folder descriptors). Nothing is deleted but files the caller proves it wrote
(:func:`remove_written`).
"""

from __future__ import annotations

import codecs
import contextlib
import errno
import os
import secrets
import shutil
import stat
from pathlib import Path

from sim.errors import ArgumentTypeError, MotionDataError, OutputError

_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_DIRECTORY = getattr(os, "O_DIRECTORY", 0)


def _parts(path: Path, root: Path | None) -> tuple[Path, tuple[str, ...], str]:
    """``(root, folders below root, file name)`` of the target ``path``; it must lie below
    ``root`` as written (no ``..``: a walk never climbs)."""
    path = Path(path)
    root = path.parent if root is None else Path(root)
    rest = path.parts[len(root.parts) :]
    if path.parts[: len(root.parts)] != root.parts or not rest or ".." in rest:
        raise OutputError(str(path), None, f"an output outside its folder {root}; refused")
    return root, rest[:-1], rest[-1]


def _describe(mode: int) -> str:
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    return next((w for test, w in _KINDS if test(mode)), "not a regular file")


def _open_folder(root: Path, parts: tuple[str, ...], *, create: bool) -> int | None:
    """A descriptor of ``root/parts...``, walked from ``root`` one name at a time without
    following links; missing folders are made (``create``) or give None."""
    if create:
        try:
            os.makedirs(root, exist_ok=True)  # the folder the user named: their path as typed
        except OSError as e:
            raise OutputError(
                str(root), None, f"cannot make the output folder: {e.strerror}"
            ) from None
    try:
        fd = os.open(root, os.O_RDONLY | _DIRECTORY | _CLOEXEC)
    except OSError as e:
        if not create and e.errno == errno.ENOENT:
            return None
        raise OutputError(str(root), None, f"cannot open the output folder: {e.strerror}") from None
    where = root
    try:
        for part in parts:
            where = where / part
            if create:
                with contextlib.suppress(FileExistsError):
                    os.mkdir(part, 0o777, dir_fd=fd)
            try:
                child = os.open(part, os.O_RDONLY | _DIRECTORY | _NOFOLLOW | _CLOEXEC, dir_fd=fd)
            except OSError as e:
                if not create and e.errno == errno.ENOENT:
                    os.close(fd)
                    return None
                try:
                    what = _describe(os.stat(part, dir_fd=fd, follow_symlinks=False).st_mode)
                except OSError:
                    what = e.strerror or "unusable"
                raise OutputError(
                    str(where), None, f"{what}, not a folder; outputs never go through one"
                ) from None
            os.close(fd)
            fd = child
    except BaseException:
        os.close(fd)
        raise
    return fd


def _check_target(dfd: int, name: str, shown) -> bool:
    """Whether the target exists; refuses one that is not a regular file (a link included)."""
    try:
        mode = os.stat(name, dir_fd=dfd, follow_symlinks=False).st_mode
    except FileNotFoundError:
        return False
    if not stat.S_ISREG(mode):
        raise OutputError(
            str(shown), None, f"{_describe(mode)}; an output replaces regular files only"
        )
    return True


def _named_temp(dfd: int, name: str) -> tuple[int, str]:
    """A fresh file ``.<name>.<random>.tmp`` in the folder ``dfd``, as ``mkstemp`` makes one."""
    for _ in range(100):
        tmp = f".{name[:200]}.{secrets.token_hex(6)}.tmp"
        try:
            flags = os.O_CREAT | os.O_EXCL | os.O_RDWR | _NOFOLLOW | _CLOEXEC
            return os.open(tmp, flags, 0o600, dir_fd=dfd), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {name}")


def _unnamed_temp(dfd: int) -> int | None:
    """An unnamed writable file in the folder ``dfd`` (``O_TMPFILE``), or None where the system
    or file system has none."""
    flag = getattr(os, "O_TMPFILE", 0)
    if not flag or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(".", flag | os.O_RDWR | _CLOEXEC, 0o600, dir_fd=dfd)
    except OSError:  # EOPNOTSUPP, EISDIR (old kernels), EINVAL: the file system lacks it
        return None


def _link_unnamed(fd: int, dfd: int, name: str) -> str | None:
    """Give the unnamed file ``fd`` a fresh hidden name in the folder ``dfd`` (``linkat`` of
    ``/proc/self/fd/N`` with ``AT_SYMLINK_FOLLOW``); None where ``/proc`` lacks the link."""
    proc = os.open("/proc/self/fd", os.O_RDONLY | _DIRECTORY | _CLOEXEC)
    try:
        for _ in range(100):
            tmp = f".{name[:200]}.{secrets.token_hex(6)}.tmp"
            try:
                os.link(str(fd), tmp, src_dir_fd=proc, dst_dir_fd=dfd, follow_symlinks=True)
                return tmp
            except FileExistsError:
                continue
            except OSError:
                return None
        raise FileExistsError(f"no free temporary name beside {name}")
    finally:
        os.close(proc)


def _temp_file(dfd: int, name: str, write) -> str:
    """Write a temporary file in the folder ``dfd`` with ``write(fileobj)``; returns its name."""
    fd = _unnamed_temp(dfd)
    tmp = None
    if fd is None:
        fd, tmp = _named_temp(dfd, name)
    try:
        with os.fdopen(fd, "w+b") as f:
            write(f)
            f.flush()
            os.fchmod(f.fileno(), 0o666 & ~_umask())
            os.fsync(f.fileno())
            if tmp is None:
                tmp = _link_unnamed(f.fileno(), dfd, name)
                if tmp is None:  # a sandbox without the /proc link: copy into a named file
                    f.seek(0)
                    tmp = _temp_file(dfd, name, lambda g: shutil.copyfileobj(f, g))
    except BaseException:
        if tmp is not None:
            _unlink_at(dfd, tmp)
        raise
    return tmp


def _unlink_at(dfd: int, name: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.unlink(name, dir_fd=dfd)


def write_atomic(path: str | os.PathLike, write, *, root: str | os.PathLike | None = None) -> None:
    """Call ``write(fileobj)`` on a temporary file in ``path``'s folder, then rename it over
    ``path``: the file is either wholly written or not there at all.

    ``root``: the output folder the user named (default: ``path``'s folder); ``path`` lies below
    it, and no symbolic link below ``root`` is followed (see the module docstring; killed while
    writing, SIGKILL included, it leaves no half file).

    Raises:
        OutputError: a link below ``root``, or a target that is not a regular file (one line).
        ArgumentTypeError: ``write`` is not callable.
    """
    if not callable(write):  # a bad argument, before any folder is made
        raise ArgumentTypeError(f"write must be callable; got {type(write).__name__}")
    root_dir, folders, name = _parts(Path(path), None if root is None else Path(root))
    dfd = _open_folder(root_dir, folders, create=True)
    try:
        _check_target(dfd, name, path)
        tmp = _temp_file(dfd, name, write)
        try:
            _check_target(dfd, name, path)
            os.rename(tmp, name, src_dir_fd=dfd, dst_dir_fd=dfd)
        except BaseException:
            _unlink_at(dfd, tmp)
            raise
    finally:
        os.close(dfd)


@contextlib.contextmanager
def written_by(path: str | os.PathLike, *, root: str | os.PathLike | None = None, suffix=""):
    """For a file another program writes to a path of its own (ffmpeg's videos): yield a path
    in a private folder (``0700``, a fresh random name in ``path``'s folder) to write to; once
    the block ends without error, the file is renamed over ``path`` (checked as in
    :func:`write_atomic`); the private folder is removed either way.

    The path yielded is ``/proc/<pid>/fd/<N>/out<suffix>``, pinned to the private folder's
    descriptor (where ``/proc`` is there), so no link swapped in meanwhile redirects it."""
    root_dir, folders, name = _parts(Path(path), None if root is None else Path(root))
    dfd = _open_folder(root_dir, folders, create=True)
    pfd = private = None
    try:
        _check_target(dfd, name, path)
        for _ in range(100):
            private = f".{name[:200]}.{secrets.token_hex(6)}.tmp"
            try:
                os.mkdir(private, 0o700, dir_fd=dfd)
                break
            except FileExistsError:
                continue
        pfd = os.open(private, os.O_RDONLY | _DIRECTORY | _NOFOLLOW | _CLOEXEC, dir_fd=dfd)
        inner = f"out{suffix}"
        proc = f"/proc/{os.getpid()}/fd/{pfd}"
        yield f"{proc}/{inner}" if os.path.isdir(proc) else str(Path(path).parent / private / inner)
        _check_target(pfd, inner, path)
        _check_target(dfd, name, path)
        os.rename(inner, name, src_dir_fd=pfd, dst_dir_fd=dfd)
    finally:
        if pfd is not None:
            for left in os.listdir(pfd):  # what the other program left (only it writes there)
                _unlink_at(pfd, left)
            os.close(pfd)
        if private is not None:
            with contextlib.suppress(OSError):
                os.rmdir(private, dir_fd=dfd)
        os.close(dfd)


def open_append(path: str | os.PathLike, *, root: str | os.PathLike | None = None, fresh: bool):
    """``path`` opened for appending (binary), inside ``root`` as :func:`write_atomic` writes:
    ``fresh``: a new empty file, put in place atomically (over any old regular file); else the
    existing regular file, created if missing. Never a link, FIFO, device or socket."""
    root_dir, folders, name = _parts(Path(path), None if root is None else Path(root))
    dfd = _open_folder(root_dir, folders, create=True)
    try:
        _check_target(dfd, name, path)
        if fresh:
            tmp = _temp_file(dfd, name, lambda f: None)
            fd = os.open(tmp, os.O_WRONLY | os.O_APPEND | _NOFOLLOW | _CLOEXEC, dir_fd=dfd)
            os.rename(tmp, name, src_dir_fd=dfd, dst_dir_fd=dfd)
        else:
            flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | _NOFOLLOW | _CLOEXEC
            fd = os.open(name, flags | getattr(os, "O_NONBLOCK", 0), 0o666, dir_fd=dfd)
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                os.close(fd)
                _check_target(dfd, name, path)  # swapped in meanwhile: refused as such
            os.set_blocking(fd, True)
    finally:
        os.close(dfd)
    return os.fdopen(fd, "ab")


def make_folders(root: str | os.PathLike, folders) -> None:
    """Make each folder of ``folders`` (relative paths) below ``root`` as the writer walks to it
    (no link followed): a batch checks its output folders before any work."""
    for rel in folders:
        os.close(_open_folder(Path(root), Path(rel).parts, create=True))


def remove_written(path: str | os.PathLike, *, root: str | os.PathLike) -> bool:
    """Delete ``path``, a file the caller proves it wrote (its name is one the caller itself
    gives), if it is a regular file reached from ``root`` through no link; anything else
    (a link, a folder, a device) is left alone. Returns whether a file was deleted."""
    root_dir, folders, name = _parts(Path(path), Path(root))
    try:
        dfd = _open_folder(root_dir, folders, create=False)
    except OutputError:
        return False
    if dfd is None:
        return False
    try:
        if not stat.S_ISREG(os.stat(name, dir_fd=dfd, follow_symlinks=False).st_mode):
            return False
        os.unlink(name, dir_fd=dfd)
        return True
    except FileNotFoundError:
        return False
    finally:
        os.close(dfd)


def open_inside(path: str | os.PathLike, max_bytes: int, *, root: str | os.PathLike):
    """Open ``path``, a file of the run's own state below ``root`` (a journal), for binary
    reading as :func:`open_regular` does, reached through no link; None if it is absent.
    A link on the way, no regular file or one over ``max_bytes``: :class:`MotionDataError`."""
    root_dir, folders, name = _parts(Path(path), Path(root))
    try:
        dfd = _open_folder(root_dir, folders, create=False)
    except OutputError as e:
        raise MotionDataError(e.path, None, e.problem) from None
    if dfd is None:
        return None
    try:
        flags = os.O_RDONLY | _NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | _CLOEXEC
        fd = os.open(name, flags, dir_fd=dfd)
    except FileNotFoundError:
        return None
    except OSError as e:
        try:
            what = _describe(os.stat(name, dir_fd=dfd, follow_symlinks=False).st_mode)
        except OSError:
            what = e.strerror or "unreadable"
        raise MotionDataError(str(path), None, f"cannot read: {what}") from None
    finally:
        os.close(dfd)
    return _checked(fd, str(path), max_bytes)


def _umask() -> int:
    os.umask(mask := os.umask(0))
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
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | _CLOEXEC
    try:
        fd = os.open(name, flags)
    except OSError as e:
        raise MotionDataError(str(name), None, f"cannot read file: {e.strerror or e}") from None
    return _checked(fd, str(name), max_bytes)


def _checked(fd: int, name: str, max_bytes: int):
    """The descriptor ``fd`` as a blocking binary file object if it is a regular file of at most
    ``max_bytes`` bytes; else it is closed and a :class:`MotionDataError` raised."""
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = next((w for test, w in _KINDS if test(st.st_mode)), "not a regular file")
            raise MotionDataError(name, None, f"not a regular file ({kind})")
        if st.st_size > max_bytes:
            raise MotionDataError(
                name, None, f"file of {st.st_size:,} bytes exceeds the limit of {max_bytes:,}"
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
