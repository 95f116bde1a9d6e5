"""Keyframe tasks: one clip reduced to what a keyframe decision needs, and where tasks come from.

- :class:`KeyframeTask`: (features (N, C), segment-cost matrix (N, N), M) of one clip, and the
  paper's error of a keyframe set on it, :func:`keyframe_q` (eq. 18, tested equal to
  :func:`sidql.keyframes.metrics.q_error` on real clips);
- :func:`synthetic_tasks`: a small deterministic problem without data (smooth random signals whose
  cost is the error of *linear* interpolation between keyframes), used by ``gymnasium.make`` without
  arguments and by CI's tiny training run;
- :func:`clip_features` / :func:`clip_task`: a 60-frame motion clip -> the paper's state
  inputs F, V (bone angles and rates of the spherical chart) and the Hermite segment-cost matrix
  (:mod:`sidql.keyframes.segment_costs`), and with ``physics`` the physical cost of each segment
  (:mod:`sidql.keyframes.physical_costs`, the ``physics`` method's) for a physical reward;
- :func:`load_tasks`: every trial under a CMU directory, cut into 60-frame clips (optionally with a
  stride smaller than 60 for more, overlapping training clips), cached per trial as ``.npz`` in
  :func:`default_cache_dir` (``$SIDQL_CACHE`` or ``~/.cache/sidql/tasks``) unless told otherwise,
  so a second load of the same files costs only the reading of the cache.

The environment (:mod:`sidql.learning.env`) builds on this module, never the other way round.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from sidql.keyframes.physical_costs import PHYSICS_WEIGHT, physical_costs, scaled, segment_inputs
from sidql.keyframes.segment_costs import segment_cost_matrix
from sidql.keyframes.spherical import chart
from sim.errors import MotionDataError, OutputError, UsageError
from sim.files import write_atomic
from sim.motion.clip import read_arrays
from sim.motion.dataset import find_trials
from sim.motion.ingest import load_motion

#: Bump when features or costs change: cached task files carry it in their name.
CACHE_VERSION = 1


@dataclass(frozen=True)
class KeyframeTask:
    """One clip as the environment sees it.

    Attributes:
        features: (N, C) float32 per-frame policy inputs (angles [rad], rates [rad/frame]).
        cost: (N, N) segment costs [rad summed over frames and bones]; only i < j is read.
        n_bones: M, the number of bones summed in ``cost`` (22 for the CMU protocol);
            Q = sum / (N M).
        source: where the clip came from (file and start frame), for reports.
        subject: subject id of the trial (for subject-wise splits); "" if unknown.
        physical: (N, N) the physical cost P of each segment (dimensionless: skating, floor and
            residual force over their scales, :func:`sidql.keyframes.physical_costs.scaled`;
            only i < j is read), or None when not computed.
    """

    features: np.ndarray
    cost: np.ndarray
    n_bones: int = 22
    source: str = ""
    subject: str = ""
    physical: np.ndarray | None = None

    def __post_init__(self):
        n = self.features.shape[0]
        if self.features.ndim != 2 or n < 3:
            raise UsageError(f"features must be (N >= 3, C); got {self.features.shape}")
        if self.cost.shape != (n, n):
            raise UsageError(f"cost must be (N, N) = ({n}, {n}); got {self.cost.shape}")
        if self.physical is not None and self.physical.shape != (n, n):
            raise UsageError(f"physical must be (N, N) = ({n}, {n}); got {self.physical.shape}")
        if self.n_bones < 1:
            raise UsageError(f"n_bones must be positive; got {self.n_bones}")

    @property
    def n_frames(self) -> int:
        return int(self.features.shape[0])


def physics_task(task: KeyframeTask, weight: float = PHYSICS_WEIGHT) -> KeyframeTask:
    """``task`` whose segment costs are the ``physics`` method's, ``cost + weight * physical``
    [rad] (its :func:`keyframe_q` is then that method's combined error): the physical reward of
    :class:`sidql.learning.env.KeyframeEnv` with ``physics_weight = weight`` folded into the
    costs, for learners that read ``cost`` (demonstrations, priors, baselines)."""
    if task.physical is None:
        raise UsageError(f"task {task.source or '?'} has no physical costs (physics=True)")
    return replace(task, cost=task.cost + weight * task.physical)


def reward_tasks(tasks: Sequence[KeyframeTask], reward: str) -> list[KeyframeTask]:
    """The tasks a run with ``reward`` ("q" or "physics", :attr:`sidql.learning.settings.Args.reward`)
    learns on: as they are, or each :func:`physics_task`."""
    return list(tasks) if reward == "q" else [physics_task(t) for t in tasks]


def keyframe_error_sum(cost: np.ndarray, keyframes: Sequence[int] | np.ndarray) -> float:
    """Sum of ``cost`` over consecutive keyframes, ``sum_w cost[k_w, k_{w+1}]``.

    Args:
        cost: (N, N) segment-cost matrix.
        keyframes: sorted frame indices (any length >= 2).
    Returns:
        The unnormalised error [rad]; divide by N M for the paper's Q (eq. 18).
    """
    k = np.asarray(keyframes, dtype=np.int64)
    return float(cost[k[:-1], k[1:]].sum())


def keyframe_q(task: KeyframeTask, keyframes: Sequence[int] | np.ndarray) -> float:
    """The paper's mean angle error Q(S, K) [rad] (eq. 18) of sorted ``keyframes`` on ``task``."""
    return keyframe_error_sum(task.cost, keyframes) / (task.n_frames * task.n_bones)


def neighbours(mask: np.ndarray, frame: int) -> tuple[int, int]:
    """Nearest keyframes strictly left and right of ``frame`` in the (N,) bool ``mask``.

    The first and last frames must be keyframes and ``frame`` must lie strictly between them.
    """
    left = int(np.flatnonzero(mask[:frame])[-1])
    right = frame + 1 + int(np.flatnonzero(mask[frame + 1 :])[0])
    return left, right


def insertion_gain(cost: np.ndarray, mask: np.ndarray, frame: int) -> float:
    """Decrease of the error sum when ``frame`` becomes a keyframe: the segment (l, r) that contains
    it is replaced by (l, frame) and (frame, r). Positive when the reconstruction improves."""
    left, right = neighbours(mask, frame)
    return float(cost[left, right] - cost[left, frame] - cost[frame, right])


def linear_cost_matrix(x: np.ndarray) -> np.ndarray:
    """Segment costs of linear interpolation: ``C[i, j]`` (i < j) = sum over frames i < n < j and
    channels c of |x[n, c] - lerp(x[i, c], x[j, c])|; zero on and below the diagonal.

    Args:
        x: (N, C) signals.
    Returns:
        (N, N) float64.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    cost = np.zeros((n, n))
    frames = np.arange(n)
    for i in range(n - 2):
        j = np.arange(i + 2, n)  # (J,)
        t = (frames[None, :] - i) / (j[:, None] - i)  # (J, N)
        inside = (frames[None, :] > i) & (frames[None, :] < j[:, None])
        interp = x[i][None, None, :] + t[..., None] * (x[j] - x[i])[:, None, :]  # (J, N, C)
        err = np.abs(interp - x[None]).sum(-1)
        cost[i, j] = np.where(inside, err, 0.0).sum(-1)
    return cost


def synthetic_tasks(
    n: int, *, n_frames: int = 60, n_channels: int = 6, seed: int = 0
) -> list[KeyframeTask]:
    """``n`` deterministic synthetic tasks: per channel a sum of three sinusoids (0.1 to 2 cycles
    per clip, random phases and amplitudes up to 1 rad) plus a random kink, so that good keyframes
    sit at the kinks and turning points. Features: the signals [rad] and their per-frame central
    differences [rad/frame], (N, 2 C). Cost: :func:`linear_cost_matrix` of the signals, M = C.
    """
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n_frames)
    tasks = []
    for k in range(n):
        freq = rng.uniform(0.1, 2.0, (3, n_channels))
        phase = rng.uniform(0, 2 * np.pi, (3, n_channels))
        amp = rng.uniform(0.0, 1.0, (3, n_channels))
        x = (amp[None] * np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None])).sum(1)
        kink = rng.uniform(0.1, 0.9, n_channels)
        x += rng.uniform(-3, 3, n_channels) * np.maximum(t[:, None] - kink[None], 0.0)
        rate = np.gradient(x, axis=0)
        features = np.concatenate([x, rate], axis=1).astype(np.float32)
        tasks.append(
            KeyframeTask(
                features=features,
                cost=linear_cost_matrix(x),
                n_bones=n_channels,
                source=f"synthetic:{seed}:{k}",
                subject=f"s{k % 4}",
            )
        )
    return tasks


# --- real clips ----------------------------------------------------------------------------------


def clip_features(series) -> np.ndarray:
    """The paper's per-frame state inputs (F, V) from a spherical chart.

    Args:
        series: a :class:`sidql.keyframes.spherical.SphericalSeries` with theta, phi, dtheta, dphi (N, M)
            [rad, rad/s] and dt [s].
    Returns:
        (N, 4 M) float32: θ [rad]; φ minus its clip mean [rad] (the chart's azimuth is only
        defined up to the heading, and the cost sees only differences); θ̇ Δ and φ̇ Δ [rad/frame].
    """
    theta = np.asarray(series.theta, dtype=np.float64)
    phi = np.asarray(series.phi, dtype=np.float64)
    dt = float(series.dt)
    rates = np.concatenate([series.dtheta * dt, series.dphi * dt], axis=1)
    return stacked_features(np.concatenate([theta, phi], axis=1), rates)


def stacked_features(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """:func:`clip_features` from the chart as :func:`sidql.keyframes.segment_costs.stacked`
    lays it out: (N, 2M) angles [theta | phi] [rad] and (N, 2M) rates times dt [rad/frame]."""
    return _stacked_features(np.ascontiguousarray(angles, dtype=np.float64),
                             np.ascontiguousarray(rates, dtype=np.float64))  # fmt: skip


@numba.njit(cache=True)
def _stacked_features(angles, rates):
    """:func:`stacked_features` compiled, with numpy's arithmetic: phi's mean over frames summed
    in frame order from the first (as ``mean(axis=0)`` sums a frame-major array), divided by N."""
    n, d = angles.shape
    m = d // 2
    mean = angles[0, m:].copy()
    for t in range(1, n):
        for k in range(m):
            mean[k] += angles[t, m + k]
    mean /= n
    out = np.empty((n, d + rates.shape[1]), np.float32)
    for t in range(n):
        for k in range(m):
            out[t, k] = angles[t, k]
            out[t, m + k] = angles[t, m + k] - mean[k]
        for k in range(rates.shape[1]):
            out[t, d + k] = rates[t, k]
    return out


def clip_task(clip, *, subject: str = "", physics: bool = False) -> KeyframeTask:
    """A motion clip (:class:`sim.motion.clip.Clip`, N frames) -> its :class:`KeyframeTask`
    (features from :func:`clip_features`, Hermite costs of :mod:`sidql.keyframes.segment_costs`;
    with ``physics`` also the physical cost P of every segment, as the ``physics`` method's)."""
    series = chart(clip)
    physical = scaled(physical_costs(segment_inputs(clip))) if physics else None
    return KeyframeTask(
        features=clip_features(series),
        cost=np.asarray(segment_cost_matrix(series, "hermite"), dtype=np.float64),
        n_bones=int(series.theta.shape[1]),
        source=f"{clip.source}@{clip.start_frame}",
        subject=subject,
        physical=physical,
    )


@dataclass(frozen=True)
class TrialTasks:
    """The tasks of one trial: ``features`` (K, N, C) float32, ``costs`` (K, N, N) float64,
    ``starts`` (K,) first frame of each clip [frames of the 30 fps trial]; ``physical``
    (K, N, N) float64 or None (:attr:`KeyframeTask.physical`)."""

    subject: str
    source: str
    features: np.ndarray
    costs: np.ndarray
    starts: np.ndarray
    n_bones: int
    physical: np.ndarray | None = None

    def tasks(self) -> list[KeyframeTask]:
        P = [None] * len(self.starts) if self.physical is None else self.physical
        return [
            KeyframeTask(f, c, self.n_bones, f"{self.source}@{int(s)}", self.subject, p)
            for f, c, s, p in zip(self.features, self.costs, self.starts, P, strict=True)
        ]


def _cache_path(cache_dir: Path, amc: Path, length: int, stride: int, fps: float, physics=False):
    st = amc.stat()
    key = f"{amc.resolve()}|{st.st_size}|{st.st_mtime_ns}|{length}|{stride}|{fps}|{CACHE_VERSION}"
    key += "|physics" * bool(physics)  # tasks without physical costs keep their old files
    return cache_dir / f"{amc.stem}-{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"


def _read_cache(path: Path, length: int, physics: bool = False):
    """``(features, costs, starts, n_bones, physical)`` of a cache file (``physical`` None
    unless ``physics``), or None when it is unreadable or not of the expected layout (it is then
    rebuilt): read within stated limits like any input."""
    keys = ("features", "costs", "starts", "n_bones") + ("physical",) * bool(physics)
    try:
        z = read_arrays(path, keys)
    except MotionDataError:
        return None
    f, c, s, n = z["features"], z["costs"], z["starts"], z["n_bones"]
    p = z["physical"] if physics else c
    K = len(s)
    if (f.ndim != 3 or f.shape[:2] != (K, length) or c.shape != (K, length, length)
            or s.ndim != 1 or n.shape != () or f.dtype.kind != "f" or c.dtype.kind != "f"
            or s.dtype.kind not in "iu" or n.dtype.kind not in "iu"
            or p.shape != c.shape or p.dtype.kind != "f"
            or not (np.isfinite(f).all() and np.isfinite(c).all() and np.isfinite(p).all())):  # fmt: skip
        return None
    return f, c, s, int(n), (p if physics else None)


def trial_tasks(
    trial, *, length: int = 60, stride: int = 60, fps: float = 30.0, cache_dir=None,
    physics: bool = False,
) -> TrialTasks:  # fmt: skip
    """Cut one trial (``sim.motion.dataset.Trial``) into ``length``-frame clips starting every ``stride``
    frames from frame 0 and reduce each to features and costs (with ``physics`` also the
    physical costs, :func:`clip_task`).

    Cached as one ``.npz`` per trial (keyed by the file's path, size, modification time, the
    arguments and :data:`CACHE_VERSION`) in ``cache_dir``; None: :func:`default_cache_dir`;
    False: no cache.

    Raises:
        MotionDataError: the trial cannot be read, or is shorter than one clip.
    """
    amc = Path(trial.amc)
    path = None
    if cache_dir is None:
        cache_dir = default_cache_dir()
    if cache_dir is not False:
        path = _cache_path(Path(cache_dir), amc, length, stride, fps, physics)
        cached = _read_cache(path, length, physics) if path.exists() else None
        if cached is not None:
            return TrialTasks(trial.subject, str(amc), *cached)
    motion = load_motion(trial.asf, trial.amc, fps=fps)
    if motion.n_frames < length:
        raise MotionDataError(str(amc), None, f"{motion.n_frames} frames < one {length}-frame clip")
    starts = np.arange(0, motion.n_frames - length + 1, stride)
    tasks = [clip_task(motion.slice(int(s), int(s) + length), physics=physics) for s in starts]
    out = TrialTasks(
        trial.subject,
        str(amc),
        np.stack([t.features for t in tasks]),
        np.stack([t.cost for t in tasks]),
        starts,
        tasks[0].n_bones,
        np.stack([t.physical for t in tasks]) if physics else None,
    )
    if path is not None:
        extra = {"physical": out.physical} if physics else {}
        try:
            write_atomic(
                path,
                lambda f: np.savez(
                    f, features=out.features, costs=out.costs, starts=starts,
                    n_bones=out.n_bones, **extra,
                ),
            )  # fmt: skip
        except (OSError, OutputError) as e:  # a cache that cannot be written only costs time
            why = e.problem if isinstance(e, OutputError) else e.strerror or e
            print(f"warning: {path}: task cache not written: {why}", file=sys.stderr)
    return out


class TaskSet(list):
    """The :class:`TrialTasks` of a folder, one per readable trial (a list), and what was skipped.

    Attributes:
        skipped: (AMC path, problem) of every trial that could not be used.
    """

    def __init__(self, trials=(), skipped=()):
        super().__init__(trials)
        self.skipped: list[tuple[str, str]] = list(skipped)

    def tasks(self) -> list[KeyframeTask]:
        """Every clip of every trial as a :class:`KeyframeTask`, in trial order."""
        return [task for trial in self for task in trial.tasks()]


def load_tasks(
    data_dir, *, length: int = 60, stride: int = 60, fps: float = 30.0, cache_dir=None,
    subjects=None, progress: bool = True, physics: bool = False,
) -> TaskSet:  # fmt: skip
    """Every trial under ``data_dir`` (``sim.motion.dataset.find_trials``) as :class:`TrialTasks`;
    ``load_tasks(DIR).tasks()`` is the flat list of clips for :class:`sidql.learning.env.KeyframeEnv`.

    Bad trials are skipped, reported on stderr and listed in ``.skipped``; ``subjects`` (a set of
    ids) keeps only those. ``cache_dir`` and ``physics`` as in :func:`trial_tasks` (default: a
    per-user cache, so a repeated load reads one ``.npz`` per trial instead of the motion files).
    """
    outside: list[dict] = []  # symbolic links leaving data_dir: listed, never read
    trials = [
        t for t in find_trials(data_dir, outside) if subjects is None or t.subject in subjects
    ]
    out = TaskSet()
    for o in outside:
        out.skipped.append((o["amc"], o["error"]))
        print(f"skipping {o['amc']}: {o['error']}", file=sys.stderr)
    for trial in tqdm(trials, desc=f"clips (stride {stride})", disable=not progress, leave=False):
        try:
            out.append(
                trial_tasks(
                    trial,
                    length=length,
                    stride=stride,
                    fps=fps,
                    cache_dir=cache_dir,
                    physics=physics,
                )  # fmt: skip
            )
        except MotionDataError as e:
            out.skipped.append((str(trial.amc), str(e)))
            print(f"skipping {trial.amc}: {e}", file=sys.stderr)
    return out


def default_cache_dir() -> Path:
    """``$SIDQL_CACHE`` or ``~/.cache/sidql/tasks``: where task files are cached by default."""
    return Path(os.environ.get("SIDQL_CACHE", Path.home() / ".cache" / "sidql" / "tasks"))
