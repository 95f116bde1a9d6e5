"""Folder walks over input folders: iterative (a stack, never recursion), depth-limited, never
entering a link to a folder. Pure standard library."""

from __future__ import annotations

import os
from pathlib import Path

#: Folders nested deeper than this below the folder walked are not entered (and are reported).
MAX_DEPTH = 64
#: A walk stops at this many entries (a folder of millions of files is refused, not listed).
MAX_ENTRIES = 1 << 20


def walk(root: str | os.PathLike) -> tuple[list[Path], list[Path]]:
    """``(entries, too_deep)``: every entry below ``root`` that is not a real folder (files,
    links of any kind, FIFOs, devices: the caller decides), sorted; and the folders more than
    :data:`MAX_DEPTH` deep, not entered. A link to a folder is an entry, never entered; so is a
    folder that cannot be listed. Stops after :data:`MAX_ENTRIES` entries (``OverflowError``)."""
    entries: list[Path] = []
    too_deep: list[Path] = []
    stack = [(Path(root), 0)]
    seen = 0
    while stack:
        folder, depth = stack.pop()
        try:
            with os.scandir(folder) as it:
                for e in it:
                    seen += 1
                    if seen > MAX_ENTRIES:
                        raise OverflowError(f"{root}: over {MAX_ENTRIES:,} entries")
                    path = folder / e.name
                    try:
                        is_dir = e.is_dir(follow_symlinks=False)
                    except OSError:
                        is_dir = False
                    if not is_dir:
                        entries.append(path)
                    elif depth + 1 > MAX_DEPTH:
                        too_deep.append(path)
                    else:
                        stack.append((path, depth + 1))
        except OSError:
            if depth == 0:
                raise
    return sorted(entries), sorted(too_deep)
