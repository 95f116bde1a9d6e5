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

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.model.kinematics import SOLE_POINTS
from sim.simulate.falls import fall_reference, has_fallen
from sim.simulate.feedforward import reference_feedforward
from sim.simulate.model import (
    CONTROL_HZ,
    SOLE_GEOMS,
    SUBSTEPS,
    TOE_GEOMS,
    G,
    Gains,
    total_mass,
)

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


@dataclass
class Tracking:
    """What one simulation produced, sampled every ``record_every`` ticks.

    Attributes:
        qpos: (F, nq) and qvel: (F, nv) the simulator's state.
        assistance: (F,) root assistance force over body weight around each recorded tick: the
            norm of the mean force over the ``record_every`` ticks centred on it.
        assist_wrench: (F, 6) the applied root wrench (free-joint generalised force: force [N]
            in the world frame, torque [N m] in the root's frame), the same mean.
        actions: (F, nu) the actuator controls (target angles [rad], feed-forward included)
            set at each recorded tick.
        joint_torque: (F, nu) the torque [N m] each actuator applied at the recorded tick's
            first physics step (``data.actuator_force``, within the joint's limit).
        foot_force: (F, 2, 3) the floor's contact force [N, world frame] on the left and right
            foot (foot and toe geoms) at that step (``mj_contactForce``); a foot is in contact
            where its force is non-zero.
        fall_frame: the recorded frame where the fall was detected, -1 if none; from that tick
            on the assistance is off and the joints hold the pose of the fall at
            :data:`FALLEN_TONE` of their stiffness and strength (no tracking, no feed-forward):
            the body stays down (no get-up is generated).
        fell: whether the body fell (``sim.simulate.falls``; see :func:`track`).
        fall_tick: the control tick whose state was found fallen first, -1 if none.
        ticks: control ticks simulated.
        mean_assistance_all: mean assistance over every tick.
        penetration: deepest floor contact penetration [m] seen at the control ticks (>= 0).
        self_penetration: deepest contact penetration [m] between two body geoms seen at the
            control ticks (self-collision keeps it small).
        contact_penetration: (F,) deepest floor contact penetration [m] at the recorded ticks, 0
            where nothing touches the floor (the steady figure: its median over contact frames).
        unstable: MuJoCo flagged a diverging acceleration (it then resets the state, so the
            recorded motion jumps: such a simulation is not a motion).
    """

    qpos: np.ndarray
    qvel: np.ndarray
    assistance: np.ndarray
    assist_wrench: np.ndarray
    fell: bool
    ticks: int
    mean_assistance_all: float = 0.0
    penetration: float = 0.0
    unstable: bool = False
    contact_penetration: np.ndarray | None = None
    actions: np.ndarray | None = None
    joint_torque: np.ndarray | None = None
    foot_force: np.ndarray | None = None
    fall_frame: int = -1
    self_penetration: float = 0.0
    fall_tick: int = -1


class ActuatorEdits:
    """The owner of temporary changes to a model: actuator gains, biases and force limits
    (:meth:`scale`: ``sim.simulate.wholebody``'s weakening; ``track`` and the sampler never call
    it: a model edited during a simulation does not replay from its MJCF) and the
    disabled-feature flags (inverse dynamics without contacts). A context manager: on exit,
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
        self.factor = 1.0
        return self

    def scale(self, factor: float) -> None:
        """Actuator stiffness, damping and torque limits at ``factor`` times their values on
        entry."""
        if factor != self.factor:
            m = self.model
            m.actuator_gainprm[:, 0] = self._gain * factor
            m.actuator_biasprm[:, :3] = self._bias * factor
            m.actuator_forcerange[:] = self._range * factor
            self.factor = factor

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
    np.clip(effort_target(target, data.qpos[7:], effort), lo, hi, out=data.ctrl)


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


def _foot_forces(model, data, floor: int, side: np.ndarray, out: np.ndarray) -> None:
    """Write into ``out`` (2, 3) the floor's contact force [N, world frame] on the left (row 0)
    and right (row 1) foot: ``side`` (ngeom,) is 0/1 for a foot geom of that side, -1 else."""
    out[:] = 0.0
    f6 = np.zeros(6)
    for c in range(data.ncon):
        con = data.contact[c]
        g1, g2 = con.geom
        if g1 == floor:
            s, sign = side[g2], 1.0  # the force acts from geom1 on geom2
        elif g2 == floor:
            s, sign = side[g1], -1.0
        else:
            continue
        if s < 0:
            continue
        mujoco.mj_contactForce(model, data, c, f6)
        out[s] += sign * (con.frame.reshape(3, 3).T @ f6[:3])


def _floor_contact(data, floor: int) -> bool:
    """Whether any contact of ``data``'s last step involves geom ``floor``."""
    n = data.ncon
    if not n:
        return False
    g = data.contact.geom[:n]
    return bool(np.any(g == floor))


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
    recorder=None,
) -> Tracking:
    """Simulate ``model`` following ``ref_qpos`` (T, nq) sampled at ``CONTROL_HZ``.

    The simulation starts in the reference's first pose and velocity. ``model`` must come from
    ``sim.simulate.model.sim_model`` (its actuators' gains are read; it is not edited). A fall is
    ``sim.simulate.falls``'s, checked every control tick; ``fall_frame`` is the first recorded
    frame at or after it.

    Args:
        gains: only its root gains are read here (the hinge gains live in ``model``'s actuators).
        assist_limit: root assistance bound [body weight]; 0 (the default): none. The
            assistance is an external force: only on explicit request, and recorded.
        assist_in_flight: let the assistance act when nothing touches the floor too (a hand
            holding the body up: only for tests of the audit that must see such a hand).
        record_every: ticks between recorded states (4: the 30 fps clip rate).
        offsets: (T, nu) [rad] added to the hinge targets at each tick while the body is up
            (the corrections a sampling controller found: ``sim.simulate.sampling``); None: none.
        recorder: called as ``recorder(k, data)`` at each control tick ``k`` just before its
            ``SUBSTEPS`` physics steps (controls and applied forces set) and as ``recorder(T,
            data)`` after the last (``sim.simulate.episode.Recorder``); None: none.

    Returns:
        :class:`Tracking` with states at ticks ``0, record_every, 2 record_every, ...``.
    """
    gains = gains or Gains()
    T = ref_qpos.shape[0]
    data = mujoco.MjData(model)  # the one MjData: precomputation first, then the simulation
    ref_qvel, ref_force = reference_feedforward(model, ref_qpos, data)
    root_inertia = _root_inertia(model, ref_qpos[0], data)
    fall_ref = fall_reference(model, ref_qpos)
    mujoco.mj_resetData(model, data)
    data.qpos[:] = ref_qpos[0]
    data.qvel[:] = ref_qvel[0]
    mujoco.mj_forward(model, data)
    weight = total_mass(model) * G
    kp_r = gains.root_omega**2
    kd_r = 2 * gains.root_zeta * gains.root_omega
    kp = model.actuator_gainprm[:, 0].copy()
    lead = model.actuator_biasprm[:, 2] / model.actuator_biasprm[:, 1]  # kv / kp [s]
    floor = model.geom("floor").id
    side = np.full(model.ngeom, -1)
    for name in SOLE_POINTS + SOLE_GEOMS + TOE_GEOMS:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        if g >= 0:
            side[g] = 0 if name.startswith("l") else 1
    push_ids = [model.body(p.body).id for p in pushes]
    dt = 1.0 / CONTROL_HZ
    rot_err = np.zeros(3)
    root_acc = np.zeros(6)
    F = (T + record_every - 1) // record_every
    rec_q = np.empty((F, model.nq))
    rec_v = np.empty((F, model.nv))
    rec_a = np.empty(F)
    rec_w = np.empty((F, 6))
    rec_p = np.zeros(F)
    rec_u = np.empty((F, model.nu))
    rec_tau = np.empty((F, model.nu))
    rec_f = np.zeros((F, 2, 3))
    fall_frame = fall_tick = -1
    all_assist = np.empty(T)
    all_wrench = np.empty((T, 6))
    fell = False
    fallen_pose = None
    deepest = deepest_self = 0.0
    for k in range(T):
        t = k * dt
        factor = weakening_factor(weakenings, t)
        if fell:  # down: the joints hold the pose of the fall with a lying body's tone
            factor = min(factor, FALLEN_TONE)
        q_ref, v_ref = ref_qpos[k], ref_qvel[k]
        # 1. feed-forward (inverse dynamics of the reference) + PD pull of the root
        mujoco.mju_subQuat(rot_err, q_ref[3:7], data.qpos[3:7])
        root_acc[:3] = kp_r * (q_ref[:3] - data.qpos[:3]) + kd_r * (v_ref[:3] - data.qvel[:3])
        root_acc[3:] = kp_r * rot_err + kd_r * (v_ref[3:6] - data.qvel[3:6])
        ff = ref_force[k]
        # 2. hinges: the actuator carries PD and feed-forward, MuJoCo clamps their sum; the
        # target leads by kv/kp * v_ref so that kp (q_ref - q) + kv (v_ref - v) is applied,
        # and by ff / kp so that the feed-forward is added (both scale with a weakening)
        if fell:  # no more tracking of a standing motion, no feed-forward: it stays down
            target = fallen_pose
        else:
            target = q_ref[7:] + lead * v_ref[6:] + ff[6:] / kp
            if offsets is not None:
                target += offsets[k]
        set_controls(model, data, target, factor)
        # 3. root: bounded assistance, only while the body touches the floor
        helped = fall_frame < 0 and assist_limit > 0  # a fallen body gets no help up
        if helped and (assist_in_flight or _floor_contact(data, floor)):
            wrench = ff[:6] + root_inertia @ root_acc
            force, torque = wrench[:3], wrench[3:]
            fmax = factor * assist_limit * weight
            tmax = fmax * ROOT_TORQUE_LEVER
            fn, tn = np.linalg.norm(force), np.linalg.norm(torque)
            if fn > fmax:
                force *= fmax / fn
            if tn > tmax:
                torque *= tmax / tn
        else:
            force, torque = np.zeros(3), np.zeros(3)
        data.qfrc_applied[:3] = force
        data.qfrc_applied[3:6] = torque
        all_assist[k] = np.linalg.norm(force) / weight
        all_wrench[k, :3], all_wrench[k, 3:] = force, torque
        apply_pushes(data, pushes, push_ids, t)
        i, on_record = divmod(k, record_every)
        on_record = on_record == 0
        if on_record:
            rec_q[i] = data.qpos
            rec_v[i] = data.qvel
            rec_u[i] = data.ctrl
        if not fell and has_fallen(model, data, fall_ref, k):
            fell, fall_tick = True, k
            fall_frame = min(F - 1, -(-k // record_every))
            fallen_pose = data.qpos[7:].copy()
        n = data.ncon
        if n:
            on_floor = (data.contact.geom[:n] == floor).any(axis=1)
            depth = -data.contact.dist[:n]
            floor_depth = max(0.0, float(depth[on_floor].max())) if on_floor.any() else 0.0
            self_depth = max(0.0, float(depth[~on_floor].max())) if not on_floor.all() else 0.0
            deepest = max(deepest, floor_depth)
            deepest_self = max(deepest_self, self_depth)
            if on_record:
                rec_p[i] = floor_depth
        if recorder is not None:
            recorder(k, data)
        mujoco.mj_step(model, data)  # the first step computes this tick's actuator force
        if on_record:
            rec_tau[i] = data.actuator_force
            _foot_forces(model, data, floor, side, rec_f[i])
        if SUBSTEPS > 1:
            mujoco.mj_step(model, data, nstep=SUBSTEPS - 1)
    if recorder is not None:
        recorder(T, data)
    # per recorded state, the mean wrench over the ticks centred on it (the impulse delivered
    # around that frame over its duration): a sample of every 4th tick would alias the 120 Hz
    # variations of the feed-forward
    half = record_every // 2
    for i in range(F):
        lo, hi = max(0, i * record_every - half), min(T, i * record_every - half + record_every)
        rec_w[i] = all_wrench[lo:hi].mean(axis=0)
        rec_a[i] = np.linalg.norm(rec_w[i, :3]) / weight
    return Tracking(
        qpos=rec_q,
        qvel=rec_v,
        assistance=rec_a,
        assist_wrench=rec_w,
        fell=fell,
        ticks=T,
        mean_assistance_all=float(all_assist.mean()) if T else 0.0,
        penetration=deepest,
        self_penetration=deepest_self,
        contact_penetration=rec_p,
        unstable=data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0,
        actions=rec_u,
        joint_torque=rec_tau,
        foot_force=rec_f,
        fall_frame=fall_frame,
        fall_tick=fall_tick,
    )
