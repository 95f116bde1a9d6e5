"""Balance feedback: hinge torques from the body's state that keep it over its stance feet.

The tracking controllers pull every hinge towards the reference; nothing in that pull knows the
body is an inverted pendulum on its feet. This feedback (after the torso and stance-hip control
of SIMBICON, Yin et al. 2007, and the ankle strategy of quiet standing) adds, every control
tick, torques on the hinges of the legs the reference stands on:

* **trunk**: a corrective torque on the pelvis, ``M_r = k_rot e + d_rot de`` [N m] (``e``: the
  pelvis orientation error as a rotation vector, world frame [rad]; ``de``: its angular
  velocity error [rad/s]), produced by the stance hips against their femurs: a hip hinge of
  world axis ``a`` and torque ``tau`` pushes the pelvis by ``-tau a``, so the hips' torques are
  ``-A^+ M_r`` (``A`` (3, 3): the hip hinges' world axes), shared between the stance legs;
* **centre of mass**: a torque on the body about the stance ankles that moves the centre of
  mass back over the feet by its error against the reference's, ``M_c = -(k_com z x e_c +
  d_com z x de_c)`` [N m] (``e_c``: the horizontal centre of mass minus the stance feet's mid-point,
  less the reference's [m]; ``de_c``: the root's horizontal velocity less the reference's [m/s]),
  produced by the stance ankles (``-A^+ M_c`` over their ``foot_rx``/``foot_rz`` axes).

A state feedback and nothing else: it reads ``qpos``/``qvel`` only (kinematics recomputed), so
the same state gives the same torques and a sampled rollout and its replay stay one computation.
The torques reach the body through the position actuators' targets (``tau / kp``), inside the
same human torque limits. Units: SI, z up, floor at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.simulate.model import SOLE_GEOMS, TOE_GEOMS, G, total_mass

#: [m] a reference foot (sole or toe box) whose lowest point is at most this high is in stance
#: (the reference may be lifted by ``sim.simulate.reference.FLOOR_LIFT``)
STANCE_HEIGHT = 0.04


@dataclass(frozen=True)
class Balance:
    """Gains of the balance feedback (module docstring), relative to the body: ``k_rot`` and
    ``k_com`` are multiples of ``m g h`` [N m/rad] and ``m g`` [N] (``m``: body mass, ``h``: 1 m),
    ``d_rot`` and ``d_com`` are time constants [s] (damping over stiffness)."""

    k_rot: float = 1.0
    d_rot: float = 0.1
    k_com: float = 1.0
    d_com: float = 0.3


@dataclass(frozen=True)
class BalancePlan:
    """What the feedback needs per reference tick (T ticks): root orientation (T, 4) and angular
    velocity (T, 3) [rad/s, local frame], root horizontal velocity (T, 2) [m/s], the centre of
    mass minus the stance feet's mid-point (T, 2) [m], stance per side (T, 2) bool; per side the
    hip hinges' joint ids (3,) and actuator ids, the ankle's likewise, the foot body ids (2,);
    the gains in SI units (k_rot [N m/rad], d_rot [N m s/rad], k_com [N], d_com [N s])."""

    quat: np.ndarray
    angvel: np.ndarray
    vel: np.ndarray
    com_off: np.ndarray
    stance: np.ndarray
    hips: list
    ankles: list
    feet: np.ndarray
    gains: tuple[float, float, float, float]


def _hinges(model, side: str, bone: str) -> tuple[np.ndarray, np.ndarray]:
    """Joint ids and actuator ids of ``side + bone``'s hinges (those the model has)."""
    jids, aids = [], []
    for a in range(model.nu):
        j = int(model.actuator_trnid[a, 0])
        if model.joint(j).name.rsplit("_", 1)[0] == side + bone:
            jids.append(j)
            aids.append(a)
    return np.array(jids, dtype=int), np.array(aids, dtype=int)


def _foot_geoms(model, side: str) -> list[int]:
    names = [n for n in SOLE_GEOMS + TOE_GEOMS if n.startswith(side)]
    return [
        model.geom(n).id
        for n in names
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) >= 0
    ]


def _bottom(model, data, g: int) -> float:
    """The lowest point [m] of box geom ``g``."""
    return float(data.geom_xpos[g, 2] - np.abs(data.geom_xmat[g, 6:9]) @ model.geom_size[g])


def balance_plan(model, ref_qpos: np.ndarray, ref_qvel: np.ndarray, gains: Balance) -> BalancePlan:
    """:class:`BalancePlan` of a reference ``ref_qpos`` (T, nq) with velocities ``ref_qvel``
    (T, nv) at the control rate."""
    data = mujoco.MjData(model)
    feet = np.array([model.body(f"{s}foot").id for s in "lr"])
    geoms = [_foot_geoms(model, s) for s in "lr"]
    T = len(ref_qpos)
    stance = np.zeros((T, 2), dtype=bool)
    com_off = np.zeros((T, 2))
    for t in range(T):
        data.qpos[:] = ref_qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        for s in range(2):
            stance[t, s] = (
                bool(geoms[s]) and min(_bottom(model, data, g) for g in geoms[s]) <= STANCE_HEIGHT
            )
        on = stance[t] if stance[t].any() else np.ones(2, dtype=bool)
        com_off[t] = (data.subtree_com[1] - data.xpos[feet[on]].mean(axis=0))[:2]
    mgh = total_mass(model) * G
    return BalancePlan(
        quat=ref_qpos[:, 3:7].copy(),
        angvel=ref_qvel[:, 3:6].copy(),
        vel=ref_qvel[:, :2].copy(),
        com_off=com_off,
        stance=stance,
        hips=[_hinges(model, s, "femur") for s in "lr"],
        ankles=[_hinges(model, s, "foot") for s in "lr"],
        feet=feet,
        gains=(
            gains.k_rot * mgh,
            gains.d_rot * gains.k_rot * mgh,
            gains.k_com * mgh,
            gains.d_com * gains.k_com * mgh,
        ),
    )


def balance_torques(model, data, plan: BalancePlan, k: int, out: np.ndarray) -> np.ndarray:
    """Write into ``out`` (nu,) the feedback torques [N m] at reference tick ``k`` for ``data``'s
    ``qpos``/``qvel`` (kinematics and centre of mass recomputed); zero off the stance legs and
    where the reference has no stance foot. Returns ``out``."""
    out[:] = 0.0
    on = np.flatnonzero(plan.stance[k])
    if on.size == 0:
        return out
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    k_rot, d_rot, k_com, d_com = plan.gains
    R = data.xmat[1].reshape(3, 3)
    e = np.zeros(3)
    mujoco.mju_subQuat(e, plan.quat[k], data.qpos[3:7])  # local frame of the simulated root
    de = plan.angvel[k] - data.qvel[3:6]  # local frame
    M_r = R @ (k_rot * e + d_rot * de) / on.size
    mid = data.xpos[plan.feet[on]].mean(axis=0)
    e_c = (data.subtree_com[1] - mid)[:2] - plan.com_off[k]
    de_c = data.qvel[:2] - plan.vel[k]
    f = k_com * e_c + d_com * de_c  # (2,) horizontal
    M_c = -np.array([-f[1], f[0], 0.0]) / on.size  # -(z x f)
    for s in on:
        for (jids, aids), M in ((plan.hips[s], M_r), (plan.ankles[s], M_c)):
            if jids.size:
                A = data.xaxis[jids].T  # (3, n) world axes
                out[aids] = -np.linalg.lstsq(A, M, rcond=1e-3)[0]
    return out
