"""A time-varying LQR tracker: full-state linear feedback around the reference from MuJoCo's
own finite-difference derivatives (no sampler, no external force).

The plain tracker's PD has no coupling (a torso lean does not move the ankles) and the
whole-body QP looks one tick ahead; a linear-quadratic regulator couples every hinge to every
state through the body's dynamics, floor contacts included. Per control tick ``k`` of a
contact-consistent reference (``sim.simulate.reference``):

* the operating control ``u0[k]`` (:func:`lqr_reference`): the free-floating inverse dynamics
  of the reference (smoothed velocities, as the whole-body QP's) with its root wrench moved
  onto the feet near the floor (``sim.simulate.feedforward.balanced_support``): on torque
  actuators (``sim_model(actuators="motor")``) those hinge torques, on position servos the
  plain tracker's targets (angle, velocity lead, feed-forward over ``kp``); clipped to the
  actuators' range;
* ``mujoco.mjd_transitionFD`` linearises one physics step (forward differences, MuJoCo's
  tangent space: the free joint's rotation a 3-vector); held for the tick's ``SUBSTEPS`` steps
  it gives ``A = A1^S``, ``B = (I + A1 + ... + A1^(S-1)) B1`` (:func:`tick_linearisation`);
* state weights ``Q`` (:func:`state_weights`: Bryson tolerances on root orientation, height and
  position, the horizontal centre of mass and its velocity through the CoM Jacobian, hinge
  angles and velocities) and control weights ``R`` (:func:`control_weights`: a share of each
  hinge's torque limit, over ``kp`` for a servo);
* online (:attr:`LQRWeights.online`, the default): linearised at the simulated state every
  tick, ``sweeps`` Riccati steps of that frozen system from the value matrix the last tick left
  (:func:`online_gain`: a receding horizon that lengthens while the contacts stay alike); or
  once along the reference (the body lowered by ``sink`` so that its stance soles touch) with one
  finite-horizon Riccati pass backward over the clip (:func:`lqr_gains`, :func:`riccati_gains`);
* the simulation applies ``u = clip(u0[k] - K dx)``, ``dx`` the state's deviation from the
  reference (``mujoco.mj_differentiatePos``, velocities subtracted).

Deterministic: the same reference gives the same simulation bit for bit. Cost: one
``mjd_transitionFD`` (about 116-138 physics steps' worth on this body) per tick. Units: metres,
seconds, radians, newton metres. What it gave (it falls less than the plain tracker, far more
than the sampler): ``docs/synthetic.md``, "The LQR tracker".
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.simulate.falls import fall_reference, has_fallen
from sim.simulate.feedforward import (
    balanced_support,
    inverse_dynamics,
    reference_derivatives,
)
from sim.simulate.model import CONTROL_HZ, SUBSTEPS
from sim.simulate.tracking import TrackRecord, floor_ids, foot_forces, foot_sides
from sim.simulate.wholebody_reference import SMOOTH_S


@dataclass(frozen=True)
class LQRWeights:
    """The LQR's costs as Bryson's rule: each state's tolerated deviation (its weight one over
    its square) and each torque's cost relative to its human limit. Deviations [m, rad, m/s,
    rad/s]. The defaults fell least of 7 weightings screened on 22 clips (docs/synthetic.md):
    weak hinge weights (the servos' PD tracks the hinges), the centre of mass strong, one
    Riccati step a tick; dearer torques and stiffer hinges hold a still pose better but fall
    more on motion, cheaper torques saturate and fall more."""

    root_rot: float = 0.02  # root orientation
    root_z: float = 0.02  # root height
    root_xy: float = 1.0  # root horizontal position
    com_xy: float = 0.05  # centre of mass, horizontal (through its Jacobian)
    hinge: float = 1.0  # every hinge angle (the servos' own PD tracks them too)
    root_vel: float = 0.3  # root linear velocity
    root_angvel: float = 1.0  # root angular velocity
    hinge_vel: float = 10.0  # every hinge velocity
    com_vel: float = 0.2  # centre-of-mass horizontal velocity
    torque: float = 0.3  # this share of a hinge's torque limit costs one tolerated deviation
    every: int = 1  # control ticks per linearisation
    eps: float = 1e-6  # finite-difference step
    sink: float = 0.0005  # [m] the operating point lowered so: stance soles in contact
    online: bool = True  # linearise at the simulated state, not along the reference
    sweeps: int = 1  # online: Riccati steps per linearisation, from the last value matrix


def riccati_gains(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray,
                  P_end: np.ndarray) -> np.ndarray:  # fmt: skip
    """(T, m, n) gains of the finite-horizon discrete LQR ``x[k+1] = A[k] x[k] + B[k] u[k]``,
    cost ``sum x'Q[k]x + u'Ru`` plus ``x[T]' P_end x[T]``, ``u[k] = -K[k] x[k]``: the Riccati
    recursion backward. ``A`` (T, n, n), ``B`` (T, n, m), ``Q`` (T, n, n), ``R`` (m, m)."""
    T = len(A)
    K = np.empty((T, B.shape[2], A.shape[1]))
    P = P_end
    for k in range(T - 1, -1, -1):
        a, b = A[k], B[k]
        BP = b.T @ P
        K[k] = np.linalg.solve(R + BP @ b, BP @ a)
        P = Q[k] + a.T @ P @ (a - b @ K[k])
        P = 0.5 * (P + P.T)
    return K


def lqr_reference(model, ref_qpos: np.ndarray, data=None):
    """The operating points of ``ref_qpos`` (T, nq at ``CONTROL_HZ``, floor z = 0): (T, nv)
    smoothed velocities (as the whole-body QP's reference) and (T, nu) controls: the
    feed-forward hinge torques [N m] (free-floating inverse dynamics, root wrench on the feet
    near the floor) clipped to the torque limits for torque actuators; for position actuators
    the plain tracker's targets [rad] (reference angle, leading by ``kv / kp`` times its
    velocity and by the feed-forward over ``kp``), clipped to their control range."""
    data = data if data is not None else mujoco.MjData(model)
    qvel, _ = reference_derivatives(model, ref_qpos)
    if len(ref_qpos) > 1:
        qvel = gaussian_filter1d(qvel, SMOOTH_S * CONTROL_HZ, axis=0, mode="nearest")
        qacc = np.gradient(qvel, 1.0 / CONTROL_HZ, axis=0)
    else:
        qacc = np.zeros_like(qvel)
    force = inverse_dynamics(model, ref_qpos, qvel, qacc, contacts=False, data=data)
    tau = balanced_support(model, ref_qpos, force, data=data)[:, 6:]
    if is_torque_body(model):
        u = tau
    else:
        kp = model.actuator_gainprm[:, 0]
        lead = model.actuator_biasprm[:, 2] / model.actuator_biasprm[:, 1]  # kv / kp [s]
        u = ref_qpos[:, 7:] + lead * qvel[:, 6:] + tau / kp
    return qvel, np.clip(u, model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1])


def is_torque_body(model) -> bool:
    """Whether ``model``'s actuators are torque motors (``sim_model(actuators="motor")``), not
    position servos."""
    return not model.actuator_biasprm[:, 1].any()


def control_weights(model, w: LQRWeights) -> np.ndarray:
    """(nu, nu) ``R``: a torque of ``w.torque`` times the hinge's limit costs 1; for position
    servos the target offset that asks for that torque (over the servo's ``kp``)."""
    scale = w.torque * model.actuator_forcerange[:, 1]
    if is_torque_body(model):
        scale = w.torque * model.actuator_ctrlrange[:, 1]
    else:
        scale = scale / model.actuator_gainprm[:, 0]
    return np.diag(scale**-2.0)


def tick_linearisation(model, data, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """(2nv, 2nv) ``A`` and (2nv, nu) ``B`` of one control tick (``SUBSTEPS`` physics steps,
    the control held) at ``data``'s state and control: one step's ``mjd_transitionFD``
    (forward differences) chained."""
    n = 2 * model.nv
    A1, B1 = np.zeros((n, n)), np.zeros((n, model.nu))
    mujoco.mjd_transitionFD(model, data, eps, 0, A1, B1, None, None)
    A, S = A1.copy(), np.eye(n) + A1
    for _ in range(SUBSTEPS - 2):
        A = A @ A1
        S += A
    return A @ A1, S @ B1


def state_weights(model, data, w: LQRWeights) -> np.ndarray:
    """(2nv, 2nv) ``Q`` at ``data``'s pose (kinematics and CoM done): diagonal tolerances of
    :class:`LQRWeights` plus the horizontal centre of mass and its velocity through the CoM
    Jacobian (``mj_jacSubtreeCom`` of the root)."""
    nv = model.nv
    diag = np.empty(2 * nv)
    diag[:2] = w.root_xy**-2
    diag[2] = w.root_z**-2
    diag[3:6] = w.root_rot**-2
    diag[6:nv] = w.hinge**-2
    diag[nv : nv + 3] = w.root_vel**-2
    diag[nv + 3 : nv + 6] = w.root_angvel**-2
    diag[nv + 6 :] = w.hinge_vel**-2
    Q = np.diag(diag)
    jac = np.zeros((3, nv))
    mujoco.mj_jacSubtreeCom(model, data, jac, 1)
    J = jac[:2]
    Q[:nv, :nv] += w.com_xy**-2 * J.T @ J
    Q[nv:, nv:] += w.com_vel**-2 * J.T @ J
    return Q


def lqr_gains(model, ref_qpos: np.ndarray, qvel: np.ndarray, u_ff: np.ndarray,
              w: LQRWeights) -> np.ndarray:  # fmt: skip
    """(T, nu, 2nv) the time-varying gains along the reference (module docstring): each
    ``w.every``-th tick linearised at (``ref_qpos``, ``qvel``, ``u_ff``) with the body lowered
    by ``w.sink``, held between; the terminal cost the last tick's ``Q``; ticks whose gains
    are not finite get zero gains."""
    T, every = len(ref_qpos), max(1, int(w.every))
    data = mujoco.MjData(model)
    n = 2 * model.nv
    A, B, Q = np.empty((T, n, n)), np.empty((T, n, model.nu)), np.empty((T, n, n))
    for k in range(0, T, every):
        data.qpos[:], data.qvel[:], data.ctrl[:] = ref_qpos[k], qvel[k], u_ff[k]
        data.qpos[2] -= w.sink  # a contact-consistent sole touches z = 0: no contact yet
        mujoco.mj_forward(model, data)
        Q[k : k + every] = state_weights(model, data, w)
        A[k : k + every], B[k : k + every] = tick_linearisation(model, data, w.eps)
    with np.errstate(over="ignore", invalid="ignore"):
        K = riccati_gains(A, B, Q, control_weights(model, w), Q[-1])
    # linearised at the reference, the recursion can blow up across a contact change (measured:
    # overflow on some clips); a tick without finite gains gets none (the servos' PD alone)
    K[~np.isfinite(K).all(axis=(1, 2))] = 0.0
    return K


def online_gain(model, data, R: np.ndarray, P: np.ndarray | None, w: LQRWeights):
    """(nu, 2nv) gain and the value matrix (2nv, 2nv) at ``data``'s state and control
    (``mj_forward`` done): the tick linearised there and ``w.sweeps`` Riccati steps of that
    frozen system from ``P`` (None: ``Q``): a receding horizon that lengthens while the state
    stays alike, the value matrix carried from tick to tick."""
    A, B = tick_linearisation(model, data, w.eps)
    Q = state_weights(model, data, w)
    P = Q if P is None else P
    for _ in range(max(1, w.sweeps)):
        BP = B.T @ P
        K = np.linalg.solve(R + BP @ B, BP @ A)
        P = Q + A.T @ P @ (A - B @ K)
        P = 0.5 * (P + P.T)
    return K, P


def state_error(model, qpos, qvel, ref_q, ref_v, out: np.ndarray) -> np.ndarray:
    """(2nv,) ``out`` = the deviation of (``qpos``, ``qvel``) from (``ref_q``, ``ref_v``):
    ``mj_differentiatePos`` (tangent space, unit time) then the velocity difference."""
    nv = model.nv
    mujoco.mj_differentiatePos(model, out[:nv], 1.0, ref_q, qpos)
    np.subtract(qvel, ref_v, out=out[nv:])
    return out


def track_lqr(model, ref_qpos: np.ndarray, *, weights: LQRWeights | None = None,
              record_every: int = 4, recorder=None):  # fmt: skip
    """Simulate ``model`` (a ``sim_model``, servo or torque actuators) following ``ref_qpos``
    (T, nq at ``CONTROL_HZ``, floor at z = 0, contact-consistent) with the time-varying LQR
    (module docstring) and nothing else: no assistance, no external force. After a fall
    (``sim.simulate.falls``) the feedback goes on. ``recorder``: called ``recorder(k, data)``
    before each tick's physics steps and ``recorder(T, data)`` after the last.

    Returns:
        ``sim.simulate.tracking.Tracking`` with states at ticks ``0, record_every, ...``;
        ``actions`` are the controls (servo targets [rad] or torques [N m]).
    """
    w = weights or LQRWeights()
    T = len(ref_qpos)
    qvel, u_ff = lqr_reference(model, ref_qpos)
    K = None if w.online else lqr_gains(model, ref_qpos, qvel, u_ff, w)
    fall_ref = fall_reference(model, ref_qpos)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref_qpos[0], qvel[0]
    mujoco.mj_forward(model, data)
    floor, side = floor_ids(model), foot_sides(model)
    rec = TrackRecord(model, T, record_every)
    rec.assist[:], rec.wrench[:] = 0.0, 0.0
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    R = control_weights(model, w)
    dx = np.empty(2 * model.nv)
    fell, P = False, None
    for k in range(T):
        mujoco.mj_forward(model, data)
        if not fell and has_fallen(model, data, fall_ref, k):
            fell = True
            rec.fall(k)
        state_error(model, data.qpos, data.qvel, ref_qpos[k], qvel[k], dx)
        if K is None and k % max(1, w.every) == 0:
            data.ctrl[:] = u_ff[k]
            gain, P = online_gain(model, data, R, P, w)
        gain = gain if K is None else K[k]
        data.ctrl[:] = np.clip(u_ff[k] - gain @ dx, lo, hi)
        i, r = divmod(k, record_every)
        rec.contacts(data, floor, i if r == 0 else None)
        if r == 0:
            rec.state(i, data)
        if recorder is not None:
            recorder(k, data)
        mujoco.mj_step(model, data)
        if r == 0:
            rec.torque[i] = data.actuator_force
            foot_forces(model, data, floor, side, rec.foot[i])
        mujoco.mj_step(model, data, nstep=SUBSTEPS - 1)
    if recorder is not None:
        recorder(T, data)
    return rec.result(model, data, fell)
