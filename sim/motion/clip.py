"""The in-memory value type for a motion clip, and its atomic ``.npz`` storage.

Pure numpy: importing this module never imports MuJoCo, so ``sidql`` can depend on it.

Conventions: world frame z up, metres, seconds; quaternions ``wxyz`` (MuJoCo's order).
Point ``j`` of a clip is the *end* of ASF bone ``names[j]`` (``root`` is the root position), so the
bone vector of point ``j`` is ``positions[:, j] - positions[:, parents[j]]``.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from sim.errors import MotionDataError, UnknownNameError
from sim.files import write_atomic


@dataclass(frozen=True)
class Clip:
    """A stretch of motion at a fixed frame rate.

    Attributes:
        names: (J,) point names: ``"root"`` then ASF bone names.
        parents: (J,) int index of each point's parent point, -1 for the root.
        positions: (T, J, 3) point positions [m], z up.
        velocities: (T, J, 3) true point velocities [m/s] from the kinematic chain (v = J(q) q̇).
        qpos: (T, nq) MuJoCo generalised positions (free root joint first, then one hinge per ASF dof).
        qvel: (T, nv) generalised velocities [rad/s, m/s].
        rotations: (T, J, 4) local rotation of each point's body relative to its parent body, as a
            unit quaternion ``wxyz`` (for the root: its world orientation). Zero-motion pose = identity.
        fps: frame rate of this clip [1/s].
        source: file the motion came from ("" for synthetic motion).
        start_frame: index of the first frame in the source file's own frame rate.
        source_fps: frame rate of the source file [1/s] (CMU: 120).
        joint_names: (nq-7,) names of the hinge joints that follow the free joint in ``qpos``.
        angular_velocities: (T, J, 3) world angular velocity [rad/s] of each point's body, from the
            kinematic chain (None when unknown, e.g. for reconstructions).
        source_velocities, accelerations: (T, J, 3) point velocities [m/s] and accelerations
            [m/s^2] from the source frames' positions around each frame
            (:func:`sim.motion.velocities.point_derivatives`; None when unknown).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    rotations: np.ndarray
    fps: float
    source: str = ""
    start_frame: int = 0
    source_fps: float = 120.0
    joint_names: tuple[str, ...] = field(default_factory=tuple)
    angular_velocities: np.ndarray | None = None
    source_velocities: np.ndarray | None = None
    accelerations: np.ndarray | None = None

    def __post_init__(self):
        T, J = self.positions.shape[:2]
        if self.positions.shape != (T, J, 3) or self.velocities.shape != (T, J, 3):
            raise ValueError(
                f"positions/velocities must be (T, J, 3); got {self.positions.shape} "
                f"and {self.velocities.shape}"
            )
        if len(self.names) != J or self.parents.shape != (J,):
            raise ValueError(f"names and parents must have J={J} entries")
        if self.rotations.shape != (T, J, 4):
            raise ValueError(f"rotations must be (T, J, 4); got {self.rotations.shape}")
        if self.qpos.shape[0] != T or self.qvel.shape[0] != T:
            raise ValueError("qpos and qvel must have T rows")
        if self.angular_velocities is not None and self.angular_velocities.shape != (T, J, 3):
            raise ValueError(
                f"angular_velocities must be (T, J, 3); got {self.angular_velocities.shape}"
            )
        for name in ("source_velocities", "accelerations"):
            a = getattr(self, name)
            if a is not None and a.shape != (T, J, 3):
                raise ValueError(f"{name} must be (T, J, 3); got {a.shape}")
        if self.fps <= 0:
            raise ValueError(f"fps must be positive; got {self.fps}")

    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def dt(self) -> float:
        """Time between frames [s]."""
        return 1.0 / self.fps

    def index(self, name: str) -> int:
        """Index of point ``name``; the error lists the valid names."""
        try:
            return self.names.index(name)
        except ValueError:
            raise UnknownNameError("point", name, self.names) from None

    def bone_vectors(self) -> np.ndarray:
        """(T, J, 3) child minus parent position [m]; the root's row is zero."""
        parent = np.where(self.parents < 0, np.arange(len(self.parents)), self.parents)
        return self.positions - self.positions[:, parent]

    def bone_lengths(self) -> np.ndarray:
        """(J,) bone length [m] (mean over frames; constant for kinematic motion); root 0."""
        return np.linalg.norm(self.bone_vectors(), axis=-1).mean(axis=0)

    def slice(self, start: int, stop: int) -> Clip:
        """Frames ``[start, stop)`` of this clip, with ``start_frame`` kept in source frames."""
        if not 0 <= start < stop <= self.n_frames:
            raise ValueError(f"bad slice [{start}, {stop}) of a {self.n_frames}-frame clip")
        step = self.source_fps / self.fps
        return replace(
            self,
            positions=self.positions[start:stop],
            velocities=self.velocities[start:stop],
            qpos=self.qpos[start:stop],
            qvel=self.qvel[start:stop],
            rotations=self.rotations[start:stop],
            angular_velocities=None
            if self.angular_velocities is None
            else self.angular_velocities[start:stop],
            source_velocities=None
            if self.source_velocities is None
            else self.source_velocities[start:stop],
            accelerations=None if self.accelerations is None else self.accelerations[start:stop],
            start_frame=int(round(self.start_frame + start * step)),
        )

    def split(self, length: int = 60) -> list[Clip]:
        """Non-overlapping ``length``-frame clips from frame 0 (a short tail is dropped)."""
        return [self.slice(s, s + length) for s in range(0, self.n_frames - length + 1, length)]


_ARRAY_KEYS = ("parents", "positions", "velocities", "qpos", "qvel", "rotations")
_OPTIONAL_KEYS = ("angular_velocities", "source_velocities", "accelerations")


def save_npz(clip: Clip, path: str | os.PathLike, extra: dict | None = None) -> Path:
    """Write ``clip`` to ``path`` atomically (temporary file in the same folder, then rename).

    Keys: names, parents, positions, velocities, qpos, qvel, rotations, fps, source, start_frame,
    source_fps, joint_names, and angular_velocities, source_velocities and accelerations when
    known; plus the arrays of ``extra``
    under their own names (per-frame labels of simulated clips: :func:`load_npz` ignores them,
    :func:`load_extra` reads them).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {k: getattr(clip, k) for k in _ARRAY_KEYS}
    for name in _OPTIONAL_KEYS:
        if getattr(clip, name) is not None:
            payload[name] = getattr(clip, name)
    payload.update(
        names=np.array(clip.names),
        joint_names=np.array(clip.joint_names, dtype=str),
        fps=np.float64(clip.fps),
        source=np.array(clip.source),
        start_frame=np.int64(clip.start_frame),
        source_fps=np.float64(clip.source_fps),
    )
    clash = set(extra or {}) & (set(payload) | set(_OPTIONAL_KEYS))
    if clash:
        raise ValueError(f"extra arrays {sorted(clash)} would overwrite clip keys")
    payload.update(extra or {})
    write_atomic(path, lambda f: np.savez_compressed(f, **payload))
    return path


def load_extra(path: str | os.PathLike, prefix: str = "") -> dict[str, np.ndarray]:
    """The arrays of a clip file written through ``save_npz(..., extra=...)`` whose names start
    with ``prefix`` (every non-clip key when empty)."""
    clip_keys = {*_ARRAY_KEYS, "names", "joint_names", "fps", "source", "start_frame",
                 "source_fps", *_OPTIONAL_KEYS}  # fmt: skip
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files if k not in clip_keys and k.startswith(prefix)}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise MotionDataError(str(path), None, f"not a clip file: {e}") from e


def load_npz(path: str | os.PathLike) -> Clip:
    """Read a clip written by :func:`save_npz`."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return Clip(
                names=tuple(str(n) for n in z["names"]),
                joint_names=tuple(str(n) for n in z["joint_names"]),
                fps=float(z["fps"]),
                source=str(z["source"]),
                start_frame=int(z["start_frame"]),
                source_fps=float(z["source_fps"]),
                **{k: (z[k] if k in z else None) for k in _OPTIONAL_KEYS},
                **{k: z[k] for k in _ARRAY_KEYS},
            )
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as e:  # truncated: zip
        raise MotionDataError(str(path), None, f"not a clip file: {e}") from e
