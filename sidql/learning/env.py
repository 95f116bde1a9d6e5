"""The keyframe-selection problem as a Gymnasium environment (the paper's MDP, section 4.1).

The core is pure over arrays. A *task* is one clip reduced to what the decision needs:

- ``features`` (N, C) float32: per-frame inputs of the policy (the paper's F and V: bone angles
  [rad] and angular rates [rad/frame]; see :func:`sidql.learning.tasks.clip_features`);
- ``cost`` (N, N) float64: the segment-cost matrix of issue 3, ``cost[i, j]`` (i < j) = summed
  |Δθ| + |Δφ| [rad] over the frames strictly between keyframes i and j and over the M bones, so
  the paper's error of a sorted keyframe set K is ``Q(K) = sum_w cost[k_w, k_{w+1}] / (N M)``
  (eq. 18).

State s_i = (F, V, X_i) with X_i the (N,) keyframe mask; an episode starts with X_0 = {0, N-1} and
each action adds one frame until W keyframes are chosen (W counts both ends). The reward is the
paper's r_i = R_{i+1} - R_i with R_i = 1 - Q_i / Q_0 (eq. 21-22). Because the normalisation
1 / (N M) cancels in Q_i / Q_0, rewards are computed from sums of cost entries (O(W) per step).

A clip whose Q_0 is zero (nothing to reconstruct: the first and last keyframes already reproduce it)
gives R_i = 0 and zero rewards throughout.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

ENV_ID = "sidql/Keyframe-v0"


class InvalidActionError(ValueError):
    """An action that the environment cannot take (a frame that is already a keyframe, an index
    outside the clip, or a step after the episode ended)."""


class KeyframeActions(spaces.Discrete):
    """``Discrete(N)`` whose ``sample()`` without a mask draws only valid actions (frames that are
    not yet keyframes), so generic clients that sample the action space (random agents, Gymnasium's
    ``check_env``) never hit an invalid action. ``sample(mask=...)`` behaves as in ``Discrete``."""

    def __init__(self, n: int, valid, seed=None):
        super().__init__(n, seed=seed)
        self._valid = valid  # () -> (n,) bool

    def sample(self, mask=None, probability=None):
        if mask is None and probability is None:
            valid = self._valid()
            if valid.any():
                mask = valid.astype(np.int8)
        return super().sample(mask=mask, probability=probability)


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
    """

    features: np.ndarray
    cost: np.ndarray
    n_bones: int = 22
    source: str = ""
    subject: str = ""

    def __post_init__(self):
        n = self.features.shape[0]
        if self.features.ndim != 2 or n < 3:
            raise ValueError(f"features must be (N >= 3, C); got {self.features.shape}")
        if self.cost.shape != (n, n):
            raise ValueError(f"cost must be (N, N) = ({n}, {n}); got {self.cost.shape}")
        if self.n_bones < 1:
            raise ValueError(f"n_bones must be positive; got {self.n_bones}")

    @property
    def n_frames(self) -> int:
        return int(self.features.shape[0])


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


class KeyframeEnv(gym.Env):
    """Choose W keyframes of a clip one at a time (registered as ``sidql/Keyframe-v0``).

    Observation (a ``Dict``):
        ``features``: (N, C) float32, the clip's F and V (constant during an episode);
        ``cost``: (N, N) float32, the clip's segment costs (a function of F and V; constant);
        ``keyframes``: (N,) int8 mask X of the chosen keyframes;
        ``remaining``: int, keyframes still to choose (W minus the number chosen).
    Action: ``Discrete(N)``, the index of the next keyframe (``action_space.sample()`` draws a
    valid one). Frames that are already keyframes are
    invalid: they are False in ``info["action_mask"]`` and :meth:`action_masks`, and ``step`` raises
    :class:`InvalidActionError` for them.
    Reward: r_i = R_{i+1} - R_i, R_i = 1 - Q_i / Q_0; ``info`` carries the terms (``R``, ``R_prev``,
    ``q``, ``q_prev``, ``q0``) so that ``reward == R - R_prev``.
    Episode: starts from {0, N-1}; terminates when W keyframes are chosen (no truncation).

    Args:
        tasks: the clips to draw from (all with the same N and C). ``None`` builds a small
            deterministic synthetic set (:func:`sidql.learning.tasks.synthetic_tasks`) so that
            ``gymnasium.make(ENV_ID)`` works without data.
        keyframes: the keyframe counts W an episode may ask for (each 3 <= W <= N); one is drawn
            per episode with ``self.np_random``.

    ``reset(options={"task": i, "keyframes": W})`` fixes the clip and/or W of the episode.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        tasks: Sequence[KeyframeTask] | None = None,
        keyframes: Sequence[int] = (5, 10, 15),
    ):
        if tasks is None:
            from sidql.learning.tasks import synthetic_tasks

            tasks = synthetic_tasks(8, seed=0)
        self.tasks = list(tasks)
        if not self.tasks:
            raise ValueError("KeyframeEnv needs at least one task")
        n, c = self.tasks[0].features.shape
        for t in self.tasks:
            if t.features.shape != (n, c):
                raise ValueError(f"all tasks must have features ({n}, {c}); got {t.features.shape}")
        self.keyframe_counts = tuple(int(w) for w in keyframes)
        bad = [w for w in self.keyframe_counts if not 3 <= w <= n]
        if not self.keyframe_counts or bad:
            raise ValueError(f"keyframe counts must lie in [3, N={n}]; got {self.keyframe_counts}")
        self.n_frames = n
        self.observation_space = spaces.Dict(
            {
                "features": spaces.Box(-np.inf, np.inf, (n, c), np.float32),
                "cost": spaces.Box(0.0, np.inf, (n, n), np.float32),
                "keyframes": spaces.MultiBinary(n),
                "remaining": spaces.Discrete(n - 1),
            }
        )
        self.action_space = KeyframeActions(n, self.action_masks)
        self._task: KeyframeTask | None = None
        self._task_index = -1
        self._mask = np.zeros(n, dtype=bool)
        self._budget = 0
        self._err0 = 0.0
        self._err = 0.0

    # -- helpers -------------------------------------------------------------------------------
    def _R(self, err: float) -> float:
        return 0.0 if self._err0 <= 0.0 else 1.0 - err / self._err0

    def _q(self, err: float) -> float:
        return err / (self.n_frames * self._task.n_bones)

    def _obs(self) -> dict:
        return {
            "features": self._task.features.copy(),
            "cost": np.maximum(self._task.cost, 0.0).astype(np.float32),
            "keyframes": self._mask.astype(np.int8),
            "remaining": int(self._budget - self._mask.sum()),
        }

    def _info(self) -> dict:
        return {
            "action_mask": self.action_masks(),
            "task_index": self._task_index,
            "keyframe_indices": np.flatnonzero(self._mask),
            "q": self._q(self._err),
            "q0": self._q(self._err0),
            "R": self._R(self._err),
        }

    def action_masks(self) -> np.ndarray:
        """(N,) bool: True for frames that may be chosen next (not yet keyframes)."""
        return ~self._mask

    # -- Gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = options or {}
        i = options.get("task")
        if i is None:
            i = int(self.np_random.integers(len(self.tasks)))
        if not 0 <= int(i) < len(self.tasks):
            raise ValueError(f"task index {i} out of range [0, {len(self.tasks)})")
        w = options.get("keyframes")
        if w is None:
            w = self.keyframe_counts[int(self.np_random.integers(len(self.keyframe_counts)))]
        if not 3 <= int(w) <= self.n_frames:
            raise ValueError(f"keyframes must lie in [3, {self.n_frames}]; got {w}")
        self._task_index = int(i)
        self._task = self.tasks[self._task_index]
        self._budget = int(w)
        self._mask = np.zeros(self.n_frames, dtype=bool)
        self._mask[[0, -1]] = True
        self._err0 = self._err = float(self._task.cost[0, self.n_frames - 1])
        return self._obs(), self._info()

    def step(self, action):
        if self._task is None:
            raise InvalidActionError("step() called before reset()")
        if self._mask.sum() >= self._budget:
            raise InvalidActionError("the episode has ended (W keyframes chosen); call reset()")
        try:
            a = int(action)
        except (TypeError, ValueError):
            raise InvalidActionError(f"action must be a frame index; got {action!r}") from None
        if not 0 <= a < self.n_frames:
            raise InvalidActionError(f"action {a} outside the clip's frames [0, {self.n_frames})")
        if self._mask[a]:
            chosen = ", ".join(map(str, np.flatnonzero(self._mask)))
            raise InvalidActionError(f"frame {a} is already a keyframe (chosen: {chosen})")
        err_prev = self._err
        self._mask[a] = True
        self._err = keyframe_error_sum(self._task.cost, np.flatnonzero(self._mask))
        R_prev, R = self._R(err_prev), self._R(self._err)
        reward = R - R_prev
        terminated = bool(self._mask.sum() >= self._budget)
        info = self._info()
        info.update(R_prev=R_prev, q_prev=self._q(err_prev))
        return self._obs(), float(reward), terminated, False, info


gym.register(id=ENV_ID, entry_point="sidql.learning.env:KeyframeEnv")
