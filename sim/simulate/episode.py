"""An episode for learners: what replays a simulation exactly, at the control rate.

A simulation (``sim.simulate.controller.track``) runs ``T`` control ticks; at each tick ``k``
the controller sets ``data.ctrl`` (the action), ``data.xfrc_applied`` (the pushes: a wrench per
body, world frame, force [N] then torque [N m]) and ``data.qfrc_applied`` (root assistance,
where a task asks for it: generalised force [N, N m]), then MuJoCo takes :data:`FRAME_SKIP`
physics steps (``mj_step``) with the model unchanged. :class:`Recorder` keeps all of it plus
the full integration state before the first tick (``mj_getState`` with
``mjSTATE_INTEGRATION``: time, ``qpos``, ``qvel``, ``act``, warm start, controls and applied
forces) and ``qpos``/``qvel`` before every tick and after the last. :func:`replay` rebuilds the
model from its MJCF and steps the stored actions and wrenches from the stored first state:
every state it reaches equals the stored one bit for bit (tested on every kind).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.model import SUBSTEPS

#: physics steps per action (control tick)
FRAME_SKIP = SUBSTEPS
#: the part of ``MjData`` an episode's first state holds
STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION


@dataclass(frozen=True)
class Episode:
    """One simulation at the control rate.

    Attributes:
        mjcf: the body's MJCF (``MjSpec.to_xml``); the model it compiles to is the one simulated.
        frame_skip: physics steps per action.
        initial_state: (S,) ``mj_getState(..., mjSTATE_INTEGRATION)`` before the first tick.
        actions: (T, nu) ``data.ctrl`` at each tick, inside the actuators' control range.
        xfrc_applied: (T, nbody, 6) applied body wrenches at each tick (world frame).
        qfrc_applied: (T, nv) applied generalised forces at each tick.
        qpos: (T + 1, nq) and qvel: (T + 1, nv): the state before each tick and after the last.
    """

    mjcf: str
    frame_skip: int
    initial_state: np.ndarray
    actions: np.ndarray
    xfrc_applied: np.ndarray
    qfrc_applied: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray


class Recorder:
    """Called by the controller as ``recorder(k, data)`` at each tick ``k`` < ``ticks``, just
    before its physics steps, and as ``recorder(ticks, data)`` after the last;
    :meth:`episode` then holds what was recorded."""

    def __init__(self, model, mjcf: str, ticks: int, frame_skip: int = FRAME_SKIP):
        self.mjcf, self.frame_skip, self.ticks = mjcf, frame_skip, ticks
        self.state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
        self.ctrl = np.empty((ticks, model.nu))
        self.xfrc = np.empty((ticks, model.nbody, 6))
        self.qfrc = np.empty((ticks, model.nv))
        self.qpos = np.empty((ticks + 1, model.nq))
        self.qvel = np.empty((ticks + 1, model.nv))
        self._model = model
        self._seen = 0

    def __call__(self, k: int, data) -> None:
        if k != self._seen or k > self.ticks:
            raise UsageError(f"tick {k} recorded out of order (expected {self._seen})")
        if k == 0:
            mujoco.mj_getState(self._model, data, self.state, STATE_SPEC)
        self.qpos[k], self.qvel[k] = data.qpos, data.qvel
        if k < self.ticks:
            self.ctrl[k], self.xfrc[k] = data.ctrl, data.xfrc_applied
            self.qfrc[k] = data.qfrc_applied
        self._seen += 1

    def episode(self) -> Episode:
        """The recorded :class:`Episode` (every tick must have been seen)."""
        if self._seen != self.ticks + 1:
            raise UsageError(f"{self._seen} of {self.ticks + 1} ticks recorded")
        return Episode(self.mjcf, self.frame_skip, self.state, self.ctrl, self.xfrc, self.qfrc,
                       self.qpos, self.qvel)  # fmt: skip


def replay(
    mjcf: str,
    initial_state: np.ndarray,
    actions: np.ndarray,
    xfrc_applied: np.ndarray,
    qfrc_applied: np.ndarray,
    frame_skip: int = FRAME_SKIP,
) -> tuple[np.ndarray, np.ndarray]:
    """Step the stored ``actions`` (T, nu) and applied wrenches (``xfrc_applied`` (T, nbody, 6),
    ``qfrc_applied`` (T, nv)) through ``mj_step`` from ``initial_state`` on the model of
    ``mjcf``, ``frame_skip`` physics steps per action.

    Returns:
        (T + 1, nq) ``qpos`` and (T + 1, nv) ``qvel``: the state before each action and after the
        last.
    """
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, np.asarray(initial_state, dtype=np.float64), STATE_SPEC)
    T = len(actions)
    qpos, qvel = np.empty((T + 1, model.nq)), np.empty((T + 1, model.nv))
    for k in range(T):
        qpos[k], qvel[k] = data.qpos, data.qvel
        data.ctrl[:], data.xfrc_applied[:], data.qfrc_applied[:] = (
            actions[k], xfrc_applied[k], qfrc_applied[k]
        )  # fmt: skip
        mujoco.mj_step(model, data, nstep=frame_skip)
    qpos[T], qvel[T] = data.qpos, data.qvel
    return qpos, qvel


def text_array(text: str) -> np.ndarray:
    """(n,) uint8: ``text`` as UTF-8 bytes, the way a clip file stores a long text (its reader
    bounds string items to names)."""
    return np.frombuffer(text.encode(), dtype=np.uint8).copy()


def array_text(array: np.ndarray) -> str:
    """The text :func:`text_array` stored."""
    return np.asarray(array, dtype=np.uint8).tobytes().decode()


def torque_limits(model) -> np.ndarray:
    """(nu,) each actuator's torque limit [N m] in ``model`` (its force range; the human peak
    torque of its hinge, ``sim.simulate.model.human_torque_limit``): the one place this data
    side reads it."""
    return model.actuator_forcerange[:, 1].copy()
