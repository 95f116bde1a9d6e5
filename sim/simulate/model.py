"""The simulated humanoid: ``build_mjcf``'s model plus actuators, for forward simulation.

``build_mjcf`` (``sim.model.humanoid``) stays the kinematic model everyone compares against; this
module edits its output through ``mujoco.MjSpec``:

* one position actuator per hinge whose stiffness ``kp`` and damping ``kv`` are the joint's
  reflected inertia at the standing rest pose (the diagonal of the mass matrix: the mass of the
  segments it moves times their squared lever arms) times ``omega**2`` and ``2 zeta omega``, so
  every joint tracks with the same bandwidth; its torque limit (``actuator_forcerange``, applied
  by the controller to the feed-forward) is ``strength`` times ``g`` times 0.2 m times the mass
  [kg] on the heavier side of the joint (in stance an ankle holds the whole body) (N m);
* each hinge's armature (rotor inertia) at least ``kp h^2`` for the step ``h``, so the stiff spine
  chain stays stable;
* a stiff floor: contact time constant 0.005 s (MuJoCo's default 0.02 s; the floor is stiffer
  than 2.4 physics steps only if the step shrinks) with priority over the body's geoms, so its
  ``solref`` is used as is (MuJoCo otherwise averages it with the body geoms' default 0.02 s:
  the former 0.01 s floor acted as 0.015 s); only body-floor contacts (the capsules of motion
  capture interpenetrate: hands through thighs). MuJoCo's soft contact settles where the
  reference acceleration ``-k d r`` balances ``(1 - d) / d`` times the contact's unconstrained
  acceleration ``a0`` (``k = 1 / (d_max tc)^2``), so ``r = (1 - d) a0 (d_max tc)^2 / d^2``: for a
  body resting under its weight (``a0 = g``) 0.012 mm, but a foot pushed down by the legs has an
  ``a0`` of hundreds of m/s^2 (light segment, body weight through it): measured, the humanoid
  holding a pose under its weight sinks 0.4 mm on two feet, 0.7 mm on one, and a walking stance
  foot 0.4-0.8 mm (median), landings 5-15 mm;
* the physics step is ``1 / (4 * 120)`` s so one control tick holds 4 steps at 120 Hz, and the
  integrator is ``implicitfast`` so the actuators' damping is integrated implicitly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from sim.acclaim.reader import Skeleton
from sim.model.humanoid import build_mjcf
from sim.model.mass import DEFAULT_BODY_MASS_KG

CONTROL_HZ = 120.0
SUBSTEPS = 4
G = 9.81
LEVER = 0.2  # [m] lever of the torque limits
# [s] floor contact time constant: at 0.01 (mixed with the body's 0.02 into 0.015) walking feet
# sank 3-5 mm (median per step) and 19-26 mm at landings; 0.005 (>= 2 physics steps, MuJoCo's
# stability bound) gives 0.3-0.8 mm and 5-8 mm
FLOOR_TIMECONST = 0.005
FLOOR_DAMPRATIO = 1.0
FLOOR_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)  # MuJoCo's default impedance


@dataclass(frozen=True)
class Gains:
    """Tracking gains: hinge bandwidth ``omega`` [rad/s] and damping ratio; root ones likewise;
    ``strength``: hinge torque limit per kg on the heavier side of the joint, in units of
    ``G * LEVER`` [N m / kg]."""

    omega: float = 2 * np.pi * 8.0
    zeta: float = 1.0
    strength: float = 2.0
    root_omega: float = 2 * np.pi * 2.0
    root_zeta: float = 1.0

    def scaled(self, factor: float) -> Gains:
        """Stiffness scaled by ``factor`` (bandwidth by its square root), limits by ``factor``."""
        return replace(self, omega=self.omega * np.sqrt(factor), strength=self.strength * factor)


def scaled_skeleton(skeleton: Skeleton, scale: float) -> Skeleton:
    """``skeleton`` with every bone length times ``scale`` (angles unchanged)."""
    if scale <= 0:
        raise ValueError(f"scale must be positive; got {scale}")
    bones = tuple(replace(b, length=b.length * scale) for b in skeleton.bones)
    return replace(skeleton, bones=bones)


def sim_model(
    skeleton: Skeleton,
    *,
    body_mass_kg: float = DEFAULT_BODY_MASS_KG,
    gains: Gains | None = None,
) -> mujoco.MjModel:
    """The actuated humanoid of ``skeleton`` (see the module docstring).

    Actuator ``i`` drives hinge ``i`` (qpos ``7 + i``, qvel ``6 + i``).
    """
    gains = gains or Gains()
    spec = mujoco.MjSpec.from_string(build_mjcf(skeleton, body_mass_kg=body_mass_kg))
    spec.option.timestep = 1.0 / (CONTROL_HZ * SUBSTEPS)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for g in spec.geoms:
        if g.name == "floor":
            g.contype, g.conaffinity = 1, 2
            g.solref = [FLOOR_TIMECONST, FLOOR_DAMPRATIO]
            g.solimp = list(FLOOR_SOLIMP)
            g.priority = 1  # the floor's contact parameters win (not averaged with the body's)
        else:
            g.contype, g.conaffinity = 2, 1
    plain = spec.compile()
    inertia, carried = rest_inertia(plain)
    total = total_mass(plain)
    for j in range(1, plain.njnt):
        a = spec.add_actuator()
        a.name = plain.joint(j).name
        a.target = plain.joint(j).name
        a.trntype = mujoco.mjtTrn.mjTRN_JOINT
        kp = gains.omega**2 * inertia[j - 1]
        kv = 2 * gains.zeta * gains.omega * inertia[j - 1]
        a.set_to_position(kp=kp, kv=kv)
        # Not clamped inside MuJoCo: a clamped position actuator under the implicit integrator
        # was measured to blow up (its velocity derivative is kept while the force is capped);
        # ``actuator_forcerange`` still holds the torque limit, which the controller applies to
        # its feed-forward.
        a.forcelimited = False
        limit = gains.strength * G * LEVER * max(carried[j - 1], total - carried[j - 1])
        a.forcerange = [-limit, limit]
        # a light segment between two stiff joints (the spine) makes a mode of inertia ~ its own;
        # armature >= kp h^2 keeps every actuator mode below 1 / h (explicit-spring stability)
        joint = spec.joint(plain.joint(j).name)
        joint.armature = max(float(plain.dof_armature[5 + j]), kp * spec.option.timestep**2)
    return spec.compile()


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
