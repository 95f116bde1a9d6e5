"""An episode for learners: what replays a simulation exactly, at the control rate.

A simulation (``sim.simulate.controller.track``) runs ``T`` control ticks; at each tick ``k``
the controller sets ``data.ctrl`` (the action), ``data.xfrc_applied`` (the pushes: a wrench per
body, world frame, force [N] then torque [N m]) and ``data.qfrc_applied`` (root assistance,
where a task asks for it: generalised force [N, N m]), and the position actuators act with the
feedback gains of that tick (a controller may choose them per window:
``sim.simulate.gainchoice``), then MuJoCo takes :data:`FRAME_SKIP` physics steps (``mj_step``).
:class:`Recorder` keeps all of it (as it acts on the model its MJCF builds: :class:`Recorder`'s
note on a controller that scales its actuators) plus the full integration state before the
first tick (``mj_getState`` with ``mjSTATE_INTEGRATION``: time, ``qpos``, ``qvel``, ``act``,
warm start, controls and applied forces) and ``qpos``/``qvel`` before every tick and after the
last. :func:`replay` rebuilds the model from its MJCF and steps the stored actions, gains and
wrenches from the stored first state: every state it reaches equals the stored one bit for bit
(tested on every kind).

**The action of a body with position actuators** is a variable-impedance action: per actuator
the PD target [rad] (``data.ctrl``, inside the MJCF's control range) and the feedback gains
``kp`` [N m/rad] and ``kv`` [N m s/rad] of the tick, the actuator applying ``kp (target - q) -
kv qdot`` clamped to the human torque limit (the MJCF's ``forcerange``, which no gain changes);
:func:`set_gains` writes a tick's gains into the model (``gainprm[0] = kp``, ``biasprm[1:3] =
-kp, -kv``: MuJoCo's position actuator). :func:`impedance_actions` joins targets and gains
into one (T, 3 U) array (the Minari export's actions), :func:`split_actions` parts them.
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
        gains: (T, 2, nu) the position actuators' ``kp`` [N m/rad] and ``kv`` [N m s/rad] at
            each tick (module docstring); None for torque actuators.
    """

    mjcf: str
    frame_skip: int
    initial_state: np.ndarray
    actions: np.ndarray
    xfrc_applied: np.ndarray
    qfrc_applied: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    gains: np.ndarray | None = None


def is_position(model) -> bool:
    """Whether ``model``'s actuators are PD servos (``sim_spec``'s ``"position"``: the action a
    target angle) rather than torque actuators (``"motor"``)."""
    return bool(model.actuator_biasprm[:, 1].any())


def pd_gains(model) -> np.ndarray | None:
    """(2, nu) ``kp`` and ``kv`` of ``model``'s position actuators, or None where one is not
    a plain PD servo (``kp (ctrl - q) - kv qdot``: gain ``kp``, bias ``0, -kp, -kv``, nothing
    else), which :func:`set_gains` could not rebuild."""
    kp, bias = model.actuator_gainprm[:, 0], model.actuator_biasprm
    plain = (
        not model.actuator_gainprm[:, 1:].any()
        and not bias[:, 0].any()
        and not bias[:, 3:].any()
        and np.array_equal(bias[:, 1], -kp)
    )
    return np.stack([kp, -bias[:, 2]]) if plain else None


def set_gains(model, gains: np.ndarray) -> None:
    """Make ``model``'s position actuators PD servos with ``gains`` (2, nu): ``kp`` [N m/rad],
    ``kv`` [N m s/rad] (in place; the control and force ranges are left as they are)."""
    model.actuator_gainprm[:, 0] = gains[0]
    model.actuator_biasprm[:, 1] = -gains[0]
    model.actuator_biasprm[:, 2] = -gains[1]


def impedance_actions(actions: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """(T, 3 nu) the variable-impedance actions: targets ``actions`` (T, nu) [rad], then ``kp``
    and ``kv`` of ``gains`` (T, 2, nu)."""
    return np.concatenate([actions, gains[:, 0], gains[:, 1]], axis=1)


def split_actions(actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The targets (T, nu) and gains (T, 2, nu) of variable-impedance ``actions`` (T, 3 nu)
    (:func:`impedance_actions`)."""
    actions = np.asarray(actions, dtype=np.float64)
    if actions.ndim != 2 or actions.shape[1] % 3:
        raise UsageError(f"impedance actions of shape {actions.shape}: expected (T, 3 nu)")
    nu = actions.shape[1] // 3
    return actions[:, :nu], np.stack([actions[:, nu : 2 * nu], actions[:, 2 * nu :]], axis=1)


class Recorder:
    """Called by the controller as ``recorder(k, data, model)`` at each tick ``k`` < ``ticks``,
    just before its physics steps (``model``: the one whose gains act this tick, the recorder's
    own body with other gains where the controller switches them; None: the recorder's own),
    and as ``recorder(ticks, data, model)`` after the last; :meth:`episode` then holds what was
    recorded.

    The action recorded is what acts on the model as its MJCF builds it, with the tick's gains
    (:func:`set_gains`): position actuators must stay PD servos of the same body (control
    range within the MJCF's, torque limits unchanged; anything else is refused: it would not
    replay). A controller that scaled torque actuators while it simulates (none does now: the
    whole-body QP weakens by bounding its torques) has the torque that acts recorded,
    ``clip(gain * clip(ctrl, ctrl range), force range)`` as MuJoCo computes it, which the
    unedited model applies unchanged (the same product, bit for bit).
    """

    def __init__(self, model, mjcf: str, ticks: int, frame_skip: int = FRAME_SKIP):
        self.mjcf, self.frame_skip, self.ticks = mjcf, frame_skip, ticks
        self.state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
        self.ctrl = np.empty((ticks, model.nu))
        self.xfrc = np.empty((ticks, model.nbody, 6))
        self.qfrc = np.empty((ticks, model.nv))
        self.qpos = np.empty((ticks + 1, model.nq))
        self.qvel = np.empty((ticks + 1, model.nv))
        self.gains = np.empty((ticks, 2, model.nu)) if is_position(model) else None
        self._model = model
        self._seen = 0
        self._gain = model.actuator_gainprm[:, 0].copy()
        self._bias = model.actuator_biasprm[:, :3].copy()
        self._force = model.actuator_forcerange.copy()
        self._range = model.actuator_ctrlrange.copy()
        self._armature = model.dof_armature.copy()

    def __call__(self, k: int, data, model=None) -> None:
        if k != self._seen or k > self.ticks:
            raise UsageError(f"tick {k} recorded out of order (expected {self._seen})")
        if k == 0:
            mujoco.mj_getState(self._model, data, self.state, STATE_SPEC)
        self.qpos[k], self.qvel[k] = data.qpos, data.qvel
        if k < self.ticks:
            m = self._model if model is None else model
            if not (
                np.array_equal(m.actuator_forcerange, self._force)
                and np.array_equal(m.dof_armature, self._armature)
            ):
                raise UsageError("another body or other torque limits: it would not replay")
            if self.gains is None:
                self.ctrl[k] = self._acting_torque(m, data.ctrl)
            else:
                self.ctrl[k], self.gains[k] = self._acting_target(m, data.ctrl)
            self.xfrc[k] = data.xfrc_applied
            self.qfrc[k] = data.qfrc_applied
        self._seen += 1

    def _acting_target(self, m, ctrl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The target (nu,) that acts as ``ctrl`` does now on ``m`` (MuJoCo clamps a control to
        its range before it acts, so the clamped value acts the same, bit for bit) and
        ``m``'s gains (2, nu) (:func:`pd_gains`)."""
        gains = pd_gains(m)
        if gains is None or not m.actuator_ctrllimited.all():
            raise UsageError("position actuators edited out of PD servos: it would not replay")
        ctrl = np.clip(ctrl, m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])
        if np.any(ctrl < self._range[:, 0]) or np.any(ctrl > self._range[:, 1]):
            raise UsageError("a target outside the MJCF's control range: it would not replay")
        return ctrl, gains

    def _acting_torque(self, m, ctrl: np.ndarray) -> np.ndarray:
        """(nu,) the control of torque actuators that acts as ``ctrl`` does now on ``m``,
        folded with any scaling of the actuators (class note)."""
        lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
        limited = m.actuator_ctrllimited.astype(bool)
        ctrl = np.where(limited, np.clip(ctrl, lo, hi), ctrl)
        gain, bias = m.actuator_gainprm[:, 0], m.actuator_biasprm[:, :3]
        if np.array_equal(gain, self._gain) and np.array_equal(bias, self._bias):
            return ctrl
        if bias.any() or np.any(self._gain != 1.0) or not limited.all():
            raise UsageError("torque actuators edited during a simulation: it would not replay")
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
                       self.qpos, self.qvel, self.gains)  # fmt: skip


def replay(
    mjcf: str,
    initial_state: np.ndarray,
    actions: np.ndarray,
    xfrc_applied: np.ndarray,
    qfrc_applied: np.ndarray,
    frame_skip: int = FRAME_SKIP,
    gains: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Step the stored ``actions`` (T, nu) and applied wrenches (``xfrc_applied`` (T, nbody, 6),
    ``qfrc_applied`` (T, nv)) through ``mj_step`` from ``initial_state`` on the model of
    ``mjcf``, ``frame_skip`` physics steps per action, each tick's position-actuator gains
    ``gains[k]`` (T, 2, nu) set first (:func:`set_gains`; None: the MJCF's throughout).

    Returns:
        (T + 1, nq) ``qpos`` and (T + 1, nv) ``qvel``: the state before each action and after the
        last.
    """
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, np.asarray(initial_state, dtype=np.float64), STATE_SPEC)
    T = len(actions)
    if gains is not None and np.shape(gains) != (T, 2, model.nu):
        raise UsageError(f"gains of shape {np.shape(gains)}: expected ({T}, 2, {model.nu})")
    qpos, qvel = np.empty((T + 1, model.nq)), np.empty((T + 1, model.nv))
    for k in range(T):
        qpos[k], qvel[k] = data.qpos, data.qvel
        if gains is not None:
            set_gains(model, gains[k])
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
