"""Reconstructions: how a receiver rebuilds a clip from its keyframes, in one registry.

A reconstruction is a :class:`Reconstruction` value (the 23 protocol points, ready to replay) and
a way to build it, registered here by name. Each declares, in one place:

* ``rebuild(clip, keyframes, series=None) -> Reconstruction``: its interpolation (``series``: the
  clip's chart when the caller already has it);
* ``payload_bytes``: what one transmitted keyframe costs (float32 values plus a one-byte index);
* ``cost_matrix(series) -> (N, N)``: its segment-cost kernel, when Q separates over segments;
* ``optimum(series, w_max=W) -> table``: the exact minimiser of its Q for every W up to ``w_max``
  (a table with ``.keyframes(W)`` and ``.q(W)``), where one exists.

The registered reconstructions:

``hermite``, ``linear``, ``catmull_rom`` (the spherical ones)
    one curve of :mod:`sidql.keyframes.curves` per bone angle (theta, phi) and root coordinate
    between keyframes, then the points rebuilt down the tree with the fixed bone lengths, so
    every bone keeps its length exactly. ``hermite`` is the paper's (eqs. 9-13).
``slerp``
    Li et al. 2015: local rotations slerped, root linear (:func:`sidql.keyframes.pitch.slerp_points`).
``cartesian``
    every point on its own cubic Hermite in xyz (bone lengths not kept): the worked example of
    adding one.
``contacts``
    ``hermite`` plus per-frame foot-contact bits (run-length coded side information, counted in
    :attr:`Reconstruction.side_bytes`); the receiver pins each foot in contact where it touched
    down by analytic two-bone IK (:mod:`sidql.keyframes.contact_pinning`).

Adding a reconstruction = one function + one :func:`register` call + its test; :mod:`evaluate
<sidql.evaluation.evaluate>`, :mod:`rate <sidql.evaluation.rate>` and :mod:`validation
<sidql.evaluation.validation>` pick it up from here. A keyframe method names the reconstruction it is
meant for when it registers (:func:`sidql.keyframes.methods.register`; ``pitch`` -> ``slerp``,
every other -> ``hermite``).

Pure numpy. Units: metres, seconds, radians; positions in world axes (z up).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from sidql.keyframes import pitch
from sidql.keyframes.curves import check_curve, interpolate_derivatives, validate_keyframes
from sidql.keyframes.optimal import catmull_rom_optimal, optimal_table
from sidql.keyframes.segment_costs import segment_cost_matrix
from sidql.keyframes.spherical import (
    M_BONES,
    POINTS,
    SphericalSeries,
    angles_and_rates,
    chart,
    protocol_indices,
    protocol_parent_indices,
    split_channels,
    world_to_chart,
)
from sidql.keyframes.unchart import accelerations_from_chart, positions_from_chart
from sim.errors import UnknownNameError
from sim.motion.clip import Clip
from sim.motion.points import PointMotion

FLOAT_BYTES = 4
INDEX_BYTES = 1
#: Floats of one spherical pose: M (theta, phi) pairs and the root position.
POSE_FLOATS = 2 * M_BONES + 3


@dataclass(frozen=True, kw_only=True)
class Reconstruction(PointMotion):
    """A clip rebuilt from keyframes: the 23 protocol points, ready to replay (a
    :class:`~sim.motion.points.PointMotion`, so replay and render take it as it is).

    Attributes (besides the point motion's names, parents, positions, fps, velocities):
        positions: (N, 23, 3) point positions [m], world axes (z up).
        velocities: (N, 23, 3) point velocities [m/s], world axes (derivative of the curves).
        names: (23,) point names (:data:`sidql.keyframes.spherical.POINTS`); parents: (23,).
        theta: (N, 22) polar angles [rad] of the rebuilt bones; phi: (N, 22) azimuths [rad].
        keyframes: (W,) keyframe indices used.
        reconstruction: the name it was rebuilt by (a key of :data:`RECONSTRUCTIONS`).
        accelerations: (N, 23, 3) point accelerations [m/s^2], world axes, from the curves
            themselves (:func:`~sidql.keyframes.curves.interpolate_derivatives`: at an inner
            keyframe the mean over the frame's interval); None where a reconstruction does not
            provide them.
        side_bytes: bytes sent per clip beside the keyframes (``contacts``: its contact runs).
    """

    theta: np.ndarray
    phi: np.ndarray
    keyframes: np.ndarray
    reconstruction: str
    accelerations: np.ndarray | None = None
    side_bytes: int = 0

    @property
    def dt(self) -> float:
        """Frame interval [s]."""
        return 1.0 / self.fps


def points_reconstruction(
    positions: np.ndarray,
    velocities: np.ndarray,
    parents: np.ndarray,
    keyframes: np.ndarray,
    reconstruction: str,
    fps: float,
    accelerations: np.ndarray | None = None,
    side_bytes: int = 0,
) -> Reconstruction:
    """A reconstruction rebuilt as points rather than in the chart (``slerp``, ``cartesian``):
    the 23 protocol points' positions (N, 23, 3) [m], velocities [m/s] and accelerations
    [m/s^2], world axes (z up), with their (23,) ``parents``; its bones' theta/phi (N, 22) [rad]
    are measured from the points."""
    child = np.arange(1, len(parents))
    bones = positions[:, child] - positions[:, parents[child]]
    theta, phi, _, _ = angles_and_rates(world_to_chart(bones))
    return Reconstruction(
        positions=positions,
        velocities=velocities,
        names=POINTS,
        parents=parents.copy(),
        theta=theta,
        phi=phi,
        keyframes=keyframes,
        reconstruction=reconstruction,
        fps=fps,
        accelerations=accelerations,
        side_bytes=side_bytes,
    )


def reconstruct_series(
    series: SphericalSeries, keyframes, curve: str = "hermite"
) -> Reconstruction:
    """A chart rebuilt from its keyframes by one curve per coordinate (the spherical
    reconstructions: the module docstring).

    Args:
        series: the true motion's chart (N frames, M bones).
        keyframes: (W,) strictly increasing indices from 0 to N-1.
        curve: one of :data:`sidql.keyframes.curves.CURVES` (the reconstruction of that name).
    """
    check_curve(curve)
    k = validate_keyframes(keyframes, series.n_frames)
    M = series.n_bones
    values, rates = series.channels()
    x, xd, xdd = interpolate_derivatives(values, rates, k, series.dt, curve)
    theta, phi, root = split_channels(x, M)
    dtheta, dphi, root_vel = split_channels(xd, M)
    ddtheta, ddphi, root_acc = split_channels(xdd, M)
    P, V = positions_from_chart(
        root, root_vel, theta, phi, dtheta, dphi, series.lengths, series.parents
    )
    A = accelerations_from_chart(
        root_acc, theta, phi, dtheta, dphi, ddtheta, ddphi, series.lengths, series.parents
    )
    return Reconstruction(
        positions=P,
        velocities=V,
        names=POINTS,
        parents=series.parents.copy(),
        theta=theta,
        phi=phi,
        keyframes=k,
        reconstruction=curve,
        fps=1.0 / series.dt,
        accelerations=A,
    )


Rebuild = Callable[..., Reconstruction]


@dataclass(frozen=True)
class ReconstructionSpec:
    """What one registered reconstruction declares (see the module docstring); ``exact_keyframes``:
    every point of every keyframe is the original's (False: ``contacts``, whose fades and lifts
    may move a leg at a keyframe near a contact change)."""

    name: str
    rebuild: Rebuild
    payload_bytes: int
    cost_matrix: Callable[[SphericalSeries], np.ndarray] | None = None
    optimum: Callable[[SphericalSeries, int], object] | None = None
    exact_keyframes: bool = True


#: name -> :class:`ReconstructionSpec`, in registration order.
RECONSTRUCTIONS: dict[str, ReconstructionSpec] = {}


def register(
    name: str,
    *,
    payload_floats: int,
    cost_matrix: Callable[[SphericalSeries], np.ndarray] | None = None,
    optimum: Callable[[SphericalSeries, int], object] | None = None,
    exact_keyframes: bool = True,
) -> Callable[[Rebuild], Rebuild]:
    """Decorator registering ``rebuild(clip, keyframes, series=None)`` as reconstruction ``name``
    whose keyframe carries ``payload_floats`` float32 values (plus the one-byte frame index)."""

    def deco(fn: Rebuild) -> Rebuild:
        RECONSTRUCTIONS[name] = ReconstructionSpec(
            name, fn, payload_floats * FLOAT_BYTES + INDEX_BYTES, cost_matrix, optimum,
            exact_keyframes,
        )  # fmt: skip
        return fn

    return deco


def get(name: str) -> ReconstructionSpec:
    """The reconstruction registered as ``name``; UnknownNameError lists the known ones."""
    try:
        return RECONSTRUCTIONS[name]
    except KeyError:
        raise UnknownNameError("reconstruction", name, RECONSTRUCTIONS) from None


def rebuild(name: str, clip: Clip, keyframes, series: SphericalSeries | None = None):
    """``clip`` rebuilt from ``keyframes`` by reconstruction ``name`` (a :class:`Reconstruction`)."""
    return get(name).rebuild(clip, keyframes, series)


def reconstruct(clip: Clip, keyframes, reconstruction: str = "hermite") -> Reconstruction:
    """``clip``'s 23 protocol points rebuilt from its keyframes.

    Args:
        clip: the true motion (names must include :data:`sidql.keyframes.spherical.POINTS`).
        keyframes: (W,) strictly increasing indices from 0 to clip.n_frames - 1.
        reconstruction: a name in :data:`RECONSTRUCTIONS` (default: the paper's).

    Returns:
        A :class:`Reconstruction`: positions/velocities (N, 23, 3) world z-up [m, m/s].
    """
    return rebuild(reconstruction, clip, keyframes)


def _chart(clip: Clip, series: SphericalSeries | None) -> SphericalSeries:
    return chart(clip) if series is None else series


@register(
    "hermite",  # pose and rates (the paper's eqs. 9-13)
    payload_floats=2 * POSE_FLOATS,
    cost_matrix=partial(segment_cost_matrix, reconstruction="hermite"),
    optimum=partial(optimal_table, reconstruction="hermite"),
)
def hermite(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """Per bone cubic Hermite in (theta, phi) with the transmitted rates; root the same in xyz."""
    return reconstruct_series(_chart(clip, series), keyframes, "hermite")


@register(
    "linear",  # pose only
    payload_floats=POSE_FLOATS,
    cost_matrix=partial(segment_cost_matrix, reconstruction="linear"),
    optimum=partial(optimal_table, reconstruction="linear"),
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
    """Li et al. 2015: local rotations slerped, root linear (:func:`sidql.keyframes.pitch.slerp_points`);
    23 quaternions and the root position per keyframe."""
    k = validate_keyframes(keyframes, clip.n_frames)
    P, V, A, parents = pitch.slerp_points(clip, k)
    return points_reconstruction(P, V, parents, k, "slerp", clip.fps, A)


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


@register("contacts", payload_floats=2 * POSE_FLOATS, exact_keyframes=False)
def contacts(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """``hermite`` with the sender's foot-contact bits (run-length coded, their bytes in
    ``side_bytes``): each foot in contact pinned where it touched down by two-bone IK
    (:func:`sidql.keyframes.contact_pinning.rebuild`)."""
    # imported on first use: the sender's contact labels stand on sim.physics (MuJoCo)
    return importlib.import_module("sidql.keyframes.contact_pinning").rebuild(
        clip, keyframes, series
    )
