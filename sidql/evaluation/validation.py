"""Validation of one clip: every method's keyframes chosen, reconstructed, replayed and measured.

:func:`validate_clip` chooses keyframes with each method (:mod:`sidql.keyframes.methods`),
reconstructs (:mod:`sidql.keyframes.reconstructions`), replays the original and every
reconstruction (:mod:`sim.replay.checks`) and, given a :class:`sim.analysis.job.PhysicsJob`,
fits the humanoid to each and adds the physics figures (contacts, dynamics, optionally forward
simulation): a :class:`ClipValidation` with each method's excess over the original. Decoded
``.sidq`` streams (:class:`DecodedStream`) are validated beside the methods.

What a trial shares between its clips: its floor (:func:`trial_ground`), its foot contacts
labelled once (:func:`trial_contacts_by_clip`), the subject's physics job (:func:`physics_job`)
and hinge ranges (:func:`joint_ranges`). :func:`checks_document` is the validation as JSON (the
report's ``checks.json``).

Units in the figures: millimetres (``*_mm``), millimetres per second (``*_mm_s``), degrees
(``*_deg``), frame counts.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from sidql.codec.decode import decode_to_reconstruction
from sidql.codec.decode import first_stream as read_stream
from sidql.codec.skeleton import skeleton_hash
from sidql.keyframes import reconstructions
from sidql.keyframes.methods import reconstruction_of, select
from sidql.keyframes.reconstructions import Reconstruction
from sidql.keyframes.spherical import POINTS
from sim.analysis.figures import HEIGHT_KEYS
from sim.analysis.job import PhysicsJob
from sim.errors import MotionDataError, UsageError
from sim.motion.clip import Clip
from sim.motion.trial import subject_model
from sim.physics.contacts import trial_contacts
from sim.physics.ground import Ground, estimate_ground
from sim.replay.checks import (
    CollisionScene,
    FrameChecks,
    PointMotion,
    excess,
    from_clip,
    from_reconstruction,
    replay,
    summarise,
)
from sim.simulate.model import CONTROL_HZ
from sim.simulate.reference import time_warp
from sim.simulate.terrain import Box, find_terrain


@dataclass
class MethodRun:
    """One method's keyframes, reconstruction and replay figures on one clip."""

    method: str
    reconstruction: str
    keyframes: np.ndarray
    motion: PointMotion
    checks: FrameChecks
    summary: dict
    excess: dict
    physics: dict = field(default_factory=dict)

    @property
    def figures(self) -> dict:
        """What the page shows: the replay summary and the :mod:`sim.physics` figures."""
        return with_physics(self.summary, self.physics)

    @property
    def label(self) -> str:
        """The method's name, with ``+reconstruction`` where that is not the one its name
        implies: ``pitch`` (under the Hermite), ``pitch+slerp``; ``cartesian`` (under its own
        Cartesian curves), ``cartesian+hermite``."""
        implied = self.method if self.method in reconstructions.RECONSTRUCTIONS else "hermite"
        if self.reconstruction == implied:
            return self.method
        return f"{self.method}+{self.reconstruction}"


@dataclass
class ClipValidation:
    """The original and every method's run on one clip."""

    clip: Clip
    W: int
    original: PointMotion
    baseline_checks: FrameChecks
    baseline: dict
    runs: list[MethodRun] = field(default_factory=list)
    physics: dict = field(default_factory=dict)
    ground: Ground | None = None  # the trial's, when the replay used one
    noise: dict = field(default_factory=dict)  # the original re-captured with marker noise
    #: the scene inferred from the original (:func:`clip_scene`): its boxes
    #: (``sim.simulate.terrain.Box``) and ground height [m] (None: no scene, the trial's floor),
    #: in the original's frame; drawn in the clip's videos and filmstrips
    scene: tuple = ()
    scene_ground: float | None = None

    @property
    def noise_floor(self) -> dict:
        """Per figure, how far the original re-captured with marker noise
        (:meth:`sim.analysis.job.PhysicsJob.noise_floor`) departs from the original: a
        difference between methods smaller than this is capture noise."""
        out = {}
        for k, v in with_physics({}, self.noise).items():
            o = self.baseline_figures.get(k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or o is None:
                continue
            if isinstance(o, bool) or not isinstance(o, (int, float)):
                continue
            if math.isfinite(v) and math.isfinite(o):
                out[k] = abs(float(v) - float(o))
        return out

    @property
    def baseline_figures(self) -> dict:
        """The original's replay summary and :mod:`sim.physics` figures."""
        return with_physics(self.baseline, self.physics)


@dataclass(frozen=True)
class DecodedStream:
    """A decoded ``.sidq`` stream, shown in a report like a method.

    Attributes:
        label: how the page names it (the file name).
        motion: the whole decoded trial (N, 23, 3) at the stream's fps; frame n is frame n of the
            trial read at that rate, so a clip's frames are a slice of it.
    """

    label: str
    motion: Reconstruction

    def clip_part(self, clip: Clip) -> tuple[np.ndarray, PointMotion]:
        """(keyframes inside the clip, clip-relative; the decoded frames of ``clip``)."""
        step = clip.source_fps / clip.fps
        i0 = int(round(clip.start_frame / step))
        i1 = i0 + clip.n_frames
        rec = self.motion
        if abs(rec.fps - clip.fps) > 1e-9 or i1 > rec.n_frames:
            raise UsageError(
                f"{self.label}: the stream has {rec.n_frames} frames at {rec.fps:g} fps; clip "
                f"frames {i0}..{i1 - 1} at {clip.fps:g} fps are not in it"
            )
        keys = np.asarray(rec.keyframes)
        keys = keys[(keys >= i0) & (keys < i1)] - i0
        part = PointMotion(
            tuple(rec.names), np.asarray(rec.parents), rec.positions[i0:i1], clip.fps,
            rec.velocities[i0:i1],
        )  # fmt: skip
        return keys, part

    def accelerations(self, clip: Clip) -> np.ndarray | None:
        """(T, 23, 3) the decoded curve's point accelerations [m/s^2] over ``clip``'s frames
        (None if the decoder gave none)."""
        acc = getattr(self.motion, "accelerations", None)
        if acc is None:
            return None
        i0 = int(round(clip.start_frame / (clip.source_fps / clip.fps)))
        return np.asarray(acc)[i0 : i0 + clip.n_frames]


def load_stream(path: str | os.PathLike, asf: str | os.PathLike) -> DecodedStream:
    """Decode a ``.sidq`` file for a report of a trial of the subject ``asf``; a stream encoded
    from another skeleton is a :class:`MotionDataError`."""
    if read_stream(path).skeleton_hash != skeleton_hash(subject_model(asf)[0]):
        raise MotionDataError(
            str(path), None, f"stream was encoded from another skeleton than {asf}"
        )
    return DecodedStream(Path(path).name, decode_to_reconstruction(path))


def joint_ranges(model) -> dict[str, tuple[float, float]]:
    """Hinge name -> (lo, hi) [rad] of every limited hinge of a MuJoCo model."""
    out = {}
    for j in range(model.njnt):
        if model.jnt_limited[j] and model.jnt_type[j] == 3:  # mjJNT_HINGE
            out[model.joint(j).name] = (float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1]))
    return out


def validate_clip(
    clip: Clip,
    methods,
    W: int,
    *,
    seed: int = 0,
    joint_ranges: dict | None = None,
    contact_height: float = 0.02,
    hops: int = 2,
    floor_z: float = 0.0,
    streams: tuple[DecodedStream, ...] = (),
    physics=None,
    ground=None,
    simulate=None,
    contacts=None,
    reconstruction: str | None = None,
    scene_body=None,
) -> ClipValidation:
    """Keyframes by every method, reconstruction, replay and figures for one clip.

    Args:
        clip: the original (T frames, any CMU point set containing the 23 protocol points).
        methods: names registered in :mod:`sidql.keyframes.methods`.
        W: keyframes per clip, both ends included.
        joint_ranges: hinge ranges [rad] for the joint-limit check of motions with joint angles.
        streams: decoded ``.sidq`` streams of the clip's trial, shown after the methods.
        physics: a :class:`sim.analysis.job.PhysicsJob` on the protocol points: adds
            :mod:`sim.physics` figures (``physics``) for the original and every run.
        ground: the trial's :class:`sim.physics.ground.Ground`; its ``floor_z`` replaces
            ``floor_z`` (default: estimated from the clip when ``physics`` is given).
        simulate: a :class:`sim.simulate.validate.ForwardValidation` of the subject (with
            ``physics``): the human-strength body tracks the IK fit of the original and of every
            run in ``mj_step`` without assistance; its figures join ``physics``.
        contacts: the original's foot contacts labelled over the whole trial, by the clip's
            ``start_frame`` (:func:`trial_contacts`); default: labelled on the clip.
        reconstruction: rebuild every method's keyframes with this one alone (default: Hermite,
            and the method's own where it differs).
        scene_body: without ``simulate``, a body with soles (``sim.simulate.validate.
            validation_model``) to infer the clip's scene with (:func:`clip_scene`; drawn only).
    """
    if physics is not None and ground is None:
        ground = estimate_ground(clip.positions, clip.names, clip.fps)
    if ground is not None:
        floor_z = ground.floor_z
    full = from_clip(clip)
    orig = full.restrict(POINTS)
    floor = dict(floor_z=floor_z, contact_height=contact_height, hops=hops)
    scene = CollisionScene.for_reference(orig, **floor)  # one MuJoCo scene per clip, reused
    kw = dict(**floor, joint_ranges=joint_ranges, scene=scene)
    base_checks = replay(orig, full, **kw)
    out = ClipValidation(clip, W, orig, base_checks, summarise(base_checks), ground=ground)
    trial_labels = (contacts or {}).get(clip.start_frame)
    analyse = None
    if physics is not None:
        out.physics = physics.analyse(clip, None, ground, contacts=trial_labels)
        out.noise = physics.noise_floor(clip, ground, contacts=trial_labels, seed=seed)
        qpos = out.physics["per_frame"]["qpos"]
        if simulate is None:
            out.scene, out.scene_ground = clip_scene(scene_body, qpos, clip.fps)
        else:  # the scene it simulated in (the empty floor: none), as it found it
            out.physics.update(simulate.run(qpos, clip.fps))
            out.scene, out.scene_ground = lifted_scene(
                getattr(simulate, "last_boxes", []), getattr(simulate, "last_ground", None)
            )
            out.physics["per_frame"]["sim_positions"] = simulated_points(simulate, clip, out)
        analyse = partial(_run_physics, out, physics, simulate, ground, trial_labels)
    for m in methods:
        out.runs += _method_runs(out, m, W, seed, full, kw, analyse, reconstruction)
    for stream in streams:
        out.runs.append(_stream_run(out, stream, full, kw, analyse))
    return out


def _stream_run(out: ClipValidation, stream: DecodedStream, full, kw: dict, analyse) -> MethodRun:
    """A decoded stream's run on ``out.clip``, measured like a method's."""
    keys, rec = stream.clip_part(out.clip)
    checks = replay(rec, full, **kw)
    s = summarise(checks)
    run = MethodRun(stream.label, stream.motion.reconstruction, keys, rec, checks, s,
                    excess(s, out.baseline))  # fmt: skip
    if analyse is not None:
        run.physics = analyse(rec, stream.accelerations(out.clip))
    return run


def clip_scene(body, qpos: np.ndarray, fps: float) -> tuple[tuple, float | None]:
    """The scene inferred from the original's IK fit ``qpos`` (T, nq at ``fps``) with ``body``'s
    soles (``sim.simulate.validate.validation_model``; None: no scene), as forward validation
    infers it (``find_terrain`` at the control rate; a report that simulates draws the scene its
    ``ForwardValidation`` found instead: :func:`lifted_scene`), in the original's frame: its
    boxes (``sim.simulate.terrain.Box``) and its ground height [m], the ground track's mean,
    which the boxes are lifted by (the simulation's frame is the original's less that track:
    its ground at z = 0); ``((), None)`` without supports."""
    if body is None:
        return (), None
    return lifted_scene(
        *find_terrain(body, time_warp(body, qpos, fps, 1.0, CONTROL_HZ), CONTROL_HZ)
    )


def lifted_scene(boxes: list[Box], track: np.ndarray | None) -> tuple[tuple, float | None]:
    """``boxes`` found in the simulation's frame, whose ground ``track`` (T,) [m] is the
    original's ground (:func:`sim.simulate.terrain.find_terrain`, or a ``ForwardValidation``'s
    ``last_boxes`` and ``last_ground``), in the original's frame: lifted by the track's mean,
    with that mean as the ground height [m]; ``((), None)`` without boxes."""
    if not boxes:
        return (), None
    ground = float(np.mean(track))
    lift = np.array([0.0, 0.0, ground])
    return tuple(replace(b, centre=b.centre + lift, half=b.half.copy()) for b in boxes), ground


def _run_physics(out: ClipValidation, physics, simulate, ground, trial_labels, rec, acc=None):
    """A reconstruction's physics figures (:meth:`sim.analysis.job.PhysicsJob.analyse`: its
    points and its curve's derivatives ``acc``, default its own), with the forward simulation's
    when ``simulate`` is given."""
    clip, names = out.clip, out.original.names
    r = rec.restrict(names)
    ix = [rec.names.index(n) for n in names]
    acc = getattr(rec, "accelerations", None) if acc is None else acc
    figures = physics.analyse(
        clip, r.positions, ground, contacts=trial_labels,
        velocities=None if acc is None else np.asarray(rec.velocity())[:, ix],
        accelerations=None if acc is None else np.asarray(acc)[:, ix],
    )  # fmt: skip
    if simulate is not None:  # the forward simulation's figures join the physics
        original_qpos = out.physics["per_frame"]["qpos"]
        figures.update(simulate.run(figures["per_frame"]["qpos"], clip.fps, original_qpos))
        figures["per_frame"]["sim_positions"] = simulated_points(simulate, clip, out)
    return figures


def simulated_points(simulate, clip: Clip, out: ClipValidation) -> np.ndarray:
    """(T, P, 3) [m] the protocol points of the simulated body in ``simulate``'s last run
    (:class:`sim.simulate.validate.ForwardValidation`), one per frame of ``clip`` (T frames),
    lifted from the simulation's floor (z = 0) to the ground ``out`` draws: its scene's
    (:func:`clip_scene`; the body then stands on the drawn boxes), else the trial's floor: the
    body as it moved, to be drawn beside the motion it tracked."""
    floor_z = out.ground.floor_z if out.ground is not None else 0.0
    floor_z = floor_z if out.scene_ground is None else out.scene_ground
    pos = simulate.points(simulate.last_qpos)[: clip.n_frames]
    if len(pos) < clip.n_frames:  # (a clip's last frame between control ticks: held)
        pos = np.concatenate([pos, np.repeat(pos[-1:], clip.n_frames - len(pos), axis=0)])
    pos[..., 2] += floor_z
    return pos


def _method_runs(
    out: ClipValidation, m: str, W: int, seed: int, full, kw: dict, analyse, reconstruction=None
):
    """Method ``m``'s runs on ``out.clip``: its keyframes under the Hermite (unless another
    method already shows the same keyframes so) and under its own reconstruction if another;
    under ``reconstruction`` alone when it is given."""
    clip = out.clip
    runs = []
    keys = np.asarray(select(m, clip, W, seed=seed))
    own = reconstruction_of(m)  # every method under Hermite, and under its own if other
    shown = any(
        r.reconstruction == "hermite" and np.array_equal(r.keyframes, keys) for r in out.runs
    )
    hermite = [] if own != "hermite" and shown else ["hermite"]  # cartesian's = uniform's
    names = hermite + ([own] if own != "hermite" else [])
    for name in [reconstruction] if reconstruction else names:
        built = reconstructions.rebuild(name, clip, keys)
        rec = from_reconstruction(built, clip.fps)
        checks = replay(rec, full, **kw)
        s = summarise(checks)
        run = MethodRun(m, name, keys, rec, checks, s, excess(s, out.baseline))
        if analyse is not None:
            run.physics = analyse(built)
        runs.append(run)
    return runs


def physics_job(model, clip: Clip):
    """A :class:`sim.analysis.job.PhysicsJob` for the protocol points of ``clip``'s subject."""
    orig = from_clip(clip).restrict(POINTS)
    return PhysicsJob(model, orig.names, orig.parents, clip.fps)


def trial_ground(clips: list[Clip]):
    """The trial's :class:`sim.physics.ground.Ground` from all its clips."""
    pos = np.concatenate([c.positions for c in clips])
    return estimate_ground(pos, clips[0].names, clips[0].fps)


def trial_contacts_by_clip(clips: list[Clip], ground: Ground) -> dict:
    """The original's ground contacts labelled once over the trial (its clips in order), as
    ``{clip.start_frame: Contacts of its frames}`` (:func:`sim.physics.contacts.trial_contacts`)."""
    pos = np.concatenate([c.positions for c in clips])
    vel = np.concatenate([c.velocities for c in clips])
    protocol = from_clip(clips[0]).restrict(POINTS).names  # the points physics analyses
    whole = trial_contacts(
        pos, clips[0].names, clips[0].fps, ground, vel, clips[0].parents, body_points=protocol
    )
    out, i = {}, 0
    for c in clips:
        out[c.start_frame] = whole.slice(i, i + c.n_frames)
        i += c.n_frames
    return out


def _clean(x):
    """JSON-ready: NaN -> None, numpy -> Python."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        return None if math.isnan(float(x)) else round(float(x), 6)
    if isinstance(x, np.integer):
        return int(x)
    return x


def per_frame(checks: FrameChecks) -> dict:
    """Per-frame arrays of :class:`FrameChecks` in report units (mm, mm/s, deg)."""
    c = checks
    return {
        "bone_drift_mm": 1e3 * c.bone_drift,
        "floor_depth_mm": 1e3 * c.floor_depth,
        "floor_bones": c.floor_bones,
        "self_pen_pairs": c.self_count,
        "self_pen_depth_mm": 1e3 * c.self_depth,
        "skate_speed_mm_s": 1e3 * c.skate_speed,
        "foot_names": list(c.foot_names),
        "foot_contact": c.foot_contact.astype(int),
        "mpjpe_mm": 1e3 * c.mpjpe,
        "velocity_error_mm_s": 1e3 * c.velocity_error,
        "joint_limit_deg": np.degrees(c.joint_limit),
    }


def checks_document(validations: list[ClipValidation], meta: dict) -> dict:
    """The ``checks.json`` document: parameters, and per clip the original's figures and each
    method's keyframes, figures, excess over the original and per-frame arrays."""
    clips = []
    for v in validations:
        clips.append(
            {
                "source": v.clip.source,
                "start_frame": v.clip.start_frame,
                "frames": v.clip.n_frames,
                "fps": v.clip.fps,
                "keyframes": v.W,
                **_scene_entry(v),
                "original": {
                    "summary": v.baseline,
                    "per_frame": per_frame(v.baseline_checks),
                    **_physics_entry(v.physics),
                },
                "noise_floor": v.noise_floor,
                "methods": [
                    {
                        "method": r.method,
                        "reconstruction": r.reconstruction,
                        "indices": r.keyframes,
                        "summary": r.summary,
                        "excess": r.excess,
                        "per_frame": per_frame(r.checks),
                        **_physics_entry(r.physics),
                    }
                    for r in v.runs
                ],
            }
        )
    return _clean({**meta, "clips": clips})


def with_physics(summary: dict, physics: dict) -> dict:
    """``summary`` plus the scalar :mod:`sim.physics` figures (what the page's table reads);
    where the trial's floor does not fit, heights above it (:data:`HEIGHT_KEYS`) are left out."""
    out = {**summary, **{k: v for k, v in physics.items() if k != "per_frame"}}
    if physics and not physics.get("floor_fits", True):
        for k in HEIGHT_KEYS:
            out[k] = None
    return out


def _scene_entry(v: ClipValidation) -> dict:
    """A clip's inferred scene in checks.json (nothing without one): its ground height [m] and
    per box its centre and half sizes [m] and yaw [rad], in the original's frame, as drawn."""
    if not v.scene:
        return {}
    boxes = [{"centre": b.centre, "half": b.half, "yaw": b.yaw} for b in v.scene]
    return {"scene_ground": v.scene_ground, "scene": boxes}


def _physics_entry(physics: dict) -> dict:
    """``physics`` (the :mod:`sim.physics` figures) and ``physics_per_frame`` of a checks.json row."""
    if not physics:
        return {}
    return {
        "physics": {k: v for k, v in physics.items() if k != "per_frame"},
        "physics_per_frame": physics["per_frame"],
    }
