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
  produced by the stance ankles (``-A^+ M_c`` over their ``foot_rx``/``foot_rz`` axes);
* **swing-foot placement** (SIMBICON's other half; off unless ``c_d`` or ``c_v`` is set): while
  the reference stands on one foot only, the other (swing) hip's targets turn its thigh so that
  the swing foot lands ``dp = c_d e_c + c_v de_c`` [m] further (horizontal) than the
  reference's: the thigh's rotation ``r = (dp x z) / L`` [rad] (``L``: hip to ankle [m]; a
  rotation ``r`` moves the ankle below the hip by ``r x (-L z) = dp``), spread over the hip's
  hinges as ``dq = (A A^T + lambda I)^-1 A r`` (``A``: their world axes as rows) and sent as
  the torque ``kp dq`` (the hinges' stiffness), i.e. a target offset of ``dq``. With ``c_d`` 1
  and ``c_v`` ``1 / omega`` (``omega = sqrt(g / z_com)``, about 0.3 s) the foot follows the
  capture point's error.
* **drift** (``Balance.k_drift``, off by default): the velocity target of ``de_c`` leads by
  ``k_drift`` times the root's horizontal position error (the reference's less the simulated,
  at most ``drift_max`` long, less ``drift_dead``), so the centre of mass is asked to move
  back towards the reference's path: ``de_c = v - v_ref - k_drift clip(p_ref - p)``; with
  ``Balance.drift_feet`` ``p`` is the mid-point of the feet the reference stands on (the
  simulated body's same feet, against the reference's) instead of the root: where the body
  stands rather than where its pelvis leans.

A state feedback and nothing else: it reads ``qpos``/``qvel`` only (kinematics recomputed), so
the same state gives the same torques and a sampled rollout and its replay stay one computation.
The torques reach the body through the position actuators' targets (``tau / kp``), inside the
same human torque limits. Units: SI, z up, floor at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.drift import drift_lead_xy
from sim.simulate.model import SOLE_GEOMS, TOE_GEOMS, G, total_mass
from sim.simulate.terrain import surface_height, terrain_geoms

#: [m] a reference foot (sole or toe box) whose lowest point is at most this high is in stance
#: (the reference may be lifted by ``sim.simulate.reference.FLOOR_LIFT``)
STANCE_HEIGHT = 0.04
#: Tikhonov damping of the hinge torques' least squares (the axes are unit vectors): a hip
#: near gimbal lock gets bounded torques
DAMPING = 1e-3
_DAMPED = DAMPING * np.eye(3)

try:  # np.linalg.solve's own kernel (LAPACK's gesv on each matrix of a stack) without the
    # checks and error state around it (the damped systems here are never singular): the same
    # numbers for a third of the cost
    from numpy.linalg import _umath_linalg

    _solve = partial(_umath_linalg.solve, signature="dd->d")
except (ImportError, AttributeError):  # a numpy without it
    _solve = np.linalg.solve


@dataclass(frozen=True)
class Balance:
    """Gains of the balance feedback (module docstring), relative to the body: ``k_rot`` and
    ``k_com`` are multiples of ``m g h`` [N m/rad] and ``m g`` [N] (``m``: body mass, ``h``: 1 m),
    ``d_rot`` and ``d_com`` are time constants [s] (damping over stiffness); the torques are
    computed every ``every`` control ticks (at ticks ``k % every == 0``) and held in between
    (2: 60 Hz, a loop delay of at most 8 ms where human balance reflexes take 30-100 ms; it
    halves the feedback's cost)."""

    k_rot: float = 1.0
    d_rot: float = 0.1
    k_com: float = 1.0
    d_com: float = 0.3
    every: int = 2
    #: swing-foot placement: metres of placement per metre of centre-of-mass error and per
    #: m/s of root velocity error [s]; 0 and 0: none (the default: on the 22 clips of
    #: ``bench_simulate.py --controllers`` at 28 samples, 1 and 0.3 s kept the same clips up
    #: with 125 mm root-relative error against 113; docs/synthetic.md)
    c_d: float = 0.0
    c_v: float = 0.0
    #: [1/s] the root's horizontal position error (reference less simulated) added to the
    #: velocity target of the centre-of-mass term; 0: off (the feedback before it). On the 22
    #: clips of ``bench_simulate.py --controllers`` at 28 samples, 2 fell in 0.32 of the clips
    #: against 0.27 (110 / 319 mm against 113 / 322); 2 beyond 0.1 m (``drift_dead``) in 0.27,
    #: 105 / 272 mm: eval's default (``sim.simulate.validate.DEFAULT_BALANCE``; docs/synthetic.md)
    k_drift: float = 0.0
    #: [m] the position error is clipped to this length
    drift_max: float = 0.3
    #: [m] and then shortened by this (an error of at most this asks nothing)
    drift_dead: float = 0.0
    #: the drift's position error measured at the mid-point of the stance feet (the feet the
    #: reference stands on, ``BalancePlan.feet``) rather than the root: off by default (a
    #: posture offset of the pelvis over feet that stand where the reference's do asks nothing)
    drift_feet: bool = False

    def __post_init__(self):
        if int(self.every) < 1:
            raise UsageError(f"Balance.every must be a positive tick count; got {self.every}")
        if min(self.k_drift, self.drift_max, self.drift_dead) < 0:
            raise UsageError(
                f"Balance.k_drift, drift_max and drift_dead must be >= 0; got {self.k_drift}, "
                f"{self.drift_max}, {self.drift_dead}"
            )


@dataclass(frozen=True)
class BalancePlan:
    """What the feedback needs per reference tick (T ticks): root orientation (T, 4) and angular
    velocity (T, 3) [rad/s, local frame], root horizontal velocity (T, 2) [m/s], the centre of
    mass minus the stance feet's mid-point (T, 2) [m], stance per side (T, 2) bool and each
    side's share of the moments (T, 2) (1 over the stance feet's count, 0 off stance); the hinges
    driven, per side (left, right) and group (hip, ankle), up to three each: joint ids and
    actuator ids (2, 2, 3) (a missing hinge repeats the first, masked out by ``mask`` (2, 2,
    3); ``valid`` its bool); the foot body ids (2,); the gains in SI units (k_rot [N m/rad], d_rot [N m s/rad],
    k_com [N], d_com [N s]); the root's horizontal position (T, 2) [m] (with ``drift_feet`` the
    stance feet's mid-point) and the drift term's ``(k_drift, drift_max, drift_dead)`` where it
    is on."""

    quat: np.ndarray
    angvel: np.ndarray
    vel: np.ndarray
    com_off: np.ndarray
    stance: np.ndarray
    share: np.ndarray
    jids: np.ndarray
    aids: np.ndarray
    mask: np.ndarray
    valid: np.ndarray
    feet: np.ndarray
    gains: tuple[float, float, float, float]
    every: int = 1
    #: swing-foot placement (c_d [m/m], c_v [s]) and the hip hinges' stiffness (2, 3) [N m/rad]
    #: (0 where masked) and the thigh body ids (2,); None: no placement
    step: tuple | None = None
    xy: np.ndarray | None = None  # (T, 2) the root's horizontal position [m]; None: no drift term
    drift: tuple[float, float, float] = (0.0, 0.0, 0.0)  # k_drift [1/s], max, dead [m]
    drift_feet: bool = False  # xy is the stance feet's mid-point, compared with the body's
    #: derived from the fields above when the plan is made (they are read-only from then on):
    #: per tick None (no stance foot) or (share row (2,) view, its two shares and their sum as
    #: floats, the swing side (0, 1) where one foot stands else -1, and the rows of ``angvel``,
    #: ``vel``, ``com_off`` and ``xy`` (None without drift) as float lists); the rows of
    #: ``xaxis`` gathered (12,), ``mask`` as (2, 2, 3, 1), and the valid hinges' actuator ids
    #: and flat (2, 2, 3) positions
    ticks: list = field(init=False, repr=False, compare=False)
    hinge_rows: np.ndarray = field(init=False, repr=False, compare=False)
    row_mask: np.ndarray = field(init=False, repr=False, compare=False)
    valid_aids: np.ndarray = field(init=False, repr=False, compare=False)
    valid_rows: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        derived = {
            "ticks": _tick_rows(self),
            "hinge_rows": np.ascontiguousarray(self.jids).reshape(-1),
            "row_mask": np.asarray(self.mask, dtype=float)[..., None],
            "valid_aids": self.aids[self.valid],
            "valid_rows": np.flatnonzero(self.valid),
        }
        for name, value in derived.items():
            object.__setattr__(self, name, value)


def _tick_rows(plan: BalancePlan) -> list:
    """``BalancePlan.ticks`` of ``plan`` (the sums and tests as the feedback made them per call)."""
    lists = [a.tolist() for a in (plan.angvel, plan.vel, plan.com_off)]
    xy = plan.xy.tolist() if plan.xy is not None else [None] * len(plan.share)
    rows = []
    for k, w in enumerate(plan.share):
        if not w.any():
            rows.append(None)
            continue
        one = w.sum() == 1.0 and w.max() == 1.0
        swing = int(np.argmin(w)) if one else -1
        w0, w1 = w.tolist()
        rows.append((w, w0, w1, float(w.sum()), swing, *(a[k] for a in lists), xy[k]))
    return rows


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


def _under(terrain, data, g: int) -> float:
    """[m] the support's height under geom ``g``'s centre (0: the floor)."""
    return float(surface_height(terrain, data.geom_xpos[g, :2]))


def balance_plan(model, ref_qpos: np.ndarray, ref_qvel: np.ndarray, gains: Balance) -> BalancePlan:
    """:class:`BalancePlan` of a reference ``ref_qpos`` (T, nq) with velocities ``ref_qvel``
    (T, nv) at the control rate."""
    data = mujoco.MjData(model)
    feet = np.array([model.body(f"{s}foot").id for s in "lr"])
    geoms = [_foot_geoms(model, s) for s in "lr"]
    T = len(ref_qpos)
    stance = np.zeros((T, 2), dtype=bool)
    com_off = np.zeros((T, 2))
    mid = np.zeros((T, 2))  # the stance feet's mid-point (both feet where none stands)
    terrain = terrain_geoms(model)  # a foot on a step stands
    for t in range(T):
        data.qpos[:] = ref_qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        for s in range(2):
            stance[t, s] = (
                bool(geoms[s])
                and min(_bottom(model, data, g) - _under(terrain, data, g) for g in geoms[s])
                <= STANCE_HEIGHT
            )
        on = stance[t] if stance[t].any() else np.ones(2, dtype=bool)
        mid[t] = data.xpos[feet[on]].mean(axis=0)[:2]
        com_off[t] = data.subtree_com[1, :2] - mid[t]
    mgh = total_mass(model) * G
    jids, aids = np.zeros((2, 2, 3), dtype=int), np.zeros((2, 2, 3), dtype=int)
    mask = np.zeros((2, 2, 3))
    for i, side in enumerate("lr"):
        for j, bone in enumerate(("femur", "foot")):
            js, as_ = _hinges(model, side, bone)
            n = min(3, js.size)
            if n:
                jids[i, j], aids[i, j] = js[0], as_[0]
                jids[i, j, :n], aids[i, j, :n], mask[i, j, :n] = js[:n], as_[:n], 1.0
    return BalancePlan(
        quat=ref_qpos[:, 3:7].copy(),
        angvel=ref_qvel[:, 3:6].copy(),
        vel=ref_qvel[:, :2].copy(),
        com_off=com_off,
        stance=stance,
        share=stance / np.maximum(1, stance.sum(axis=1, keepdims=True)),
        jids=jids,
        aids=aids,
        mask=mask,
        valid=mask > 0,
        feet=feet,
        gains=(
            gains.k_rot * mgh,
            gains.d_rot * gains.k_rot * mgh,
            gains.k_com * mgh,
            gains.d_com * gains.k_com * mgh,
        ),
        every=int(gains.every),
        step=_step_plan(model, aids, mask, gains),
        xy=(mid if gains.drift_feet else ref_qpos[:, :2].copy()) if gains.k_drift > 0 else None,
        drift=(float(gains.k_drift), float(gains.drift_max), float(gains.drift_dead)),
        drift_feet=bool(gains.drift_feet),
    )


def _step_plan(model, aids: np.ndarray, mask: np.ndarray, gains: Balance) -> tuple | None:
    """``BalancePlan.step`` of actuators ``aids`` (2, 2, 3) masked by ``mask``."""
    if gains.c_d == 0.0 and gains.c_v == 0.0:
        return None
    kp = model.actuator_gainprm[aids[:, 0], 0] * mask[:, 0]
    thighs = np.array([model.body(f"{s}femur").id for s in "lr"])
    return (float(gains.c_d), float(gains.c_v)), kp, thighs


def balance_torques(model, data, plan: BalancePlan, k: int, out: np.ndarray) -> np.ndarray:
    """Write into ``out`` (nu,) the feedback torques [N m] at reference tick ``k`` for ``data``'s
    ``qpos``/``qvel`` (kinematics and centre of mass recomputed); zero off the stance legs and
    where the reference has no stance foot. Returns ``out``.

    The small vector algebra runs on Python floats (the same IEEE operations in the same order
    as numpy's elementwise ones); every matrix product and solve is numpy's on the shapes it
    always had (BLAS and LAPACK kernels, whose rounding is theirs), so the torques are the same
    to the last bit however the arithmetic around them is arranged."""
    out.fill(0.0)
    tick = plan.ticks[k]
    if tick is None:  # the reference has no stance foot
        return out
    w, w0, w1, wsum, swing, angvel, vel, com_off, xy = tick
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    k_rot, d_rot, k_com, d_com = plan.gains
    qpos = data.qpos
    e = np.zeros(3)
    mujoco.mju_subQuat(e, plan.quat[k], qpos[3:7])  # local frame of the simulated root
    e0, e1, e2 = e.tolist()
    v0, v1, _, om0, om1, om2 = data.qvel[:6].tolist()
    pull = (  # k_rot e + d_rot de, de the angular velocity error (local frame)
        k_rot * e0 + d_rot * (angvel[0] - om0),
        k_rot * e1 + d_rot * (angvel[1] - om1),
        k_rot * e2 + d_rot * (angvel[2] - om2),
    )
    r0, r1, r2 = (data.xmat[1].reshape(3, 3) @ np.array(pull)).tolist()  # world [N m]
    m0, m1, _ = (w @ data.xpos.take(plan.feet, axis=0)).tolist()
    m0, m1 = m0 / wsum, m1 / wsum  # the stance feet's mid-point
    c0, c1, _ = data.subtree_com[1].tolist()
    f0 = k_com * ((c0 - m0) - com_off[0])
    f1 = k_com * ((c1 - m1) - com_off[1])
    if xy is not None:  # the velocity target leads by the root's (feet's) position error
        s0, s1 = (m0, m1) if plan.drift_feet else qpos[:2].tolist()
        l0, l1 = drift_lead_xy(xy[0] - s0, xy[1] - s1, *plan.drift)
        f0 -= d_com * l0
        f1 -= d_com * l1
    f0 += d_com * (v0 - vel[0])  # horizontal [N]
    f1 += d_com * (v1 - vel[1])
    M = np.array((  # per side and group (hip, ankle): the moment asked for [N m]; -(z x f)
        w0 * r0, w0 * r1, w0 * r2, w0 * f1, w0 * -f0, w0 * 0.0,
        w1 * r0, w1 * r1, w1 * r2, w1 * f1, w1 * -f0, w1 * 0.0,
    )).reshape(2, 2, 3, 1)  # fmt: skip
    # damped least squares over each group's hinge axes X (rows: world axes; masked rows 0)
    X = data.xaxis.take(plan.hinge_rows, axis=0).reshape(2, 2, 3, 3)
    X *= plan.row_mask
    XXt = X @ X.swapaxes(-1, -2)
    XXt += _DAMPED
    tau = _solve(XXt, X @ M)
    out[plan.valid_aids] = -tau.take(plan.valid_rows)
    if plan.step is not None and swing >= 0:  # one stance foot
        _place_swing_foot(data, plan, swing, k, (m0, m1), X[swing, 0], XXt[swing, 0], out)
    return out


def _place_swing_foot(data, plan, side: int, k: int, mid, X, XXt, out) -> None:
    """Add to ``out`` the swing hip's placement torques (module docstring) of leg ``side``;
    ``mid`` the stance feet's horizontal mid-point (2,) [m], ``X`` (3, 3) the swing hip's hinges'
    world axes (masked rows 0), ``XXt`` the damped ``X X^T``."""
    (c_d, c_v), kp, thighs = plan.step
    e_c = data.subtree_com[1, :2] - np.asarray(mid) - plan.com_off[k]  # [m]
    de_c = data.qvel[:2] - plan.vel[k]  # [m/s]
    dp = c_d * e_c + c_v * de_c
    hip_to_ankle = data.xpos[plan.feet[side]] - data.xpos[thighs[side]]
    r = np.array([dp[1], -dp[0], 0.0]) / max(np.linalg.norm(hip_to_ankle), 1e-3)  # dp x z
    dq = np.linalg.solve(XXt, X @ r)
    valid = plan.valid[side, 0]
    out[plan.aids[side, 0][valid]] += (kp[side] * dq)[valid]


def held_torques(model, data, plan: BalancePlan, k: int, out: np.ndarray) -> np.ndarray:
    """:func:`balance_torques` at ticks ``k % plan.every == 0``; at the others ``out`` (nu,) as
    the last such tick left it (the caller keeps ``out`` from tick to tick and starts at such a
    tick). Returns ``out``."""
    return balance_torques(model, data, plan, k, out) if k % plan.every == 0 else out
