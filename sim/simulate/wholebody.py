"""A contact-aware whole-body tracking controller: an inverse-dynamics QP every control tick.

After Macchietto, Zordan & Shelton 2009 (momentum control for balance), Muico et al. 2009
(contact-aware nonlinear control) and Lee, Kim & Lee 2010 (data-driven biped control): each
control tick solves one small dense quadratic program over the joint accelerations ``qdd`` (nv,)
and the floor's contact forces, and applies the joint torques it implies through torque
actuators (``sim_model(actuators="motor")``), whose range is the human limit. No other force acts
on the body: no root assistance, ever (pushes, when scripted, are the only external forces).

Variables ``x = [qdd (nv), lam (4 C)]``: ``C`` support points (MuJoCo's own contact points of
the sole and toe boxes on the floor, so the planned forces act where the floor's do), each force a
non-negative combination of the four edges of a linearised friction pyramid (coefficient
:attr:`WholeBodyGains.friction`). Constraints:

* the floating base's equations of motion (6 rows, exact): ``M_u qdd + h_u = J_u^T E lam``;
* ``lam >= 0`` (the floor only pushes, inside the pyramid);
* the hinge torques ``tau = M_a qdd + h_a - J_a^T E lam`` within the human limits;
* no hinge accelerated past its range within :attr:`WholeBodyGains.limit_horizon` (MuJoCo's
  joint-limit forces are not in the plan).

Costs (weighted least squares, :class:`WholeBodyGains`), each a PD on the reference plus its
feed-forward acceleration:

* hinge tracking: ``qdd_hinge = qdd_ref + kp (q_ref - q) + kd (v_ref - v)``;
* root orientation, the same on the free joint's rotation;
* centre of mass: ``sum f / m = a_ref + kp (c_ref - c) + kd (cdot_ref - cdot) - g``, and the
  rate of centroidal angular momentum ``sum (p - c) x f`` towards the reference's: balance,
  through the contact forces (Macchietto 2009);
* feet: every support point keeps still (its velocity damped to zero: no slip, no push into
  the floor); a foot the reference has on the floor (its sole within :data:`STANCE_GAP`) that
  touches it turns to the reference sole's orientation (flat, or rolling heel to toe); every
  other foot tracks the reference's sole pose (position and orientation, world frame, moved
  with the support offset, :func:`_anchor`): the reference's foot placement. Options
  (:class:`WholeBodyGains`, all off by default): the swing sole's orientation with the
  reference's angular velocity (``swing_feedforward``), its target moved by the CoM's error
  (``placement``, ``placement_v``: SIMBICON's ``c_d e + c_v de``), a foot the reference stands
  on that does not touch driven into the floor (``land_depth``), a swing foot's contact
  points not held (``hold_swing``);
* a small regularisation of ``qdd`` and the forces (a unique solution).

``M`` (``mj_fullM``), ``h`` (``qfrc_bias - qfrc_passive``) and the point Jacobians (``mj_jac`` at
the contact points) come from MuJoCo at the current state; the QP is solved by DAQP (a dense
active-set solver). The torques are held for the tick's ``SUBSTEPS`` physics steps; MuJoCo's
own contacts then decide what the floor does. Deterministic: the same reference gives the same
simulation bit for bit.

What it achieves and what was tried: ``docs/synthetic.md`` (the body still falls in most dynamic
clips: a one-tick QP does not plan steps).
"""

from __future__ import annotations

from dataclasses import dataclass

import daqp
import mujoco
import numpy as np

from sim.errors import UsageError
from sim.simulate.controller import (
    Push,
    Weakening,
    apply_pushes,
    weakening_factor,
)
from sim.simulate.falls import fall_reference, has_fallen
from sim.simulate.model import (
    CONTROL_HZ,
    SUBSTEPS,
    G,
    rest_inertia,
    total_mass,
)
from sim.simulate.tracking import Tracking, divergences, floor_ids, foot_forces
from sim.simulate.wholebody_reference import (
    WholeBodyReference,
    foot_box_ids,
    sole_corners,
    wholebody_reference,
)

BIG = 1e30  # an unbounded side of a DAQP constraint


@dataclass(frozen=True)
class WholeBodyGains:
    """Gains [1/s^2, 1/s] and weights of the QP's tasks (each task's rows are accelerations
    [m/s^2, rad/s^2] before weighting)."""

    joint_omega: float = 2 * np.pi * 2.0  # hinge tracking bandwidth [rad/s], critically damped
    root_omega: float = 2 * np.pi * 1.5  # root orientation
    com_omega: float = 2 * np.pi * 1.0  # centre of mass
    momentum_damping: float = 5.0  # [1/s] angular momentum towards the reference's
    foot_omega: float = 2 * np.pi * 2.0  # swing foot pose
    stance_omega: float = 2 * np.pi * 3.0  # a stance foot held still and flat on the floor
    w_joint: float = 1.0
    w_root: float = 10.0
    w_com: float = 10.0
    w_momentum: float = 1.0
    w_swing: float = 10.0
    w_stance: float = 100.0
    w_reg: float = 1e-4  # on qdd
    w_force: float = 1e-6  # on the edge forces [N^2]
    friction: float = 0.8
    anchor: float = 1.0  # share of the support offset the balance targets follow (0: global)
    anchor_tau: float = 0.1  # [s] its filter's time constant
    every_step: bool = False  # solve the QP before every physics step, not every control tick
    placement: float = 0.0  # swing feet placed relative to the CoM (1) or the stance feet (0)
    placement_v: float = 0.0  # [s] a swing foot's target moves this far per m/s of CoM speed error
    inertia_power: float = 1.0  # hinge weights: (reflected inertia / mean) to this power
    limit_horizon: float = 0.05  # [s] hinge accelerations keep the range this far ahead (0: off)
    contact_damping: float = 20.0  # [1/s] a supporting point's velocity to zero
    w_contact: float = 100.0
    # a swing sole's orientation tracks the reference's angular velocity and acceleration too
    # (False: a PD towards its orientation at rest, lagging about 2 / foot_omega behind)
    swing_feedforward: bool = False
    # [m] a foot the reference has on the floor that does not touch it aims this far below
    # its reference sole (0: at the sole): it seeks the floor instead of hovering above it
    land_depth: float = 0.0
    w_land: float | None = None  # that foot's pose weight (None: ``w_swing``)
    # the contact points of a foot the reference has in the air are held still too (False:
    # a toe that scuffs the floor mid-swing does not pin the foot there)
    hold_swing: bool = True
    # [m] a stance sole (the reference stands on it, it touches) also offers its box's bottom
    # corners within this height of the floor as support (0: MuJoCo's contact points only): a
    # flat foot resting on one edge can still plan its centre of pressure over the whole sole
    sole_gap: float = 0.0


def _edges(mu: float) -> np.ndarray:
    """(3, 4) unit-free edges of the linearised friction pyramid (normal z, coefficient mu)."""
    s = mu / np.sqrt(2.0)
    return np.array([[s, s, 1.0], [s, -s, 1.0], [-s, s, 1.0], [-s, -s, 1.0]]).T


@dataclass
class QPResult:
    """One tick's solution: ``tau`` (nu,) hinge torques [N m], ``qdd`` (nv,) planned
    accelerations, ``forces`` (C, 3) planned contact forces [N, world] at ``points`` (C, 3),
    ``status`` DAQP's exit flag (1: optimal)."""

    tau: np.ndarray
    qdd: np.ndarray
    forces: np.ndarray
    points: np.ndarray
    status: int


def _touching(model, data, floor: int) -> set[int]:
    n = data.ncon
    if not n:
        return set()
    g = data.contact.geom[:n]
    return set(g[g[:, 0] == floor, 1].tolist()) | set(g[g[:, 1] == floor, 0].tolist())


def _support(model, data, gains: WholeBodyGains, scratch: dict, stance: np.ndarray):
    """The support points and their edge matrices at ``data``'s state: ``points`` (C, 3), ``JE``
    (nv, 4C) the generalised force of each pyramid edge's unit force, ``wrench`` (6, 4C) each
    edge's force and moment about the CoM, ``Jc`` (3C, nv) the points' Jacobians, the set of
    geoms touching the floor and ``sides`` (C,) each point's foot (0 left, 1 right);
    ``stance`` (2,) the reference's feet on the floor (``gains.sole_gap``)."""
    soles, toes = scratch["ids"]
    E, jacp = scratch["E"], scratch["jacp"]
    touching = _touching(model, data, scratch["floor"])
    com = data.subtree_com[1]
    points, bodies, sides = [], [], []
    feet = {int(g): s for s in range(2) for g in (soles[s], toes[s])}
    floor = scratch["floor"]
    for i in range(data.ncon):  # MuJoCo's own contact points of the feet on the floor
        g1, g2 = data.contact.geom[i]
        g = g2 if g1 == floor else g1 if g2 == floor else -1
        if g in feet:
            points.append(data.contact.pos[i].copy())
            bodies.append(int(model.geom_bodyid[g]))
            sides.append(feet[g])
    for side in range(2) if gains.sole_gap > 0 else ():  # a stance sole's corners near the floor
        if stance[side] and soles[side] in touching:
            for p in sole_corners(model, data, soles[side]):
                if p[2] < gains.sole_gap:
                    points.append(p)
                    bodies.append(int(model.geom_bodyid[soles[side]]))
                    sides.append(side)
    C = len(points)
    JE = np.empty((model.nv, 4 * C))
    wrench = np.zeros((6, 4 * C))
    Jc = np.empty((3 * C, model.nv))  # the points' Jacobians: they do not move on the floor
    for c, (p, b) in enumerate(zip(points, bodies, strict=True)):
        mujoco.mj_jac(model, data, jacp, None, p, b)
        Jc[3 * c : 3 * c + 3] = jacp
        JE[:, 4 * c : 4 * c + 4] = jacp.T @ E
        wrench[:3, 4 * c : 4 * c + 4] = E
        wrench[3:, 4 * c : 4 * c + 4] = np.cross(p - com, E.T).T
    return np.array(points).reshape(C, 3), JE, wrench, Jc, touching, np.array(sides, dtype=int)


def _anchor(data, ref: WholeBodyReference, k: int, gains, touching, scratch) -> np.ndarray:
    """(3,) the support offset: where the simulated stance feet stand minus where the
    reference's do (horizontal), filtered (first order, ``anchor_tau``: no jump at a
    touchdown); the balance and foot placement targets move with it, so the body keeps the
    reference's relation to its own feet."""
    soles = scratch["ids"][0]
    shift = [data.geom_xpos[soles[s], :2] - ref.sole_pos[k, s, :2]
             for s in range(2) if ref.stance[k, s] and soles[s] in touching]  # fmt: skip
    delta = scratch.setdefault("delta", np.zeros(3))
    if shift:
        a = min(1.0, 1.0 / (gains.anchor_tau * CONTROL_HZ))
        delta[:2] += a * (gains.anchor * np.mean(shift, axis=0) - delta[:2])
    return delta


def _body_tasks(model, data, ref, k, gains, n, wrench, delta, scratch, task) -> None:
    """The hinge, root orientation, CoM and angular momentum tasks (module docstring)."""
    nv, nu = model.nv, model.nu
    kj, dj = gains.joint_omega**2, 2 * gains.joint_omega
    qr, vr, ar = ref.qpos[k], ref.qvel[k], ref.qacc[k]
    A = np.zeros((nu, n))
    A[:, 6:nv] = np.eye(nu)
    b = ar[6:] + kj * (qr[7:] - data.qpos[7:]) + dj * (vr[6:] - data.qvel[6:])
    task(A, b, scratch["joint_w"])
    kr, dr = gains.root_omega**2, 2 * gains.root_omega
    rot = np.zeros(3)
    mujoco.mju_subQuat(rot, qr[3:7], data.qpos[3:7])
    A = np.zeros((3, n))
    A[:, 3:6] = np.eye(3)
    task(A, ar[3:6] + kr * rot + dr * (vr[3:6] - data.qvel[3:6]), gains.w_root)
    if wrench.shape[1] == 0:  # in flight the forces are zero: momentum is not controllable
        return
    mass = total_mass(model)
    com = data.subtree_com[1]
    kc, dc = gains.com_omega**2, 2 * gains.com_omega
    a_com = ref.com_acc[k] + kc * (ref.com[k] + delta - com)
    a_com += dc * (ref.com_vel[k] - data.subtree_linvel[1])
    A = np.zeros((3, n))
    A[:, nv:] = wrench[:3] / mass
    task(A, a_com + [0.0, 0.0, G], gains.w_com)
    kdot = ref.angmom_rate[k] + gains.momentum_damping * (ref.angmom[k] - data.subtree_angmom[1])
    A = np.zeros((3, n))
    A[:, nv:] = wrench[3:] / mass
    task(A, kdot / mass, gains.w_momentum)


def _foot_tasks(model, data, ref, k, gains, n, touching, delta, scratch, task) -> None:
    """Each foot: still and on the floor where the reference stands and the foot touches,
    else to the reference's sole pose (swing)."""
    jacp, jacr = scratch["jacp"], scratch["jacr"]
    com = data.subtree_com[1]
    for side, g in enumerate(scratch["ids"][0]):
        p = data.geom_xpos[g]
        mujoco.mj_jac(model, data, jacp, jacr, p, int(model.geom_bodyid[g]))
        J = np.vstack([jacp, jacr])
        vel = J @ data.qvel
        A = np.zeros((6, n))
        A[:, : model.nv] = J
        q_sim, q_ref, err = np.zeros(4), np.zeros(4), np.zeros(3)
        mujoco.mju_mat2Quat(q_sim, data.geom_xmat[g])
        mujoco.mju_mat2Quat(q_ref, ref.sole_mat[k, side].ravel())
        mujoco.mju_subQuat(err, q_ref, q_sim)
        err = data.geom_xmat[g].reshape(3, 3) @ err  # world frame
        if ref.stance[k, side] and g in touching:  # its points keep still (see qp_tick);
            # its orientation follows the reference's sole (flat, or rolling heel to toe)
            ks, ds = gains.stance_omega**2, 2 * gains.stance_omega
            task(A[3:], ks * err - ds * vel[3:], gains.w_stance)
            continue
        target = ref.sole_pos[k, side] + delta
        landing = bool(ref.stance[k, side]) and gains.land_depth > 0
        if landing:  # the reference stands on it: seek the floor
            target = target - [0.0, 0.0, gains.land_depth]
        if gains.placement:  # foot placement relative to the body's own centre of mass
            dv = (data.subtree_linvel[1] - ref.com_vel[k])[:2]
            rel = com[:2] + ref.sole_pos[k, side, :2] - ref.com[k, :2] + gains.placement_v * dv
            target = target.copy()
            target[:2] = (1 - gains.placement) * target[:2] + gains.placement * rel
        kf, df = gains.foot_omega**2, 2 * gains.foot_omega
        lin = ref.sole_acc[k, side] + kf * (target - p) + df * (ref.sole_vel[k, side] - vel[:3])
        ang = kf * err - df * vel[3:]
        if gains.swing_feedforward:
            ang = ref.sole_angacc[k, side] + kf * err + df * (ref.sole_angvel[k, side] - vel[3:])
        w = gains.w_land if landing and gains.w_land is not None else gains.w_swing
        task(A, np.concatenate([lin, ang]), w)


def _limits(model, data, gains, scratch, C: int, h, limit):
    """DAQP's bounds (lower, upper) and senses: the hinges' accelerations that keep their
    range ``limit_horizon`` ahead (MuJoCo's limit forces are not in the plan: better not to
    meet them), the edge forces >= 0, the base's equations (equalities), the torque limits."""
    nv, nu = model.nv, model.nu
    qdd_lo, qdd_hi = np.full(nv, -BIG), np.full(nv, BIG)
    if gains.limit_horizon > 0:
        T = gains.limit_horizon
        q, v, rng = data.qpos[7:], data.qvel[6:], scratch["range"]
        qdd_lo[6:] = np.minimum(2 * (rng[:, 0] - q - v * T) / T**2, 0.0)
        qdd_hi[6:] = np.maximum(2 * (rng[:, 1] - q - v * T) / T**2, 0.0)
    upper = np.concatenate([qdd_hi, np.full(4 * C, BIG), -h[:6], limit - h[6:]])
    lower = np.concatenate([qdd_lo, np.zeros(4 * C), -h[:6], -limit - h[6:]])
    sense = np.zeros(nv + 4 * C + 6 + nu, dtype=np.int32)
    sense[nv + 4 * C : nv + 4 * C + 6] = 5  # equality
    return lower, upper, sense


def qp_tick(model, data, ref: WholeBodyReference, k: int, gains: WholeBodyGains,
            limit: np.ndarray, scratch: dict) -> QPResult:  # fmt: skip
    """Solve the whole-body QP (module docstring) at ``data``'s state (``mj_forward`` done)
    for reference tick ``k``; ``limit`` (nu,) the torque limits [N m] now; ``scratch``: reused
    arrays (an empty dict the first time)."""
    nv, nu = model.nv, model.nu
    if not scratch:
        inertia, _ = rest_inertia(model)
        share = (inertia / inertia.mean()) ** gains.inertia_power
        scratch.update(joint_w=gains.w_joint * share, M=np.zeros((nv, nv)),
                       range=model.jnt_range[1:].copy(), jacp=np.zeros((3, nv)),
                       jacr=np.zeros((3, nv)), E=_edges(gains.friction), ids=foot_box_ids(model),
                       floor=model.geom("floor").id)  # fmt: skip
    M = scratch["M"]
    mujoco.mj_fullM(model, data, M)
    mujoco.mj_subtreeVel(model, data)
    h = data.qfrc_bias - data.qfrc_passive
    points, JE, wrench, Jc, touching, sides = _support(model, data, gains, scratch, ref.stance[k])
    C = len(points)
    n = nv + 4 * C
    delta = _anchor(data, ref, k, gains, touching, scratch)
    rows, rhs, weights = [], [], []

    def task(A, b, w):
        rows.append(A)
        rhs.append(b)
        weights.append(np.broadcast_to(w, b.shape))

    _body_tasks(model, data, ref, k, gains, n, wrench, delta, scratch, task)
    _foot_tasks(model, data, ref, k, gains, n, touching, delta, scratch, task)
    if C:  # the supporting points keep still: no slip, no push into the floor
        A = np.zeros((3 * C, n))
        A[:, :nv] = Jc
        held = np.ones(3 * C, dtype=bool)
        if not gains.hold_swing:  # not those of a foot the reference has in the air
            held = np.repeat(ref.stance[k, sides], 3)
        if held.any():
            task(A[held], -gains.contact_damping * (Jc[held] @ data.qvel), gains.w_contact)
    A, b = np.vstack(rows), np.concatenate(rhs)
    Aw = A * np.concatenate(weights)[:, None]
    H = A.T @ Aw
    H[np.arange(nv), np.arange(nv)] += gains.w_reg
    H[np.arange(nv, n), np.arange(nv, n)] += gains.w_force
    Cm = np.zeros((6 + nu, n))  # the base's equations, then the hinge torques
    Cm[:, :nv] = M[: 6 + nu]
    Cm[:, nv:] = -JE[: 6 + nu]
    lower, upper, sense = _limits(model, data, gains, scratch, C, h, limit)
    x, _, status, _ = daqp.solve(H, -(Aw.T @ b), Cm, upper, lower, sense)
    if status < 1:  # infeasible or not converged: the torques that keep the hinges passive
        x = np.zeros(n)
        x[:nv] = np.linalg.solve(M, -h)
    qdd, lam = x[:nv], x[nv:]
    tau = np.clip(M[6:] @ qdd + h[6:] - JE[6:] @ lam, -limit, limit)
    forces = (scratch["E"] @ lam.reshape(C, 4).T).T if C else np.zeros((0, 3))
    return QPResult(tau=tau, qdd=qdd, forces=forces, points=points, status=int(status))


def _foot_sides(model) -> np.ndarray:
    """(ngeom,) 0 for a geom of the left foot, 1 of the right, -1 for any other."""
    side = np.full(model.ngeom, -1)
    for name in ("lfoot", "ltoes", "lsole", "ltoesole", "rfoot", "rtoes", "rsole", "rtoesole"):
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        if g >= 0:
            side[g] = 0 if name.startswith("l") else 1
    return side


def _penetration(data, floor) -> tuple[float, float]:
    """The deepest floor contact (``floor``: its geom ids) and the deepest body-body contact
    [m] (>= 0) of ``data``."""
    n = data.ncon
    if not n:
        return 0.0, 0.0
    on_floor = np.isin(data.contact.geom[:n], floor).any(axis=1)
    depth = -data.contact.dist[:n]
    fd = max(0.0, float(depth[on_floor].max())) if on_floor.any() else 0.0
    sd = max(0.0, float(depth[~on_floor].max())) if not on_floor.all() else 0.0
    return fd, sd


def _finish_tick(model, data, ref, k: int, gains, limit: np.ndarray, scratch: dict) -> None:
    """The physics steps of control tick ``k`` after its first: the torques held, or with
    ``gains.every_step`` a QP (torques within ``limit`` (nu,) [N m]) before each, the reference
    held."""
    if not gains.every_step:
        mujoco.mj_step(model, data, nstep=SUBSTEPS - 1)
        return
    for _ in range(SUBSTEPS - 1):
        mujoco.mj_forward(model, data)
        data.ctrl[:] = qp_tick(model, data, ref, k, gains, limit, scratch).tau
        mujoco.mj_step(model, data)


def track_wholebody(
    model,
    ref_qpos: np.ndarray,
    *,
    gains: WholeBodyGains | None = None,
    pushes: tuple[Push, ...] = (),
    weakenings: tuple[Weakening, ...] = (),
    record_every: int = 4,
    recorder=None,
) -> Tracking:
    """Simulate ``model`` (``sim_model(..., actuators="motor")``) following ``ref_qpos`` (T, nq
    at ``CONTROL_HZ``, floor at z = 0) with the whole-body QP (module docstring) and nothing
    else: no assistance (the :class:`Tracking`'s assistance is zero), pushes the only external
    forces. A weakening scales the torque limits (the QP's and the actuators'). After a fall
    (``sim.simulate.falls``) the QP goes on tracking: whether the body gets up is its own doing.
    ``recorder``: as ``track``'s (``sim.simulate.episode.Recorder``: called before each tick's
    physics steps and after the last; not with ``gains.every_step``).

    Returns:
        :class:`Tracking` with states at ticks ``0, record_every, ...``; ``actions`` are the
        torques [N m] (the actuators' controls).
    """
    if model.actuator_biasprm[:, 1].any():
        raise UsageError("track_wholebody needs torque actuators: sim_model(actuators='motor')")
    gains = gains or WholeBodyGains()
    if recorder is not None and gains.every_step:
        raise UsageError("a recorder needs one action per control tick: not with every_step")
    T = ref_qpos.shape[0]
    ref = wholebody_reference(model, ref_qpos)
    fall_ref = fall_reference(model, ref_qpos)
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = ref_qpos[0], ref.qvel[0]
    mujoco.mj_forward(model, data)
    floor = floor_ids(model)  # what the record counts as floor: the terrain's boxes too
    side = _foot_sides(model)
    push_ids = [model.body(p.body).id for p in pushes]
    F = (T + record_every - 1) // record_every
    rec_q, rec_v = np.empty((F, model.nq)), np.empty((F, model.nv))
    rec_u, rec_tau = np.empty((F, model.nu)), np.empty((F, model.nu))
    rec_f, rec_p = np.zeros((F, 2, 3)), np.zeros(F)
    fell, fall_frame, fall_tick = False, -1, -1
    deepest = deepest_self = 0.0
    scratch: dict = {}
    base_limit = model.actuator_ctrlrange[:, 1].copy()
    for k in range(T):
        t = k / CONTROL_HZ
        factor = weakening_factor(weakenings, t)
        mujoco.mj_forward(model, data)
        if not fell and has_fallen(model, data, fall_ref, k):
            fell, fall_frame, fall_tick = True, min(F - 1, -(-k // record_every)), k
        res = qp_tick(model, data, ref, k, gains, factor * base_limit, scratch)
        data.ctrl[:] = res.tau
        apply_pushes(data, pushes, push_ids, t)
        i, r = divmod(k, record_every)
        on_record = r == 0
        fd, sd = _penetration(data, floor)
        deepest, deepest_self = max(deepest, fd), max(deepest_self, sd)
        if on_record:
            rec_p[i] = fd
        if on_record:
            rec_q[i], rec_v[i], rec_u[i] = data.qpos, data.qvel, data.ctrl
        if recorder is not None:
            recorder(k, data)
        mujoco.mj_step(model, data)
        if on_record:
            rec_tau[i] = data.actuator_force
            foot_forces(model, data, floor, side, rec_f[i])
        _finish_tick(model, data, ref, k, gains, factor * base_limit, scratch)
    if recorder is not None:
        recorder(T, data)
    return Tracking(
        qpos=rec_q, qvel=rec_v, assistance=np.zeros(F), assist_wrench=np.zeros((F, 6)),
        fell=fell, ticks=T, penetration=deepest, self_penetration=deepest_self,
        contact_penetration=rec_p,
        unstable=divergences(data) > 0,
        actions=rec_u, joint_torque=rec_tau, foot_force=rec_f, fall_frame=fall_frame,
        fall_tick=fall_tick,
    )  # fmt: skip
