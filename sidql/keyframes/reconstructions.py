"""The one registry of reconstructions: how a receiver rebuilds a clip from its keyframes.

Each variant declares, in one place:

* ``rebuild(clip, keyframes, series=None) -> Reconstruction``: its interpolation (``series``: the
  clip's chart when the caller already has it);
* ``payload_bytes``: what one transmitted keyframe costs (float32 values plus a one-byte index);
* ``cost_matrix(series) -> (N, N)``: its segment-cost kernel, when Q separates over segments;
* ``optimum(series, w_max=W) -> table``: the exact minimiser of its Q for every W up to ``w_max``
  (a table with ``.keyframes(W)`` and ``.q(W)``), where one exists.

Adding a variant = one function + one :func:`register` call + its test; :mod:`evaluate
<sidql.evaluation.evaluate>`, :mod:`rate <sidql.evaluation.rate>` and :mod:`report
<sidql.evaluation.report>` pick it up from here. ``cartesian`` below is the worked example.

A keyframe method names the reconstruction it is meant for when it registers
(:func:`sidql.keyframes.methods.register`; ``pitch`` -> ``slerp``, every other -> ``hermite``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from sidql.keyframes import pitch
from sidql.keyframes.optimal import catmull_rom_optimal, optimal_table
from sidql.keyframes.reconstruct import (
    Reconstruction,
    interpolate_derivatives,
    points_reconstruction,
    reconstruct_series,
    validate_keyframes,
)
from sidql.keyframes.segment_costs import segment_cost_matrix
from sidql.keyframes.spherical import (
    M_BONES,
    POINTS,
    SphericalSeries,
    chart,
    protocol_indices,
    protocol_parent_indices,
)
from sim.motion.clip import Clip

FLOAT_BYTES = 4
INDEX_BYTES = 1
#: Floats of one spherical pose: M (theta, phi) pairs and the root position.
POSE_FLOATS = 2 * M_BONES + 3

Rebuild = Callable[..., Reconstruction]


@dataclass(frozen=True)
class Variant:
    """One reconstruction (see the module docstring)."""

    name: str
    rebuild: Rebuild
    payload_bytes: int
    cost_matrix: Callable[[SphericalSeries], np.ndarray] | None = None
    optimum: Callable[[SphericalSeries, int], object] | None = None


#: name -> :class:`Variant`, in registration order.
VARIANTS: dict[str, Variant] = {}


def register(
    name: str,
    *,
    payload_floats: int,
    cost_matrix: Callable[[SphericalSeries], np.ndarray] | None = None,
    optimum: Callable[[SphericalSeries, int], object] | None = None,
) -> Callable[[Rebuild], Rebuild]:
    """Decorator registering ``rebuild(clip, keyframes, series=None)`` as variant ``name`` whose
    keyframe carries ``payload_floats`` float32 values (plus the one-byte frame index)."""

    def deco(fn: Rebuild) -> Rebuild:
        VARIANTS[name] = Variant(
            name, fn, payload_floats * FLOAT_BYTES + INDEX_BYTES, cost_matrix, optimum
        )
        return fn

    return deco


def get(name: str) -> Variant:
    """The variant registered as ``name``; ValueError lists the known ones."""
    try:
        return VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown reconstruction {name!r}; known: {', '.join(VARIANTS)}") from None


def rebuild(name: str, clip: Clip, keyframes, series: SphericalSeries | None = None):
    """``clip`` rebuilt from ``keyframes`` by variant ``name`` (a :class:`Reconstruction`)."""
    return get(name).rebuild(clip, keyframes, series)


def reconstruct(clip: Clip, keyframes, variant: str = "hermite") -> Reconstruction:
    """``clip`` rebuilt from ``keyframes`` by any registered variant (default: the paper's)."""
    return rebuild(variant, clip, keyframes)


def _chart(clip: Clip, series: SphericalSeries | None) -> SphericalSeries:
    return chart(clip) if series is None else series


@register(
    "hermite",  # pose and rates (the paper's eqs. 9-13)
    payload_floats=2 * POSE_FLOATS,
    cost_matrix=partial(segment_cost_matrix, variant="hermite"),
    optimum=partial(optimal_table, variant="hermite"),
)
def hermite(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """Per bone cubic Hermite in (theta, phi) with the transmitted rates; root the same in xyz."""
    return reconstruct_series(_chart(clip, series), keyframes, "hermite")


@register(
    "linear",  # pose only
    payload_floats=POSE_FLOATS,
    cost_matrix=partial(segment_cost_matrix, variant="linear"),
    optimum=partial(optimal_table, variant="linear"),
)
def linear(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """Straight lines in (theta, phi) and root xyz between keyframes."""
    return reconstruct_series(_chart(clip, series), keyframes, "linear")


@register("catmull_rom", payload_floats=POSE_FLOATS, optimum=catmull_rom_optimal)
def catmull_rom(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """Cubic Hermite with rates estimated from neighbouring keyframes (pose only). Q does not
    separate over segments, so no (N, N) kernel; its optimum is a DP over keyframe triples."""
    return reconstruct_series(_chart(clip, series), keyframes, "catmull_rom")


@register("slerp", payload_floats=len(POINTS) * 4 + 3)
def slerp(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """Li et al. 2015: local rotations slerped, root linear (:func:`sidql.keyframes.pitch.reconstruct`);
    23 quaternions and the root position per keyframe."""
    return pitch.reconstruct(clip, keyframes)


@register("cartesian", payload_floats=2 * 3 * len(POINTS))
def cartesian(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """Every protocol point on its own cubic Hermite in xyz between keyframes, matching the
    keyframes' positions and point velocities (23 positions and velocities per keyframe).

    Exact for motion that is cubic in xyz between keyframes; bone lengths are NOT kept (a point
    on a rotating bone cuts the chord), the baseline the physics work measures drift against.
    """
    idx = protocol_indices(clip)
    N = clip.n_frames
    k = validate_keyframes(keyframes, N)
    pos = clip.positions[:, idx].reshape(N, -1)
    vel = clip.velocities[:, idx].reshape(N, -1)
    P, V, A = interpolate_derivatives(pos, vel, k, clip.dt, "hermite")
    P, V, A = (x.reshape(N, len(POINTS), 3) for x in (P, V, A))
    return points_reconstruction(P, V, protocol_parent_indices(), k, "cartesian", clip.fps, A)
