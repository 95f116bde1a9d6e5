"""The physics of one motion against its original, one job per subject and point set.

:class:`PhysicsJob` owns everything MuJoCo for one subject and one point set (the IK model and data,
the inverse-dynamics model and data, the capsule collision scene of the kinematic replay), made
once and reused for the original and every reconstruction of every clip.
:meth:`PhysicsJob.analyse` (or the one-shot :func:`analyse`) fits the humanoid to the points
(:mod:`sim.physics.ik`), labels the ground contacts (:mod:`sim.physics.contacts`), replays the
points (:mod:`sim.replay.checks`) and runs the inverse dynamics (:mod:`sim.physics.dynamics`);
:mod:`sim.analysis.figures` lists the figures it returns for the original (``positions=None``) or
a reconstruction's points.

Derivatives come from where they are known, as point velocities and accelerations mapped onto
the fitted humanoid through its Jacobians (:meth:`sim.physics.ik.HumanoidIK.rates`). The
original's: its points in the source frames around each frame (``clip.source_velocities``,
``clip.accelerations``: :func:`sim.motion.velocities.point_derivatives`, a local polynomial at
120 fps whose response is stated there). A reconstruction's: its curve's own
(``Reconstruction.velocities`` and ``accelerations``); degrees of freedom the points do not see
keep the original's rates, as the fit keeps their angles. Only where neither exists (points
alone) the Savitzky-Golay filter of :func:`sim.physics.dynamics.derivatives` differentiates the
fit.

Contacts: the original's labels come from the whole trial, labelled once (pass them as
``contacts``; else the clip's own); a reconstruction's from the soles of its fitted humanoid,
starting from the original's state at frame 0. Both use :mod:`sim.physics.contacts`.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace

import mujoco
import numpy as np

from sim.analysis.figures import EXCESS_KEYS, MotionPhysics, figures
from sim.errors import UsageError
from sim.model.capsules import bones_of
from sim.model.kinematics import FOOT_POINTS, SOLE_POINTS
from sim.motion.points import PointMotion
from sim.physics.contact_metrics import lowest_body_point
from sim.physics.contacts import Contacts, body_contacts, motion_contacts, trial_contacts
from sim.physics.dynamics import MU, InverseDynamics
from sim.physics.ground import Ground, estimate_ground
from sim.physics.ik import NON_ANATOMICAL, HumanoidIK, hinge_names, limit_excess
from sim.physics.noise import NOISE_MM, noisy_original
from sim.replay.checks import CollisionScene, FrameChecks, _lengths, replay

#: A frame's dynamics is measured when none of its points' accelerations lets through more than
#: this many times the sample noise of the centred source window
#: (:func:`sim.motion.velocities.derivative_noise`): the first frame of a take (5.3x: 1 mm of
#: marker jitter becomes ~6 m/s^2, up to 2 BW in CMU walks) and frames beside a pose jump are
#: not; the second frame of a take (1.0x at 30 of 120 fps) is.
MAX_DERIVATIVE_NOISE = 2.0

#: Originals a job keeps (a few hundred kB each): ``sidql eval`` revisits every clip per method and W.
ORIGINALS_CACHED = 1024


class PhysicsJob:
    """MuJoCo state for the physics of motions of one subject on one point set.

    Args:
        model: the subject's humanoid (:func:`sim.model.humanoid.subject_model`).
        names: (P,) point names of the motions (``"root"`` and bone names).
        parents: (P,) parent index of each point.
        fps: frame rate [1/s].
        mu: ground friction coefficient; window: Savitzky-Golay window [frames] (only for motions
            without known derivatives).
    """

    def __init__(self, model, names, parents, fps: float, *, mu: float = MU, window: int = 9):
        self._args = (model, tuple(names), np.asarray(parents), float(fps), mu, window)
        self.names = tuple(names)
        self.parents = np.asarray(parents)
        self.fps = float(fps)
        self.ik = HumanoidIK(model, self.names)
        self.inv = InverseDynamics(model, mu=mu, window=window)
        self.model = model
        self._data = mujoco.MjData(model)
        self._scene: CollisionScene | None = None
        self._observed: tuple[str, ...] | None = None
        self._originals: dict = {}
        hinges = hinge_names(model)
        self._anatomical = np.array([h.rsplit("_", 1)[0] not in NON_ANATOMICAL for h in hinges])
        # the soles of the fitted humanoid: its ankle, ball and toe-tip sites
        self._feet = tuple(
            n for n in FOOT_POINTS
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{n}_end") >= 0
        )  # fmt: skip
        self._feet_site = np.array([model.site(f"{n}_end").id for n in self._feet], dtype=int)
        self._jac = np.zeros((3, model.nv))
        # capsules of the body surface (PhysDiff's lowest point); the feet are their soles
        self._bones = bones_of(self.names, self.parents)
        self._body_bones = np.array(
            [self.names[c] not in SOLE_POINTS for c in self._bones.child], dtype=bool
        )

    def __reduce__(self):
        # Sent to another process (a pool or Ray worker) as its constructor's arguments: the job's
        # MuJoCo data and scratch buffers are rebuilt there, writable (Ray hands arrays back
        # read-only), and the cache of originals starts empty.
        model, names, parents, fps, mu, window = self._args
        return (_rebuild_job, (model, names, parents, fps, mu, window))

    def _replay(self, motion: PointMotion, reference: PointMotion, ground: Ground) -> FrameChecks:
        if self._scene is None:
            self._scene = CollisionScene(bones_of(self.names, self.parents, _lengths(reference)))
        self._scene.move_floor(ground.floor_z)
        return replay(motion, reference, floor_z=ground.floor_z, scene=self._scene, ground=ground)

    def feet_of_fit(self, qpos: np.ndarray, qvel: np.ndarray | None = None):
        """The fitted humanoid's foot points (ankle, ball, toe tip) per frame.

        Returns:
            names (F,), positions (T, F, 3) [m], velocities (T, F, 3) [m/s] (``J qvel``; finite
            differences without ``qvel``).
        """
        m, d = self.model, self._data
        T = len(qpos)
        pos = np.empty((T, len(self._feet), 3))
        vel = np.empty_like(pos)
        for t in range(T):
            d.qpos[:] = qpos[t]
            mujoco.mj_kinematics(m, d)
            pos[t] = d.site_xpos[self._feet_site]
            if qvel is not None:
                mujoco.mj_comPos(m, d)
                for k, s in enumerate(self._feet_site):
                    mujoco.mj_jacSite(m, d, self._jac, None, int(s))
                    vel[t, k] = self._jac @ qvel[t]
        if qvel is None:
            vel = np.gradient(pos, 1.0 / self.fps, axis=0) if T > 1 else np.zeros_like(pos)
        return self._feet, pos, vel

    def force_points(self, contacts: Contacts, ground: Ground) -> list:
        """Per frame the ``(body id, point (3,))`` list where ground forces may act
        (:meth:`sim.physics.contacts.Contacts.points`)."""
        out = []
        for t in range(contacts.contact.shape[0]):
            out.append([(self.model.body(b).id, p) for b, p in contacts.points(ground, t)])
        return out

    def motion_physics(
        self,
        positions: np.ndarray,
        reference: PointMotion | None,
        ground: Ground,
        start,
        *,
        velocities: np.ndarray | None = None,
        accelerations: np.ndarray | None = None,
        rates: tuple[np.ndarray, np.ndarray] | None = None,
        contacts: Contacts | None = None,
        initial=None,
        initial_body=None,
        source: str = "curve",
        measured: np.ndarray | None = None,
    ) -> MotionPhysics:
        """IK, contacts, replay and dynamics of one motion's points (T, P, 3) [m].

        Args:
            reference: the original on this job's points (bone lengths of the collision scene;
                default the motion itself).
            start: IK start, None (cold), (nq,) for frame 0 (then warm starts) or (T, nq) per
                frame (:meth:`sim.physics.ik.HumanoidIK.fit`'s ``guesses``).
            velocities, accelerations: (T, P, 3) the points' own derivatives [m/s, m/s^2] (the
                original's source frames, a reconstruction's curve): mapped onto the fit by
                :meth:`sim.physics.ik.HumanoidIK.rates`, ``rates`` the prior.
            rates: ``(qvel, qacc)`` (T, nv): the prior of that mapping (default 0).
            source: what the derivatives are, for the figures' ``derivatives``.
            measured: (T,) bool, the frames whose derivatives are measured (default all).
            contacts: the motion's ground contacts (the original's, from its trial); default
                from the fitted humanoid's soles, starting from ``initial`` (F,), and the rest of
                the motion's body points (:func:`sim.physics.contacts.body_contacts`), starting
                from ``initial_body``.
        """
        if start is not None and np.ndim(start) == 2:
            fit = self.ik.fit(positions, guesses=start)
        else:
            fit = self.ik.fit(positions, q_init=start)
        if self._observed is None:  # the same hinges for the original and every reconstruction
            self._observed = self.ik.observed_hinges(fit.qpos[0])
        if velocities is not None and accelerations is not None:
            prior = rates if rates is not None else (None, None)
            qvel, qacc = self.ik.rates(
                fit.qpos, velocities, accelerations, prior_qvel=prior[0], prior_qacc=prior[1]
            )
        else:
            qvel = qacc = None
            source = f"Savitzky-Golay {self.inv.window} frames"
        if contacts is None:
            feet, fp, fv = self.feet_of_fit(fit.qpos, qvel)
            contacts = motion_contacts(fp, feet, self.fps, ground, initial=initial, velocities=fv)
            contacts = replace(contacts, body=body_contacts(
                positions, self.names, self.parents, self.fps, ground, radius=self._bones.radius,
                initial=initial_body,
            ))  # fmt: skip
        points = self.force_points(contacts, ground)
        dyn = self.inv.run(fit.qpos, self.fps, points, qvel=qvel, qacc=qacc)
        motion = PointMotion(self.names, self.parents, positions, self.fps)
        checks = self._replay(motion, motion if reference is None else reference, ground)
        lowest = lowest_body_point(
            positions, self.names, self.parents, self._bones.radius, ground, contacts.sole,
            bones=self._body_bones,
        )  # fmt: skip
        T = len(positions)
        measured = np.ones(T, dtype=bool) if measured is None else np.asarray(measured, bool)
        return MotionPhysics(
            positions, fit, dyn, contacts, checks,
            limit_excess(fit.qpos, self.model, self._observed), lowest, source, measured,
            np.array([len(p) for p in points], dtype=int),
        )  # fmt: skip

    def original(self, clip, ground: Ground, contacts: Contacts | None = None) -> MotionPhysics:
        """The original clip's physics on this job's points (cached per clip, ground and
        contacts).

        The cache key holds the points themselves (a digest) and the whole ground: clips can share
        source, start and length yet differ (synthetic clips of one trial all start at frame 0)."""
        idx = [clip.names.index(n) for n in self.names]
        pos = np.ascontiguousarray(np.asarray(clip.positions, dtype=np.float64)[:, idx])
        key = (
            clip.source, clip.start_frame, pos.shape, hashlib.sha1(pos.tobytes()).hexdigest(),
            float(ground.z), tuple(ground.sides), tuple(ground.slope), tuple(ground.origin),
            np.asarray(ground.offset, dtype=np.float64).tobytes(), float(ground.spread),
            None if contacts is None else contacts.contact.tobytes(),
        )  # fmt: skip
        if key not in self._originals:
            ref = PointMotion(self.names, self.parents, pos, self.fps)
            if len(self._originals) >= ORIGINALS_CACHED:
                self._originals.clear()
            q0 = _q_init(clip, self.model)
            if contacts is None:
                contacts = trial_contacts(
                    clip.positions, clip.names, self.fps, ground, clip.velocities, clip.parents,
                    body_points=self.names,
                )  # fmt: skip
            vel, acc = _source_derivatives(clip, idx)
            self._originals[key] = self.motion_physics(
                ref.positions, ref, ground, q0, velocities=vel, accelerations=acc,
                contacts=contacts, source="source frames", measured=measured_frames(clip, idx),
            )  # fmt: skip
        return self._originals[key]

    def analyse(
        self,
        clip,
        positions: np.ndarray | None = None,
        ground: Ground | None = None,
        *,
        contacts: Contacts | None = None,
        velocities: np.ndarray | None = None,
        accelerations: np.ndarray | None = None,
    ) -> dict:
        """Figures of a motion against the original ``clip`` (see the module docstring).

        Args:
            clip: the original (:class:`sim.motion.clip.Clip`, containing this job's points).
            positions: (T, P, 3) [m] the reconstruction's points in this job's ``names`` order;
                ``None`` analyses the original itself (the baseline row: excesses 0).
            ground: the trial's ground (default: estimated from ``clip`` alone).
            contacts: the original's contacts over the clip's frames (:meth:`Contacts.slice` of
                :func:`sim.physics.contacts.trial_contacts`; default: labelled on the clip).
            velocities, accelerations: (T, P, 3) the reconstruction's own point derivatives
                [m/s, m/s^2] (its curve's); without them its fit is differentiated by the filter.
        Returns:
            JSON-ready numbers plus ``per_frame``: ``foot_names`` (F,) feet, ``contact`` (T, F)
            0/1, ``foot_height_mm`` (T, F) lowest sole point above the floor,
            ``foot_speed_mm_s`` (T, F) its horizontal speed, ``residual_force_bw`` (T,),
            ``residual_torque_nm_kg`` (T,), ``joint_torque_rms_nm_kg`` (T,),
            ``limit_excess_deg`` (T,), ``ik_error_mm`` (T,), ``lowest_mm`` (T,) the lowest body
            surface point above the floor, ``qpos`` (T, nq) the IK fit.
        """
        if ground is None:
            ground = estimate_ground(clip.positions, clip.names, clip.fps)
        orig = self.original(clip, ground, contacts)
        if positions is None:
            mp = orig
        else:
            p = np.asarray(positions, dtype=np.float64)
            if p.shape != orig.positions.shape:
                raise UsageError(f"positions must be {orig.positions.shape}; got {p.shape}")
            ref = PointMotion(self.names, self.parents, orig.positions, self.fps)
            mp = self.motion_physics(
                p, ref, ground, _q_init(clip, self.model), velocities=velocities,
                accelerations=accelerations, rates=(orig.dynamics.qvel, orig.dynamics.qacc),
                initial=orig.contacts.contact[0], initial_body=_initial_body(orig, self.names),
                measured=orig.measured,
            )  # fmt: skip
        out = figures(mp, orig, ground, self.fps, self._anatomical, self.inv.mu)
        per_frame = out.pop("per_frame")
        if positions is None:
            base = out
        else:
            base = self.analyse(clip, None, ground, contacts=contacts)
        for k in EXCESS_KEYS:
            out[f"{k}_excess"] = out[k] - base[k]
        out["per_frame"] = per_frame
        return out

    def noise_floor(
        self,
        clip,
        ground: Ground,
        *,
        contacts: Contacts | None = None,
        sigma_mm: float = NOISE_MM,
        seed: int = 0,
    ) -> dict:
        """:meth:`analyse` of the original re-captured with ``sigma_mm`` of marker noise
        (:func:`sim.physics.noise.noisy_original`, seeded): each figure's excess over the
        original is what capture noise alone does to it, its noise floor."""
        idx = [clip.names.index(n) for n in self.names]
        pos = np.asarray(clip.positions, dtype=np.float64)[:, idx]
        vel, acc = _source_derivatives(clip, idx)
        if vel is None:  # no source frames: positions only, the filter differentiates
            vel = acc = np.zeros_like(pos)
            noisy = noisy_original(pos, vel, acc, clip.fps, clip.fps, sigma_mm=sigma_mm, seed=seed)
            return self.analyse(clip, noisy[0], ground, contacts=contacts)
        p, v, a = noisy_original(
            pos, vel, acc, clip.fps, clip.source_fps, sigma_mm=sigma_mm, seed=seed
        )
        return self.analyse(clip, p, ground, contacts=contacts, velocities=v, accelerations=a)


def _q_init(clip, model) -> np.ndarray | None:
    """The clip's own poses (T, nq) when they live on ``model`` (same nq): each frame of the
    original and of its reconstructions is fitted starting from the original's pose at that frame
    (robust to fast turns and glitches that derail warm starts; the points decide the rest);
    else None (cold start, then warm starts and the soft limit penalty)."""
    q = np.asarray(clip.qpos)
    return q if q.ndim == 2 and q.shape[1] == model.nq and len(q) == clip.n_frames else None


def _initial_body(orig: MotionPhysics, names) -> np.ndarray | None:
    """The original's body contacts at frame 0 on the job's body points (a reconstruction's
    start), or None when the original has none labelled."""
    body = orig.contacts.body
    if body is None:
        return None
    keep = [n for n in names if n not in FOOT_POINTS]
    on = dict(zip(body.names, body.contact[0], strict=True))
    return np.array([bool(on.get(n, False)) for n in keep])


def measured_frames(clip, idx) -> np.ndarray:
    """(T,) bool: the frames of ``clip`` whose source derivatives on the points ``idx`` are all
    measured, none letting through more than :data:`MAX_DERIVATIVE_NOISE` times the centred
    window's noise (``clip.derivative_noise``; all where the clip does not say)."""
    noise = getattr(clip, "derivative_noise", None)
    if noise is None or getattr(clip, "accelerations", None) is None:
        return np.ones(clip.n_frames, dtype=bool)
    return (np.asarray(noise)[:, idx] <= MAX_DERIVATIVE_NOISE).all(axis=1)


def _source_derivatives(clip, idx):
    """The clip's point velocities and accelerations (T, P, 3) from its source frames on the
    points ``idx``, or (None, None) where the clip has none (the filter differentiates the fit)."""
    vel = getattr(clip, "source_velocities", None)
    acc = getattr(clip, "accelerations", None)
    if vel is None or acc is None:
        return None, None
    return np.asarray(vel, dtype=np.float64)[:, idx], np.asarray(acc, dtype=np.float64)[:, idx]


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
