"""The simulated humanoid: ``build_mjcf``'s model plus actuators, for forward simulation.

``build_mjcf`` (``sim.model.humanoid``) stays the kinematic model everyone compares against; this
module edits its output through ``mujoco.MjSpec``:

* one position actuator per hinge whose stiffness ``kp`` and damping ``kv`` are the joint's
  reflected inertia at the standing rest pose (the diagonal of the mass matrix: the mass of the
  segments it moves times their squared lever arms) times ``omega**2`` and ``2 zeta omega``, so
  every joint tracks with the same bandwidth, except that ``kp`` is capped at the joint's torque
  limit over ``MIN_DEFLECTION`` (a joint reaches its peak torque only a quarter radian off
  target: a human joint's stiffness, not a servo's), ``kv`` following the same cap;
* each actuator's whole output (PD and feed-forward: the controller passes the feed-forward
  through ``ctrl``) is clamped by MuJoCo to the joint's torque limit (``forcelimited``): the
  peak isometric torque of an adult man per joint (:data:`HUMAN_PEAK_TORQUE`), scaled by the
  body mass over 75 kg and by nothing else: strength is anatomy, not a controller setting, so no
  gain changes it (``actuators="motor"``: torque actuators whose control range is that limit,
  for controllers that compute torques themselves, ``sim.simulate.wholebody``);
* each hinge's armature (rotor inertia) at least ``kp h^2`` for the step ``h``, so the stiff spine
  chain stays stable;
* a stiff floor: contact time constant 0.005 s (MuJoCo's default 0.02 s; the floor is stiffer
  than 2.4 physics steps only if the step shrinks) with priority over the body's geoms, so its
  ``solref`` is used as is (MuJoCo otherwise averages it with the body geoms' default 0.02 s:
  the former 0.01 s floor acted as 0.015 s). MuJoCo's soft contact settles where the
  reference acceleration ``-k d r`` balances ``(1 - d) / d`` times the contact's unconstrained
  acceleration ``a0`` (``k = 1 / (d_max tc)^2``), so ``r = (1 - d) a0 (d_max tc)^2 / d^2``: for a
  body resting under its weight (``a0 = g``) 0.012 mm, but a foot pushed down by the legs has an
  ``a0`` of hundreds of m/s^2 (light segment, body weight through it): measured, the humanoid
  holding a pose under its weight sinks 0.4 mm on two feet, 0.7 mm on one, and a walking stance
  foot 0.4-0.8 mm (median), landings 5-15 mm;
* opt-in compliant soles (``soft_soles``: :class:`SoftSole`, :data:`PAD_SOLE`): the sole and
  toe boxes' floor contacts with their own ``solref``/``solimp``, the floor's friction kept;
* self-collision: body geoms collide with each other except bodies within two joints of each
  other and pairs overlapping in the rest pose (:func:`self_collision_exclusions`), so a
  falling body's limbs cannot pass through each other or through its trunk;
* feet that can stand (``soles=True``, the default): a flat sole box under each foot from
  :data:`SOLE_HEEL` behind the ankle to the ball and a toe box under the toes from the ball to
  their tip (:func:`add_soles`; the foot and toe capsules then touch the body only; ``sim.physics.feet``'s sole points, the physics
  analysis's, stay the capsules); opt-in (``stance_ankles=True``) ankles at least as stiff as
  the standing body's toppling stiffness (:func:`stance_stiffness`);
* the physics step is ``1 / (4 * 120)`` s so one control tick holds 4 steps at 120 Hz, and the
  integrator is ``implicitfast`` so the actuators' damping is integrated implicitly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from sim import mujoco_log  # noqa: F401  # MuJoCo's warnings on stderr, not in a file
from sim.acclaim.records import Skeleton
from sim.errors import UsageError
from sim.model.humanoid import build_mjcf
from sim.model.mass import DEFAULT_BODY_MASS_KG
from sim.simulate.friction import Friction, apply_friction

CONTROL_HZ = 120.0
SUBSTEPS = 4
G = 9.81
MIN_DEFLECTION = 0.25  # [rad] default: the smallest angle error that asks for a peak torque
LEG_BONES = ("femur", "tibia", "foot", "toes")  # the leg hinges' bones (``Gains.legs``)
# [rad/s] a position actuator's control range is its joint's range widened by (limit + kv *
# TARGET_SPEED) / kp: a target that far out asks for the peak torque from anywhere in the range
# while the joint moves towards it at up to this speed (faster, the damping takes a share)
TARGET_SPEED = 30.0
REFERENCE_MASS_KG = 75.0  # [kg] body mass of the peak torques below

# Peak isometric joint torque [N m] of an adult man (about 75 kg), per joint and ASF axis (rx:
# flexion/extension, rz: ab/adduction or lateral bending, ry: axial rotation), the stronger of the
# two directions, rounded. Hip, knee, ankle, shoulder, elbow and wrist: Harbo, Brincks &
# Andersen 2012 (Eur J Appl Physiol 112:267, isometric strength of 178 healthy adults) and
# Anderson, Madigan & Nussbaum 2007 (J Biomech 40:3105, hip/knee/ankle torque); trunk and neck:
# the ranges reported for isometric trunk extension (200-300 N m) and neck extension (30-60 N m).
# Secondary axes (hip rotation, ankle inversion, spine torsion) and the hand are round figures
# of the same order as reported values; toes, fingers and thumb get a few N m. The three spine
# joints and the two neck joints are in series, so each carries the whole trunk (neck) torque.
HUMAN_PEAK_TORQUE: dict[str, dict[str, float]] = {
    "femur": {"rx": 250.0, "rz": 150.0, "ry": 80.0},
    "tibia": {"rx": 250.0},
    "foot": {"rx": 200.0, "rz": 50.0},
    "toes": {"rx": 30.0},
    "lowerback": {"rx": 250.0, "rz": 180.0, "ry": 100.0},
    "upperback": {"rx": 250.0, "rz": 180.0, "ry": 100.0},
    "thorax": {"rx": 200.0, "rz": 150.0, "ry": 80.0},
    "lowerneck": {"rx": 50.0, "rz": 40.0, "ry": 20.0},
    "upperneck": {"rx": 50.0, "rz": 40.0, "ry": 20.0},
    "head": {"rx": 30.0, "rz": 25.0, "ry": 15.0},
    "clavicle": {"rz": 100.0, "ry": 100.0},
    "humerus": {"rx": 90.0, "rz": 80.0, "ry": 50.0},
    "radius": {"rx": 75.0},
    "wrist": {"ry": 10.0},
    "hand": {"rx": 15.0, "rz": 15.0},
    "fingers": {"rx": 5.0},
    "thumb": {"rx": 5.0, "rz": 5.0},
}


def human_torque_limit(joint: str, body_mass_kg: float = REFERENCE_MASS_KG) -> float:
    """Peak torque [N m] of hinge ``joint`` (a name such as ``"lfemur_rx"``): the
    :data:`HUMAN_PEAK_TORQUE` figure scaled by ``body_mass_kg / 75`` (strength grows with muscle
    cross-section times lever, so with size cubed, so with mass). Raises ``KeyError`` for a joint
    the table does not know."""
    bone, axis = joint.rsplit("_", 1)
    if bone[:1] in "lr" and bone[1:] in HUMAN_PEAK_TORQUE:
        bone = bone[1:]
    return HUMAN_PEAK_TORQUE[bone][axis] * body_mass_kg / REFERENCE_MASS_KG


# [s] floor contact time constant: at 0.01 (mixed with the body's 0.02 into 0.015) walking feet
# sank 3-5 mm (median per step) and 19-26 mm at landings; 0.005 (>= 2 physics steps, MuJoCo's
# stability bound) gives 0.3-0.8 mm and 5-8 mm
FLOOR_TIMECONST = 0.005
FLOOR_DAMPRATIO = 1.0
FLOOR_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)  # MuJoCo's default impedance


@dataclass(frozen=True)
class SoftSole:
    """Contact parameters of compliant soles (``sim_spec(soft_soles=...)``): the sole and toe
    boxes' own ``solref`` (``timeconst`` [s], ``dampratio``) and ``solimp`` for their contacts
    with the floor, in place of the stiff floor's (:data:`FLOOR_TIMECONST`); friction and
    everything else as the floor's. A softer contact lets a loaded sole sink a few millimetres
    (a heel pad compresses 5-10 mm under body weight), so a sole tilted a degree or two still
    bears load at heel and ball instead of on one edge."""

    timeconst: float = 0.02
    dampratio: float = 1.0
    solimp: tuple = FLOOR_SOLIMP


#: a padded sole: the floor's time constant, but an impedance of 0.2 at the surface rising to
#: the floor's 0.95 over 6 mm (MuJoCo's ``solimp``): the first millimetres give (a loaded sole
#: sinks 2-3 mm), deeper it is as stiff as the floor (a landing stops within about 5-15 mm);
#: a softer time constant instead (0.02 s) let stamping feet sink 20-50 mm
PAD_SOLE = SoftSole(timeconst=FLOOR_TIMECONST, solimp=(0.2, 0.95, 0.006, 0.5, 2.0))


@dataclass(frozen=True)
class Gains:
    """Tracking gains of the position actuators' feedback: hinge bandwidth ``omega`` [rad/s] and
    damping ratio; root ones likewise; ``min_deflection`` [rad] caps each hinge's stiffness at
    its torque limit over it (the smallest angle error that asks for the peak torque; smaller:
    a stiffer controller). Feedback gains belong to the controller; the torque limits
    (:data:`HUMAN_PEAK_TORQUE`) are the body's and no gain scales them. ``legs``: the leg
    hinges' own gains (:data:`LEG_BONES`; their ``legs`` and root gains unused), None: these."""

    omega: float = 2 * np.pi * 8.0
    zeta: float = 1.0
    root_omega: float = 2 * np.pi * 2.0
    root_zeta: float = 1.0
    min_deflection: float = MIN_DEFLECTION
    legs: Gains | None = None

    def __post_init__(self):
        if not self.min_deflection > 0:
            raise UsageError(f"min_deflection must be positive; got {self.min_deflection}")

    def scaled(self, factor: float) -> Gains:
        """Stiffness scaled by ``factor`` (bandwidth by its square root); the torque limits stay
        the human ones (a stiffer controller is no stronger body)."""
        return replace(self, omega=self.omega * np.sqrt(factor))

    def of(self, joint: str) -> Gains:
        """The gains of hinge ``joint`` (``"ltibia_rx"``): :attr:`legs` for a leg's, else these."""
        bone = joint.rsplit("_", 1)[0]
        leg = bone[:1] in "lr" and bone[1:] in LEG_BONES
        return self.legs if leg and self.legs is not None else self


def scaled_skeleton(skeleton: Skeleton, scale: float) -> Skeleton:
    """``skeleton`` with every bone length times ``scale`` (angles unchanged)."""
    if scale <= 0:
        raise UsageError(f"scale must be positive; got {scale}")
    bones = tuple(replace(b, length=b.length * scale) for b in skeleton.bones)
    return replace(skeleton, bones=bones)


def sim_model(skeleton: Skeleton, **kwargs) -> mujoco.MjModel:
    """The actuated humanoid of ``skeleton`` (see the module docstring): :func:`sim_spec`
    compiled (same keyword arguments)."""
    return sim_spec(skeleton, **kwargs).compile()


def sim_spec(
    skeleton: Skeleton,
    *,
    body_mass_kg: float = DEFAULT_BODY_MASS_KG,
    gains: Gains | None = None,
    soles: bool = True,
    stance_ankles: bool = False,
    actuators: str = "position",
    lean: bool = False,
    soft_soles: SoftSole | None = None,
    friction: Friction | None = None,
) -> mujoco.MjSpec:
    """The ``MjSpec`` of :func:`sim_model` (``spec.to_xml()``: the MJCF a dataset stores).

    Actuator ``i`` drives hinge ``i`` (qpos ``7 + i``, qvel ``6 + i``); a position actuator's
    control (the PD target [rad], the feed-forward folded in as ``ff / kp``) is limited to the
    joint's range widened by ``(limit + kv TARGET_SPEED) / kp`` either side (``ctrllimited``): a
    target further out asks for more than the joint's peak torque anywhere in its range (while
    the joint moves towards it at up to :data:`TARGET_SPEED`), so the bound costs no torque
    there, and actions stay in a fixed box. ``soles``: each foot
    touches the floor through a flat sole box reaching behind the ankle (:func:`add_soles`)
    instead of its capsule (False: the capsule feet of motion capture). ``stance_ankles``: the
    ankle hinges (``foot_rx``, ``foot_rz``) at least :func:`stance_stiffness` (capped by the
    torque limit like every joint). ``actuators``: ``"position"`` (PD servos with ``gains``,
    output clamped to the human limit) or ``"motor"`` (``ctrl`` is the torque [N m], clamped to
    the human limit); the armature is the same in both, so both are one body. ``lean``: MuJoCo
    skips the stages this body has nothing for (:data:`LEAN_DISABLED`; the same motion).
    ``soft_soles``: the soles' contacts with the floor use these parameters (:class:`SoftSole`)
    instead of the floor's (None: the stiff floor's, as for every other geom); needs ``soles``.
    ``friction``: how hard the friction cone is enforced (``sim.simulate.friction.Friction``;
    None: MuJoCo's default, the pyramidal cone at impratio 1).
    """
    if soft_soles is not None and not soles:
        raise UsageError("soft_soles needs soles=True")
    if actuators not in ("position", "motor"):
        raise UsageError(f"unknown actuators {actuators!r}; known: 'position', 'motor'")
    gains = gains or Gains()
    spec = mujoco.MjSpec.from_string(build_mjcf(skeleton, body_mass_kg=body_mass_kg))
    spec.option.timestep = 1.0 / (CONTROL_HZ * SUBSTEPS)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.disableflags |= LEAN_DISABLED if lean else 0
    _set_contacts(spec)
    if soles:
        add_soles(spec, soft_soles)
    if friction is not None:
        apply_friction(spec, friction, SOLE_GEOMS + TOE_GEOMS)
    plain = spec.compile()
    inertia, _ = rest_inertia(plain)
    stance = stance_stiffness(plain) if stance_ankles else 0.0
    for j in range(1, plain.njnt):
        name = plain.joint(j).name
        a = spec.add_actuator()
        a.name = name
        a.target = name
        a.trntype = mujoco.mjtTrn.mjTRN_JOINT
        limit, g = human_torque_limit(name, body_mass_kg), gains.of(name)  # limit: no gain's
        kp = g.omega**2 * inertia[j - 1]
        raised = max(1.0, stance / kp) if name[1:] in ANKLE_JOINTS else 1.0
        kp *= raised
        cap = min(1.0, limit / g.min_deflection / kp)  # the controller's cap; zeta kept
        kp *= cap
        kv = 2 * g.zeta * g.omega * inertia[j - 1] * np.sqrt(raised * cap)
        if actuators == "motor":
            a.set_to_motor()
            a.ctrllimited = True
            a.ctrlrange = [-limit, limit]
        else:
            a.set_to_position(kp=kp, kv=kv)
            lo, hi = plain.jnt_range[j]
            a.ctrllimited = True
            reach = (limit + kv * TARGET_SPEED) / kp
            a.ctrlrange = [lo - reach, hi + reach]
        a.forcelimited = True
        a.forcerange = [-limit, limit]
        # a light segment between two stiff joints (the spine) makes a mode of inertia ~ its own;
        # armature >= kp h^2 keeps every actuator mode below 1 / h (explicit-spring stability)
        joint = spec.joint(name)
        joint.armature = max(float(plain.dof_armature[5 + j]), kp * spec.option.timestep**2)
    return spec


def _set_contacts(spec) -> None:
    """The stiff floor (with priority) and self-collision (bar
    :func:`self_collision_exclusions`) of ``spec``, in place."""
    for g in spec.geoms:
        if g.name == "floor":
            g.contype, g.conaffinity = FLOOR_BITS
            g.solref = [FLOOR_TIMECONST, FLOOR_DAMPRATIO]
            g.solimp = list(FLOOR_SOLIMP)
            g.priority = 1  # the floor's contact parameters win (not averaged with the body's)
        else:
            g.contype, g.conaffinity = BODY_BITS
            g.solref = [SELF_TIMECONST, 1.0]
    for a, b in self_collision_exclusions(spec.compile()):
        e = spec.add_exclude()
        e.bodyname1, e.bodyname2 = a, b


_D = mujoco.mjtDisableBit
#: what ``sim_spec(lean=True)`` switches off, none of which changes this body's motion: island
#: discovery (one kinematic tree: whatever touches, the constraints form one island), the
#: collision mid-phase (a cull within body pairs of one to three geoms: the same contacts),
#: and the stages for what the body has none of: equality constraints, friction loss, joint
#: springs, sensors. Joint damping, limits, contacts and self-collision stay.
LEAN_DISABLED = int(
    _D.mjDSBL_ISLAND
    | _D.mjDSBL_MIDPHASE
    | _D.mjDSBL_EQUALITY
    | _D.mjDSBL_FRICTIONLOSS
    | _D.mjDSBL_SPRING
    | _D.mjDSBL_SENSOR
)
ANKLE_JOINTS = ("foot_rx", "foot_rz")  # the ankle (plantar/dorsiflexion) and subtalar hinges
STANCE_MARGIN = 1.2  # ankle stiffness over the body's toppling stiffness m g h


def stance_stiffness(model) -> float:
    """[N m/rad] the ankle stiffness that holds the standing body up on its own:
    :data:`STANCE_MARGIN` times ``m g h`` (``m``: body mass, ``h``: height of the centre of mass
    above the ankles in the upright rest pose). A body pivoting at the ankle is an inverted
    pendulum whose gravity torque grows by ``m g h`` per radian of lean; the ankle stiffness
    must exceed it to stand without active control (Winter et al. 1998, J Neurophysiol 80:1211,
    "Stiffness control of balance in quiet standing"; Loram & Lakie 2002 measured intrinsic
    ankle stiffness at 0.9 ``m g h``, the rest being active). Each ankle gets the whole of it,
    as in single stance."""
    data = mujoco.MjData(model)
    data.qpos[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # upright (y up -> z up)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    ankles = np.mean([data.xpos[model.body(f"{s}foot").id][2] for s in "lr"])
    h = float(data.subtree_com[0][2] - ankles)
    return STANCE_MARGIN * total_mass(model) * G * h


SOLE_GEOMS = ("lsole", "rsole")
TOE_GEOMS = ("ltoesole", "rtoesole")  # the toes' boxes (:func:`add_soles`)
SOLE_HALF_WIDTH = 0.045  # [m] a foot is about 9 cm wide at the ball
SOLE_HEEL = 0.05  # [m] the heel reaches this far behind the ankle joint
SOLE_HALF_THICKNESS = 0.01  # [m]


# The sole's normal in the foot bone's frame (x flips for the right foot): the mean "up"
# direction of a captured foot during floor contact. Measured on CMU walks (02_01, 07_01, 35_01,
# 16_24, 05_01; per trial within 6 deg of this) on the canonical skeleton; the skeleton's rest pose
# is no stance (its feet are 18-28 deg off flat), so the rest pose cannot give the sole.
STANCE_UP = (-0.06, 0.08, 0.995)


def sole_boxes(model) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per foot body (``"lfoot"``, ``"rfoot"``), the sole box in that body's frame: centre (3,),
    orientation (4,) quaternion and half sizes (3,): length, width, thickness [m].

    The box's bottom face is the sole: normal to :data:`STANCE_UP`, through the lowest point of
    the foot capsule and the toes in that direction, from :data:`SOLE_HEEL` behind the ankle
    joint to the front of the foot capsule (the ball of the foot), :data:`SOLE_HALF_WIDTH`
    either side; and per toes body (``"ltoes"``, ``"rtoes"``, where the toes reach beyond the
    ball) the toe box in the toes' frame: the same bottom plane at rest, from the ball to the
    tip of the toes. ``model``: the humanoid of ``build_mjcf`` (capsule feet, sphere or capsule
    toes), its joints at zero."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    out = {}
    for side in "lr":
        foot = model.body(f"{side}foot").id
        R_foot, x_foot = data.xmat[foot].reshape(3, 3), data.xpos[foot]

        n = np.array(STANCE_UP) * ([1.0, 1.0, 1.0] if side == "l" else [-1.0, 1.0, 1.0])
        n /= np.linalg.norm(n)
        g = model.geom(f"{side}foot").id
        axis = R_foot.T @ data.geom_xmat[g].reshape(3, 3)[:, 2]
        half, radius = model.geom_size[g, 1], model.geom_size[g, 0]
        ends = R_foot.T @ (data.geom_xpos[g] - x_foot) + np.outer([half, -half], axis)
        toe_end = ends[np.argmax(np.linalg.norm(ends, axis=1))]  # away from the ankle
        depth = float(np.max(-ends @ n)) + radius  # the lowest point along -n
        toes = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{side}toes")
        if toes >= 0:
            toe_centre = R_foot.T @ (data.geom_xpos[toes] - x_foot)
            depth = max(depth, float(-toe_centre @ n) + model.geom_size[toes, 0])
        forward = toe_end - (toe_end @ n) * n
        length = np.linalg.norm(forward)
        forward /= length
        lateral = np.cross(n, forward)
        heel, front = -SOLE_HEEL, length + 0.5 * radius
        centre = 0.5 * (heel + front) * forward - (depth - SOLE_HALF_THICKNESS) * n
        q = np.zeros(4)
        frame = np.column_stack([forward, lateral, n])
        mujoco.mju_mat2Quat(q, frame.ravel())
        size = np.array([0.5 * (front - heel), SOLE_HALF_WIDTH, SOLE_HALF_THICKNESS])
        out[f"{side}foot"] = (centre, q, size)
        if toes < 0:
            continue
        # the toe box: the same bottom plane, from the ball to the tip of the toes, on the toes'
        # body (the toe joint bends it: a foot standing on its ball stands on its toes' box)
        t_axis = R_foot.T @ data.geom_xmat[toes].reshape(3, 3)[:, 2]
        t_half = model.geom_size[toes, 1] if model.geom_type[toes] == 3 else 0.0
        tip = float(np.max((toe_centre + np.outer([t_half, -t_half], t_axis)) @ forward))
        tip += model.geom_size[toes, 0]
        if tip <= front:
            continue
        body = model.geom_bodyid[toes]
        R_toes, x_toes = data.xmat[body].reshape(3, 3), data.xpos[body]
        c_foot = 0.5 * (front + tip) * forward - (depth - SOLE_HALF_THICKNESS) * n
        c_toes = R_toes.T @ (R_foot @ c_foot + x_foot - x_toes)
        qt = np.zeros(4)
        mujoco.mju_mat2Quat(qt, (R_toes.T @ R_foot @ frame).ravel())
        size_t = np.array([0.5 * (tip - front), SOLE_HALF_WIDTH, SOLE_HALF_THICKNESS])
        out[f"{side}toes"] = (c_toes, qt, size_t)
    return out


def add_soles(spec, soft: SoftSole | None = None) -> None:
    """Give each foot of ``spec`` a massless sole box (:func:`sole_boxes`, heel to ball) and its
    toes a toe box (ball to tip), which alone touch the floor for it: a foot then stands on a
    flat sole, not on the point or edge where a capsule meets a plane, nor on a toe capsule
    that the captured toe angle holds below the sole; on its ball it stands on its toes' box.
    The foot and toe capsules keep colliding with the other body geoms. ``soft``: the boxes
    take priority over the floor with these contact parameters (:class:`SoftSole`), the
    floor's friction kept (None: the floor's parameters, the stiff floor)."""
    boxes = sole_boxes(spec.compile())
    for body, (pos, quat, size) in boxes.items():
        b = spec.body(body)
        g = b.add_geom()
        g.name = body[0] + ("sole" if body.endswith("foot") else "toesole")
        g.type = mujoco.mjtGeom.mjGEOM_BOX
        g.size = size
        g.pos = pos
        g.quat = quat
        g.density = 0.0
        g.mass = 0.0
        g.contype, g.conaffinity = SOLE_BITS
        g.group = 3
        g.solref = [SELF_TIMECONST, 1.0]
        if soft is not None:  # the sole's parameters win for its floor contacts; friction kept
            floor = spec.geom("floor")
            g.priority = floor.priority + 1
            g.solref = [soft.timeconst, soft.dampratio]
            g.solimp = list(soft.solimp)
            g.friction = floor.friction
            g.condim = floor.condim
        for name in (body, body[0] + "toes"):
            capsule = spec.geom(name)
            if capsule is not None:
                capsule.contype, capsule.conaffinity = SELF_BITS


# contype, conaffinity: the floor touches every body geom; body geoms touch each other (bit 4)
# except the pairs of :func:`self_collision_exclusions`
FLOOR_BITS = (1, 2)
BODY_BITS = (2 | 4, 1 | 4)
SOLE_BITS = (2, 1)  # the soles touch the floor only
SELF_BITS = (4, 4)  # the foot capsules touch the body only
ADJACENT_HOPS = 2  # bodies this close in the kinematic tree never collide with each other
SELF_TIMECONST = 0.01  # [s] contact time constant between body geoms (MuJoCo default 0.02)


def self_collision_exclusions(model) -> list[tuple[str, str]]:
    """Body pairs that never collide: those within :data:`ADJACENT_HOPS` joints of each other
    (parent and child, siblings, grandparent: their capsules meet at a shared joint: clavicles
    and neck, hip joints and lower back), those within one hand (the fingers' and thumb's
    capsules overlap in nearly every frame of CMU's grips) and those whose capsules overlap in
    the standing rest pose. Every other pair collides: a shin cannot pass through a shin.

    ``model``: the humanoid with body-body contacts enabled (:data:`BODY_BITS`)."""
    parent = model.body_parentid

    def chain(b: int) -> list[int]:
        out = [b]
        while out[-1] != 0:
            out.append(int(parent[out[-1]]))
        return out

    pairs = set()
    chains = {b: chain(b) for b in range(1, model.nbody)}
    wrists = {b for b in range(1, model.nbody) if model.body(b).name.endswith("wrist")}
    for a in range(1, model.nbody):
        for b in range(a + 1, model.nbody):
            common = next(x for x in chains[a] if x in chains[b])
            if chains[a].index(common) + chains[b].index(common) <= ADJACENT_HOPS:
                pairs.add((a, b))
            elif wrists & set(chains[a]) & set(chains[b]):
                pairs.add((a, b))  # within one hand (fingers, thumb): a coarse model of a grip
    data = mujoco.MjData(model)
    data.qpos[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # upright (y up -> z up)
    data.qpos[2] = 2.0  # clear of the floor
    mujoco.mj_forward(model, data)
    for c in range(data.ncon):
        a, b = sorted(int(model.geom_bodyid[g]) for g in data.contact.geom[c])
        if a > 0:
            pairs.add((a, b))
    return sorted((model.body(a).name, model.body(b).name) for a, b in pairs)


def rest_inertia(model) -> tuple[np.ndarray, np.ndarray]:
    """(nv - 6,) reflected inertia [kg m^2] of each hinge at ``qpos0``, and (nv - 6,) mass [kg]
    of the subtree each hinge moves."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    body = model.jnt_bodyid[1:]
    return np.diag(M)[6:].copy(), model.body_subtreemass[body].copy()


def total_mass(model) -> float:
    """Total body mass [kg]."""
    return float(model.body_subtreemass[0])
