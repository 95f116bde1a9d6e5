"""What the physics and the forward simulation of an evaluation's clips share per trial: the
subject's :class:`sim.analysis.job.PhysicsJob`, the trial's ground and its original's contacts
(:class:`TrialPhysics`, :func:`physics_setup`), and one torque-limited simulated body per
subject (:func:`simulate_setup`).

Units: metres, seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sidql.evaluation.cases import Case
from sidql.keyframes.spherical import POINTS
from sim.analysis.job import PhysicsJob
from sim.errors import MotionDataError
from sim.motion.clip import Clip
from sim.motion.trial import subject_model
from sim.physics.contacts import Contacts, trial_contacts
from sim.physics.ground import Ground, estimate_ground
from sim.replay.checks import from_clip
from sim.simulate.validate import DEFAULT_TERRAIN, forward_validation


@dataclass(frozen=True)
class TrialPhysics:
    """What the physics of one trial's clips share: the subject's
    :class:`sim.analysis.job.PhysicsJob` on the protocol points, the trial's ground, and the
    original's contacts labelled once over the whole trial (``start``: each clip's
    ``start_frame`` -> its first frame in ``contacts``; clip objects do not keep their identity
    on the way to worker processes or Ray)."""

    job: PhysicsJob
    ground: Ground
    contacts: Contacts
    start: dict

    def clip_contacts(self, clip: Clip) -> Contacts | None:
        """The original's contacts over ``clip``'s frames (None for a clip not of this trial:
        the job labels it on its own)."""
        i = self.start.get(clip.start_frame)
        return None if i is None else self.contacts.slice(i, i + clip.n_frames)

    def noise_floor(self, clip: Clip, *, seed: int = 0) -> dict:
        """The original re-captured with marker noise, analysed against the original
        (:meth:`sim.analysis.job.PhysicsJob.noise_floor`)."""
        return self.job.noise_floor(clip, self.ground, contacts=self.clip_contacts(clip), seed=seed)

    def analyse(self, clip: Clip, rec=None) -> dict:
        """:meth:`sim.analysis.job.PhysicsJob.analyse` of the original (``rec`` None) or of a
        reconstruction (its points, velocities and accelerations)."""
        c = self.clip_contacts(clip)
        if rec is None:
            return self.job.analyse(clip, None, self.ground, contacts=c)
        acc = getattr(rec, "accelerations", None)
        return self.job.analyse(
            clip, rec.positions, self.ground, contacts=c,
            velocities=None if acc is None else rec.velocities, accelerations=acc,
        )  # fmt: skip


def physics_setup(cases: Sequence[Case]) -> dict:
    """Per trial (``clip.source``): its :class:`TrialPhysics` for :func:`sidql.evaluation.scoring.score`: the ground and
    the original's contacts from all the trial's clips (in time order), one
    :class:`sim.analysis.job.PhysicsJob` per subject skeleton."""

    jobs, out = {}, {}
    by_trial: dict[str, list[Case]] = {}
    for c in cases:
        if not c.asf:
            raise MotionDataError(
                c.clip.source, None, "physics needs the clip on its subject's own skeleton (ASF); "
                "e.g. a folder of CMU files, or 'sidql dataset --skeleton subject' output",
            )  # fmt: skip
        by_trial.setdefault(c.clip.source, []).append(c)
    for source, group in by_trial.items():
        group = sorted(group, key=lambda c: c.clip.start_frame)
        clip = group[0].clip
        if group[0].asf not in jobs:
            pts = from_clip(clip).restrict(POINTS)
            model = subject_model(group[0].asf)[1]
            jobs[group[0].asf] = PhysicsJob(model, pts.names, pts.parents, clip.fps)
        pos = np.concatenate([c.clip.positions for c in group])
        vel = np.concatenate([c.clip.velocities for c in group])
        ground = estimate_ground(pos, clip.names, clip.fps)
        start, i = {}, 0
        for c in group:
            start[c.clip.start_frame] = i
            i += c.clip.n_frames
        out[source] = TrialPhysics(
            jobs[group[0].asf], ground,
            trial_contacts(pos, clip.names, clip.fps, ground, vel, clip.parents,
                           body_points=jobs[group[0].asf].names),
            start,
        )  # fmt: skip
    return out


def simulate_setup(
    cases: Sequence[Case], samples: int = 0, threads: int = 1, terrain: bool = DEFAULT_TERRAIN
) -> dict:
    """Per trial (``clip.source``): the :class:`sim.simulate.validate.ForwardValidation` of its
    subject (one torque-limited simulated body per skeleton) for :func:`sidql.evaluation.scoring.score`; ``samples``:
    its sampling tracker's rollouts per window (0: ``sim.simulate.validate``'s default
    controller); ``threads``: the sampler's rollouts on that many threads; ``terrain``: each
    clip in the scene inferred from its original motion (False: the empty floor)."""
    bodies, out = {}, {}
    for c in cases:
        if c.asf not in bodies:
            skeleton = subject_model(c.asf)[0]
            names = _protocol_names(c.clip)
            bodies[c.asf] = forward_validation(
                skeleton, names, samples=samples, threads=threads, terrain=terrain
            )
        out[c.clip.source] = bodies[c.asf]
    return out


def _protocol_names(clip: Clip) -> tuple[str, ...]:
    return from_clip(clip).restrict(POINTS).names
