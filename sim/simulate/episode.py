"""An episode for learners: what replays a simulation exactly, at the control rate.

A simulation (``sim.simulate.controller.track``) runs ``T`` control ticks; at each tick ``k``
the controller sets ``data.ctrl`` (the action), ``data.xfrc_applied`` (the pushes: a wrench per
body, world frame, force [N] then torque [N m]) and ``data.qfrc_applied`` (root assistance,
where a task asks for it: generalised force [N, N m]), then MuJoCo takes :data:`FRAME_SKIP`
physics steps (``mj_step``). :class:`Recorder` keeps all of it (as it acts on the model its
MJCF builds: :class:`Recorder`'s note on a controller that scales its actuators) plus
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
    :meth:`episode` then holds what was recorded.

    The action recorded is what acts on the model as its MJCF builds it. A controller that
    scaled the actuators while it simulates would change what a control does (none does now:
    the whole-body QP weakens by bounding its torques); for torque actuators (gain 1, no
    bias) the recorded action is then the torque that acts, ``clip(gain * clip(ctrl, ctrl
    range), force range)`` as MuJoCo computes it, which the unedited model applies unchanged
    (the same product, bit for bit), so the episode still replays from its MJCF. An edited
    position actuator cannot be folded into its control: refused.
    """

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
        self._gain = model.actuator_gainprm[:, 0].copy()
        self._bias = model.actuator_biasprm[:, :3].copy()
        self._force = model.actuator_forcerange.copy()

    def __call__(self, k: int, data) -> None:
        if k != self._seen or k > self.ticks:
            raise UsageError(f"tick {k} recorded out of order (expected {self._seen})")
        if k == 0:
            mujoco.mj_getState(self._model, data, self.state, STATE_SPEC)
        self.qpos[k], self.qvel[k] = data.qpos, data.qvel
        if k < self.ticks:
            self.ctrl[k], self.xfrc[k] = self._acting(data.ctrl), data.xfrc_applied
            self.qfrc[k] = data.qfrc_applied
        self._seen += 1

    def _acting(self, ctrl: np.ndarray) -> np.ndarray:
        """(nu,) the control that acts as ``ctrl`` does now, on the model as it was built: inside
        the control range (MuJoCo clamps a control to it before it acts, so the clamped value
        acts the same, bit for bit), folded with any scaling of the actuators (class note)."""
        m = self._model
        lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
        limited = m.actuator_ctrllimited.astype(bool)
        ctrl = np.where(limited, np.clip(ctrl, lo, hi), ctrl)
        gain, bias = m.actuator_gainprm[:, 0], m.actuator_biasprm[:, :3]
        if (
            np.array_equal(gain, self._gain)
            and np.array_equal(bias, self._bias)
            and np.array_equal(m.actuator_forcerange, self._force)
        ):
            return ctrl
        if self._bias.any() or bias.any() or np.any(self._gain != 1.0) or not limited.all():
            raise UsageError("position actuators edited during a simulation: it would not replay")
        force = np.clip(gain * ctrl, *m.actuator_forcerange.T)
        if np.any(force < np.maximum(lo, self._force[:, 0])) or np.any(
            force > np.minimum(hi, self._force[:, 1])
        ):
            raise UsageError("actuators strengthened during a simulation: it would not replay")
        return force

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
