"""Inverse kinematics: joint angles of the subject's humanoid that put its points on given points.

Each frame is a damped least-squares (Levenberg-Marquardt) fit on MuJoCo's Jacobians: with ``e``
the stacked point errors (3P,) [m] and ``J`` (3P, nv) the Jacobian of the points,
``dq = (J^T J + lambda I)^-1 J^T e`` is integrated on the configuration manifold
(``mj_integratePos``: quaternion root, hinges) until the step is below ``tol``. Frames are
warm-started from the previous frame's solution, so a 60-frame clip needs a few iterations per
frame; the damping keeps degrees of freedom the points do not determine (e.g. the twist of a bone
whose child is not among the points, or finger/thumb/toe hinges) where the warm start put them.

Joint limits enter as a soft penalty: each anatomical hinge (:func:`anatomical_ranges`) outside its
ASF range adds a residual ``limit_weight * (distance to the range)`` [m per rad]. Point sets leave
branches ambiguous (a straight knee can bend either way if the thigh turns 180 deg about itself);
the penalty picks the branch inside the limits, which the points cannot tell apart, while a
violation the points force (they cannot be matched inside the range) still shows, at the cost of
``limit_weight`` metres per radian of point error. Hard limits (mink's QP constraints) would
instead hide forced violations; mink (one position task per point, daqp) is also slower per clip
and less exact on this job (``benchmarks/bench_physics.py``, ``docs/results/physics.md``).

Points: ``"root"`` is the root body's origin; any other name ``b`` is the site ``b_end`` (the end of
bone ``b``) of a model built by :func:`sim.model.humanoid.build_mjcf`. Units: metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim import mujoco_log  # noqa: F401  # MuJoCo's warnings on stderr, not in a file
from sim.errors import UnknownNameError, UsageError
from sim.model import quaternion as quat
from sim.model.angles import wrap_angle

#: Hinges of bones whose CMU channels are junk or unobserved (hands, fingers, thumbs, toes): left
#: out of the joint-limit check.
NON_ANATOMICAL = ("lhand", "rhand", "lfingers", "rfingers", "lthumb", "rthumb", "ltoes", "rtoes")


#: [m] RMS point error above which a frame gets more iterations and a cold start as well.
HARD_FRAME_M = 0.01


@dataclass(frozen=True)
class Fit:
    """Result of :meth:`HumanoidIK.fit`.

    Attributes:
        qpos: (T, nq) fitted configurations (root position [m], quaternion wxyz, hinges [rad]).
        error: (T,) RMS distance of the model's points to the targets [m].
        iterations: (T,) iterations used per frame.
    """

    qpos: np.ndarray
    error: np.ndarray
    iterations: np.ndarray


class HumanoidIK:
    """Owns a copy of the model and its data, and fits point sets named ``names`` onto it.

    Args:
        model: MjModel from :func:`sim.model.humanoid.build_mjcf` (e.g. ``subject_model``'s).
        names: (P,) point names: ``"root"`` and/or bone names (each needs a site ``<name>_end``).
        damping: Levenberg-Marquardt damping ``lambda`` [m^2/rad^2].
        limit_weight: weight [m/rad] of the soft joint-limit penalty (0: none).
    """

    def __init__(self, model, names, *, damping: float = 1e-4, limit_weight: float = 0.01):
        self.model = model
        self.data = mujoco.MjData(model)
        self.names = tuple(names)
        self.damping = float(damping)
        self.limit_weight = float(limit_weight)
        ranges = anatomical_ranges(model)
        jid = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in ranges]
        self._lim_q = np.array([model.jnt_qposadr[j] for j in jid], dtype=int)
        self._lim_v = np.array([model.jnt_dofadr[j] for j in jid], dtype=int)
        self._lim_lo = np.array([r[0] for r in ranges.values()])
        self._lim_hi = np.array([r[1] for r in ranges.values()])
        self._root_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "root")
        sites, self._root_slot = [], -1
        for k, n in enumerate(self.names):
            if n == "root":
                self._root_slot = k
                sites.append(-1)
                continue
            s = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{n}_end")
            if s < 0:
                known = [model.site(i).name for i in range(model.nsite)]
                raise UnknownNameError("site for a point", f"{n}_end", known)
            sites.append(s)
        self._sites = np.array(sites)
        self._site_rows = np.flatnonzero(self._sites >= 0)
        self._J = np.zeros((3 * len(self.names), model.nv))

    def points(self, qpos: np.ndarray) -> np.ndarray:
        """(P, 3) the model's points at ``qpos`` (nq,)."""
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        return self._points()

    def _points(self) -> np.ndarray:
        x = np.empty((len(self.names), 3))
        x[self._site_rows] = self.data.site_xpos[self._sites[self._site_rows]]
        if self._root_slot >= 0:
            x[self._root_slot] = self.data.xpos[self._root_body]
        return x

    def _jacobian(self) -> np.ndarray:
        m, d, J = self.model, self.data, self._J
        mujoco.mj_comPos(m, d)
        for k in self._site_rows:
            mujoco.mj_jacSite(m, d, J[3 * k : 3 * k + 3], None, int(self._sites[k]))
        if self._root_slot >= 0:
            k = self._root_slot
            mujoco.mj_jacBody(m, d, J[3 * k : 3 * k + 3], None, self._root_body)
        return J

    def observed_hinges(self, qpos: np.ndarray, *, tol: float = 1e-6) -> tuple[str, ...]:
        """Hinges whose motion moves at least one of the points at ``qpos`` (nq,): the others
        (e.g. a forearm's twist when the hand is not a point) are left where the warm start put
        them by the fit, so their angles say nothing about the motion."""
        self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        moved = np.linalg.norm(self._jacobian(), axis=0) > tol
        names = hinge_names(self.model)
        return tuple(n for k, n in enumerate(names) if moved[6 + k])

    def _cost(self, target: np.ndarray, q: np.ndarray) -> float:
        """Summed squared distance [m^2] of the model's points at ``q`` to ``target`` (P, 3)."""
        return float(np.sum((self.points(q) - target) ** 2))

    def initial_pose(self, targets: np.ndarray) -> np.ndarray:
        """(nq,) a starting configuration for ``targets`` (P, 3): hinges at zero, the root placed and
        turned (Kabsch) so that the model's points best match the targets as a rigid body."""
        q = np.zeros(self.model.nq)
        q[3] = 1.0
        x = self.points(q)
        xc, tc = x.mean(axis=0), targets.mean(axis=0)
        H = (x - xc).T @ (targets - tc)
        U, _, Vt = np.linalg.svd(H)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        q[3:7] = quat.from_matrix(R)
        q[:3] = tc - R @ xc
        return q

    def fit_frame(self, target: np.ndarray, q0: np.ndarray, *, max_iter: int, tol: float):
        """Fit one frame from ``q0``; returns (qpos, rms error [m], iterations)."""
        m, d = self.model, self.data
        q = np.array(q0, dtype=np.float64)
        lam = self.damping * np.eye(m.nv)
        it, prev = 0, np.inf
        for it in range(1, max_iter + 1):  # noqa: B007
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            e = (target - self._points()).ravel()
            cost = float(e @ e)
            if 0.0 <= prev - cost < 1e-12:  # [m^2]: the points stopped improving
                break
            prev = cost
            J = self._jacobian()
            A, g = J.T @ J + lam, J.T @ e
            if self.limit_weight > 0 and len(self._lim_q):
                qh = q[self._lim_q]
                out = np.where(qh < self._lim_lo, self._lim_lo - qh, 0.0) + np.where(
                    qh > self._lim_hi, self._lim_hi - qh, 0.0
                )
                w2 = self.limit_weight**2
                act = out != 0
                A[self._lim_v[act], self._lim_v[act]] += w2
                g[self._lim_v[act]] += w2 * out[act]
            dq = np.linalg.solve(A, g)
            mujoco.mj_integratePos(m, q, dq, 1.0)
            if np.abs(dq).max() < tol:
                break
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        err = float(np.sqrt(np.mean(np.sum((target - self._points()) ** 2, axis=1))))
        return q, err, it

    def fit(
        self,
        positions: np.ndarray,
        *,
        q_init: np.ndarray | None = None,
        guesses: np.ndarray | None = None,
        first_iter: int = 100,
        max_iter: int = 20,
        tol: float = 1e-6,
    ) -> Fit:
        """Fit every frame of ``positions`` (T, P, 3) [m].

        Args:
            q_init: (nq,) start of frame 0 (default :meth:`initial_pose`); later frames start from
                the previous frame's solution (warm start). Degrees of freedom the points leave
                free keep the start's values.
            guesses: (T, nq) candidate starts per frame (e.g. the original clip's own poses when
                fitting its reconstruction): each frame starts from its guess or from the previous
                frame's solution, whichever matches the points better; the guesses, not the soft
                limit penalty (off for this call), pick among configurations the points cannot
                tell apart.
            first_iter, max_iter: iteration caps of frame 0 and of the others; a frame still
                :data:`HARD_FRAME_M` off after ``max_iter`` gets ``first_iter`` more, and a cold
                start (:meth:`initial_pose`) with ``first_iter``, keeping the best.
            tol: stop when the largest step component is below this [rad or m], or when an
                iteration improves the summed squared point error by less than 1e-12 m^2.
        """
        p = np.asarray(positions, dtype=np.float64)
        if p.ndim != 3 or p.shape[1:] != (len(self.names), 3):
            raise UsageError(f"positions must be (T, {len(self.names)}, 3); got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise UsageError("positions must be finite")
        T = p.shape[0]
        if guesses is not None and np.shape(guesses) != (T, self.model.nq):
            raise UsageError(f"guesses must be {(T, self.model.nq)}; got {np.shape(guesses)}")
        qpos = np.empty((T, self.model.nq))
        err, its = np.empty(T), np.empty(T, dtype=int)
        q = self.initial_pose(p[0]) if q_init is None else np.asarray(q_init, dtype=np.float64)
        weight = self.limit_weight
        if guesses is not None:
            self.limit_weight = 0.0
        try:
            for t in range(T):
                if guesses is not None:
                    g = np.asarray(guesses[t], dtype=np.float64)
                    if t == 0 or self._cost(p[t], g) <= self._cost(p[t], q):
                        q = g  # else keep the previous frame's solution (warm start)
                    cap = max_iter
                else:
                    cap = first_iter if t == 0 else max_iter
                q, err[t], its[t] = self.fit_frame(p[t], q, max_iter=cap, tol=tol)
                if err[t] > HARD_FRAME_M:  # far from every start: go on, and try a cold start
                    tries = [(q, err[t], its[t])]
                    for q1 in (q, self.initial_pose(p[t])):
                        q2, e2, i2 = self.fit_frame(p[t], q1, max_iter=first_iter, tol=tol)
                        tries.append((q2, e2, its[t] + i2))
                    q, err[t], its[t] = min(tries, key=lambda x: x[1])
                qpos[t] = q
        finally:
            self.limit_weight = weight
        return Fit(qpos, err, its)

    def rates(
        self,
        qpos: np.ndarray,
        velocities: np.ndarray,
        accelerations: np.ndarray,
        *,
        prior_qvel: np.ndarray | None = None,
        prior_qacc: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``qvel`` and ``qacc`` (T, nv) of fitted configurations ``qpos`` (T, nq) whose points move
        with ``velocities`` and ``accelerations`` (T, P, 3) [m/s, m/s^2].

        The points' velocity is ``J qvel`` and their acceleration ``J qacc + Jdot qvel`` (MuJoCo's
        ``mj_jacSite``/``mj_jacDot``), so per frame ``qvel = argmin |J qvel - v|^2 +
        lambda |qvel - prior|^2`` and likewise ``qacc`` for ``a - Jdot qvel``: degrees of freedom
        the points see follow the points exactly, those they do not (a forearm's twist without
        the hand) keep the prior's rates, as :meth:`fit` keeps their angles (default prior 0).
        """
        q = np.asarray(qpos, dtype=np.float64)
        v = np.asarray(velocities, dtype=np.float64).reshape(len(q), -1)
        a = np.asarray(accelerations, dtype=np.float64).reshape(len(q), -1)
        m, d = self.model, self.data
        nv = m.nv
        pv = np.zeros((len(q), nv)) if prior_qvel is None else np.asarray(prior_qvel, float)
        pa = np.zeros((len(q), nv)) if prior_qacc is None else np.asarray(prior_qacc, float)
        lam = self.damping
        qvel, qacc = np.zeros((len(q), nv)), np.zeros((len(q), nv))
        jdot = np.zeros((3, nv))
        bias = np.zeros(3 * len(self.names))
        for t in range(len(q)):
            d.qpos[:] = q[t]
            mujoco.mj_kinematics(m, d)
            J = self._jacobian()  # (3P, nv), comPos done
            A = J.T @ J + lam * np.eye(nv)
            qvel[t] = np.linalg.solve(A, J.T @ v[t] + lam * pv[t])
            d.qvel[:] = qvel[t]
            mujoco.mj_comVel(m, d)
            for k in range(len(self.names)):
                if k == self._root_slot:
                    point, body = d.xpos[self._root_body], self._root_body
                else:
                    s_ = int(self._sites[k])
                    point, body = d.site_xpos[s_], int(m.site_bodyid[s_])
                mujoco.mj_jacDot(m, d, jdot, None, point, body)
                bias[3 * k : 3 * k + 3] = jdot @ qvel[t]
            qacc[t] = np.linalg.solve(A, J.T @ (a[t] - bias) + lam * pa[t])
        return qvel, qacc


def anatomical_ranges(model) -> dict[str, tuple[float, float]]:
    """Hinge name -> (lo, hi) [rad] of every limited hinge except :data:`NON_ANATOMICAL` bones'."""
    out = {}
    for j in range(model.njnt):
        if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE or not model.jnt_limited[j]:
            continue
        name = model.joint(j).name
        if name.rsplit("_", 1)[0] in NON_ANATOMICAL:
            continue
        out[name] = (float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1]))
    return out


def hinge_names(model) -> tuple[str, ...]:
    """(nq - 7,) names of the hinges after the free root, in ``qpos`` order."""
    names = [""] * (model.nq - 7)
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            names[int(model.jnt_qposadr[j]) - 7] = model.joint(j).name
    return tuple(names)


def limit_excess(qpos: np.ndarray, model, hinges=None) -> np.ndarray:
    """(T,) worst excess [deg] of an anatomical hinge angle beyond its range, on the circle (0 inside).

    ``hinges``: only these hinge names (e.g. :meth:`HumanoidIK.observed_hinges`); default all.
    """
    ranges = anatomical_ranges(model)
    if hinges is not None:
        ranges = {k: v for k, v in ranges.items() if k in set(hinges)}
    names = hinge_names(model)
    q = wrap_angle(np.asarray(qpos, dtype=np.float64)[:, 7:])
    keep = [k for k, n in enumerate(names) if n in ranges]
    if not keep:
        return np.zeros(len(q))
    lo = np.array([ranges[names[k]][0] for k in keep])
    hi = np.array([ranges[names[k]][1] for k in keep])
    return np.degrees(circular_excess(q[:, keep], lo, hi).max(axis=1))


def circular_excess(a: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Angular distance [rad] of angles ``a`` from the arcs ``[lo, hi]`` on the circle (0 on the
    arc): an angle is compared modulo 2 pi, so 190 deg against [0, 170] is 20 deg out, not 170."""
    two_pi = 2 * np.pi
    span = hi - lo
    above = np.mod(a - lo, two_pi)  # in [0, 2 pi): how far past lo, going up
    inside = (above <= span) | (span >= two_pi)
    return np.where(inside, 0.0, np.minimum(above - span, two_pi - above))
