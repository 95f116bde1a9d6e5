"""A point set moving over time: the one container of positions that replay, render and the
reconstructions share (a :class:`~sidql.keyframes.reconstructions.Reconstruction` is one).

Pure numpy (no MuJoCo). Units: metres, seconds; world z up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sim.errors import UnknownNameError, UsageError


def finite_velocity(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ..., 3) central-difference velocity [m/s] of ``positions`` (T, ..., 3) [m] (one-sided at
    the ends; zero for a single frame)."""
    if positions.shape[0] < 2:
        return np.zeros_like(positions)
    return np.gradient(positions, 1.0 / fps, axis=0)


@dataclass(frozen=True)
class PointMotion:
    """Positions of a point set over time: what every replay check consumes.

    Attributes:
        names: (P,) point names (root first).
        parents: (P,) parent index, -1 for the root.
        positions: (T, P, 3) [m], z up.
        fps: frames per second [1/s].
        velocities: (T, P, 3) [m/s] if the motion knows them exactly, else ``None`` (finite
            differences of ``positions`` are used).
        qpos: (T, 7 + H) joint angles (free root, then hinges [rad]) if the motion maps to them.
        joint_names: (H,) hinge names for ``qpos[:, 7:]``.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    positions: np.ndarray
    fps: float
    velocities: np.ndarray | None = None
    qpos: np.ndarray | None = None
    joint_names: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self):
        T, P = self.positions.shape[:2]
        if self.positions.shape != (T, P, 3):
            raise UsageError(f"positions must be (T, P, 3); got {self.positions.shape}")
        if len(self.names) != P or np.shape(self.parents) != (P,):
            raise UsageError(f"names and parents must have P={P} entries")
        if self.velocities is not None and self.velocities.shape != (T, P, 3):
            raise UsageError(f"velocities must be {(T, P, 3)}; got {self.velocities.shape}")
        if self.qpos is not None and (
            self.qpos.shape[0] != T or self.qpos.shape[1] != 7 + len(self.joint_names)
        ):
            raise UsageError(
                f"qpos must be (T, 7 + {len(self.joint_names)}); got {self.qpos.shape}"
            )
        if self.fps <= 0:
            raise UsageError(f"fps must be positive; got {self.fps}")

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    def velocity(self) -> np.ndarray:
        """(T, P, 3) [m/s]: the exact velocities if known, else central differences."""
        if self.velocities is not None:
            return self.velocities
        return finite_velocity(self.positions, self.fps)

    def restrict(self, names) -> PointMotion:
        """The same motion on the points ``names`` (a subset, any order with parents first); each
        point's parent becomes its nearest ancestor in the subset."""
        idx = []
        for n in names:
            if n not in self.names:
                raise UnknownNameError("point", n, self.names)
            idx.append(self.names.index(n))
        where = {j: k for k, j in enumerate(idx)}
        parents = []
        for j in idx:
            p = int(self.parents[j])
            while p >= 0 and p not in where:
                p = int(self.parents[p])
            parents.append(where[p] if p >= 0 else -1)
        vel = None if self.velocities is None else self.velocities[:, idx]
        return PointMotion(
            tuple(names), np.array(parents), self.positions[:, idx], self.fps, vel,
            self.qpos, self.joint_names,
        )  # fmt: skip

    def slice(self, start: int, stop: int) -> PointMotion:
        """Frames ``[start, stop)``."""
        s = slice(start, stop)
        return PointMotion(
            self.names, self.parents, self.positions[s], self.fps,
            None if self.velocities is None else self.velocities[s],
            None if self.qpos is None else self.qpos[s], self.joint_names,
        )  # fmt: skip
