"""A tracking controller for the humanoid in MuJoCo's forward simulation (``mj_step``).

Before the run, for the whole reference (a ``qpos`` stream at 120 Hz):

1. **Inverse-dynamics feed-forward.** ``mujoco.mj_inverse`` of the reference, free-floating (no
   contacts), gives hinge torques and the 6-d root wrench the motion needs from outside;
   :func:`contact_feedforward` moves that root force onto the foot and toe capsules near the floor
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
from scipy.optimize import nnls

from sim.model.kinematics import SOLE_POINTS
from sim.motion.velocities import qvel_from_qpos
from sim.simulate.falls import fall_reference, has_fallen
from sim.simulate.model import (
    CONTROL_HZ,
    FLOOR_BITS,
    SOLE_GEOMS,
    SUBSTEPS,
    G,
    Gains,
    total_mass,
)

FLOOR_CONTYPE = FLOOR_BITS[0]  # a geom touches the floor where its conaffinity has this bit

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
    """The owner of the temporary change inverse dynamics makes to a model: the disabled-feature
    flags (without contacts). A context manager: on exit, however reached, the model holds
    exactly the flags it had on entry.
    """

    def __init__(self, model):
        self.model = model

    def __enter__(self) -> ActuatorEdits:
        self._flags = int(self.model.opt.disableflags)
        return self

    def without_contacts(self) -> None:
        """Disable contacts (until exit)."""
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT

    def __exit__(self, *exc) -> None:
        self.model.opt.disableflags = self._flags


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


def reference_derivatives(model, qpos: np.ndarray, rate: float = CONTROL_HZ):
    """(T, nv) velocity and (T, nv) acceleration of a reference ``qpos`` stream at ``rate``.

    The reference is a target, not an output: differencing it is fine (central differences on the
    configuration manifold for velocities, ``np.gradient`` of those for accelerations).
    """
    qvel = qvel_from_qpos(model, qpos, rate)
    qacc = np.gradient(qvel, 1.0 / rate, axis=0) if len(qpos) > 1 else np.zeros_like(qvel)
    return qvel, qacc


def inverse_dynamics(model, qpos, qvel, qacc, *, contacts: bool = True, data=None) -> np.ndarray:
    """(T, nv) generalised force that produces ``qacc`` at each (``qpos``, ``qvel``):
    ``mujoco.mj_inverse``, floor contacts of that pose included (MuJoCo's soft-contact inverse).
    The first 6 columns are the root wrench nothing inside the body can supply. ``data``: an
    ``MjData`` of ``model`` to work in (its state is overwritten), a new one if None."""
    data = data if data is not None else mujoco.MjData(model)
    out = np.empty((len(qpos), model.nv))
    with ActuatorEdits(model) as edits:
        if not contacts:
            edits.without_contacts()
        for t in range(len(qpos)):
            data.qpos[:], data.qvel[:], data.qacc[:] = qpos[t], qvel[t], qacc[t]
            mujoco.mj_inverse(model, data)
            out[t] = data.qfrc_inverse
    return out


def _support_points(model, data, ids, contact_height: float):
    """[(point (3,), body id)] of ``ids``' geoms near the floor: a capsule's lowest end point,
    a box's (a sole's, ``sim.simulate.model.add_soles``) bottom corners, those within
    ``contact_height`` of z = 0."""
    out = []
    for g in ids:
        R, c, size = data.geom_xmat[g].reshape(3, 3), data.geom_xpos[g], model.geom_size[g]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            corners = c + (_CORNERS * size) @ R.T
            pts = corners[np.argsort(corners[:, 2])[:4]]  # the face nearest the floor
        else:
            axis = R[:, 2] * size[1]
            p = c - axis if axis[2] > 0 else c + axis
            pts = [p - [0.0, 0.0, size[0]]]
        out += [(p, int(model.geom_bodyid[g])) for p in pts if p[2] < contact_height]
    return out


def _support_jacobians(model, qpos, ids, contact_height: float, data=None):
    """For each frame ``t`` of ``qpos`` (T, nq) with some support point of ``ids``' geoms near
    the floor (:func:`_support_points`): ``(t, [(nv, 3) transposed point Jacobian, ...])``.
    ``data``: an ``MjData`` of ``model`` to work in (its state is overwritten), a new one if
    None."""
    data = data if data is not None else mujoco.MjData(model)
    jacp = np.zeros((3, model.nv))
    for t in range(len(qpos)):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        cols = []
        for p, body in _support_points(model, data, ids, contact_height):
            mujoco.mj_jac(model, data, jacp, None, p, body)
            cols.append(jacp.T.copy())
        if cols:
            yield t, cols


_CORNERS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
#: weight of the squared edge forces [N^2] against the squared wrench error [N^2, N^2 m^2] in
#: :func:`balanced_support`'s least squares: among the supports that give the root wrench, the
#: one with the smallest forces (spread over the points)
SUPPORT_REGULARISATION = 1e-6


def contact_feedforward(
    model, qpos, force, *, contact_height: float = 0.03, friction: float = 0.8, data=None
) -> np.ndarray:
    """Move the root wrench of a free-floating inverse dynamics onto the feet that touch the floor.

    ``force`` (T, nv) comes from :func:`inverse_dynamics` without contacts: its root rows are the
    whole external wrench the motion needs (body weight included). In each frame the foot and toe
    capsules whose lowest point is within ``contact_height`` of z = 0 take point forces ``F`` at
    that point: the root force shared equally, upward only and inside a friction cone (a
    quasi-static support); the hinges get ``tau - J_hinge^T F`` (the stance legs now carry the body) and the
    root keeps the residual the floor cannot give, which is what the assistance has to supply.
    A model with soles (``sim.simulate.model.add_soles``) gets :func:`balanced_support` instead.

    Returns:
        (T, nv) feed-forward: root rows = residual wrench, hinge rows = joint torques.
    ``data``: an ``MjData`` of ``model`` to work in (its state is overwritten), a new one if None.
    """
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, SOLE_GEOMS[0]) >= 0:
        return balanced_support(
            model, qpos, force, contact_height=contact_height, friction=friction, data=data
        )
    ids = [model.geom(n).id for n in SOLE_POINTS]  # the foot and toe capsules
    out = force.copy()
    for t, cols in _support_jacobians(model, qpos, ids, contact_height, data):
        JT = np.concatenate(cols, axis=1)  # (nv, 3k)
        F = np.tile(force[t, :3] / len(cols), (len(cols), 1))  # shared by the touching points
        F[:, 2] = np.maximum(F[:, 2], 0.0)  # the floor only pushes
        h = np.linalg.norm(F[:, :2], axis=1)
        cap = friction * F[:, 2]
        F[:, :2] *= np.minimum(1.0, cap / np.maximum(h, 1e-12))[:, None]  # friction cone
        out[t] = force[t] - JT @ F.reshape(-1)
    return out


def balanced_support(
    model, qpos, force, *, contact_height: float = 0.03, friction: float = 0.8, data=None
) -> np.ndarray:
    """:func:`contact_feedforward` for a model with soles: the support points near the floor
    (the sole boxes' bottom corners and the toe capsules' lowest points, within
    ``contact_height`` of z = 0) take point forces ``F``, upward only and inside a friction
    pyramid (four edges, coefficient ``friction``), that best give the root wrench, force and
    moment (non-negative least squares over the pyramid edges, slightly regularised:
    :data:`SUPPORT_REGULARISATION`): the centre of pressure lies under the body where the
    support polygon allows it, instead of the force shared equally by the touching points
    (whose moment tips the body). Same arguments and result as :func:`contact_feedforward`."""
    names = [
        n
        for n in SOLE_POINTS + SOLE_GEOMS
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) >= 0
    ]
    ids = [model.geom(n).id for n in names if int(model.geom(n).conaffinity[0]) & FLOOR_CONTYPE]
    s = friction / np.sqrt(2.0)
    edges = np.array([[s, s, 1.0], [s, -s, 1.0], [-s, s, 1.0], [-s, -s, 1.0]]).T  # (3, 4)
    out = force.copy()
    for t, cols in _support_jacobians(model, qpos, ids, contact_height, data):
        JE = np.concatenate([JT @ edges for JT in cols], axis=1)  # (nv, 4k): each edge's force
        A = np.vstack([JE[:6], np.sqrt(SUPPORT_REGULARISATION) * np.eye(JE.shape[1])])
        b = np.concatenate([force[t, :6], np.zeros(JE.shape[1])])
        c, _ = nnls(A, b)
        out[t] = force[t] - JE @ c
    return out


def reference_feedforward(model, ref_qpos: np.ndarray, data=None):
    """(T, nv) reference velocity and (T, nv) feed-forward of ``ref_qpos`` (T, nq) at
    ``CONTROL_HZ``: :func:`inverse_dynamics` without contacts, its root force moved onto the
    feet by :func:`contact_feedforward` (root rows: residual wrench [N, N m]; hinge rows: joint
    torques [N m]). ``data``: an ``MjData`` of ``model`` to work in (overwritten)."""
    data = data if data is not None else mujoco.MjData(model)
    ref_qvel, ref_qacc = reference_derivatives(model, ref_qpos)
    force = inverse_dynamics(model, ref_qpos, ref_qvel, ref_qacc, contacts=False, data=data)
    return ref_qvel, contact_feedforward(model, ref_qpos, force, data=data)


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
    assist_limit: float = 0.5,
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
        assist_limit: root assistance bound [body weight]; 0: none.
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
    for name in SOLE_POINTS + SOLE_GEOMS:
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
