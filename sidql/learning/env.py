"""The keyframe-selection problem as a Gymnasium environment (the paper's MDP, section 4.1).

The core is pure over arrays. A *task* (:class:`sidql.learning.tasks.KeyframeTask`) is one clip
reduced to what the decision needs:

- ``features`` (N, C) float32: per-frame inputs of the policy (the paper's F and V: bone angles
  [rad] and angular rates [rad/frame]; see :func:`sidql.learning.tasks.clip_features`);
- ``cost`` (N, N) float64: the Hermite segment-cost matrix (:mod:`sidql.keyframes.segment_costs`), ``cost[i, j]`` (i < j) = summed
  |Δθ| + |Δφ| [rad] over the frames strictly between keyframes i and j and over the M bones, so
  the paper's error of a sorted keyframe set K is ``Q(K) = sum_w cost[k_w, k_{w+1}] / (N M)``
  (eq. 18, :func:`sidql.learning.tasks.keyframe_q`).

State s_i = (F, V, X_i) with X_i the (N,) keyframe mask; an episode starts with X_0 = {0, N-1} and
each action adds one frame until W keyframes are chosen (W counts both ends). The reward is the
paper's r_i = R_{i+1} - R_i with R_i = 1 - Q_i / Q_0 (eq. 21-22), Q from
:func:`~sidql.learning.tasks.keyframe_q` (O(W) per step).

A clip whose Q_0 is zero (nothing to reconstruct: the first and last keyframes already reproduce it)
gives R_i = 0 and zero rewards throughout.

**The physical reward** (``physics_weight`` lambda > 0, e.g. the ``physics`` method's
:data:`sidql.keyframes.physical_costs.PHYSICS_WEIGHT`): the error becomes the ``physics``
method's, ``E = Q + lambda Phi`` with ``Phi = sum_w P[k_w, k_{w+1}] / (N M)`` the physical cost
of the segments (each task's ``physical``, :attr:`sidql.learning.tasks.KeyframeTask.physical`),
and ``R_i = 1 - E_i / E_0``; the reward of a step then splits into ``(Q_i - Q_{i+1}) / E_0``
(``info["reward_q"]``) and ``lambda (Phi_i - Phi_{i+1}) / E_0`` (``info["reward_physics"]``).
With lambda = 0 (the default) everything is as above, to the bit.

Observations are on a unit scale with finite bounds (see :class:`KeyframeEnv`); learners that want
the raw arrays read ``env.unwrapped.tasks[info["task_index"]]``.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sidql.keyframes.counts import LEAST_LEARNED_W, check_counts
from sidql.learning.tasks import (
    KeyframeTask,
    insertion_gain,
    keyframe_error_sum,
    keyframe_q,
    neighbours,
    synthetic_tasks,
)
from sim.errors import ArgumentTypeError, UsageError

__all__ = [
    "ENV_ID", "FEATURE_CLIP", "RESET_OPTIONS", "InvalidActionError", "KeyframeActions",
    "KeyframeEnv", "as_index",
    # re-exported from sidql.learning.tasks, the environment's vocabulary
    "KeyframeTask", "insertion_gain", "keyframe_error_sum", "keyframe_q", "neighbours",
    "synthetic_tasks",
]  # fmt: skip

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


#: Standardised features are clipped to [-FEATURE_CLIP, FEATURE_CLIP] (the Box's bounds).
FEATURE_CLIP = 5.0

#: The keys ``reset(options=...)`` accepts.
RESET_OPTIONS = ("task", "keyframes")


def as_index(value, what: str) -> int:
    """``value`` as a Python int if it is an integer (int, numpy integer, integer array of one
    element); floats, booleans and anything else raise ``TypeError`` naming ``what``."""
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in "iu":
        value = value.reshape(()).item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ArgumentTypeError(
            f"{what} must be an integer; got {value!r} ({type(value).__name__})"
        )
    return operator.index(value)


class KeyframeEnv(gym.Env):
    """Choose W keyframes of a clip one at a time (registered as ``sidql/Keyframe-v0``).

    Observation (a ``Dict``, every entry bounded and on a unit scale):
        ``features``: (N, C) float32 in [-5, 5], the clip's F and V standardised per channel,
            ``(features - feature_mean) / feature_std`` with the mean and standard deviation over
            every frame of the environment's tasks (or the ``feature_stats`` given), clipped to
            ±:data:`FEATURE_CLIP`;
        ``cost``: (N, N) float32 in [0, 1], the clip's segment costs divided by their largest entry
            (all zero if the clip has no error). The problem is scale-free: rewards and Q ratios
            are unchanged, and ``cost[0, N-1]`` is the reward unit (the reward of adding a inside
            segment (l, r) is ``(cost[l, r] - cost[l, a] - cost[a, r]) / cost[0, N-1]``);
        ``keyframes``: (N,) int8 mask X of the chosen keyframes;
        ``remaining``: int, keyframes still to choose (W minus the number chosen).
        The raw arrays (radians) are ``env.unwrapped.tasks[info["task_index"]]``.
    Action: ``Discrete(N)``, the index of the next keyframe, an integer (a float such as 13.9 is
    refused, not truncated). ``action_space.sample()`` draws a valid one. Frames that are already
    keyframes are invalid: they are False in ``info["action_mask"]`` and :meth:`action_masks`, and
    ``step`` raises :class:`InvalidActionError` for them. Through wrappers (``gymnasium.make``)
    reach the method as ``env.unwrapped.action_masks()`` or
    ``env.get_wrapper_attr("action_masks")()``; in a vector env use ``infos["action_mask"]`` or
    ``envs.call("action_masks")``.
    Reward: r_i = R_{i+1} - R_i, R_i = 1 - Q_i / Q_0; ``info`` carries the terms (``R``, ``R_prev``,
    ``q``, ``q_prev``, ``q0``) so that ``reward == R - R_prev``; with ``physics_weight`` lambda the
    error is ``E = Q + lambda Phi`` (the module docstring) and ``reward == reward_q + reward_physics``.
    Info (fixed shapes, so vector envs can stack them): ``action_mask`` (N,) bool,
    ``keyframe_mask`` (N,) bool, ``task_index`` int, ``q``, ``q_prev``, ``q0``, ``R``, ``R_prev``,
    ``physical``, ``physical_prev`` (Phi; 0 without a physical reward), ``reward_q``,
    ``reward_physics`` floats (at reset the ``_prev`` terms equal the current ones and the
    rewards are 0).
    Episode: starts from {0, N-1}; terminates when W keyframes are chosen (no truncation).

    Args:
        tasks: the clips to draw from (all with the same N and C). ``None`` builds a small
            deterministic synthetic set (:func:`sidql.learning.tasks.synthetic_tasks`) so that
            ``gymnasium.make(ENV_ID)`` works without data.
        keyframes: the keyframe counts W an episode may ask for (each 3 <= W <= N: :data:`sidql.keyframes.counts.LEAST_LEARNED_W`); one is drawn
            per episode with ``self.np_random``.
        feature_stats: (mean, std), each (C,), for the observation's standardisation (e.g. the
            training environment's, for an evaluation environment); None: from ``tasks``.
        physics_weight: lambda of the physical reward (the module docstring); > 0 needs every
            task's ``physical`` (:func:`sidql.learning.tasks.clip_task` with ``physics``).

    ``reset(options={"task": i, "keyframes": W})`` fixes the clip and/or W of the episode (integers;
    any other key is refused with ``ValueError``).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        tasks: Sequence[KeyframeTask] | None = None,
        keyframes: Sequence[int] = (5, 10, 15),
        feature_stats: tuple[np.ndarray, np.ndarray] | None = None,
        physics_weight: float = 0.0,
    ):
        self.tasks = list(synthetic_tasks(8, seed=0) if tasks is None else tasks)
        if not self.tasks:
            raise UsageError("KeyframeEnv needs at least one task")
        self.physics_weight = float(physics_weight)
        if not (np.isfinite(self.physics_weight) and self.physics_weight >= 0):
            raise UsageError(f"physics_weight must be >= 0; got {physics_weight}")
        if self.physics_weight > 0 and any(t.physical is None for t in self.tasks):
            raise UsageError("a physical reward needs tasks with physical costs (physics=True)")
        n, c = self.tasks[0].features.shape
        for t in self.tasks:
            if t.features.shape != (n, c):
                raise UsageError(f"all tasks must have features ({n}, {c}); got {t.features.shape}")
        self.keyframe_counts = tuple(as_index(w, "keyframes") for w in keyframes)
        check_counts(self.keyframe_counts, n, least=LEAST_LEARNED_W, name="keyframe counts")
        self.n_frames = n
        if feature_stats is None:
            flat = np.concatenate([t.features for t in self.tasks]).astype(np.float64)
            feature_stats = (flat.mean(0), flat.std(0))
        mean, std = (np.asarray(x, np.float64).reshape(c) for x in feature_stats)
        self.feature_mean, self.feature_std = mean, np.maximum(std, 1e-6)
        self.observation_space = spaces.Dict(
            {
                "features": spaces.Box(-FEATURE_CLIP, FEATURE_CLIP, (n, c), np.float32),
                "cost": spaces.Box(0.0, 1.0, (n, n), np.float32),
                "keyframes": spaces.MultiBinary(n),
                "remaining": spaces.Discrete(n - 1),
            }
        )
        self.action_space = KeyframeActions(n, self.action_masks)
        self._task: KeyframeTask | None = None
        self._task_index = -1
        self._mask = np.zeros(n, dtype=bool)
        self._budget = 0
        self._q0 = self._q = self._q_prev = 0.0
        self._phi0 = self._phi = self._phi_prev = 0.0
        self._scaled: tuple[np.ndarray, np.ndarray] | None = None

    # -- helpers -------------------------------------------------------------------------------
    def _error(self, q: float, phi: float) -> float:
        """E = Q + lambda Phi (Q itself, to the bit, when lambda is 0)."""
        return q + self.physics_weight * phi if self.physics_weight > 0 else q

    def _R(self, q: float, phi: float = 0.0) -> float:
        e0 = self._error(self._q0, self._phi0)
        return 0.0 if e0 <= 0.0 else 1.0 - self._error(q, phi) / e0

    def _physical(self, keyframes) -> float:
        """Phi of sorted ``keyframes`` on the current task (0 without a physical reward)."""
        if self.physics_weight <= 0:
            return 0.0
        t = self._task
        return keyframe_error_sum(t.physical, keyframes) / (t.n_frames * t.n_bones)

    def segment_cost(self, task: KeyframeTask) -> np.ndarray:
        """(N, N) the segment costs a task's error sums: ``cost`` (+ lambda ``physical``)."""
        if self.physics_weight <= 0:
            return task.cost
        return task.cost + self.physics_weight * task.physical

    def scaled(self, task: KeyframeTask) -> tuple[np.ndarray, np.ndarray]:
        """A task's (features, cost) as observed: standardised and clipped features (N, C), costs
        over their largest entry (N, N), both float32 (see the class docstring)."""
        f = (task.features - self.feature_mean) / self.feature_std
        f = np.clip(f, -FEATURE_CLIP, FEATURE_CLIP).astype(np.float32)
        cost = np.maximum(self.segment_cost(task), 0.0)
        top = float(cost.max())
        cost = (cost / top if top > 0.0 else cost).astype(np.float32)
        return f, cost

    def _obs(self) -> dict:
        features, cost = self._scaled
        return {
            "features": features.copy(),
            "cost": cost.copy(),
            "keyframes": self._mask.astype(np.int8),
            "remaining": int(self._budget - self._mask.sum()),
        }

    def _info(self) -> dict:
        e0 = self._error(self._q0, self._phi0)
        unit = 0.0 if e0 <= 0.0 else 1.0 / e0
        return {
            "action_mask": self.action_masks(),
            "keyframe_mask": self._mask.copy(),
            "task_index": self._task_index,
            "q": self._q,
            "q_prev": self._q_prev,
            "q0": self._q0,
            "R": self._R(self._q, self._phi),
            "R_prev": self._R(self._q_prev, self._phi_prev),
            "physical": self._phi,
            "physical_prev": self._phi_prev,
            "reward_q": (self._q_prev - self._q) * unit,
            "reward_physics": self.physics_weight * (self._phi_prev - self._phi) * unit,
        }

    def action_masks(self) -> np.ndarray:
        """(N,) bool: True for frames that may be chosen next (not yet keyframes)."""
        return ~self._mask

    # -- Gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(RESET_OPTIONS), key=str)
        if unknown:
            raise UsageError(
                f"unknown reset option(s) {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(RESET_OPTIONS)}"
            )
        i = options.get("task")
        if i is None:
            i = int(self.np_random.integers(len(self.tasks)))
        i = as_index(i, "options['task']")
        if not 0 <= i < len(self.tasks):
            raise UsageError(f"task index {i} out of range [0, {len(self.tasks)})")
        w = options.get("keyframes")
        if w is None:
            w = self.keyframe_counts[int(self.np_random.integers(len(self.keyframe_counts)))]
        w = as_index(w, "options['keyframes']")
        check_counts([w], self.n_frames, least=LEAST_LEARNED_W, name="options['keyframes']")
        self._task_index = i
        self._task = self.tasks[i]
        self._scaled = self.scaled(self._task)
        self._budget = w
        self._mask = np.zeros(self.n_frames, dtype=bool)
        self._mask[[0, -1]] = True
        self._q0 = self._q = self._q_prev = keyframe_q(self._task, [0, self.n_frames - 1])
        self._phi0 = self._phi = self._phi_prev = self._physical([0, self.n_frames - 1])
        return self._obs(), self._info()

    def step(self, action):
        if self._task is None:
            raise InvalidActionError("step() called before reset()")
        if self._mask.sum() >= self._budget:
            raise InvalidActionError("the episode has ended (W keyframes chosen); call reset()")
        try:
            a = as_index(action, "action (a frame index)")
        except TypeError as e:
            raise InvalidActionError(str(e)) from None
        if not 0 <= a < self.n_frames:
            raise InvalidActionError(f"action {a} outside the clip's frames [0, {self.n_frames})")
        if self._mask[a]:
            chosen = ", ".join(map(str, np.flatnonzero(self._mask)))
            raise InvalidActionError(f"frame {a} is already a keyframe (chosen: {chosen})")
        self._mask[a] = True
        keys = np.flatnonzero(self._mask)
        self._q_prev, self._q = self._q, keyframe_q(self._task, keys)
        self._phi_prev, self._phi = self._phi, self._physical(keys)
        reward = self._R(self._q, self._phi) - self._R(self._q_prev, self._phi_prev)
        terminated = bool(self._mask.sum() >= self._budget)
        return self._obs(), float(reward), terminated, False, self._info()


gym.register(id=ENV_ID, entry_point="sidql.learning.env:KeyframeEnv")
