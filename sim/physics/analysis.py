"""Physics of one motion against its original: contacts, self-penetration, joint limits, dynamics.

:class:`PhysicsJob` owns everything MuJoCo for one subject and one point set (the IK model and data,
the inverse-dynamics model and data, the capsule collision scene), made once and reused for the
original and every reconstruction of every clip. :meth:`PhysicsJob.analyse` (or the one-shot
:func:`analyse`) returns, for the original (``positions=None``) or a reconstruction's points:

* ``ground_z_m`` and the floor's fit (``floor_deviation_mm``, ``floor_fits``, ... of
  :meth:`sim.physics.ground.Ground.summary`): the trial's floor (:mod:`sim.physics.ground`);
  where it does not fit, float and penetration are measured against a floor the feet do not
  follow;
* ``penetration_mm``, ``float_mm``, ``skate_mm_s``, ``contact_precision``, ``contact_recall``
  against the original's contacts (:mod:`sim.physics.contacts`), each with ``*_n`` samples;
* ``self_pen_excess_mm``, ``lost_contacts``: self-penetration beyond the original's, pair by pair
  (:func:`sim.replay.checks.self_penetration_excess`);
* ``limit_excess_deg``: mean over frames of the worst wrapped anatomical hinge angle beyond its
  ASF range, on the humanoid fitted to the points (:mod:`sim.physics.ik`), ``limit_excess_max_deg``;
  only hinges the points observe count (a forearm's twist, say, is invisible without the hand);
* ``residual_force_bw`` (mean) and ``residual_force_bw_p95``: residual force / body weight;
  ``residual_torque_nm_kg``: mean |residual torque| / body mass; ``joint_torque_rms_nm_kg``: RMS
  anatomical joint torque / body mass (:mod:`sim.physics.dynamics`), with ``dynamics_n`` frames;
* ``ik_error_mm``: mean RMS distance of the fitted humanoid's points to the motion's (large when
  a reconstruction stretches bones);
* ``<key>_excess``: the figure minus the original's, for the dynamics, contact and limit figures;
* ``per_frame``: arrays for plots (see :meth:`PhysicsJob.analyse`).

Both the original and the reconstruction go through the same pipeline (IK on the same points, each
frame started from the original's pose at that frame; same filter, same contact rules), so their
difference is the reconstruction's.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import mujoco
import numpy as np

from sim.physics.contacts import contact_metrics, foot_heights, label_contacts, point_speed
from sim.physics.dynamics import MU, Dynamics, InverseDynamics
from sim.physics.feet import SOLE_RADIUS
from sim.physics.ground import Ground, estimate_ground, foot_points, horizontal_speed
from sim.physics.ik import NON_ANATOMICAL, Fit, HumanoidIK, hinge_names, limit_excess
from sim.replay.capsules import bones_of
from sim.replay.checks import (
    CollisionScene,
    FrameChecks,
    PointMotion,
    _lengths,
    replay,
    self_penetration_excess,
)

#: Figures whose excess over the original is reported as ``<key>_excess``.
EXCESS_KEYS = (
    "penetration_mm", "float_mm", "skate_mm_s", "limit_excess_deg", "residual_force_bw",
    "residual_force_bw_p95", "residual_torque_nm_kg", "joint_torque_rms_nm_kg",
)  # fmt: skip


#: Originals a job keeps (a few hundred kB each): ``sidql eval`` revisits every clip per method and W.
ORIGINALS_CACHED = 1024


@dataclass(frozen=True)
class MotionPhysics:
    """Everything computed for one motion (T frames, F foot points)."""

    positions: np.ndarray  # (T, P, 3) [m]
    fit: Fit
    dynamics: Dynamics
    feet: tuple[str, ...]
    height: np.ndarray  # (T, F) [m] above stance level
    hspeed: np.ndarray  # (T, F) [m/s]
    contact: np.ndarray  # (T, F) bool
    checks: FrameChecks
    limit: np.ndarray  # (T,) [deg]


class PhysicsJob:
    """MuJoCo state for the physics of motions of one subject on one point set.

    Args:
        model: the subject's humanoid (:func:`sim.model.humanoid.subject_model`).
        names: (P,) point names of the motions (``"root"`` and bone names).
        parents: (P,) parent index of each point.
        fps: frame rate [1/s].
        mu: ground friction coefficient; window: Savitzky-Golay window [frames].
    """

    def __init__(self, model, names, parents, fps: float, *, mu: float = MU, window: int = 9):
        self._args = (model, tuple(names), np.asarray(parents), float(fps), mu, window)
        self.names = tuple(names)
        self.parents = np.asarray(parents)
        self.fps = float(fps)
        self.ik = HumanoidIK(model, self.names)
        self.inv = InverseDynamics(model, mu=mu, window=window)
        self.model = model
        self._scene: CollisionScene | None = None
        self._observed: tuple[str, ...] | None = None
        self._originals: dict = {}
        hinges = hinge_names(model)
        self._anatomical = np.array([h.rsplit("_", 1)[0] not in NON_ANATOMICAL for h in hinges])
        self._site_body = {
            n: int(
                model.site_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{n}_end")]
            )
            for n in self.names
            if n != "root"
        }

    def __reduce__(self):
        # Sent to another process (a pool or Ray worker) as its constructor's arguments: the job's
        # MuJoCo data and scratch buffers are rebuilt there, writable (Ray hands arrays back
        # read-only), and the cache of originals starts empty.
        model, names, parents, fps, mu, window = self._args
        return (_rebuild_job, (model, names, parents, fps, mu, window))

    def _replay(self, motion: PointMotion, reference: PointMotion, floor_z: float) -> FrameChecks:
        if self._scene is None:
            self._scene = CollisionScene(bones_of(self.names, self.parents, _lengths(reference)))
        self._scene.move_floor(floor_z)
        return replay(motion, reference, floor_z=floor_z, scene=self._scene)

    def ground_contacts(self, positions: np.ndarray, ground: Ground):
        """A motion's own foot contacts.

        Args:
            positions: (T, P, 3) [m] in this job's ``names`` order.
        Returns:
            feet (F,) foot point names, height (T, F) above stance level [m], contact (T, F) bool,
            and per frame the ``(body id, point (3,))`` list where ground forces may act (the
            points in contact, dropped onto the floor plane ``ground.floor_z``).
        """
        feet = tuple(f for f in foot_points(self.names) if f in ground.points)
        pf = np.asarray(positions)[:, [self.names.index(f) for f in feet]]
        height = foot_heights(pf, ground, feet)
        contact = label_contacts(height, point_speed(pf, self.fps), points=feet)
        floor = ground.level(pf[..., :2]) - SOLE_RADIUS  # (T, F) the plane under each point
        contacts = [
            [
                (self._site_body[f], np.array([pf[t, k, 0], pf[t, k, 1], floor[t, k]]))
                for k, f in enumerate(feet)
                if contact[t, k]
            ]
            for t in range(len(pf))
        ]
        return feet, height, contact, contacts

    def motion_physics(
        self, positions: np.ndarray, reference: PointMotion | None, ground: Ground, start
    ) -> MotionPhysics:
        """IK, contacts, replay and dynamics of one motion's points (T, P, 3) [m].

        ``reference``: the original on this job's points (bone lengths of the collision scene;
        default the motion itself); ``start``: IK start, None (cold), (nq,) for frame 0 (then
        warm starts) or (T, nq) per frame (:meth:`sim.physics.ik.HumanoidIK.fit`'s ``guesses``)."""
        feet, height, contact, contacts = self.ground_contacts(positions, ground)
        pf = positions[:, [self.names.index(f) for f in feet]]
        if start is not None and np.ndim(start) == 2:
            fit = self.ik.fit(positions, guesses=start)
        else:
            fit = self.ik.fit(positions, q_init=start)
        if self._observed is None:  # the same hinges for the original and every reconstruction
            self._observed = self.ik.observed_hinges(fit.qpos[0])
        floor = ground.floor_z
        dyn = self.inv.run(fit.qpos, self.fps, contacts)
        motion = PointMotion(self.names, self.parents, positions, self.fps)
        checks = self._replay(motion, motion if reference is None else reference, floor)
        return MotionPhysics(
            positions, fit, dyn, feet, height, horizontal_speed(pf, self.fps), contact, checks,
            limit_excess(fit.qpos, self.model, self._observed),
        )  # fmt: skip

    def original(self, clip, ground: Ground) -> MotionPhysics:
        """The original clip's physics on this job's points (cached per clip and ground).

        The cache key holds the points themselves (a digest) and the whole ground: clips can share
        source, start and length yet differ (synthetic clips of one trial all start at frame 0)."""
        idx = [clip.names.index(n) for n in self.names]
        pos = np.ascontiguousarray(np.asarray(clip.positions, dtype=np.float64)[:, idx])
        key = (
            clip.source, clip.start_frame, pos.shape, hashlib.sha1(pos.tobytes()).hexdigest(),
            float(ground.z), tuple(ground.points), tuple(ground.slope), tuple(ground.origin),
            np.asarray(ground.clearance, dtype=np.float64).tobytes(),
        )  # fmt: skip
        if key not in self._originals:
            ref = PointMotion(self.names, self.parents, pos, self.fps)
            if len(self._originals) >= ORIGINALS_CACHED:
                self._originals.clear()
            q0 = _q_init(clip, self.model)
            self._originals[key] = self.motion_physics(ref.positions, ref, ground, q0)
        return self._originals[key]

    def analyse(
        self, clip, positions: np.ndarray | None = None, ground: Ground | None = None
    ) -> dict:
        """Figures of a motion against the original ``clip`` (see the module docstring).

        Args:
            clip: the original (:class:`sim.motion.clip.Clip`, containing this job's points).
            positions: (T, P, 3) [m] the reconstruction's points in this job's ``names`` order;
                ``None`` analyses the original itself (the baseline row: excesses 0).
            ground: the trial's ground (default: estimated from ``clip`` alone).
        Returns:
            JSON-ready numbers plus ``per_frame``: ``foot_names`` (F,), ``contact`` (T, F) 0/1,
            ``foot_height_mm`` (T, F), ``foot_speed_mm_s`` (T, F) horizontal,
            ``residual_force_bw`` (T,), ``residual_torque_nm_kg`` (T,),
            ``joint_torque_rms_nm_kg`` (T,), ``limit_excess_deg`` (T,), ``ik_error_mm`` (T,),
            ``qpos`` (T, nq) the IK fit.
        """
        if ground is None:
            ground = estimate_ground(clip.positions, clip.names, clip.fps)
        orig = self.original(clip, ground)
        if positions is None:
            mp = orig
        else:
            p = np.asarray(positions, dtype=np.float64)
            if p.shape != orig.positions.shape:
                raise ValueError(f"positions must be {orig.positions.shape}; got {p.shape}")
            ref = PointMotion(self.names, self.parents, orig.positions, self.fps)
            mp = self.motion_physics(p, ref, ground, _q_init(clip, self.model))
        out = {"ground_z_m": ground.z, **ground.summary()}
        out.update(contact_metrics(orig.contact, mp.height, mp.hspeed, mp.contact))
        out.update(self_penetration_excess(mp.checks, orig.checks))
        frames = summarise_dynamics(mp.dynamics, self._anatomical)
        out.update(frames.pop("summary"))
        out["limit_excess_deg"] = float(mp.limit.mean())
        out["limit_excess_max_deg"] = float(mp.limit.max(initial=0.0))
        out["limit_excess_n"] = int(len(mp.limit))
        out["ik_error_mm"] = 1e3 * float(mp.fit.error.mean())
        if positions is None:
            base = out
        else:
            base = self.analyse(clip, None, ground)
        for k in EXCESS_KEYS:
            out[f"{k}_excess"] = out[k] - base[k]
        out["per_frame"] = {
            "foot_names": list(mp.feet),
            "contact": mp.contact.astype(int),
            "foot_height_mm": 1e3 * mp.height,
            "foot_speed_mm_s": 1e3 * mp.hspeed,
            **frames,
            "limit_excess_deg": mp.limit,
            "ik_error_mm": 1e3 * mp.fit.error,
            "qpos": mp.fit.qpos,  # (T, nq) the fitted configurations (forward simulation's input)
        }
        return out


def summarise_dynamics(dyn: Dynamics, anatomical: np.ndarray) -> dict:
    """Per-frame dynamics figures and their clip summary (key ``"summary"``)."""
    rf = np.linalg.norm(dyn.residual_force, axis=1) / dyn.weight
    rt = np.linalg.norm(dyn.residual_torque, axis=1) / dyn.mass
    tau = dyn.joint_torque[:, anatomical]
    jt = np.sqrt(np.mean(tau**2, axis=1)) / dyn.mass if tau.shape[1] else np.zeros(len(rf))
    return {
        "residual_force_bw": rf,
        "residual_torque_nm_kg": rt,
        "joint_torque_rms_nm_kg": jt,
        "summary": {
            "residual_force_bw": float(rf.mean()),
            "residual_force_bw_p95": float(np.percentile(rf, 95)),
            "residual_torque_nm_kg": float(rt.mean()),
            "joint_torque_rms_nm_kg": float(np.sqrt(np.mean(tau**2)) / dyn.mass)
            if tau.size
            else 0.0,
            "dynamics_n": int(len(rf)),
        },
    }


def _q_init(clip, model) -> np.ndarray | None:
    """The clip's own poses (T, nq) when they live on ``model`` (same nq): each frame of the
    original and of its reconstructions is fitted starting from the original's pose at that frame
    (robust to fast turns and glitches that derail warm starts; the points decide the rest);
    else None (cold start, then warm starts and the soft limit penalty)."""
    q = np.asarray(clip.qpos)
    return q if q.ndim == 2 and q.shape[1] == model.nq and len(q) == clip.n_frames else None


def analyse(
    clip,
    positions: np.ndarray | None,
    *,
    names,
    parents,
    model,
    ground: Ground | None = None,
    job: PhysicsJob | None = None,
) -> dict:
    """One-shot :meth:`PhysicsJob.analyse` (pass ``job`` to reuse MuJoCo state across calls)."""
    job = job or PhysicsJob(model, names, parents, clip.fps)
    return job.analyse(clip, positions, ground)


def _rebuild_job(model, names, parents, fps, mu, window) -> PhysicsJob:
    return PhysicsJob(model, names, parents, fps, mu=mu, window=window)
