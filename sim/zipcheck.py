"""Zip archives checked before any member is read (clip ``.npz`` files, policies and checkpoints):
the directory's members, names, methods and sizes against stated limits (zip bombs refused).

Pure standard library.
"""

from __future__ import annotations

import zipfile

from sim.errors import MotionDataError
from sim.files import excerpt


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
