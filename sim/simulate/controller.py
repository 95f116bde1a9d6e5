"""A tracking controller for the humanoid in MuJoCo's forward simulation (``mj_step``).

Before the run, for the whole reference (a ``qpos`` stream at 120 Hz):

1. **Inverse-dynamics feed-forward.** ``mujoco.mj_inverse`` of the reference, free-floating (no
   contacts), gives hinge torques and the 6-d root wrench the motion needs from outside;
   ``sim.simulate.feedforward.contact_feedforward`` moves that root force onto the foot and toe capsules near the floor
   (shared, upward only, inside a friction cone): stance legs now carry the body, and the root
   keeps only what the floor cannot give.

Every control tick (``sim.simulate.model.SUBSTEPS`` physics steps each):

2. **Hinge actuators.** Position actuators (``sim.simulate.model``: human joint stiffness and
   damping) pull each hinge to its reference angle and velocity (the target leads by ``kv / kp``
   times the reference velocity) and carry the feed-forward torque too (the target is moved by
   ``ff / kp``), so MuJoCo clamps the whole joint torque to the joint's human limit
   (``forcelimited``): no torque outside the actuators acts on a hinge.
3. **Bounded root assistance, only on the floor.** A person has no motor at the pelvis: the
   residual root wrench plus a PD pull of the pelvis towards its reference pose is the help the
   motion needs that its joints and the floor do not give. It acts only while some body geom
   touches the floor (MuJoCo's contacts of the last step; in flight the body is on its own),
   clipped to ``assist_limit`` times the body weight (force) and that times
   ``ROOT_TORQUE_LEVER`` (torque); its 6-d wrench is recorded every tick: the honest label of
   how much help the motion needed.

4. **A fall stays down.** Once the body has fallen (``sim.simulate.falls``: a part other than
   the feet on the floor where the reference has none, or the head below half the
   reference's), the assistance stops for good and the joints hold the pose of the fall at
   :data:`FALLEN_TONE` of their effort, without feed-forward: the body settles on the floor (a
   get-up is not generated).

External pushes (``xfrc_applied`` on a body for a while) and a weakened controller (its effort
and the assistance scaled down for a while: :func:`effort_target`) perturb the motion. The model
is never edited while it is simulated (the torque limits are anatomy: no weakening or gain
changes them), so the controls, applied forces and first state a ``recorder`` sees replay the
simulation exactly (``sim.simulate.episode``). Recorded states are the simulator's own ``qpos``
and ``qvel``, never differences. Inverse dynamics without contacts edits the model's flags:
:class:`ActuatorEdits` owns that edit and restores it however it ends.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from sim.simulate.balance import Balance, balance_plan, held_torques
from sim.simulate.falls import fall_reference, has_fallen
from sim.simulate.feedforward import reference_feedforward
from sim.simulate.model import CONTROL_HZ, SUBSTEPS, G, Gains, total_mass
from sim.simulate.tracking import Tracking, TrackRecord, floor_ids, foot_forces, foot_sides

ROOT_TORQUE_LEVER = 1.0  # [m]: root torque bound = assist_limit * body weight * this lever
FALLEN_TONE = 0.3  # share of effort with which a fallen body holds its pose


@dataclass(frozen=True)
class Push:
    """A constant force [N] on ``body`` (world frame) from ``start`` for ``duration`` seconds;
    its impulse is ``force * duration`` [N s]."""

    body: str
    start: float
    duration: float
    force: tuple[float, float, float]

    @property
    def impulse(self) -> np.ndarray:
        return np.asarray(self.force) * self.duration


@dataclass(frozen=True)
class Weakening:
    """From ``start`` for ``duration`` seconds the controller's effort (:func:`effort_target`)
    and root assistance are multiplied by ``factor`` (0..1); the torque limits stay."""

    start: float
    duration: float
    factor: float


class ActuatorEdits:
    """The owner of temporary changes to a model: the disabled-feature flags (inverse dynamics
    without contacts; no controller edits its actuators while it simulates: a model edited
    during a simulation does not replay from its MJCF), and the actuator gains, biases and force
    limits are restored too. A context manager: on exit,
    however reached, the model holds exactly the values it had on entry.
    """

    def __init__(self, model):
        self.model = model

    def __enter__(self) -> ActuatorEdits:
        m = self.model
        self._gain = m.actuator_gainprm[:, 0].copy()
        self._bias = m.actuator_biasprm[:, :3].copy()
        self._range = m.actuator_forcerange.copy()
        self._flags = int(m.opt.disableflags)
        return self

    def without_contacts(self) -> None:
        """Disable contacts (until exit)."""
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT

    def __exit__(self, *exc) -> None:
        m = self.model
        m.actuator_gainprm[:, 0] = self._gain
        m.actuator_biasprm[:, :3] = self._bias
        m.actuator_forcerange[:] = self._range
        m.opt.disableflags = self._flags


def effort_target(target: np.ndarray, q: np.ndarray, effort: float) -> np.ndarray:
    """(nu,) hinge targets [rad] of a controller working at ``effort`` (0..1): moved from the
    current angles ``q`` (nu,) towards ``target`` (nu,) by that share, so the pull of the PD
    and the feed-forward folded into the target scale with it (a joint's damping stays: a
    weakened muscle is still viscous; its torque limit stays: anatomy). ``effort`` 1:
    ``target`` itself."""
    return target if effort == 1.0 else q + effort * (target - q)


def set_controls(model, data, target: np.ndarray, effort: float) -> None:
    """``data.ctrl`` = :func:`effort_target` of ``target`` (nu,) [rad] from ``data``'s hinge
    angles, clipped to the actuators' control range (``sim.simulate.model.sim_spec``; MuJoCo
    would clip it there too, so ``data.ctrl`` holds exactly what acts)."""
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    np.maximum(effort_target(target, data.qpos[7:], effort), lo, out=data.ctrl)
    np.minimum(data.ctrl, hi, out=data.ctrl)  # np.clip's result, without its overhead


def _root_inertia(model, qpos, data) -> np.ndarray:
    """(6, 6) the free joint's block of the mass matrix at ``qpos`` (whole-body mass and
    rotational inertia), without its force-rotation coupling: rotation errors of a jittery
    mocap pelvis must not turn into assistance force. ``data`` is overwritten."""
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    out = M[:6, :6].copy()
    out[:3, 3:] = out[3:, :3] = 0.0  # block-diagonal: the force pulls the position only
    return out


def _floor_contact(data, floor) -> bool:
    """Whether any contact of ``data``'s last step involves a geom of ``floor`` (ids:
    ``tracking.floor_ids``, the floor and the scene's terrain boxes)."""
    n = data.ncon
    if not n:
        return False
    return bool(np.isin(data.contact.geom[:n], floor).any())


def weakening_factor(weakenings: tuple[Weakening, ...], t: float) -> float:
    """The controller's strength share at time ``t`` [s]: the smallest factor of the weakenings
    acting then, 1 if none."""
    factor = 1.0
    for w in weakenings:
        if w.start <= t < w.start + w.duration:
            factor = min(factor, w.factor)
    return factor


def apply_pushes(data, pushes: tuple[Push, ...], body_ids, t: float) -> None:
    """Set ``data.xfrc_applied`` to the pushes acting at time ``t`` [s] (``body_ids``: each
    push's body id); every other body's external force is cleared."""
    data.xfrc_applied[:] = 0.0
    for p, b in zip(pushes, body_ids, strict=True):
        if p.start <= t < p.start + p.duration:
            data.xfrc_applied[b, :3] += p.force


def _root_assistance(
    ff_root: np.ndarray, root_inertia: np.ndarray, root_acc: np.ndarray, fmax: float
) -> tuple[np.ndarray, np.ndarray]:
    """The root assistance: force (3,) [N] and torque (3,) [N m] of the reference's residual
    root wrench ``ff_root`` (6,) plus ``root_inertia`` (6, 6) times the PD pull ``root_acc``
    (6,), the force's norm clipped to ``fmax`` [N], the torque's to ``fmax`` times
    :data:`ROOT_TORQUE_LEVER`."""
    wrench = ff_root + root_inertia @ root_acc
    force, torque = wrench[:3], wrench[3:]
    tmax = fmax * ROOT_TORQUE_LEVER
    fn, tn = np.linalg.norm(force), np.linalg.norm(torque)
    if fn > fmax:
        force *= fmax / fn
    if tn > tmax:
        torque *= tmax / tn
    return force, torque


@dataclass(frozen=True)
class _Plan:
    """What ``track`` computes before its simulation: the reference's velocities (T, nv) and
    inverse-dynamics feed-forward (T, nv), the root's inertia block (6, 6), the fall reference,
    the actuators' stiffness ``kp`` (nu,) and target lead ``kv / kp`` (nu,) [s], the root PD's
    gains, the body weight [N], the floor's geom id, the foot geoms' sides and the pushes' body
    ids."""

    ref_qvel: np.ndarray
    ref_force: np.ndarray
    root_inertia: np.ndarray
    fall_ref: object
    kp: np.ndarray
    lead: np.ndarray
    kp_r: float
    kd_r: float
    weight: float
    floor: np.ndarray  # the floor geom and the terrain boxes (tracking.floor_ids)
    side: np.ndarray
    push_ids: list


def _plan(model, ref_qpos: np.ndarray, gains: Gains, pushes: tuple[Push, ...], data) -> _Plan:
    """:class:`_Plan` of tracking ``ref_qpos`` (T, nq); ``data`` is used, then left in the
    reference's first state (position and velocity, ``mj_forward`` done)."""
    ref_qvel, ref_force = reference_feedforward(model, ref_qpos, data)
    root_inertia = _root_inertia(model, ref_qpos[0], data)
    fall_ref = fall_reference(model, ref_qpos)
    mujoco.mj_resetData(model, data)
    data.qpos[:] = ref_qpos[0]
    data.qvel[:] = ref_qvel[0]
    mujoco.mj_forward(model, data)
    return _Plan(
        ref_qvel=ref_qvel,
        ref_force=ref_force,
        root_inertia=root_inertia,
        fall_ref=fall_ref,
        kp=model.actuator_gainprm[:, 0].copy(),
        lead=model.actuator_biasprm[:, 2] / model.actuator_biasprm[:, 1],  # kv / kp [s]
        kp_r=gains.root_omega**2,
        kd_r=2 * gains.root_zeta * gains.root_omega,
        weight=total_mass(model) * G,
        floor=floor_ids(model),
        side=foot_sides(model),
        push_ids=[model.body(p.body).id for p in pushes],
    )


def _root_pull(plan: _Plan, q_ref: np.ndarray, v_ref: np.ndarray, data) -> np.ndarray:
    """(6,) the root's PD acceleration towards ``q_ref`` (nq,) and ``v_ref`` (nv,): linear
    [m/s^2] and angular [rad/s^2] (the orientation error by ``mju_subQuat``)."""
    rot_err = np.zeros(3)
    root_acc = np.zeros(6)
    mujoco.mju_subQuat(rot_err, q_ref[3:7], data.qpos[3:7])
    root_acc[:3] = plan.kp_r * (q_ref[:3] - data.qpos[:3]) + plan.kd_r * (v_ref[:3] - data.qvel[:3])
    root_acc[3:] = plan.kp_r * rot_err + plan.kd_r * (v_ref[3:6] - data.qvel[3:6])
    return root_acc


def _control_tick(model, data, plan: _Plan, ref_qpos, k: int, target, factor, assist) -> None:
    """Set tick ``k``'s controls: hinge ``target`` (nu,) [rad] at effort ``factor``, and the
    root assistance bounded by ``assist`` body weights (0: none) in ``data.qfrc_applied``."""
    set_controls(model, data, target, factor)
    if assist > 0:
        root_acc = _root_pull(plan, ref_qpos[k], plan.ref_qvel[k], data)
        fmax = factor * assist * plan.weight
        force, torque = _root_assistance(plan.ref_force[k][:6], plan.root_inertia, root_acc, fmax)
    else:
        force, torque = np.zeros(3), np.zeros(3)
    data.qfrc_applied[:3] = force
    data.qfrc_applied[3:6] = torque


def _target(model, data, plan: _Plan, ref_qpos, k: int, offsets, balance, feedback=None):
    """(nu,) tick ``k``'s hinge targets [rad] of a body that is up. The actuator carries PD and
    feed-forward, MuJoCo clamps their sum: the target leads by kv/kp * v_ref (kp (q_ref - q) +
    kv (v_ref - v) applied) and by ff / kp; plus ``offsets[k]`` (None: none) and the balance
    feedback's torques over kp (``balance``: (its plan, (nu,) the torques held from tick to
    tick, updated here) or None) after ``feedback(model, data, k)`` (None: none)."""
    target = ref_qpos[k, 7:] + plan.lead * plan.ref_qvel[k, 6:] + plan.ref_force[k, 6:] / plan.kp
    if offsets is not None:
        target += offsets[k]
    if feedback is not None:
        target += feedback(model, data, k)
    if balance is not None:
        target += held_torques(model, data, balance[0], k, balance[1]) / plan.kp
    return target


def _switched(model, plan: _Plan, switch, T: int) -> tuple[list, list, np.ndarray]:
    """The models of ``switch`` = (models, choice), their plans (``plan`` with each model's
    ``kp`` and ``kv / kp``) and the (T,) choice; ([model], [plan], zeros) where it is None."""
    if switch is None:
        return [model], [plan], np.zeros(T, dtype=int)
    models = list(switch[0])
    plans = [
        replace(plan, kp=m.actuator_gainprm[:, 0].copy(),
                lead=m.actuator_biasprm[:, 2] / m.actuator_biasprm[:, 1])
        for m in models
    ]  # fmt: skip
    return models, plans, np.asarray(switch[1], dtype=int)


def track(
    model,
    ref_qpos: np.ndarray,
    *,
    gains: Gains | None = None,
    assist_limit: float = 0.0,
    assist_in_flight: bool = False,
    pushes: tuple[Push, ...] = (),
    weakenings: tuple[Weakening, ...] = (),
    record_every: int = 4,
    offsets: np.ndarray | None = None,
    balance: Balance | None = None,
    recorder=None,
    switch: tuple | None = None,
    feedback=None,
) -> Tracking:
    """Simulate ``model`` following ``ref_qpos`` (T, nq) sampled at ``CONTROL_HZ``: a
    :class:`sim.simulate.tracking.Tracking`, states at ticks 0, record_every, 2 record_every...

    Starts in the reference's first pose and velocity; ``model``: a ``sim_model`` (its
    actuators' gains are read, never edited). A fall is ``sim.simulate.falls``'s, checked every
    control tick; ``fall_frame`` is the first recorded frame at or after it.

    Args:
        gains: only its root gains are read here (the hinge gains live in ``model``'s actuators).
        assist_limit: root assistance bound [body weight]; 0 (the default): none. The
            assistance is an external force: only on explicit request, and recorded.
        assist_in_flight: let the assistance act when nothing touches the floor too (a hand
            holding the body up: only for tests of the audit that must see such a hand).
        record_every: ticks between recorded states (4: the 30 fps clip rate).
        offsets: (T, nu) [rad] added to the hinge targets at each tick while the body is up
            (the corrections a sampling controller found: ``sim.simulate.sampling``); None: none.
        balance: gains of the balance feedback (``sim.simulate.balance``) whose torques are
            added to the targets (as ``tau / kp``) while the body is up; None: none.
        recorder: ``recorder(k, data, model)`` at each tick ``k`` before its physics steps
            (controls, forces and the tick's model, ``switch``'s, set) and ``recorder(T, data,
            model)`` after the last (``sim.simulate.episode.Recorder``); None: none.
        switch: (models, choice (T,) ints): tick ``k`` runs on ``models[choice[k]]``,
            ``model``'s body with other gains (``sim.simulate.gainchoice``); None: ``model``.
        feedback: ``feedback(model, data, k)`` (nu,) [rad] added after ``offsets``; None: none.
    """
    T = ref_qpos.shape[0]
    data = mujoco.MjData(model)  # the one MjData: precomputation first, then the simulation
    plan = _plan(model, ref_qpos, gains or Gains(), pushes, data)
    rec = TrackRecord(model, T, record_every)
    fell, fallen_pose, dt = False, None, 1.0 / CONTROL_HZ
    bal = balance and (balance_plan(model, ref_qpos, plan.ref_qvel, balance), np.zeros(model.nu))
    models, plans, which = _switched(model, plan, switch, T)
    for k in range(T):
        t = k * dt
        model, plan = models[which[k]], plans[which[k]]  # this tick's gains (the same body)
        factor = weakening_factor(weakenings, t)
        if fell:  # down: the joints hold the pose of the fall with a lying body's tone
            factor = min(factor, FALLEN_TONE)
            target = fallen_pose  # no tracking of a standing motion, no feed-forward
        else:  # PD, feed-forward, offsets and balance feedback
            target = _target(model, data, plan, ref_qpos, k, offsets, bal, feedback)
        helped = rec.fall_frame < 0 and assist_limit > 0  # a fallen body gets no help up
        on = helped and (assist_in_flight or _floor_contact(data, plan.floor))
        _control_tick(model, data, plan, ref_qpos, k, target, factor, assist_limit if on else 0.0)
        rec.assist[k] = np.linalg.norm(data.qfrc_applied[:3]) / plan.weight
        rec.wrench[k] = data.qfrc_applied[:6]
        apply_pushes(data, pushes, plan.push_ids, t)
        if (i := k // record_every if k % record_every == 0 else None) is not None:
            rec.state(i, data)  # a recorded tick's frame
        if not fell and has_fallen(model, data, plan.fall_ref, k):
            fell, fallen_pose = True, data.qpos[7:].copy()
            rec.fall(k)
        rec.contacts(data, plan.floor, i)
        if recorder is not None:
            recorder(k, data, model)  # this tick's model: its gains act
        mujoco.mj_step(model, data)  # the first step computes this tick's actuator force
        if i is not None:
            rec.torque[i] = data.actuator_force
            foot_forces(model, data, plan.floor, plan.side, rec.foot[i])
        if SUBSTEPS > 1:
            mujoco.mj_step(model, data, nstep=SUBSTEPS - 1)
    if recorder is not None:
        recorder(T, data, model)
    return rec.result(model, data, fell)
