"""Runs of AMC frames read by one compiled pass: the AMC reader's fast path
(:meth:`sim.acclaim.amc._AmcParser.feed`).

A run is ``T`` frames laid out exactly like the first frame of the file: a frame-number line
(ASCII digits, at most 12, blanks around them allowed, numbers following on from ``first``),
then one line per bone in the first frame's order, each the bone's name, then its values each
after one space (a bone without values: its name alone). :func:`read_run` converts such a run
in one pass over its text, every value with :func:`sim.decimals.number_at` (a strict decimal,
converted exactly: the double Python's ``float()`` gives); a run that is anything else (another
layout, character, number or spacing, a value it cannot convert exactly) gives None, and the
reader then reads it as it would without this pass (numpy's reader, then line by line), so what
the reader accepts, refuses and says does not change. Bounds are the caller's.
"""

from __future__ import annotations

import numba
import numpy as np

from sim.decimals import POW10, number_at

_SPACE, _TAB, _LF, _ZERO, _NINE = 32, 9, 10, 48, 57
_MAX_FRAME_DIGITS = 12


def read_run(lines: list[str], names: tuple[str, ...], counts: tuple[int, ...], first: int):
    """(T, sum(counts)) float64 values of the run of frames ``lines`` (frame-number line, one
    line per bone of ``names`` with ``counts`` values, frame after frame), its first frame
    numbered ``first``; or None (see the module docstring)."""
    L = len(names) + 1
    if len(lines) % L:
        return None
    text = "\n".join(lines)
    if not text.isascii():
        return None
    heads = [name + " " if k else name for name, k in zip(names, counts, strict=True)]
    ends = np.cumsum([len(h) for h in heads])
    out = np.empty((len(lines) // L, int(sum(counts))))
    ok = _read(
        np.frombuffer(text.encode("ascii"), dtype=np.uint8),
        np.frombuffer("".join(heads).encode("ascii"), dtype=np.uint8),
        np.concatenate([[0], ends]).astype(np.int64),
        np.array(counts, dtype=np.int64),
        first,
        out,
        POW10,
    )  # fmt: skip
    return out if ok else None


@numba.njit(cache=True, nogil=True)
def _frame_number(buf, pos, expected):
    """The frame-number line at ``pos``: (position of its line break or end, ok)."""
    n = buf.shape[0]
    while pos < n and (buf[pos] == _SPACE or buf[pos] == _TAB):
        pos += 1
    number, digits = 0, 0
    while pos < n and _ZERO <= buf[pos] <= _NINE:
        number = 10 * number + (buf[pos] - _ZERO)
        digits += 1
        pos += 1
    while pos < n and (buf[pos] == _SPACE or buf[pos] == _TAB):
        pos += 1
    ok = 0 < digits <= _MAX_FRAME_DIGITS and number == expected and (pos == n or buf[pos] == _LF)
    return pos, ok


@numba.njit(cache=True, nogil=True)
def _read(buf, heads, starts, counts, first, out, pow10):
    """Fill ``out`` (T, sum(counts)) from the run ``buf`` (uint8); False where it is not one."""
    T = out.shape[0]
    n = buf.shape[0]
    pos = 0
    for t in range(T):
        pos, ok = _frame_number(buf, pos, first + t)
        if not ok:
            return False
        col = 0
        for b in range(counts.shape[0]):
            if pos >= n:
                return False
            pos += 1  # the line break before the bone's line
            for k in range(starts[b], starts[b + 1]):
                if pos >= n or buf[pos] != heads[k]:
                    return False
                pos += 1
            for c in range(counts[b]):
                if c > 0:
                    if pos >= n or buf[pos] != _SPACE:
                        return False
                    pos += 1
                v, pos, ok = number_at(buf, pos, pow10)
                if not ok:
                    return False
                out[t, col] = v
                col += 1
            if pos < n and buf[pos] != _LF:
                return False
        if t < T - 1:
            if pos >= n or buf[pos] != _LF:
                return False
            pos += 1
    return pos == n
