"""The sampler's bookkeeping between windows (``sim.simulate.sampling``,
``sim.simulate.gainchoice``): the first state, the window's check against the balance feedback,
and the cheapest path traced back through the kept states."""

from __future__ import annotations

import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.balance import Balance


def backtrack(history, T: int, window: int, nu: int, nq: int):
    """The cheapest final state's offsets (T, nu) and window-end ``qpos`` (W, nq), window by
    window back to the start through ``history`` (per window, of the kept states: parent index,
    offset, ``qpos`` reached; the cheapest kept first)."""
    offsets = np.zeros((T, nu))
    window_qpos = np.empty((len(history), nq))
    j = 0
    for w in range(len(history) - 1, -1, -1):
        parent, off, reached = history[w]
        offsets[w * window : min(T, (w + 1) * window)] = off[j]
        window_qpos[w] = reached[j]
        j = parent[j]
    return offsets, window_qpos


def check_window(window: int, balance: Balance | None) -> None:
    """Refuse windows that start between two updates of the balance feedback (a rollout could
    not start where the replay holds torques computed before it)."""
    if balance is not None and window % balance.every:
        raise UsageError(
            f"window ({window} ticks) must be a multiple of Balance.every ({balance.every}): "
            "a rollout starts where the replay updates its feedback"
        )


def first_state(model, data, qpos: np.ndarray, qvel: np.ndarray, spec) -> np.ndarray:
    """(1, state size) the full state of ``data`` reset to ``qpos`` (nq,) and ``qvel`` (nv,)."""
    mujoco.mj_resetData(model, data)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    state = np.empty((1, mujoco.mj_stateSize(model, spec)))
    mujoco.mj_getState(model, data, state[0], spec)
    return state
