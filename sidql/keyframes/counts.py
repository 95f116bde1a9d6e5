"""The keyframe count W: one rule for every method, command and the learned policy.

W counts both end frames of a clip, which are always keyframes, so the least W is
:data:`LEAST_W` = 2 (nothing left to choose) and the most the clip's N frames. A learned policy
chooses the W - 2 inner keyframes one decision at a time, so a training episode asks for at least
one decision: :data:`LEAST_LEARNED_W` = 3.

Words: in the library ``W`` is a count and ``keyframes`` an index array ((W,) int64 frame
indices, sorted, first 0 and last N - 1); on the command line ``-W/--keyframes`` is the count.

Light to import (no numpy): the command line checks W before it loads anything.
"""

from __future__ import annotations

from collections.abc import Iterable

from sim.errors import UsageError

#: The least keyframe count: the first and the last frame.
LEAST_W = 2

#: The least keyframe count a policy learns from: one keyframe to decide besides both ends.
LEAST_LEARNED_W = LEAST_W + 1


def check_counts(
    counts: Iterable[int], n_frames: int, *, least: int = LEAST_W, name: str = "W"
) -> None:
    """Refuse keyframe counts outside ``[least, n_frames]``.

    Args:
        counts: keyframe counts W (both ends included); n_frames: frames N per clip.
        least: :data:`LEAST_W`, or :data:`LEAST_LEARNED_W` for training.
        name: how the message names the value (``"W"``, or the option ``"--keyframes"``).

    Raises:
        UsageError: a count that is not an integer in range; the message names ``name``, the
            range and the values given.
    """
    counts = list(counts)
    bad = [w for w in counts if isinstance(w, bool) or not isinstance(w, int)
           or not least <= w <= n_frames]  # fmt: skip
    if bad or not counts:
        got = counts[0] if len(counts) == 1 else counts
        raise UsageError(f"{name} must be in [{least}, {n_frames}]; got {got}")
