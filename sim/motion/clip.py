"""The in-memory value type for a motion clip, and its atomic ``.npz`` storage.

Pure numpy: importing this module never imports MuJoCo, so ``sidql`` can depend on it.

Conventions: world frame z up, metres, seconds; quaternions ``wxyz`` (MuJoCo's order).
Point ``j`` of a clip is the *end* of ASF bone ``names[j]`` (``root`` is the root position), so the
bone vector of point ``j`` is ``positions[:, j] - positions[:, parents[j]]``.
"""

from __future__ import annotations

import math
import os
import zipfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.lib import format as npformat

from sim.errors import MotionDataError, OutputError, UnknownNameError, UsageError, require_type
from sim.files import MAX_NPZ_BYTES, excerpt, open_regular, write_atomic
from sim.zipcheck import check_zip


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
        derivative_noise: (T, J) how much more sample noise reaches each of those accelerations
            than reaches a centred window (:func:`sim.motion.velocities.derivative_noise`: 1
            inside a take, more where the window is shifted against the take's ends or a pose
            jump; None when unknown: taken as 1).
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
    derivative_noise: np.ndarray | None = None

    def __post_init__(self):
        T, J = self.positions.shape[:2]
        if self.positions.shape != (T, J, 3) or self.velocities.shape != (T, J, 3):
            raise UsageError(
                f"positions/velocities must be (T, J, 3); got {self.positions.shape} "
                f"and {self.velocities.shape}"
            )
        if len(self.names) != J or self.parents.shape != (J,):
            raise UsageError(f"names and parents must have J={J} entries")
        if self.rotations.shape != (T, J, 4):
            raise UsageError(f"rotations must be (T, J, 4); got {self.rotations.shape}")
        if self.qpos.shape[0] != T or self.qvel.shape[0] != T:
            raise UsageError("qpos and qvel must have T rows")
        if self.angular_velocities is not None and self.angular_velocities.shape != (T, J, 3):
            raise UsageError(
                f"angular_velocities must be (T, J, 3); got {self.angular_velocities.shape}"
            )
        for name in ("source_velocities", "accelerations"):
            a = getattr(self, name)
            if a is not None and a.shape != (T, J, 3):
                raise UsageError(f"{name} must be (T, J, 3); got {a.shape}")
        if self.derivative_noise is not None and self.derivative_noise.shape != (T, J):
            raise UsageError(f"derivative_noise must be (T, J); got {self.derivative_noise.shape}")
        if self.fps <= 0:
            raise UsageError(f"fps must be positive; got {self.fps}")

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
            raise UsageError(f"bad slice [{start}, {stop}) of a {self.n_frames}-frame clip")
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
            derivative_noise=None
            if self.derivative_noise is None
            else self.derivative_noise[start:stop],
            start_frame=int(round(self.start_frame + start * step)),
        )

    def split(self, length: int = 60) -> list[Clip]:
        """Non-overlapping ``length``-frame clips from frame 0 (a short tail is dropped)."""
        return [self.slice(s, s + length) for s in range(0, self.n_frames - length + 1, length)]


_ARRAY_KEYS = ("parents", "positions", "velocities", "qpos", "qvel", "rotations")
_OPTIONAL_KEYS = ("angular_velocities", "source_velocities", "accelerations", "derivative_noise")


def save_npz(clip: Clip, path: str | os.PathLike, extra: dict | None = None, *, root=None) -> Path:
    """Write ``clip`` to ``path`` atomically (temporary file in the same folder, then rename).

    Keys: names, parents, positions, velocities, qpos, qvel, rotations, fps, source, start_frame,
    source_fps, joint_names, and angular_velocities, source_velocities, accelerations and
    derivative_noise when known; plus the arrays of ``extra``
    under their own names (per-frame labels of simulated clips: :func:`load_npz` ignores them,
    :func:`load_extra` reads them).
    """
    require_type(clip, Clip, "clip")
    path = Path(path)
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
        raise UsageError(f"extra arrays {sorted(clash)} would overwrite clip keys")
    payload.update(extra or {})
    T, J = clip.positions.shape[:2]
    for what, n, limit in (("frames", T, MAX_CLIP_FRAMES), ("points", J, MAX_POINTS),
                           ("coordinates", max(clip.qpos.shape[1], clip.qvel.shape[1]),
                            MAX_COORDINATES)):  # fmt: skip
        if n > limit:  # the writer refuses what its reader (load_npz) would refuse
            raise OutputError(str(path), None, f"a clip of {n:,} {what}; its reader takes at "
                              f"most {limit:,}")  # fmt: skip
    write_atomic(path, lambda f: _write_npz(f, payload, str(path)), root=root)
    return path


def _write_npz(f, payload: dict, path: str) -> None:
    """The arrays compressed, or stored where compression would inflate more than the reader
    allows (:class:`NpzReader`: a clip of constant frames compresses ~1000x)."""
    np.savez_compressed(f, **payload)
    inflated = sum(np.asarray(v).nbytes + 256 for v in payload.values())
    if inflated > min(MAX_NPZ_INFLATED, max(NPZ_INFLATION_FLOOR, NPZ_INFLATION * f.tell())):
        f.seek(0)
        f.truncate()
        np.savez(f, **payload)
    if f.tell() > MAX_NPZ_BYTES or inflated > MAX_NPZ_INFLATED:
        raise OutputError(path, None, f"a clip file of {inflated:,} bytes of arrays; its reader "
                          f"takes at most {min(MAX_NPZ_BYTES, MAX_NPZ_INFLATED):,}")  # fmt: skip


#: Stated limits of a clip file (:func:`load_npz`), checked on the arrays' headers before any
#: array is read: frames (18 minutes at 120 fps), points, generalised coordinates, characters
#: of a name; and the members' inflated size: at most :data:`MAX_NPZ_INFLATED` bytes, and at
#: most :data:`NPZ_INFLATION` times the file's size once past :data:`NPZ_INFLATION_FLOOR` (real
#: clip files inflate ~1.2x; a deflate bomb ~1000x).
MAX_CLIP_FRAMES = 1 << 17
MAX_POINTS = 512
MAX_COORDINATES = 2048
MAX_NAME_CHARS = 256
MAX_NPZ_MEMBERS = 256
MAX_NPZ_INFLATED = 1 << 30
NPZ_INFLATION = 128
NPZ_INFLATION_FLOOR = 64 << 20
_NPY_HEADER_BYTES = 10_000
_KINDS = {"f": "floating-point", "i": "integer", "u": "unsigned integer", "b": "boolean",
          "U": "text"}  # fmt: skip


class NpzReader:
    """A ``.npz`` file opened for bounded reading: a regular file of at most ``max_bytes``, its
    zip directory checked (:func:`sim.zipcheck.check_zip`), every member an ``.npy`` array whose
    header (shape, dtype) is read and checked against its member's size before any array is
    read. Arrays of numbers, booleans and text only (never objects: nothing is unpickled).

    Use as a context manager; :attr:`headers` maps each key to ``(shape, dtype)``; :meth:`array`
    reads one array.

    Raises:
        MotionDataError: one line naming the file and the problem.
    """

    def __init__(self, path: str | os.PathLike, max_bytes: int = MAX_NPZ_BYTES):
        self.path = str(path)
        self._file = open_regular(path, max_bytes)
        try:
            self._open()
        except BaseException:
            self._file.close()
            raise

    def _open(self) -> None:
        path = self.path
        size = os.fstat(self._file.fileno()).st_size
        try:
            self._zip = zipfile.ZipFile(self._file)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
            raise MotionDataError(path, None, f"not a clip file (npz): {_first_line(e)}") from None
        cap = min(MAX_NPZ_INFLATED, max(NPZ_INFLATION_FLOOR, NPZ_INFLATION * size))
        infos = check_zip(
            self._zip, size, path, max_members=MAX_NPZ_MEMBERS, max_inflated=cap,
            stored_only=False,
        )  # fmt: skip
        self.headers: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
        self._members: dict[str, tuple] = {}
        for info in infos:
            key = info.filename[:-4] if info.filename.endswith(".npy") else None
            if not key:
                raise MotionDataError(
                    path, None, f"zip member {excerpt(info.filename)} is not an .npy array"
                )
            shape, fortran, dtype, offset = self._header(info)
            self.headers[key] = (shape, dtype)
            self._members[key] = (info, fortran, offset)

    def _header(self, info):
        path, what = self.path, f"array {excerpt(info.filename)}"
        try:
            with self._zip.open(info) as f:
                version = npformat.read_magic(f)
                read = {(1, 0): npformat.read_array_header_1_0,
                        (2, 0): npformat.read_array_header_2_0}.get(version)  # fmt: skip
                if read is None:
                    raise ValueError(f"npy format version {version}")
                shape, fortran, dtype = read(f, max_header_size=_NPY_HEADER_BYTES)
                offset = f.tell()
        except (ValueError, OSError, EOFError, SyntaxError, zipfile.BadZipFile, zlib.error) as e:
            raise MotionDataError(path, None, f"{what}: bad header: {_first_line(e)}") from None
        if dtype.kind not in _KINDS or dtype.fields is not None or dtype.subdtype is not None:
            raise MotionDataError(path, None, f"{what}: dtype {excerpt(str(dtype))} refused")
        if dtype.itemsize > 4 * MAX_NAME_CHARS or dtype.itemsize == 0:
            raise MotionDataError(path, None, f"{what}: items of {dtype.itemsize} bytes")
        if any(not 0 <= n <= MAX_CLIP_FRAMES * MAX_COORDINATES for n in shape) or len(shape) > 4:
            raise MotionDataError(path, None, f"{what}: shape {excerpt(str(shape))} refused")
        nbytes = math.prod(shape) * dtype.itemsize
        if offset + nbytes != info.file_size:
            raise MotionDataError(
                path, None, f"{what}: {info.file_size - offset:,} bytes of data; its header "
                f"{shape} {dtype} needs {nbytes:,}",
            )  # fmt: skip
        return shape, fortran, dtype, offset

    def array(self, key: str) -> np.ndarray:
        """The array ``key``, read straight into its own memory (a writable copy)."""
        info, fortran, offset = self._members[key]
        shape, dtype = self.headers[key]
        out = np.empty(shape[::-1] if fortran else shape, dtype=dtype)
        view = memoryview(out.reshape(-1).view(np.uint8)) if out.size else memoryview(b"")
        try:
            with self._zip.open(info) as f:
                if len(f.read(offset)) != offset:  # the header, read and checked already
                    raise EOFError("header ends early")
                done = 0
                while done < len(view):
                    n = f.readinto(view[done:])
                    if not n:
                        raise EOFError("data end early")
                    done += n
                f.read(1)  # reaching the end checks the member's CRC-32
        except (OSError, EOFError, zipfile.BadZipFile, zlib.error, ValueError) as e:
            raise MotionDataError(
                self.path, None, f"array {excerpt(key)}: unreadable: {_first_line(e)}"
            ) from None
        return out.T if fortran else out

    def close(self) -> None:
        self._zip.close()
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _first_line(e: BaseException) -> str:
    return excerpt((str(e).strip().splitlines() or [type(e).__name__])[0], 120, quote=False)


def read_arrays(
    path: str | os.PathLike, keys=None, *, prefix: str = "", max_bytes: int = MAX_NPZ_BYTES
) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` file, read within stated limits (:class:`NpzReader`): those named
    in ``keys`` (each must be there), else every one whose name starts with ``prefix``."""
    with NpzReader(path, max_bytes) as z:
        if keys is None:
            keys = [k for k in z.headers if k.startswith(prefix)]
        missing = [k for k in keys if k not in z.headers]
        if missing:
            raise MotionDataError(str(path), None, f"no array {excerpt(missing[0])}")
        return {k: z.array(k) for k in keys}


_CLIP_KEYS = (*_ARRAY_KEYS, "names", "joint_names", "fps", "source", "start_frame",
              "source_fps", *_OPTIONAL_KEYS)  # fmt: skip


def load_extra(path: str | os.PathLike, prefix: str = "") -> dict[str, np.ndarray]:
    """The arrays of a clip file written through ``save_npz(..., extra=...)`` whose names start
    with ``prefix`` (every non-clip key when empty)."""
    with NpzReader(path) as z:
        keys = [k for k in z.headers if k not in _CLIP_KEYS and k.startswith(prefix)]
        out = {k: z.array(k) for k in keys}
    for k, v in out.items():
        if v.dtype.kind == "f" and not np.isfinite(v).all():
            raise MotionDataError(str(path), None, f"non-finite values in {excerpt(k)}")
    return out


def load_npz(path: str | os.PathLike) -> Clip:
    """Read a clip written by :func:`save_npz`, within stated limits: a regular file of at most
    :data:`~sim.files.MAX_NPZ_BYTES`, every array's shape and type checked against the clip
    layout and :data:`MAX_CLIP_FRAMES` etc. from the headers before any array is read, every
    number finite, parents a tree.

    Raises:
        MotionDataError: one line naming the file and the problem.
    """
    path = str(path)
    with NpzReader(path) as z:
        _check_clip_layout(z.headers, path)
        a = {k: z.array(k) for k in _CLIP_KEYS if k in z.headers}
    for k in ("positions", "velocities", "qpos", "qvel", "rotations", *_OPTIONAL_KEYS,
              "fps", "source_fps"):  # fmt: skip
        if k in a:
            a[k] = a[k].astype(np.float64, copy=False)
            if not np.isfinite(a[k]).all():
                raise MotionDataError(path, None, f"non-finite values in {k}")
    J = len(a["names"])
    parents = a["parents"].astype(np.int64)
    if J and (parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= J)
              or np.any(parents[1:] == np.arange(1, J))):  # fmt: skip
        raise MotionDataError(path, None, "parents: not a tree (the root first, -1)")
    fps, source_fps = float(a["fps"]), float(a["source_fps"])
    if not (0 < fps <= 1e4 and 0 < source_fps <= 1e4):
        raise MotionDataError(path, None, f"frame rates {fps:g}, {source_fps:g} out of (0, 1e4]")
    for key in ("names", "joint_names"):  # printed in messages and pages: printable only
        if not all(str(n).isprintable() for n in a[key]):
            raise MotionDataError(path, None, f"{key}: a name that cannot be printed")
    start = int(a["start_frame"])
    if not 0 <= start <= 1 << 40:
        raise MotionDataError(path, None, f"start_frame {start} out of range")
    try:
        return Clip(
            names=tuple(str(n) for n in a["names"]),
            joint_names=tuple(str(n) for n in a["joint_names"]),
            fps=fps,
            source="".join(ch if ch.isprintable() else "?" for ch in str(a["source"])),
            start_frame=start,
            source_fps=source_fps,
            **{k: a.get(k) for k in _OPTIONAL_KEYS},
            parents=parents,
            **{k: a[k] for k in _ARRAY_KEYS if k != "parents"},
        )
    except ValueError as e:  # unreachable after the layout check; a second line of defence
        raise MotionDataError(path, None, f"not a clip file: {_first_line(e)}") from None


def _check_clip_layout(headers: dict, path: str) -> None:
    """Every clip array present, of the right kind and of consistent shapes within the limits
    (from the headers alone: nothing is read yet)."""
    want = {
        "names": "U", "joint_names": "U", "source": "U", "parents": "iu", "positions": "f",
        "velocities": "f", "qpos": "f", "qvel": "f", "rotations": "f", "fps": "fiu",
        "start_frame": "iu", "source_fps": "fiu", **dict.fromkeys(_OPTIONAL_KEYS, "f"),
    }  # fmt: skip
    for key, kinds in want.items():
        if key not in headers:
            if key in _OPTIONAL_KEYS:
                continue
            raise MotionDataError(path, None, f"not a clip file: no array {key!r}")
        if headers[key][1].kind not in kinds:
            raise MotionDataError(
                path, None, f"{key}: {_KINDS[headers[key][1].kind]} values, expected "
                f"{' or '.join(_KINDS[k] for k in kinds)}",
            )  # fmt: skip
    shape = {k: headers[k][0] for k in want if k in headers}
    T, J = (shape["positions"] + (0, 0))[:2]
    nq, nv = (shape["qpos"] + (0, 0))[1], (shape["qvel"] + (0, 0))[1]
    expected = {
        "names": (J,), "parents": (J,), "positions": (T, J, 3), "velocities": (T, J, 3),
        "rotations": (T, J, 4), "qpos": (T, nq), "qvel": (T, nv), "fps": (), "source": (),
        "start_frame": (), "source_fps": (), **dict.fromkeys(_OPTIONAL_KEYS, (T, J, 3)),
        "derivative_noise": (T, J), "joint_names": (shape["joint_names"] + (0,))[:1],
    }  # fmt: skip
    for key, s in expected.items():
        if key in shape and shape[key] != s:
            raise MotionDataError(
                path, None, f"{key}: shape {shape[key]}, the clip's layout needs {s}"
            )
    for what, n, limit in (("frames", T, MAX_CLIP_FRAMES), ("points", J, MAX_POINTS),
                           ("qpos columns", nq, MAX_COORDINATES),
                           ("qvel columns", nv, MAX_COORDINATES),
                           ("joint names", shape["joint_names"][0], MAX_COORDINATES)):  # fmt: skip
        if n > limit:
            raise MotionDataError(path, None, f"{n:,} {what}; at most {limit:,}")
    if T < 1:
        raise MotionDataError(path, None, "a clip of no frames")
