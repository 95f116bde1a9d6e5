"""The validation report of a trial: every method's reconstruction replayed, measured, rendered, on one page.

:func:`report_trial` ingests a CMU trial, cuts it into clips and reports the chosen ones;
:func:`report_clips` validates clips through :func:`sim.batch.run_batch` (this process, a pool or
Ray; a clip that fails is listed on the page) and writes the page. The parts, one concept each:

* :mod:`sidql.evaluation.validation`: per clip, choose -> reconstruct -> replay -> physics;
* :mod:`sidql.evaluation.metrics`: the declared figures and the best value per column;
* :mod:`sidql.evaluation.plots`: the per-metric and per-frame plots;
* :mod:`sidql.evaluation.page`: videos, filmstrips, ``checks.json`` and ``index.html``.
"""

from __future__ import annotations

import os
from functools import partial
from pathlib import Path

from sidql.evaluation.page import write_report
from sidql.evaluation.validation import (
    DecodedStream,
    joint_ranges,
    load_stream,
    physics_job,
    trial_contacts_by_clip,
    trial_ground,
    validate_clip,
)
from sidql.keyframes import methods as keyframe_methods
from sidql.keyframes.counts import check_counts
from sidql.keyframes.spherical import POINTS, protocol_indices
from sim.batch import run_batch
from sim.errors import AllFailedError, MotionDataError, UsageError, require_type
from sim.motion.clip import Clip
from sim.motion.ingest import load_motion
from sim.motion.trial import is_bvh, subject_model
from sim.replay.checks import from_clip
from sim.replay.render import DEFAULT_STYLE, RenderStyle
from sim.simulate.validate import DEFAULT_TERRAIN, forward_validation, validation_model


def report_clips(
    clips: list[Clip],
    out_dir: str | os.PathLike,
    *,
    W: int,
    methods,
    seed: int = 0,
    joint_ranges: dict | None = None,
    videos: bool = True,
    style: RenderStyle = DEFAULT_STYLE,
    title: str = "Replay checks",
    meta: dict | None = None,
    progress: bool = True,
    clip_numbers=None,
    streams: tuple[DecodedStream, ...] = (),
    model=None,
    ground=None,
    contacts=None,
    workers: int = 1,
    ray: str | None = None,
    simulate=None,
    reconstruction: str | None = None,
    scene_body=None,
) -> Path:
    """Validate every clip in ``clips`` with every method (and decoded ``streams``) and write the
    report; returns ``out_dir/index.html``. ``clip_numbers``: the clips' numbers in their trial, for
    labels and file names (default 0, 1, ...). With ``model`` (the subject's humanoid) every motion
    also gets the :mod:`sim.physics` figures, on ``ground`` (default: estimated per clip) with the
    original's ``contacts`` labelled over the trial (:func:`trial_contacts_by_clip`), and with
    ``simulate`` (a :class:`sim.simulate.validate.ForwardValidation`) the forward simulation's. Clips are
    validated through ``sim.batch.run_batch`` (``workers`` processes or Ray); a clip that fails is
    listed in the report's ``failed`` field. ``reconstruction``: every method's keyframes rebuilt
    with it alone (default: Hermite, and the method's own where it differs). ``scene_body``:
    without ``simulate``, the body whose soles find each clip's scene (drawn only:
    :func:`sidql.evaluation.validation.clip_scene`).

    Raises:
        UnknownNameError: an unknown method. UsageError: W out of range for a clip (both before
            any clip is validated).
    """
    methods = list(methods)
    for name in methods:
        keyframe_methods.get(keyframe_methods.current_name(name))
    for clip in clips:
        check_counts([W], require_type(clip, Clip, "clip").n_frames)
    numbers = list(range(len(clips)) if clip_numbers is None else clip_numbers)
    job = physics_job(model, clips[0]) if model is not None and clips else None
    validate = partial(
        validate_clip, methods=list(methods), W=W, seed=seed, joint_ranges=joint_ranges,
        streams=streams, physics=job, ground=ground, contacts=contacts,
        simulate=simulate if job else None, reconstruction=reconstruction, scene_body=scene_body,
    )  # fmt: skip
    outcomes = run_batch(
        validate, clips, workers=workers, ray=ray, desc="replay", progress=progress
    )
    vals = [o.result for o in outcomes if o.ok]
    kept = [n for n, o in zip(numbers, outcomes, strict=True) if o.ok]
    failed = [f"clip {n}: {o.error}" for n, o in zip(numbers, outcomes, strict=True) if not o.ok]
    if not vals:
        kind = AllFailedError if all(o.bad_input for o in outcomes) else RuntimeError  # a bug
        raise kind("every clip failed: " + "; ".join(failed))
    shown = [*methods, *(s.label for s in streams)]
    meta = {"keyframes": W, "methods": " ".join(shown), "seed": seed, **(meta or {})}
    if failed:
        meta["failed"] = "; ".join(failed)
    return write_report(
        vals, out_dir, title=title, meta=meta, videos=videos, style=style, progress=progress,
        clip_numbers=kept,
    )  # fmt: skip


def report_trial(
    asf: str | os.PathLike,
    amc: str | os.PathLike | None,
    out_dir: str | os.PathLike,
    *,
    W: int,
    methods,
    clips=(0,),
    seed: int = 0,
    videos: bool = True,
    style: RenderStyle = DEFAULT_STYLE,
    progress: bool = True,
    streams=(),
    workers: int = 1,
    ray: str | None = None,
    simulate: bool = False,
    reconstruction: str | None = None,
    terrain: bool = DEFAULT_TERRAIN,
) -> Path:
    """Ingest a CMU trial, cut it into 60-frame clips at 30 fps and report the clips numbered
    ``clips`` (see :func:`report_clips`); joint limits come from the subject's humanoid.
    ``streams``: paths of ``.sidq`` files encoded from this trial, reported beside the methods.
    ``simulate``: also track every motion in forward simulation (the subject's torque-limited
    body, no assistance: :mod:`sim.simulate.validate`), in the scene inferred from each clip's
    original motion unless ``terrain`` is False (the empty floor). Every video and filmstrip
    draws that scene (none on the empty floor); without ``simulate`` too, inferred alike from the
    original (unless ``terrain`` is False). ``reconstruction``: every method's
    keyframes rebuilt with it (:func:`report_clips`). A BVH file stands for both ``asf`` and
    ``amc`` (``amc`` None)."""
    amc = asf if amc is None and is_bvh(asf) else amc
    decoded = tuple(load_stream(p, asf) for p in streams)
    motion = load_motion(asf, amc, fps=30.0)
    for path, d in zip(streams, decoded, strict=True):
        # the skeleton check passes any trial of the subject: the stream must span this trial
        rec = d.motion
        if abs(rec.fps - motion.fps) > 1e-9 or rec.n_frames != motion.n_frames:
            raise MotionDataError(
                str(path), None, f"stream has {rec.n_frames} frames at {rec.fps:g} fps; "
                f"{Path(amc).name} has {motion.n_frames} at {motion.fps:g} fps (encoded from "
                "another trial or rate?)",
            )  # fmt: skip
    all_clips = motion.split(60)
    if not all_clips:
        raise MotionDataError(str(amc), None, "trial is shorter than one 60-frame clip")
    protocol_indices(all_clips[0])  # a skeleton without the protocol's bones: one clean error
    bad = [c for c in clips if not 0 <= c < len(all_clips)]
    if bad:
        raise UsageError(f"clip numbers {bad} out of range: the trial has {len(all_clips)} clips")
    skeleton, model = subject_model(asf)
    ground = trial_ground(all_clips)
    forward = scene_body = None
    if simulate:
        names = from_clip(all_clips[0]).restrict(POINTS).names
        forward = forward_validation(skeleton, names, terrain=terrain)
    elif terrain:  # the scene is the original's alone: drawn without a simulation too
        scene_body = validation_model(skeleton)
    return report_clips(
        [all_clips[c] for c in clips], out_dir, W=W, methods=methods, seed=seed,
        joint_ranges=joint_ranges(model), videos=videos, style=style,
        title=f"Replay checks: {Path(amc).stem}",
        meta={"asf": str(asf), "amc": str(amc), "clips": " ".join(map(str, clips))},
        progress=progress, clip_numbers=list(clips), streams=decoded, model=model,
        ground=ground, contacts=trial_contacts_by_clip(all_clips, ground), workers=workers,
        ray=ray, simulate=forward, reconstruction=reconstruction, scene_body=scene_body,
    )  # fmt: skip
