"""One encoding of a trial (:class:`Encoded`) and how its error is measured: Q of the decoded
chart, eq. 18, keyframes included (so quantisation error counts).

Units: radians, bytes per second, millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass

from sidql.codec import format as sidq
from sidql.codec.decode import decoded_chart
from sidql.keyframes.metrics import q_from_angles
from sidql.keyframes.spherical import SphericalSeries, split_channels


@dataclass(frozen=True)
class Encoded:
    """One encoding.

    Attributes:
        stream: the container; data: its bytes.
        q: measured Q [rad] of the decoded chart (eq. 18, keyframes included).
        bytes_per_second: ``len(data)`` over the trial's duration ``N / fps`` [B/s].
        candidates: "reconstruction/bits" -> (q, bytes) of every encoding tried.
        mean_error_mm, p95_error_mm: mean and 95th percentile of the decoded points' Euclidean
            error [mm] against the chart's points (all points, all frames).
    """

    stream: sidq.Stream
    data: bytes
    q: float
    bytes_per_second: float
    candidates: dict
    mean_error_mm: float = float("nan")
    p95_error_mm: float = float("nan")


def measure(series: SphericalSeries, stream: sidq.Stream) -> float:
    """Q [rad] of ``stream`` decoded, against the true chart ``series`` (eq. 18)."""
    theta, phi, _ = split_channels(decoded_chart(stream)["values"], series.n_bones)
    return q_from_angles(series, theta, phi)


def where_prefix(where: str, problem: str) -> str:
    """``problem`` prefixed with the trial it is about (when known)."""
    return f"{where}: {problem}" if where else problem
