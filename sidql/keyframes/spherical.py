"""The spherical chart of the keyframe problem (Zhang et al. 2024, eqs. 1, 6, 7).

The protocol uses 23 points of the CMU skeleton (:data:`POINTS`): the root and 22 bones (all ASF
bones except hands, fingers, thumbs and toes). Each bone is the vector from its parent point to its
own point, expressed in **CMU's native axes** (y up): with world axes z up,
``(x, y, z)_cmu = (x_w, z_w, -y_w)``. For a bone ``b = (x, y, z)`` in those axes::

    r = |b|,   theta = arccos(z / r) in [0, pi],   phi = atan2(y, x)

``phi`` is unwrapped along time, so it is continuous. Angular rates come from the bone's velocity
``(xd, yd, zd) = v_child - v_parent`` by the paper's equations (6)-(7)::

    theta_dot = (cos(theta) cos(phi) xd + cos(theta) sin(phi) yd - sin(theta) zd) / r
    phi_dot   = (-sin(phi) xd + cos(phi) yd) / (r sin(theta))

The chart's poles are the horizontal directions ``+-z_cmu`` (``-+y_w``).

**Pole behaviour**: there ``sin(theta) -> 0`` and ``phi`` loses meaning; we divide by
``max(sin(theta), SIN_EPS)`` so every rate stays finite (``|phi_dot| <= |v| / (r * SIN_EPS)``), and
``atan2(0, 0) = 0`` gives ``phi = 0`` on the pole itself. Positions rebuilt from the chart stay
exact at keyframes (``sin(theta)`` multiplies every ``phi`` term), but a huge ``phi_dot`` at a
keyframe near a pole makes the interpolating cubic in ``phi`` spin, so reconstruction near the
poles is poor; the error measure stays bounded because angle differences are wrapped to [-pi, pi).

Pure numpy. Units: metres, seconds, radians.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numba
import numpy as np

from sim.errors import MotionDataError, UsageError, require_type
from sim.files import excerpt
from sim.model.angles import wrap_angle
from sim.model.rotations import y_up_to_z_up, z_up_to_y_up
from sim.motion.clip import Clip

#: The 23 protocol points, root first, every parent before its children.
POINTS: tuple[str, ...] = (
    "root",
    "lhipjoint",
    "lfemur",
    "ltibia",
    "lfoot",
    "rhipjoint",
    "rfemur",
    "rtibia",
    "rfoot",
    "lowerback",
    "upperback",
    "thorax",
    "lowerneck",
    "upperneck",
    "head",
    "lclavicle",
    "lhumerus",
    "lradius",
    "lwrist",
    "rclavicle",
    "rhumerus",
    "rradius",
    "rwrist",
)

#: The 22 bones (every point but the root), in :data:`POINTS` order.
BONES: tuple[str, ...] = POINTS[1:]

#: Number of bones M in the error measure.
M_BONES = len(BONES)

#: Lower bound on ``sin(theta)`` in the ``phi`` rate (see the module docstring).
SIN_EPS = 1e-6

#: Chart (CMU, y up) axes <-> world (z up) axes: the one axis change of
#: :data:`sim.model.rotations.Y_UP_TO_Z_UP`.
world_to_chart = z_up_to_y_up
chart_to_world = y_up_to_z_up


@dataclass(frozen=True)
class SphericalSeries:
    """A clip in the spherical chart: N frames, M = 22 bones.

    Attributes:
        theta: (N, M) polar angle of each bone from the CMU z axis [rad], in [0, pi].
        phi: (N, M) azimuth in the CMU x-y plane [rad], unwrapped along time.
        dtheta: (N, M) d theta / dt [rad/s] (eq. 6).
        dphi: (N, M) d phi / dt [rad/s] (eq. 7, finite at the poles).
        root_pos: (N, 3) root position in CMU axes [m].
        root_vel: (N, 3) root velocity in CMU axes [m/s].
        lengths: (M,) bone lengths [m] (mean over frames).
        parents: (23,) parent of each point of :data:`POINTS` as an index into it (-1 for the root).
        dt: time between frames [s].
    """

    theta: np.ndarray
    phi: np.ndarray
    dtheta: np.ndarray
    dphi: np.ndarray
    root_pos: np.ndarray
    root_vel: np.ndarray
    lengths: np.ndarray
    parents: np.ndarray
    dt: float

    def __post_init__(self):
        N, M = self.theta.shape
        for name in ("phi", "dtheta", "dphi"):
            if getattr(self, name).shape != (N, M):
                raise UsageError(f"{name} must be ({N}, {M}); got {getattr(self, name).shape}")
        if self.root_pos.shape != (N, 3) or self.root_vel.shape != (N, 3):
            raise UsageError(f"root_pos and root_vel must be ({N}, 3)")
        if self.lengths.shape != (M,) or self.parents.shape != (M + 1,):
            raise UsageError(f"lengths must be ({M},) and parents ({M + 1},)")
        if not self.dt > 0:
            raise UsageError(f"dt must be positive; got {self.dt}")

    @property
    def n_frames(self) -> int:
        return int(self.theta.shape[0])

    @property
    def n_bones(self) -> int:
        return int(self.theta.shape[1])

    def frames(self, index) -> SphericalSeries:
        """The chart at frames ``index`` (a slice or an index array along time); bone lengths,
        parents and dt kept."""
        return replace(
            self,
            theta=self.theta[index],
            phi=self.phi[index],
            dtheta=self.dtheta[index],
            dphi=self.dphi[index],
            root_pos=self.root_pos[index],
            root_vel=self.root_vel[index],
        )

    def channels(self) -> tuple[np.ndarray, np.ndarray]:
        """The chart as flat channels: (N, 2 M + 3) values [theta | phi | root position] in
        [rad, rad, m] and (N, 2 M + 3) their rates [per s]; :func:`split_channels` undoes it."""
        values = np.concatenate([self.theta, self.phi, self.root_pos], axis=1)
        rates = np.concatenate([self.dtheta, self.dphi, self.root_vel], axis=1)
        return values, rates


def split_channels(x: np.ndarray, n_bones: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 2 M + 3) channels in :meth:`SphericalSeries.channels`'s order -> views (theta (N, M),
    phi (N, M), root (N, 3)); the same for their rates."""
    M = n_bones
    return x[:, :M], x[:, M : 2 * M], x[:, 2 * M :]


def protocol_parents(names, parents) -> np.ndarray:
    """(23,) parents of :data:`POINTS` as indices into POINTS, from a skeleton's names/parents.

    Raises:
        MotionDataError: a protocol point is missing or its parent is not a protocol point.
    """
    names = tuple(names)
    out = np.full(len(POINTS), -1, dtype=np.int64)
    for k, name in enumerate(POINTS):
        if name not in names:
            raise MotionDataError(
                None, None, f"skeleton lacks point {name!r}; the protocol needs {', '.join(POINTS)}"
            )
        if k == 0:
            continue
        parent = int(np.asarray(parents)[names.index(name)])
        pname = names[parent] if parent >= 0 else None
        if pname not in POINTS[:k]:
            problem = f"parent of {name!r} is {pname!r}, not a protocol point"
            raise MotionDataError(None, None, problem)
        out[k] = POINTS.index(pname)
    return out


def angles_and_rates(
    bones_c: np.ndarray, bone_vel_c: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Spherical angles (eq. 1) and their rates (eqs. 6-7) of bone vectors in CMU axes.

    Args:
        bones_c: (N, M, 3) bone vectors [m] in CMU axes.
        bone_vel_c: (N, M, 3) bone velocities [m/s] in CMU axes, or None.

    Returns:
        theta (N, M) [rad], phi (N, M) [rad] unwrapped along axis 0, and dtheta, dphi (N, M)
        [rad/s] (None when ``bone_vel_c`` is None).
    """
    x, y, z = bones_c[..., 0], bones_c[..., 1], bones_c[..., 2]
    r = np.linalg.norm(bones_c, axis=-1)
    r_safe = np.where(r > 0, r, 1.0)
    theta = np.arccos(np.clip(z / r_safe, -1.0, 1.0))
    phi = np.unwrap(np.arctan2(y, x), axis=0)
    if bone_vel_c is None:
        return theta, phi, None, None
    xd, yd, zd = bone_vel_c[..., 0], bone_vel_c[..., 1], bone_vel_c[..., 2]
    st, ct = np.sin(theta), np.cos(theta)
    sp, cp = np.sin(phi), np.cos(phi)
    dtheta = (ct * cp * xd + ct * sp * yd - st * zd) / r_safe
    dphi = (-sp * xd + cp * yd) / (r_safe * np.maximum(st, SIN_EPS))
    return theta, phi, dtheta, dphi


def directions(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """(..., 3) unit vectors in CMU axes for angles theta, phi [rad] of any shape (...)."""
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def direction_rates(
    theta: np.ndarray, phi: np.ndarray, dtheta: np.ndarray, dphi: np.ndarray
) -> np.ndarray:
    """(..., 3) time derivative [1/s] of :func:`directions` given angle rates [rad/s]."""
    st, ct = np.sin(theta), np.cos(theta)
    sp, cp = np.sin(phi), np.cos(phi)
    return np.stack(
        [
            ct * cp * dtheta - st * sp * dphi,
            ct * sp * dtheta + st * cp * dphi,
            -st * dtheta,
        ],
        axis=-1,
    )


@numba.njit(cache=True)
def _chart_kernel(P, V, parents, sin_eps):
    """Numba version of :func:`chart_arrays` (world-axes (N, J, 3) inputs)."""
    N, J, _ = P.shape
    M = J - 1
    theta = np.empty((N, M))
    phi = np.empty((N, M))
    dtheta = np.empty((N, M))
    dphi = np.empty((N, M))
    lengths = np.zeros(M)
    for m in range(M):
        c = m + 1
        p = parents[c]
        prev = 0.0
        for n in range(N):
            # chart axes: (x, y, z)_cmu = (x_w, z_w, -y_w)
            x = P[n, c, 0] - P[n, p, 0]
            y = P[n, c, 2] - P[n, p, 2]
            z = -(P[n, c, 1] - P[n, p, 1])
            xd = V[n, c, 0] - V[n, p, 0]
            yd = V[n, c, 2] - V[n, p, 2]
            zd = -(V[n, c, 1] - V[n, p, 1])
            rho = np.sqrt(x * x + y * y)
            r = np.sqrt(rho * rho + z * z)
            lengths[m] += r
            rs = r if r > 0.0 else 1.0
            t = np.arccos(min(1.0, max(-1.0, z / rs)))
            raw = np.arctan2(y, x)
            f = raw
            if n > 0:  # unwrap like numpy: steps of pi or more are taken modulo 2 pi
                d = raw - prev
                if abs(d) >= np.pi:
                    dm = wrap_angle(d)
                    if dm == -np.pi and d > 0:
                        dm = np.pi
                    d = dm
                f = phi[n - 1, m] + d
            prev = raw
            # sines and cosines from the components (the same as of the angles)
            st = min(rho / rs, 1.0)
            ct = min(1.0, max(-1.0, z / rs))
            if rho > 0.0:
                sp = y / rho
                cp = x / rho
            else:
                sp = 0.0
                cp = 1.0
            theta[n, m] = t
            phi[n, m] = f
            dtheta[n, m] = (ct * cp * xd + ct * sp * yd - st * zd) / rs
            dphi[n, m] = (-sp * xd + cp * yd) / (rs * max(st, sin_eps))
        lengths[m] /= N
    return theta, phi, dtheta, dphi, lengths


def chart_arrays(
    positions_w: np.ndarray,
    velocities_w: np.ndarray,
    parents: np.ndarray,
    dt: float,
) -> SphericalSeries:
    """The chart of 23-point arrays already in :data:`POINTS` order.

    Args:
        positions_w: (N, 23, 3) point positions [m], world axes (z up).
        velocities_w: (N, 23, 3) point velocities [m/s], world axes.
        parents: (23,) parent indices into POINTS (-1 for the root).
        dt: time between frames [s].
    """
    parents = np.asarray(parents, dtype=np.int64)
    P = np.ascontiguousarray(positions_w, dtype=np.float64)
    V = np.ascontiguousarray(velocities_w, dtype=np.float64)
    theta, phi, dtheta, dphi, lengths = _chart_kernel(P, V, parents, SIN_EPS)
    return SphericalSeries(
        theta=theta,
        phi=phi,
        dtheta=dtheta,
        dphi=dphi,
        root_pos=world_to_chart(P[:, 0]),
        root_vel=world_to_chart(V[:, 0]),
        lengths=lengths,
        parents=parents,
        dt=float(dt),
    )


def protocol_indices(clip: Clip) -> np.ndarray:
    """(23,) indices of :data:`POINTS` in ``clip.names``; MotionDataError naming a missing point."""
    missing = [p for p in POINTS if p not in clip.names]
    if missing:
        raise MotionDataError(
            clip.source or None,
            None,
            f"clip lacks protocol point(s) {', '.join(missing)}; known: "
            f"{excerpt(', '.join(clip.names), 300, quote=False)}",
        )
    return np.array([clip.names.index(p) for p in POINTS], dtype=np.int64)


@functools.lru_cache(maxsize=64)
def _skeleton_maps(names: tuple[str, ...], parents: tuple[int, ...]):
    idx = np.array([names.index(p) for p in POINTS], dtype=np.int64)
    return idx, protocol_parents(names, np.array(parents))


def protocol_maps(clip: Clip) -> tuple[np.ndarray, np.ndarray]:
    """(23,) indices of :data:`POINTS` in ``clip.names`` and (23,) their parents as indices into
    POINTS, cached per skeleton (a clip costs a look-up; treat both as read-only).

    Raises:
        MotionDataError: a protocol point is missing (the message names it).
    """
    try:
        return _skeleton_maps(tuple(clip.names), tuple(clip.parents.tolist()))
    except MotionDataError as e:
        raise MotionDataError(clip.source or None, None, e.problem) from None
    except ValueError:  # a protocol point is missing
        protocol_indices(clip)  # a clear error naming it
        raise


def chart_points_of(clip: Clip) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The protocol points of a clip as the chart kernel takes them: (N, 23, 3) positions [m] and
    velocities [m/s] (world axes, contiguous float64) and (23,) parents, checked as
    :func:`chart` checks them.

    Raises:
        MotionDataError: a protocol point is missing, or the data holds non-finite values.
    """
    idx, parents = protocol_maps(clip)
    pos = np.ascontiguousarray(clip.positions[:, idx], dtype=np.float64)
    vel = np.ascontiguousarray(clip.velocities[:, idx], dtype=np.float64)
    if not (np.isfinite(pos).all() and np.isfinite(vel).all()):
        raise MotionDataError(clip.source or None, None, "non-finite positions or velocities")
    return pos, vel, parents.copy()  # the cached array stays private


def chart(clip: Clip) -> SphericalSeries:
    """The spherical chart of a clip's 23 protocol points (see the module docstring).

    Args:
        clip: any clip whose names include :data:`POINTS` (extra points are ignored).

    Returns:
        A :class:`SphericalSeries` with N = clip.n_frames, M = 22, dt = clip.dt [s].

    Raises:
        MotionDataError: a protocol point is missing, or the data holds non-finite values.
        ArgumentTypeError: ``clip`` is not a :class:`Clip`.
    """
    require_type(clip, Clip, "clip")
    pos, vel, parents = chart_points_of(clip)
    return chart_arrays(pos, vel, parents, clip.dt)


def protocol_parent_indices() -> np.ndarray:
    """(23,) parents of :data:`POINTS` in the CMU skeleton, as indices into POINTS."""
    return np.array([-1] + [POINTS.index(_CMU_PARENT[p]) for p in POINTS[1:]], dtype=np.int64)


_CMU_PARENT = {
    "lhipjoint": "root",
    "lfemur": "lhipjoint",
    "ltibia": "lfemur",
    "lfoot": "ltibia",
    "rhipjoint": "root",
    "rfemur": "rhipjoint",
    "rtibia": "rfemur",
    "rfoot": "rtibia",
    "lowerback": "root",
    "upperback": "lowerback",
    "thorax": "upperback",
    "lowerneck": "thorax",
    "upperneck": "lowerneck",
    "head": "upperneck",
    "lclavicle": "thorax",
    "lhumerus": "lclavicle",
    "lradius": "lhumerus",
    "lwrist": "lradius",
    "rclavicle": "thorax",
    "rhumerus": "rclavicle",
    "rradius": "rhumerus",
    "rwrist": "rradius",
}
