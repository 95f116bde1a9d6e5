"""The replay memory of DQN training (:class:`ReplayMemory`, a fixed-size ring of n-step
transitions) and the n-step returns that fill it (:class:`NStep`).

A state is (task index, keyframe mask (N,) bool, keyframes still to choose); returns are
discounted by γ per step.
"""

from __future__ import annotations

import numpy as np
import torch


class ReplayMemory:
    """Fixed-size ring of n-step transitions; states are (task index, keyframe mask, remaining)."""

    def __init__(self, size: int, n_frames: int):
        self.size, self.pos, self.full = size, 0, False
        self.task = np.zeros(size, np.int64)
        self.mask = np.zeros((size, n_frames), bool)
        self.rem = np.zeros(size, np.int64)
        self.action = np.zeros(size, np.int64)
        self.ret = np.zeros(size, np.float32)
        self.next_mask = np.zeros((size, n_frames), bool)
        self.next_rem = np.zeros(size, np.int64)
        self.done = np.zeros(size, np.float32)
        self.disc = np.zeros(size, np.float32)
        self.expert = np.zeros((size, n_frames), bool)  # demonstrations: optimal frames still free

    def __len__(self):
        return self.size if self.full else self.pos

    def add(self, task, mask, rem, action, ret, next_mask, next_rem, done, disc, expert=None):
        i = self.pos
        self.expert[i] = False if expert is None else expert
        self.task[i], self.mask[i], self.rem[i], self.action[i] = task, mask, rem, action
        self.ret[i], self.next_mask[i], self.next_rem[i] = ret, next_mask, next_rem
        self.done[i], self.disc[i] = done, disc
        self.pos = (i + 1) % self.size
        self.full = self.full or self.pos == 0

    def sample(self, rng: np.random.Generator, k: int) -> np.ndarray:
        return rng.integers(len(self), size=k)

    def state_dict(self) -> dict:
        """Tensors and plain values only (a checkpoint is loaded with ``weights_only=True``)."""
        return {k: torch.from_numpy(v.copy()) if isinstance(v, np.ndarray) else v
                for k, v in vars(self).items()}  # fmt: skip

    def load_state_dict(self, d: dict) -> None:
        arrays = {k: v for k, v in vars(self).items() if isinstance(v, np.ndarray)}
        for k, v in d.items():
            if k in arrays:
                v = np.asarray(v.numpy(), dtype=arrays[k].dtype)
                if v.shape != arrays[k].shape:
                    raise ValueError(f"replay memory {k}: shape {v.shape} != {arrays[k].shape}")
            setattr(self, k, v)


class NStep:
    """Turns one episode's steps into n-step transitions (returns discounted by γ)."""

    def __init__(self, n: int, gamma: float):
        self.n, self.gamma, self.steps = n, gamma, []

    def push(self, memory, task, mask, rem, action, reward, next_mask, next_rem, done, expert=None):
        self.steps.append((task, mask, rem, action, reward, expert))
        if done:
            while self.steps:
                self._emit(memory, next_mask, next_rem, True)
        elif len(self.steps) == self.n:
            self._emit(memory, next_mask, next_rem, False)

    def _emit(self, memory, next_mask, next_rem, done):
        task, mask, rem, action, _, expert = self.steps[0]
        ret = sum(self.gamma**k * s[4] for k, s in enumerate(self.steps))
        disc = self.gamma ** len(self.steps)
        memory.add(task, mask, rem, action, ret, next_mask, next_rem, done, disc, expert)
        self.steps.pop(0)

    def clear(self):
        self.steps = []
