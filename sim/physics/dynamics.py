"""Inverse dynamics of a fitted motion on the humanoid: whole-body wrench, residual, joint torques.

Pipeline per motion (``qpos`` (T, nq) on a model from :func:`sim.model.humanoid.build_mjcf`):

1. **Derivatives**, from where they are known: :meth:`InverseDynamics.run` takes the motion's
   ``qvel``/``qacc`` where the caller has them (:class:`sim.analysis.job.PhysicsJob` maps the
   original's source-frame point derivatives and a reconstruction's curve derivatives through
   the fitted humanoid's Jacobians, :meth:`sim.physics.ik.HumanoidIK.rates`). Otherwise (frames
   at the analysis rate only) :func:`derivatives` differences consecutive samples on the
   configuration manifold (``mj_differentiatePos``, hinge steps wrapped) into a tangent path and
   applies a Savitzky-Golay filter (cubic, ``window`` frames, default 9 = 0.3 s at 30 fps;
   polynomial fits at the clip ends), there because second differences of raw mocap amplify
   marker noise. Its gain at 30 fps: velocity 0.994 at 1.5 Hz, 0.92 at 3 Hz, 0.56 at 5 Hz;
   acceleration 0.87 at 1.5 Hz, 0.56 at 3 Hz, 0.14 at 5 Hz
   (:func:`sim.motion.velocities.local_polynomial_gain`); an impact spreads over +-4 frames.
2. **Whole-body wrench.** ``mj_inverse`` with constraints (contacts, limits) disabled gives
   ``qfrc_inverse``; its six free-joint entries are the external wrench Newton-Euler requires
   beyond gravity: force ``F = m (a_com - g)`` [N] (world axes) and, moved to the centre of mass,
   torque ``tau = dL/dt`` [N m], the rate of angular momentum about the CoM.
3. **Residual, force and torque apart.** Ground forces may act at the sole points of the feet in
   contact (:meth:`sim.physics.contacts.Contacts.points`, on the floor plane), each inside a
   friction pyramid of ``PYRAMID_EDGES`` edges with coefficient ``mu`` (default 0.8, shoe on
   floor). The *residual force* is what a non-negative least-squares fit of the edge magnitudes
   (``scipy.optimize.nnls``) to ``F`` alone leaves: the force no admissible ground force supplies.
   The *residual torque* is what a second fit, to ``F`` first (rows weighted
   ``FORCE_PRIORITY``) and then ``tau`` (per metre), leaves of ``tau``. With no foot in contact
   the frame is ballistic and the whole wrench is residual.
4. **Joint torques.** ``qfrc_inverse`` minus the generalised force of the force-first fit's
   ground forces (``J^T f`` at the contact points); its hinge entries are the joint torques [N m].

The analysis model is a copy with joint armature and damping set to zero (they are simulation
stabilisers, not anatomy: the armature alone would turn a jittery thumb into hundreds of N m).

Units: metres, seconds, radians, newtons, kilograms; world z up, gravity from the model.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.optimize import nnls
from scipy.signal import savgol_filter

from sim import mujoco_log  # noqa: F401  # MuJoCo's warnings on stderr, not in a file
from sim.errors import UsageError
from sim.model.angles import wrap_angle

MU = 0.8  # friction coefficient of the ground (shoe sole on a floor)
PYRAMID_EDGES = 4
TORQUE_SCALE_M = 1.0  # [m] torque rows per metre in the force-first fit
FORCE_PRIORITY = 100.0  # weight of force rows over torque rows: the force is explained first


def analysis_model(model):
    """A copy of ``model`` for inverse dynamics: no armature, damping, springs or constraints."""
    m = copy.deepcopy(model)
    m.dof_armature[:] = 0.0
    m.dof_damping[:] = 0.0
    m.opt.disableflags |= int(
        mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
        | mujoco.mjtDisableBit.mjDSBL_CONTACT
        | mujoco.mjtDisableBit.mjDSBL_SPRING
        | mujoco.mjtDisableBit.mjDSBL_DAMPER
    )
    return m


def tangent_path(model, qpos: np.ndarray) -> np.ndarray:
    """(T, nv) cumulative sum of ``mj_differentiatePos`` between consecutive frames (s_0 = 0);
    hinge steps are wrapped into [-pi, pi) (a hinge 2 pi further on is the same pose)."""
    q = np.asarray(qpos, dtype=np.float64)
    T = len(q)
    s = np.zeros((T, model.nv))
    v = np.empty(model.nv)
    hinge = model.jnt_type[model.dof_jntid] == mujoco.mjtJoint.mjJNT_HINGE
    for t in range(1, T):
        mujoco.mj_differentiatePos(model, v, 1.0, q[t - 1], q[t])
        v[hinge] = wrap_angle(v[hinge])
        s[t] = s[t - 1] + v
    return s


def derivatives(model, qpos: np.ndarray, fps: float, *, window: int = 9, polyorder: int = 3):
    """Filtered ``qvel`` and ``qacc`` (T, nv) of ``qpos`` (T, nq) at ``fps`` (see module doc).

    ``window`` shrinks to the largest odd number <= T for short motions; below 3 frames the
    derivatives are zero.
    """
    s = tangent_path(model, qpos)
    T = len(s)
    if T < 3:
        return np.zeros_like(s), np.zeros_like(s)
    w = min(window, T if T % 2 else T - 1)
    p = min(polyorder, w - 1)
    dt = 1.0 / fps
    vel = savgol_filter(s, w, p, deriv=1, delta=dt, axis=0, mode="interp")
    acc = savgol_filter(s, w, p, deriv=2, delta=dt, axis=0, mode="interp") if p >= 2 else 0 * s
    return vel, acc


def pyramid(mu: float = MU, edges: int = PYRAMID_EDGES) -> np.ndarray:
    """(edges, 3) unit edge directions of the friction pyramid about +z."""
    a = 2 * np.pi * np.arange(edges) / edges
    d = np.stack([mu * np.cos(a), mu * np.sin(a), np.ones(edges)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def residual_wrench(
    force: np.ndarray,
    torque: np.ndarray,
    com: np.ndarray,
    contacts: np.ndarray,
    *,
    mu: float = MU,
    edges: int = PYRAMID_EDGES,
):
    """The part of a required wrench no ground forces at ``contacts`` can supply, force and
    torque apart.

    * Residual force: what remains of ``force`` after the best non-negative combination of the
      friction pyramids' edges at the contact points (force rows only: any point of contact can
      carry any force inside its cone, so this is the force no contact can supply, whatever the
      torque).
    * Residual torque: with the ground forces chosen to explain the force first (force rows
      weighted :data:`FORCE_PRIORITY` times the torque rows, torque rows per metre
      :data:`TORQUE_SCALE_M`), the torque about the CoM they leave unexplained.

    Args:
        force: (3,) required external force [N] (beyond gravity).
        torque: (3,) required torque about ``com`` [N m].
        com: (3,) centre of mass [m].
        contacts: (K, 3) contact points [m] (K may be 0: ballistic frame).
    Returns:
        residual force (3,) [N], residual torque (3,) [N m], contact forces (K, 3) [N] of the
        force-first fit.
    """
    K = len(contacts)
    if K == 0:
        return np.array(force, float), np.array(torque, float), np.zeros((0, 3))
    D = pyramid(mu, edges)  # (E, 3)
    r = np.asarray(contacts) - com  # (K, 3)
    top = np.tile(D.T, (1, K))  # (3, K E)
    lam_f, _ = nnls(top, np.asarray(force, float), maxiter=50 * top.shape[1])
    res_force = np.asarray(force, float) - top @ lam_f
    bot = np.cross(np.repeat(r, edges, axis=0), np.tile(D, (K, 1))).T / TORQUE_SCALE_M
    A = np.vstack([FORCE_PRIORITY * top, bot])
    b = np.concatenate(
        [FORCE_PRIORITY * np.asarray(force, float), np.asarray(torque) / TORQUE_SCALE_M]
    )
    lam, _ = nnls(A, b, maxiter=50 * A.shape[1])
    f = (lam.reshape(K, edges, 1) * D[None]).sum(axis=1)
    res_torque = np.asarray(torque, float) - np.cross(r, f).sum(axis=0)
    return res_force, res_torque, f


@dataclass(frozen=True)
class Dynamics:
    """Per-frame dynamics of one motion (T frames, H hinges).

    Attributes:
        qvel, qacc: (T, nv) the derivatives used (given, or filtered).
        com: (T, 3) centre of mass [m].
        force, torque: (T, 3) required external wrench beyond gravity: force [N] and torque about
            the CoM [N m] (= rate of angular momentum about the CoM), world axes.
        residual_force: (T, 3) the force no ground force explains [N] (force-only fit).
        residual_torque: (T, 3) the torque about the CoM the force-first fit leaves [N m].
        contact_force: (T, 3) total fitted ground force [N].
        joint_torque: (T, H) hinge torques [N m] with the fitted ground forces acting.
        mass: total mass [kg]; weight: its weight [N].
    """

    qvel: np.ndarray
    qacc: np.ndarray
    com: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    residual_force: np.ndarray
    residual_torque: np.ndarray
    contact_force: np.ndarray
    joint_torque: np.ndarray
    mass: float
    weight: float


class InverseDynamics:
    """Owns the analysis model (:func:`analysis_model`) and its data; made once, reused.

    Args:
        model: MjModel from :func:`sim.model.humanoid.build_mjcf`.
        mu: ground friction coefficient; window, polyorder: the Savitzky-Golay filter.
    """

    def __init__(self, model, *, mu: float = MU, window: int = 9, polyorder: int = 3):
        self.model = analysis_model(model)
        self.data = mujoco.MjData(self.model)
        self.mu, self.window, self.polyorder = mu, window, polyorder
        self.root = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "root")
        self.mass = float(self.model.body_subtreemass[self.root])
        self.weight = self.mass * float(np.linalg.norm(self.model.opt.gravity))
        self._jac = np.zeros((3, self.model.nv))

    def wrench(self, qpos, qvel, qacc):
        """Required wrench of one frame: force (3,) [N], torque about CoM (3,) [N m], CoM (3,) [m],
        and ``qfrc_inverse`` (nv,). Leaves ``self.data`` at this frame."""
        m, d = self.model, self.data
        d.qpos[:], d.qvel[:], d.qacc[:] = qpos, qvel, qacc
        mujoco.mj_inverse(m, d)
        qfrc = d.qfrc_inverse.copy()
        R = d.xmat[self.root].reshape(3, 3)
        o = d.xpos[self.root]
        com = d.subtree_com[self.root].copy()
        F = qfrc[:3].copy()
        tau_o = R @ qfrc[3:6]
        return F, tau_o + np.cross(o - com, F), com, qfrc

    def run(self, qpos: np.ndarray, fps: float, contacts, *, qvel=None, qacc=None) -> Dynamics:
        """Dynamics of ``qpos`` (T, nq) at ``fps``.

        Args:
            contacts: per frame a list of ``(body id, point (3,))`` where ground forces may act
                (points on the ground plane, bodies of the model).
            qvel, qacc: (T, nv) the motion's derivatives where known (e.g.
                :func:`stencil_derivatives` of denser samples); default :func:`derivatives`.
        """
        qpos = np.asarray(qpos, dtype=np.float64)
        T = len(qpos)
        if (qvel is None) != (qacc is None):
            raise UsageError("give both qvel and qacc, or neither")
        if qvel is None:
            qvel, qacc = derivatives(
                self.model, qpos, fps, window=self.window, polyorder=self.polyorder
            )
        elif np.shape(qvel) != (T, self.model.nv) or np.shape(qacc) != (T, self.model.nv):
            raise UsageError(f"qvel and qacc must be {(T, self.model.nv)}")
        H = self.model.nv - 6
        out = {k: np.zeros((T, 3)) for k in ("com", "F", "tau", "rF", "rtau", "cF")}
        jt = np.zeros((T, H))
        for t in range(T):
            F, tau, com, qfrc = self.wrench(qpos[t], qvel[t], qacc[t])
            pts = np.array([p for _, p in contacts[t]]).reshape(-1, 3)
            rF, rtau, f = residual_wrench(F, tau, com, pts, mu=self.mu)
            gen = np.zeros(self.model.nv)
            for (body, p), fk in zip(contacts[t], f, strict=True):
                mujoco.mj_jac(self.model, self.data, self._jac, None, np.asarray(p, float), body)
                gen += self._jac.T @ fk
            jt[t] = (qfrc - gen)[6:]
            vals = (com, F, tau, rF, rtau, f.sum(0))
            for k, v in zip(("com", "F", "tau", "rF", "rtau", "cF"), vals, strict=True):
                out[k][t] = v
        return Dynamics(
            qvel, qacc, out["com"], out["F"], out["tau"], out["rF"], out["rtau"], out["cF"], jt,
            self.mass, self.weight,
        )  # fmt: skip


def summarise_dynamics(
    dyn: Dynamics, anatomical: np.ndarray, measured: np.ndarray | None = None
) -> dict:
    """Per-frame dynamics figures (T,) and their clip summary (key ``"summary"``) over the
    ``measured`` frames (T,) bool (default all; none measured: the figures are nan), with
    ``dynamics_n`` and ``dynamics_unmeasured_n`` frames and ``residual_force_bw_unmeasured``
    (mean over the unmeasured frames, None if none)."""
    rf = np.linalg.norm(dyn.residual_force, axis=1) / dyn.weight
    rt = np.linalg.norm(dyn.residual_torque, axis=1) / dyn.mass
    tau = dyn.joint_torque[:, anatomical]
    jt = np.sqrt(np.mean(tau**2, axis=1)) / dyn.mass if tau.shape[1] else np.zeros(len(rf))
    m = np.ones(len(rf), dtype=bool) if measured is None else np.asarray(measured, dtype=bool)
    some = bool(m.any())
    nan = float("nan")
    return {
        "residual_force_bw": rf,
        "residual_torque_nm_kg": rt,
        "joint_torque_rms_nm_kg": jt,
        "summary": {
            "residual_force_bw": float(rf[m].mean()) if some else nan,
            "residual_force_bw_p95": float(np.percentile(rf[m], 95)) if some else nan,
            "residual_torque_nm_kg": float(rt[m].mean()) if some else nan,
            "joint_torque_rms_nm_kg": (
                float(np.sqrt(np.mean(tau[m] ** 2)) / dyn.mass) if tau.shape[1] else 0.0
            )
            if some
            else nan,
            "dynamics_n": int(m.sum()),
            "dynamics_unmeasured_n": int((~m).sum()),
            "residual_force_bw_unmeasured": float(rf[~m].mean()) if (~m).any() else None,
        },
    }
