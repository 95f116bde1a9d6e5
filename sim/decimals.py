"""Tables of plain ASCII decimal numbers parsed by a compiled loop: the motion readers' fast path
(:mod:`sim.acclaim.amc`, :mod:`sim.bvh.reader`).

A table is lines of text (one ``\\n`` between lines, none after the last), each ``skip`` bytes
(e.g. a bone's name and its space, already checked by the caller) then ``C`` numbers separated
by blanks (spaces, tabs). :func:`parse_table` takes only what it can convert exactly:

- each number a strict decimal, ``[+-]?([0-9]+(\\.[0-9]*)?|\\.[0-9]+)([eE][+-]?[0-9]+)?`` (the
  readers' own grammar), of at most 18 digits;
- its value ``m x 10^p`` with the integer ``m <= 2^53`` and ``|p| <= 22`` (else 0): ``m`` and
  ``10^|p|`` are then exact doubles, and one IEEE multiplication or division of the two is the
  correctly rounded value of the decimal, the same double Python's ``float()`` and numpy's
  reader give (Clinger's fast path);
- exactly ``C`` numbers on each of the table's lines.

Anything else (another character, a longer number, a line with more or fewer numbers) makes it
return None: the caller then reads the table as it did without it, so what a reader accepts,
refuses and says about a malformed file does not change. Nothing here checks bounds or line
numbers; the callers do.
"""

from __future__ import annotations

import numba
import numpy as np

#: 10^0 .. 10^22: every one an exact double.
POW10 = np.array([10.0**k for k in range(23)])
_SPACE, _TAB, _LF, _PLUS, _MINUS, _POINT, _ZERO, _NINE = 32, 9, 10, 43, 45, 46, 48, 57
_LOWER_E, _UPPER_E = 101, 69
_MAX_DIGITS = 18
_EXACT = 2**53


def parse_table(text: str, rows: int, columns: int, skip: int = 0) -> np.ndarray | None:
    """(rows, columns) float64 of the table ``text`` (see the module docstring), or None when
    it is not one this parser converts exactly."""
    if not text.isascii():
        return None
    out = np.empty((rows, columns))
    ok = _parse(np.frombuffer(text.encode("ascii"), dtype=np.uint8), skip, out, POW10)
    return out if ok else None


@numba.njit(cache=True, nogil=True, inline="always")
def _blank(c):
    return c == _SPACE or c == _TAB


@numba.njit(cache=True, nogil=True, inline="always")
def number_at(buf, pos, pow10):
    """The number at ``buf[pos]``: (value, position after it, ok)."""
    n = buf.shape[0]
    c = buf[pos] if pos < n else 0
    neg = c == _MINUS
    if c == _PLUS or c == _MINUS:
        pos += 1
    m, digits, p = 0, 0, 0
    while pos < n and _ZERO <= buf[pos] <= _NINE:
        m = 10 * m + (buf[pos] - _ZERO)
        digits += 1
        pos += 1
    if pos < n and buf[pos] == _POINT:
        pos += 1
        while pos < n and _ZERO <= buf[pos] <= _NINE:
            m = 10 * m + (buf[pos] - _ZERO)
            digits += 1
            p -= 1
            pos += 1
    if digits == 0 or digits > _MAX_DIGITS:
        return 0.0, pos, False
    c = buf[pos] if pos < n else _LF
    if c == _LOWER_E or c == _UPPER_E:
        pos += 1
        c = buf[pos] if pos < n else 0
        eneg = c == _MINUS
        if c == _PLUS or c == _MINUS:
            pos += 1
        e, edigits = 0, 0
        while pos < n and _ZERO <= buf[pos] <= _NINE:
            if e < 100000:
                e = 10 * e + (buf[pos] - _ZERO)
            edigits += 1
            pos += 1
        if edigits == 0:
            return 0.0, pos, False
        p += -e if eneg else e
        c = buf[pos] if pos < n else _LF
    if not (c == _SPACE or c == _TAB or c == _LF):
        return 0.0, pos, False
    if m == 0:
        v = 0.0
    elif m > _EXACT or p < -22 or p > 22:
        return 0.0, pos, False
    elif p < 0:
        v = m / pow10[-p]
    else:
        v = m * pow10[p]
    return (-v if neg else v), pos, True


@numba.njit(cache=True, nogil=True)
def _parse(buf, skip, out, pow10):
    """Fill ``out`` (T, C) from the table ``buf`` (uint8); False where it is not one."""
    T, C = out.shape
    n = buf.shape[0]
    pos = 0
    for t in range(T):
        pos += skip
        for c in range(C):
            while pos < n and _blank(buf[pos]):
                pos += 1
            v, pos, ok = number_at(buf, pos, pow10)
            if not ok:
                return False
            out[t, c] = v
        while pos < n and _blank(buf[pos]):
            pos += 1
        if t < T - 1:
            if pos >= n or buf[pos] != _LF:
                return False
            pos += 1
    return pos == n
