"""Tokens of an Acclaim line as numbers, and name lists for error messages: what the ASF and AMC
readers share."""

from __future__ import annotations

import math
import re

import numpy as np

from sim.errors import MotionDataError
from sim.files import excerpt


def known_names(names, chars: int = 300) -> str:
    """``names`` for an error message: as many as fit in about ``chars`` characters, then how
    many there are in all (a hostile skeleton may have a thousand names of 64 characters)."""
    names = list(names)
    shown, size = [], 0
    for name in names:
        if size + len(name) > chars:
            return ", ".join(shown) + f", ... ({len(names)} in all)"
        shown.append(name)
        size += len(name) + 2
    return ", ".join(shown)


#: A number as Acclaim files spell them: ASCII decimal digits, an optional sign, point and
#: exponent (Python's float() would also take ``1_0_8``, non-ASCII digits, ``0x``-less words).
_NUMBER_RE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")


def float_list(
    tokens: list[str], path: str, line: int, what: str, bound: float | list | None = None
) -> list[float]:
    """Finite numbers of ``tokens``, each ASCII decimal (:data:`_NUMBER_RE`) and at most
    ``bound`` (one for all, or one per token) in magnitude. Plain Python: this runs once per line on the checked AMC path."""
    bad = next((t for t in tokens if not _NUMBER_RE.match(t)), None)
    if bad is not None and not (is_float(bad) and not math.isfinite(float(bad))):
        raise MotionDataError(path, line, f"non-numeric value {excerpt(bad)} in {what}")
    values = [float(t) for t in tokens]  # nan and inf: refused below as non-finite
    bounds = [bound] * len(values) if bound is None or isinstance(bound, (int, float)) else bound
    for t, v, b in zip(tokens, values, bounds, strict=True):
        if not math.isfinite(v):
            raise MotionDataError(path, line, f"non-finite value {excerpt(t)} in {what}")
        if b is not None and abs(v) > b:
            raise MotionDataError(
                path, line, f"value {excerpt(t, quote=False)} in {what} exceeds {b:g} in magnitude"
            )
    return values


def floats(
    tokens: list[str], path: str, line: int, what: str, bound: float | None = None
) -> np.ndarray:
    """:func:`float_list` as an array."""
    return np.array(float_list(tokens, path, line, what, bound), dtype=np.float64)


def is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True
