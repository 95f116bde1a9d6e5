"""The validation report: every method's reconstruction replayed, measured, rendered, on one page.

:func:`validate_clip` chooses keyframes with each method, reconstructs, replays the original and
every reconstruction (:mod:`sim.replay.checks`) and returns JSON-ready figures with each method's excess
over the original. :func:`write_report` renders the videos and keyframe filmstrips
(:mod:`sim.replay.render`), plots every per-frame metric for all methods on one shared axis each, and
writes ``index.html`` (one self-contained page: images and videos embedded as base64, copies beside
it), the ``.mp4`` and ``.png`` files and ``checks.json`` atomically.

The page is driven by :data:`METRICS`, a declarative list (key, label, unit, which way is better,
description, per-frame series): the table's columns, the best value per column, the plots and the
legend all come from it, so a new figure in the summaries is one line there. Clips are labelled by
their real numbers in the trial, frames are numbered from 0 everywhere, every video's poster is its
worst-error frame, and one control plays, pauses and seeks all videos of a clip together.

Units in the figures: millimetres (``*_mm``), millimetres per second (``*_mm_s``), degrees
(``*_deg``), frame counts.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from PIL import Image
from tqdm import tqdm

from sidql.codec.decode import decode_to_reconstruction
from sidql.codec.format import read as read_stream
from sidql.codec.skeleton import skeleton_hash
from sidql.keyframes import reconstructions
from sidql.keyframes.methods import reconstruction_of, select
from sidql.keyframes.reconstructions import Reconstruction
from sidql.keyframes.spherical import POINTS, protocol_indices
from sim.batch import run_batch
from sim.errors import MotionDataError
from sim.files import write_atomic
from sim.model.humanoid import subject_model
from sim.motion.clip import Clip
from sim.motion.ingest import load_motion
from sim.physics.analysis import HEIGHT_KEYS, PhysicsJob
from sim.physics.contacts import foot_states, trial_contacts
from sim.physics.ground import Ground, estimate_ground
from sim.physics.noise import NOISE_MM
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
from sim.replay.foot_state import FootState
from sim.replay.render import (
    DEFAULT_STYLE,
    RenderStyle,
    SkeletonRenderer,
    keyframe_sheet,
    render_frames,
    write_video,
)
from sim.simulate.model import sim_model
from sim.simulate.validate import ForwardValidation


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
        return (
            self.method
            if self.reconstruction == "hermite"
            else f"{self.method}+{self.reconstruction}"
        )


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

    @property
    def noise_floor(self) -> dict:
        """Per figure, how far the original re-captured with marker noise
        (:meth:`sim.physics.analysis.PhysicsJob.noise_floor`) departs from the original: a
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
            raise ValueError(
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
) -> ClipValidation:
    """Keyframes by every method, reconstruction, replay and figures for one clip.

    Args:
        clip: the original (T frames, any CMU point set containing the 23 protocol points).
        methods: names registered in :mod:`sidql.keyframes.methods`.
        W: keyframes per clip, both ends included.
        joint_ranges: hinge ranges [rad] for the joint-limit check of motions with joint angles.
        streams: decoded ``.sidq`` streams of the clip's trial, shown after the methods.
        physics: a :class:`sim.physics.analysis.PhysicsJob` on the protocol points: adds
            :mod:`sim.physics` figures (``physics``) for the original and every run.
        ground: the trial's :class:`sim.physics.ground.Ground`; its ``floor_z`` replaces
            ``floor_z`` (default: estimated from the clip when ``physics`` is given).
        simulate: a :class:`sim.simulate.validate.ForwardValidation` of the subject (with
            ``physics``): the human-strength body tracks the IK fit of the original and of every
            run in ``mj_step`` without assistance; its figures join ``physics``.
        contacts: the original's foot contacts labelled over the whole trial, by the clip's
            ``start_frame`` (:func:`trial_contacts`); default: labelled on the clip.
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

    def analyse(rec, acc=None):  # a reconstruction's physics: its points and curve's derivatives
        r = rec.restrict(orig.names)
        ix = [rec.names.index(n) for n in orig.names]
        acc = getattr(rec, "accelerations", None) if acc is None else acc
        figures = physics.analyse(
            clip, r.positions, ground, contacts=trial_labels,
            velocities=None if acc is None else np.asarray(rec.velocity())[:, ix],
            accelerations=None if acc is None else np.asarray(acc)[:, ix],
        )  # fmt: skip
        if simulate is not None:  # the forward simulation's figures join the physics
            original_qpos = out.physics["per_frame"]["qpos"]
            figures.update(simulate.run(figures["per_frame"]["qpos"], clip.fps, original_qpos))
        return figures

    if physics is not None:
        out.physics = physics.analyse(clip, None, ground, contacts=trial_labels)
        out.noise = physics.noise_floor(clip, ground, contacts=trial_labels, seed=seed)
        if simulate is not None:
            out.physics.update(simulate.run(out.physics["per_frame"]["qpos"], clip.fps))
    for m in methods:
        keys = np.asarray(select(m, clip, W, seed=seed))
        own = reconstruction_of(m)  # every method under Hermite, and under its own if other
        shown = any(
            r.reconstruction == "hermite" and np.array_equal(r.keyframes, keys) for r in out.runs
        )
        hermite = [] if own != "hermite" and shown else ["hermite"]  # e.g. xyz's = uniform's
        for name in hermite + ([own] if own != "hermite" else []):
            built = reconstructions.rebuild(name, clip, keys)
            rec = from_reconstruction(built, clip.fps)
            checks = replay(rec, full, **kw)
            s = summarise(checks)
            run = MethodRun(m, name, keys, rec, checks, s, excess(s, out.baseline))
            if physics is not None:
                run.physics = analyse(built)
            out.runs.append(run)
    for stream in streams:
        keys, rec = stream.clip_part(clip)
        checks = replay(rec, full, **kw)
        s = summarise(checks)
        run = MethodRun(
            stream.label,
            stream.motion.reconstruction,
            keys,
            rec,
            checks,
            s,
            excess(s, out.baseline),
        )
        if physics is not None:
            run.physics = analyse(rec, stream.accelerations(clip))
        out.runs.append(run)
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


def _physics_entry(physics: dict) -> dict:
    """``physics`` (the :mod:`sim.physics` figures) and ``physics_per_frame`` of a checks.json row."""
    if not physics:
        return {}
    return {
        "physics": {k: v for k, v in physics.items() if k != "per_frame"},
        "physics_per_frame": physics["per_frame"],
    }


def _slug(s: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in s)


@dataclass(frozen=True)
class Metric:
    """One figure of the page: a table column, a legend line and (with ``per_frame``) a plot.

    Attributes:
        key: key in the summaries (``MethodRun.summary``/``excess``, ``ClipValidation.baseline``).
        label: column heading; unit: shown beside it (``""`` for counts and ratios).
        better: ``"lower"``, ``"higher"``, ``"zero"`` (closest to 0 is best: an excess over the
            original either way), ``"original"`` (closest to the original's own value is best) or
            ``""`` (not ranked).
        description: one sentence for the legend.
        fmt: Python format of a value; ``excess``: method rows show ``MethodRun.excess[key]``.
        per_frame: key of the :func:`per_frame` array plotted per frame, if any.
        resolution: differences below this are ties when choosing the best (e.g. bone drift of
            1e-13 mm is rounding, not a better method); 0: compare as shown.
        group: which table of the clip shows it (:data:`GROUPS`).
        superseded_by: a :mod:`sim.physics` key that measures the same thing better (calibrated
            ground, contact labels, per-pair excess); where rows carry it, this metric is left
            out of the page (it stays in ``checks.json``).
    """

    key: str
    label: str
    unit: str
    better: str
    description: str
    fmt: str = "{:.1f}"
    excess: bool = False
    per_frame: str | None = None
    resolution: float = 0.0
    group: str = "accuracy"
    superseded_by: str | None = None


#: Every figure the page knows, in column order. Keys absent from a run show ``n/a``; keys absent
#: from every row of a clip are left out of its table and plots (the legend still lists them).
METRICS: tuple[Metric, ...] = (
    Metric("mpjpe_mm", "MPJPE", "mm", "lower",
           "mean distance of the reconstruction's points from the original's", "{:.1f}",
           per_frame="mpjpe_mm"),
    Metric("velocity_error_mm_s", "velocity error", "mm/s", "lower",
           "mean |v - v_original| over points", "{:.0f}", per_frame="velocity_error_mm_s"),
    Metric("bone_drift_max_mm", "bone drift", "mm", "lower",
           "largest change of a bone's length against the original", "{:.2g}",
           resolution=0.01),
    Metric("floor_depth_max_mm", "floor depth", "mm", "zero",
           "deepest capsule below the floor z = 0; methods: excess over the original", "{:+.1f}",
           excess=True, per_frame="floor_depth_mm", superseded_by="penetration_mm"),
    Metric("floor_frames", "floor frames", "", "zero",
           "frames with a capsule > 1 mm below the floor; methods: excess over the original",
           "{:+d}", excess=True, superseded_by="penetration_mm"),
    Metric("self_pen_frames", "self-pen. frames", "", "zero",
           "frames where non-adjacent bones overlap; methods: excess over the original", "{:+d}",
           excess=True, superseded_by="self_pen_excess_mm"),
    Metric("self_pen_depth_max_mm", "self-pen. depth", "mm", "zero",
           "deepest overlap of non-adjacent bones; methods: excess over the original", "{:+.1f}",
           excess=True, per_frame="self_pen_depth_mm", superseded_by="self_pen_excess_mm"),
    Metric("skate_mean_mm_s", "skate", "mm/s", "zero",
           "mean horizontal foot speed while a foot touches the floor; methods: excess over the "
           "original", "{:+.0f}", excess=True, per_frame="skate_speed_mm_s", superseded_by="skate_mm_s"),
    Metric("joint_limit_max_deg", "joint limit", "deg", "zero",
           "largest hinge angle past its ASF limit (needs joint angles); methods: excess",
           "{:+.1f}", excess=True, superseded_by="limit_excess_deg"),
    # physics: filled by sim.physics where it runs
    Metric("penetration_mm", "penetration", "mm", "lower",
           "mean depth of a foot's lowest sole point below the floor", "{:.1f}", group="contacts"),
    Metric("float_mm", "float", "mm", "lower",
           "mean height of a foot's lowest sole point while the original's foot is in contact",
           "{:.1f}", group="contacts"),
    Metric("skate_mm_s", "skate (contact)", "mm/s", "lower",
           "mean horizontal speed of a foot's lowest sole point while the original's foot is in "
           "contact", "{:.0f}", group="contacts"),
    Metric("contact_precision", "contact precision", "", "higher",
           "share of the reconstruction's contacts that the original also has", "{:.2f}", group="contacts"),
    Metric("contact_recall", "contact recall", "", "higher",
           "share of the original's contacts that the reconstruction keeps", "{:.2f}", group="contacts"),
    Metric("physdiff_penetrate_mm", "PhysDiff penetrate", "mm", "lower",
           "PhysDiff (Yuan et al. 2023): mean depth of the body surface's lowest point below the "
           "floor", "{:.1f}", group="contacts"),
    Metric("physdiff_float_mm", "PhysDiff float", "mm", "lower",
           "PhysDiff: mean height of the body surface's lowest point above the floor, beyond 5 mm",
           "{:.1f}", group="contacts"),
    Metric("physdiff_skate", "PhysDiff skate", "", "lower",
           "PhysDiff-style skate: share of frames in which a foot in contact in it and the "
           "previous frame moves more than 2.5 cm horizontally", "{:.2f}", group="contacts"),
    Metric("self_pen_excess_mm", "self-pen. excess", "mm", "lower",
           "mean per-pair overlap beyond the original's in the same frame", "{:.1f}", group="contacts"),
    Metric("lost_contacts", "lost contacts", "", "lower",
           "touching bone pairs of the original that the reconstruction separates", "{:d}", group="contacts"),
    Metric("limit_excess_deg", "limit excess", "deg", "lower",
           "worst anatomical hinge angle of the fitted humanoid past its ASF limit", "{:.1f}",
           group="contacts"),
    Metric("residual_force_bw", "residual force", "BW", "lower",
           "mean external force no ground contact can supply (force alone), in body weights",
           "{:.2f}", group="dynamics"),
    Metric("residual_force_bw_p95", "residual force p95", "BW", "lower",
           "95th percentile of the residual force, in body weights", "{:.2f}", group="dynamics"),
    Metric("residual_torque_nm_kg", "residual torque", "N m/kg", "lower",
           "mean torque about the centre of mass that the ground forces supplying the force "
           "leave, per kg of body mass", "{:.2f}", group="dynamics"),
    Metric("joint_torque_rms_nm_kg", "joint torque RMS", "N m/kg", "original",
           "RMS joint torque per kg from inverse dynamics; closest to the original's is best "
           "(over-smoothed motion needs less than the original, not better)", "{:.2f}",
           group="dynamics"),
    # forward simulation (report --simulate): filled by sim.simulate.validate
    Metric("sim_error_mm", "sim. error", "mm", "lower",
           "mean distance of the simulated body's points from the motion it tracked", "{:.0f}",
           group="simulation"),
    Metric("sim_error_original_mm", "sim. error vs original", "mm", "lower",
           "mean distance of the simulated body's points from the original motion", "{:.0f}",
           group="simulation"),
    Metric("sim_fell", "fell", "", "lower",
           "1 if the simulated body fell (root below half its reference height)", "{:d}",
           group="simulation"),
    Metric("sim_fall_s", "fall time", "s", "higher",
           "when the simulated body fell (n/a: it did not)", "{:.2f}", group="simulation"),
    Metric("sim_torque_rms_nm_kg", "sim. joint torque RMS", "N m/kg", "lower",
           "RMS joint torque the simulated body applied, per kg", "{:.2f}", group="simulation"),
    Metric("sim_torque_saturated", "torque at limit", "", "lower",
           "share of joint-torque samples at the joint's human limit", "{:.3f}",
           group="simulation"),
)  # fmt: skip

#: The clip's tables, in order: (group, heading).
GROUPS = (
    ("accuracy", "Accuracy and geometry"),
    (
        "contacts",
        "Contacts, penetration and joint limits (sim.physics; against the original's contacts)",
    ),
    (
        "dynamics",
        "Dynamics: forces the motion needs (sim.physics; inverse dynamics on the fitted humanoid)",
    ),
    (
        "simulation",
        "Forward simulation: could a body perform it? The human-strength body tracks each fitted "
        "motion in mj_step with no assistance (sim.simulate)",
    ),
)

_BETTER = {"lower": "lower is better", "higher": "higher is better",
           "zero": "closest to 0 (the original) is best",
           "original": "closest to the original's value is best", "": "not ranked"}  # fmt: skip
_ARROW = {"lower": "\u2193", "higher": "\u2191", "zero": "\u21950", "original": "\u2248o", "": ""}
#: Method colours shared by plots, table swatches and video cards.
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf",
           "#bcbd22", "#ff7f0e", "#7f7f7f")  # fmt: skip


def _number(value):
    """A finite float, or ``None`` (absent, ``None`` or NaN)."""
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(x) else x


def metric_value(m: Metric, summary: dict, excess: dict | None = None):
    """The value a table cell shows: ``excess[key]`` for an excess metric of a method row (when
    present), else ``summary[key]``; ``None`` when absent or NaN."""
    if m.excess and excess is not None and m.key in excess:
        return _number(excess[m.key])
    return _number(summary.get(m.key))


def _cell(fmt: str, value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if "d}" in fmt:
        value = int(round(value))
    return fmt.format(value)


def best_rows(m: Metric, values, *, original=None, noise: float = 0.0) -> set[int]:
    """Indices of the best of ``values`` (``None`` skipped) by ``m.better``, compared as shown
    (formatted); empty when not ranked, fewer than two values, or all show the same.

    ``original``: the original's value (``better == "original"`` scores ``|v - original|``).
    ``noise``: the figure's noise floor (how far capture noise alone moves it): values within it
    of the best tie with it, and none is marked unless some value is worse than the best by more
    than the noise floor (a noise-level difference is no difference)."""
    shown = [(i, v) for i, v in enumerate(values) if v is not None]
    if not m.better or len(shown) < 2 or (m.better == "original" and original is None):
        return set()
    score = {
        "lower": lambda v: v, "higher": lambda v: -v, "zero": abs,
        "original": lambda v: abs(v - original),
    }[m.better]  # fmt: skip
    if m.resolution > 0:
        text = {i: str(round(score(v) / m.resolution)) for i, v in shown}
    else:
        text = {i: _cell(m.fmt.replace("+", ""), abs(score(v))) for i, v in shown}
    if len(set(text.values())) == 1:
        return set()
    top = min(score(v) for _, v in shown)
    if noise > 0:
        if max(score(v) for _, v in shown) - top <= noise:
            return set()
        return {i for i, v in shown if score(v) - top <= noise}
    best = next(text[i] for i, v in shown if score(v) == top)
    return {i for i, _ in shown if text[i] == best}


def _best(v: ClipValidation, m: Metric, values) -> set[int]:
    """:func:`best_rows` of one clip's column, against the original's value and beyond the
    figure's noise floor on that clip."""
    return best_rows(
        m, values, original=metric_value(m, v.baseline_figures),
        noise=v.noise_floor.get(m.key, 0.0) if not m.excess else 0.0,
    )  # fmt: skip


def shown_metrics(v: ClipValidation) -> list[Metric]:
    """The metrics with a value in at least one row of the clip, less those a :mod:`sim.physics`
    metric supersedes where the rows carry it (even as n/a: heights above a floor that does not
    fit are not scored, nor are the older checks' against it)."""
    rows = [(v.baseline_figures, None)] + [(r.figures, r.excess) for r in v.runs]
    present = [m for m in METRICS if any(metric_value(m, s, e) is not None for s, e in rows)]
    carried = {k for s, _ in rows for k in s}
    return [m for m in present if m.superseded_by not in carried]


def _tables(v: ClipValidation, colours) -> str:
    """One table per metric group (:data:`GROUPS`) that has a shown metric."""
    shown = shown_metrics(v)
    out = []
    for group, heading in GROUPS:
        ms = [m for m in shown if m.group == group]
        if ms:
            out.append(f"<h3>{html.escape(heading)}</h3>" + _table(v, colours, ms))
    return "".join(out) + (
        "<p class='note'>Green cell: the best method in that column; methods within the column's "
        "noise floor of the best are marked with it, and none is marked when all methods lie "
        "within the noise floor of each other (or show the same). Original row: its own figures; "
        "noise-floor row: how far each figure moves when the original is captured again with "
        f"{NOISE_MM:g} mm of marker noise. Method rows: MPJPE, velocity error and bone drift "
        "against the original, columns marked \u21950 the excess over the original (0 = as the "
        "original), \u2248o closest to the original's own value.</p>"
    )


def _table(v: ClipValidation, colours, ms: list[Metric]) -> str:
    head = "".join(
        f"<th title='{html.escape(m.description)} ({_BETTER[m.better]})'>{html.escape(m.label)}"
        f"{'<br><small>' + html.escape(m.unit) + '</small>' if m.unit else ''}"
        f"<span class='dir'>{_ARROW[m.better]}</span></th>"
        for m in ms
    )
    vals = {m.key: [metric_value(m, r.figures, r.excess) for r in v.runs] for m in ms}
    nf = v.noise_floor
    best = {m.key: _best(v, m, vals[m.key]) for m in ms}
    base = "".join(
        f"<td>{html.escape(_cell(m.fmt.replace('+', ''), metric_value(m, v.baseline_figures)))}</td>"
        for m in ms
    )
    rows = [f"<tr class='orig'><td>original (baseline)</td><td>-</td>{base}</tr>"]
    if any(nf.get(m.key) is not None for m in ms):
        noise = "".join(
            f"<td>{html.escape(_cell(m.fmt.replace('+', ''), nf.get(m.key)))}</td>" for m in ms
        )
        rows.append(
            f"<tr class='noise'><td>noise floor</td><td class='k'>original + {NOISE_MM:g} mm "
            f"noise</td>{noise}</tr>"
        )
    for i, (r, colour) in enumerate(zip(v.runs, colours, strict=True)):
        cells = "".join(
            f"<td{' class=best' if i in best[m.key] else ''}>"
            f"{html.escape(_cell(m.fmt, vals[m.key][i]))}</td>"
            for m in ms
        )
        keys = " ".join(str(int(k)) for k in r.keyframes)
        rows.append(
            f"<tr><td><span class='sw' style='background:{colour}'></span>{html.escape(r.label)}"
            f"</td><td class='k'>{keys}</td>{cells}</tr>"
        )
    return (
        f"<table class='metrics'><tr><th>method</th><th>keyframes (frame numbers from 0)</th>{head}"
        f"</tr>{''.join(rows)}</table>"
    )


def legend_html(metrics=METRICS, *, full: bool = False) -> str:
    """A short legend of ``metrics``: label, unit, which way is better, what it means. ``full``: a
    closed ``<details>`` listing every declared metric instead."""
    items = "".join(
        f"<div><b>{html.escape(m.label)}</b>{' [' + html.escape(m.unit) + ']' if m.unit else ''} "
        f"<span class='dir'>{_ARROW[m.better]} {_BETTER[m.better]}</span>: "
        f"{html.escape(m.description)}</div>"
        for m in metrics
    )
    if full:
        return (
            "<details class='legend'><summary>Every metric the page knows (those a run did not "
            f"measure are left out of its table; n/a where only some rows have them)</summary>"
            f"<div class='legend'>{items}</div></details>"
        )
    return f"<div class='legend'>{items}</div>"


VIDEO_LEGEND = (
    "<p class='note'><b>Videos and filmstrips:</b> the original in blue; the reconstruction as a "
    "thinner orange ghost, so orange shows only where it departs from the original; "
    "<b style='color:#009e8f'>teal</b> foot and footprint: the original's foot is on the ground; "
    "a ball on the reconstruction's foot: <b style='color:#2673ff'>blue</b> floats above the "
    "ground while the original stands, <b style='color:#e01a1a'>red</b> sinks below it, "
    "<b style='color:#d926d9'>magenta</b> skates (slides while the original stands). Each poster "
    "is the method's worst frame; the bar above the videos plays, pauses and seeks them all "
    "together (click a video, or use the arrows to step). Frames are numbered from 0 "
    "everywhere.</p>"
)


def summary_plot(v: ClipValidation, colours) -> bytes | None:
    """PNG: one small panel per ranked metric of the table, a bar per method on the panel's one
    scale, the original's own value as a dashed line (for excess metrics the bars are the excess
    over it, so the line is at 0). Metrics on which every method shows the same (within the
    metric's resolution) get no panel. ``None`` when nothing is left."""
    import matplotlib  # lazy: a heavy optional plotting dependency, only for the figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy, after choosing the headless backend

    ms = [m for m in shown_metrics(v) if m.better]

    def informative(m):  # some value, and not every method showing the same one
        vals = [metric_value(m, r.figures, r.excess) for r in v.runs]
        shown = [x for x in vals if x is not None]
        return bool(shown) and (len(shown) < 2 or bool(best_rows(m, vals)))

    ms = [m for m in ms if informative(m)]
    if not ms:
        return None
    cols = min(len(ms), 5)
    rows = -(-len(ms) // cols)
    n = len(v.runs)
    fig, axes = plt.subplots(
        rows, cols, figsize=(2.2 * cols, 0.45 + 0.22 * n * rows + 0.7 * rows), dpi=100,
        squeeze=False,
    )  # fmt: skip
    y = np.arange(n)
    for ax, m in zip(axes.flat, ms, strict=False):
        vals = [metric_value(m, r.figures, r.excess) for r in v.runs]
        best = _best(v, m, vals)
        x = [0.0 if a is None else a for a in vals]
        ax.barh(y, x, color=colours, height=0.7)
        for i, a in enumerate(vals):
            if a is None:
                ax.text(0, i, " n/a", va="center", fontsize=7, color="#666")
            elif i in best:
                ax.text(a, i, " \u2605", va="center", fontsize=8, color="#1a7f37")
        ref = 0.0 if m.excess else metric_value(m, v.baseline_figures)
        if ref is not None and not (m.key in ("mpjpe_mm", "velocity_error_mm_s") and ref == 0):
            ax.axvline(ref, color="k", ls="--", lw=0.8)
        unit = f" [{m.unit}]" if m.unit else ""
        ax.set_title(f"{m.label}{unit} {_ARROW[m.better]}", fontsize=8)
        ax.set_yticks(y, [r.label for r in v.runs] if ax in axes[:, 0] else [], fontsize=7)
        ax.invert_yaxis()
        ax.tick_params(axis="x", labelsize=6)
        ax.grid(axis="x", alpha=0.3)
    for ax in list(axes.flat)[len(ms) :]:
        ax.axis("off")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def metrics_plot(v: ClipValidation, colours) -> bytes | None:
    """PNG: one panel per per-frame metric, every method on the panel's one y scale, the original
    dotted, each method's keyframes as ticks in its colour under the axis. ``None`` when no
    per-frame metric is available."""
    import matplotlib  # lazy: a heavy optional plotting dependency, only for the figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy, after choosing the headless backend

    series = [m for m in shown_metrics(v) if m.per_frame]
    frames = {id(r): per_frame(r.checks) for r in v.runs}
    base = per_frame(v.baseline_checks)
    series = [m for m in series if m.per_frame in base]
    if not series:
        return None
    T = v.clip.n_frames
    t = np.arange(T)
    cols = 2
    rows = -(-len(series) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(11, 2.6 * rows), dpi=100, squeeze=False)
    n = len(v.runs)
    for ax, m in zip(axes.flat, series, strict=False):
        top = 0.0
        if m.key != "mpjpe_mm" and m.key != "velocity_error_mm_s":
            y0 = np.asarray(base[m.per_frame], dtype=float)
            if np.any(y0):
                ax.plot(t, y0, color="k", ls=":", lw=1.2, label="original")
                top = max(top, float(np.nanmax(y0)))
        for r, colour in zip(v.runs, colours, strict=True):
            y = np.asarray(frames[id(r)][m.per_frame], dtype=float)
            ax.plot(t, y, color=colour, lw=1.4, label=r.label)
            top = max(top, float(np.nanmax(y)) if y.size else 0.0)
        top = top if top > 0 else 1.0
        for i, (r, colour) in enumerate(zip(v.runs, colours, strict=True)):
            yk = -top * (0.06 + 0.05 * i)
            ax.plot(r.keyframes, np.full(len(r.keyframes), yk), "|", color=colour, ms=6, mew=1.5)
        ax.set_ylim(-top * (0.08 + 0.05 * n), top * 1.08)
        ax.set_yticks([y for y in ax.get_yticks() if 0 <= y <= top * 1.08])
        unit = f" [{m.unit}]" if m.unit else ""
        ax.set_title(f"{m.label}{unit}  ({_BETTER[m.better]})", fontsize=9)
        ax.set_xlim(0, T - 1)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("frame (from 0); ticks below: each method's keyframes", fontsize=7)
    for ax in list(axes.flat)[len(series) :]:
        ax.axis("off")
    h, lab = axes.flat[0].get_legend_handles_labels()
    for ax in axes.flat[1 : len(series)]:
        for hh, ll in zip(*ax.get_legend_handles_labels(), strict=True):
            if ll not in lab:
                h.append(hh)
                lab.append(ll)
    fig.legend(h, lab, loc="upper center", ncol=min(len(lab), 8), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / (2.6 * rows)))
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


_CSS = """
body{font-family:system-ui,sans-serif;margin:20px auto;color:#222;max-width:1400px;padding:0 16px}
h1{margin-bottom:4px}h2{margin-top:28px;border-bottom:2px solid #ddd;padding-bottom:4px}
table{border-collapse:collapse;font-size:13px;margin:8px 0}
td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}
th{background:#f4f5f7;font-weight:600;vertical-align:bottom}
th small{font-weight:normal;color:#666}
th .dir{display:block;color:#888;font-weight:normal}
td:first-child,th:first-child{text-align:left;white-space:nowrap}
td.k{font-family:monospace;font-size:11px;text-align:left}
td.best{background:#c9efcf;font-weight:700}
tr.orig{background:#eef}
tr.noise{background:#f7f7f7;color:#666;font-style:italic}
details.legend{margin:18px 0 4px 0;font-size:13px}
details.legend summary{cursor:pointer;font-weight:600}
.note{font-size:12px;color:#555;max-width:1100px}
.sw{display:inline-block;width:10px;height:10px;border-radius:2px;margin-right:6px}
.player{position:sticky;top:0;z-index:2;background:#fafbfc;border:1px solid #ddd;
  padding:6px 10px;margin:10px 0;display:flex;gap:10px;align-items:center;font-size:14px}
.player input[type=range]{flex:1}
.player button{font-size:14px;min-width:2.6em}
.player .frame{font-variant-numeric:tabular-nums;min-width:8.5em}
.videos{display:grid;grid-template-columns:repeat(auto-fill,minmax(440px,1fr));gap:10px}
.card{border:1px solid #ddd;border-top:4px solid var(--c);padding:6px;background:#fff}
.card h3{margin:2px 0 4px 0;font-size:15px}
.card video{width:100%;height:auto;display:block;cursor:pointer;background:#dde3ea}
.card .note a{cursor:pointer}
img.plot,img.sheet{display:block;max-width:100%;margin:6px 0}
div.legend{columns:2;column-gap:24px;font-size:12px;color:#333;max-width:1300px;margin:6px 0}
div.legend div{break-inside:avoid;margin:2px 0}
div.legend .dir{color:#777}
.sheetcap{font-weight:600;margin:12px 0 0 0;font-size:14px}
"""

#: One control per clip plays, pauses and seeks all its videos together; the first video is the
#: clock, the others are pulled to it whenever they drift by half a frame.
_JS = """
function syncPlayer(root){
  const vids=[...root.querySelectorAll('video')]; if(!vids.length) return;
  const fps=+root.dataset.fps, n=+root.dataset.frames, clock=vids[0];
  const btn=root.querySelector('.play'), seek=root.querySelector('.seek'),
        out=root.querySelector('.frame');
  let playing=false;
  const frameOf=t=>Math.max(0,Math.min(n-1,Math.floor(t*fps+1e-6)));
  const show=()=>{const f=frameOf(clock.currentTime); seek.value=f;
    out.textContent='frame '+f+' of 0-'+(n-1);};
  const align=()=>{const t=clock.currentTime;
    for(const v of vids) if(v!==clock && Math.abs(v.currentTime-t)>0.5/fps) v.currentTime=t;};
  function tick(){ if(!playing) return; align(); show(); requestAnimationFrame(tick); }
  function play(){ const t=clock.currentTime; for(const v of vids){v.currentTime=t;}
    Promise.all(vids.map(v=>v.play())).catch(()=>{}); playing=true; btn.textContent='\\u23f8';
    requestAnimationFrame(tick); }
  function pause(){ for(const v of vids) v.pause(); playing=false; align(); show();
    btn.textContent='\\u25b6'; }
  function goto(f){ pause(); f=Math.max(0,Math.min(n-1,f));
    for(const v of vids) v.currentTime=(f+0.5)/fps; seek.value=f;
    out.textContent='frame '+f+' of 0-'+(n-1); }
  root.syncPlay=play; root.syncPause=pause; root.syncGoto=goto;
  btn.addEventListener('click',()=>playing?pause():play());
  seek.addEventListener('input',()=>goto(+seek.value));
  root.querySelector('.prev').addEventListener('click',()=>goto(frameOf(clock.currentTime)-1));
  root.querySelector('.next').addEventListener('click',()=>goto(frameOf(clock.currentTime)+1));
  root.querySelector('.rate').addEventListener('change',e=>{
    for(const v of vids) v.playbackRate=+e.target.value;});
  for(const v of vids) v.addEventListener('click',()=>playing?pause():play());
  for(const a of root.querySelectorAll('[data-goto]'))
    a.addEventListener('click',e=>{e.preventDefault(); goto(+a.dataset.goto);});
  clock.addEventListener('timeupdate',show);
}
document.querySelectorAll('.clip').forEach(syncPlayer);
"""


def _player(T: int, fps: float) -> str:
    return (
        "<div class='player'><button class='play' title='play/pause all videos'>\u25b6</button>"
        "<button class='prev' title='previous frame'>\u25c0|</button>"
        "<button class='next' title='next frame'>|\u25b6</button>"
        f"<input class='seek' type='range' min='0' max='{T - 1}' value='0' step='1' "
        "title='seek all videos'>"
        f"<span class='frame'>frame 0 of 0-{T - 1}</span>"
        "<select class='rate' title='speed'><option value='0.25'>0.25x</option>"
        "<option value='0.5'>0.5x</option><option value='1' selected>1x</option></select>"
        "<span class='note'>one control for all videos of this clip</span></div>"
    )


def _jpeg(image: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="JPEG", quality=85)
    return buf.getvalue()


def floor_sentence(physics: dict) -> str:
    """One sentence on the trial's floor (:meth:`sim.physics.ground.Ground.summary` figures):
    where it is, its slope, how far the planted feet sit from it, and whether it fits."""
    sx, sy = physics.get("floor_slope", (0.0, 0.0))
    dev = physics.get("floor_deviation_mm")
    head = (
        f"Floor of the trial (sim.physics, fitted to {physics.get('floor_footprints', 0)} "
        f"footprints): z = {physics['floor_z_m']:.3f} m at its centre, slope "
        f"{1e3 * sx:+.1f}, {1e3 * sy:+.1f} mm/m"
    )
    if physics.get("floor_fits"):
        return f"{head}; the planted feet sit within {dev:.1f} mm of it."
    why = "no foot stands still long enough" if dev is None else f"they depart by {dev:.1f} mm"
    return (
        f"{head}. THE FLOOR DOES NOT FIT this trial ({why}: uneven ground, a drifting capture "
        "floor or support other than the floor): float and penetration are not scored (n/a)."
    )


def ground_and_feet(v: ClipValidation, run: MethodRun) -> tuple[float, FootState]:
    """Floor height [m] and foot states drawn for one method's video: the trial's ground
    (:mod:`sim.physics.ground`, from the clip when the report had no trial ground) and the
    contact labels and flags of :func:`sim.physics.contacts.foot_states`."""
    ground = v.ground or estimate_ground(v.clip.positions, v.clip.names, v.clip.fps)
    return ground.floor_z, foot_states(v.original, run.motion, ground)


def _data_uri(mime: str, data: bytes) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def write_report(
    validations: list[ClipValidation],
    out_dir: str | os.PathLike,
    *,
    title: str,
    meta: dict | None = None,
    videos: bool = True,
    style: RenderStyle = DEFAULT_STYLE,
    progress: bool = True,
    clip_numbers=None,
) -> Path:
    """Write ``index.html``, ``checks.json``, one ``.mp4`` and one keyframe filmstrip ``.png`` per
    clip and method, and one per-frame metrics plot per clip, into ``out_dir``; files are named
    ``clipNN_*`` by the clip's real number ``clip_numbers[i]`` (default 0, 1, ...). Returns the
    page's path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    numbers = list(range(len(validations)) if clip_numbers is None else clip_numbers)
    if len(numbers) != len(validations):
        raise ValueError(f"{len(numbers)} clip numbers for {len(validations)} clips")
    meta = dict(meta or {})
    doc = checks_document(validations, meta)
    for c, number in zip(doc["clips"], numbers, strict=True):
        c["clip"] = int(number)
    text = json.dumps(doc, indent=1)
    write_atomic(out / "checks.json", lambda f: f.write(text.encode()))

    parts = [f"<h1>{html.escape(title)}</h1>"]
    if meta:
        parts.append(
            "<p class='note'>"
            + "; ".join(f"{html.escape(str(k))}: {html.escape(str(v))}" for k, v in meta.items())
            + "</p>"
        )
    parts.append(VIDEO_LEGEND)
    jobs = [(ci, r) for ci, v in enumerate(validations) for r in v.runs]
    bar = tqdm(total=len(jobs), desc="report", unit="video", disable=not progress)
    stack = ExitStack()
    try:
        for number, v in zip(numbers, validations, strict=True):
            stack.close()  # the previous clip's renderer
            T = v.clip.n_frames
            start = v.clip.start_frame
            colours = [PALETTE[i % len(PALETTE)] for i in range(len(v.runs))]
            parts.append(
                f"<section class='clip' data-fps='{v.clip.fps:g}' data-frames='{T}'>"
                f"<h2>Clip {number}: {html.escape(Path(v.clip.source).name or 'synthetic')} from "
                f"source frame {start}, {T} frames (0-{T - 1}) at {v.clip.fps:g} fps, W = {v.W}</h2>"
            )
            if v.physics:
                parts.append(f"<p class='note'>{html.escape(floor_sentence(v.physics))}</p>")
            parts.append(_tables(v, colours))
            parts.append(legend_html(shown_metrics(v)))
            bars = summary_plot(v, colours)
            if bars is not None:
                write_atomic(out / f"clip{number:02d}_summary.png", lambda f, b=bars: f.write(b))
                parts.append(
                    "<h3>Per metric, every method on one scale (dashed: the original; \u2605 best)</h3>"
                    f"<img class='plot' alt='metrics per method' src='{_data_uri('image/png', bars)}'>"
                )
            cards, sheets = [], []
            # One MuJoCo renderer per clip for the videos, reused by every method (closed on error too).
            video_r = None
            if videos:
                ground = ground_and_feet(v, v.runs[0])[0] if v.runs else 0.0
                video_r = stack.enter_context(
                    SkeletonRenderer(v.original.names, v.original.parents, style, ground_z=ground)
                )
            for r, colour in zip(v.runs, colours, strict=True):
                stem = f"clip{number:02d}_{_slug(r.label)}"
                ground, feet = ground_and_feet(v, r)
                err = 1e3 * r.checks.mpjpe
                worst = int(np.argmax(err)) if err.size else 0
                card = [f"<div class='card' style='--c:{colour}'><h3>{html.escape(r.label)}</h3>"]
                if videos:
                    poster = {}

                    def keep(frames, poster=poster, worst=worst):
                        for t, f in enumerate(frames):
                            if t == worst:
                                poster["jpg"] = _jpeg(f)
                            yield f

                    mp4 = write_video(
                        keep(render_frames(
                            v.original, r.motion, keyframes=r.keyframes, method=r.label, style=style,
                            feet=feet, ground_z=ground, renderer=video_r,
                        )),
                        out / f"{stem}.mp4",
                        v.clip.fps,
                    )  # fmt: skip
                    write_atomic(out / f"{stem}_poster.jpg", lambda f, b=poster["jpg"]: f.write(b))
                    card.append(
                        f"<video loop muted playsinline preload='auto' width='{style.width}' "
                        f"height='{style.height}' data-file='{mp4.name}' data-worst='{worst}' "
                        f"poster='{_data_uri('image/jpeg', poster['jpg'])}' "
                        f"src='{_data_uri('video/mp4', mp4.read_bytes())}'></video>"
                    )
                card.append(
                    f"<p class='note'>mean MPJPE {float(err.mean()):.1f} mm; "
                    f"<a data-goto='{worst}' href='#'>worst frame {worst}</a> "
                    f"({float(err[worst]):.1f} mm{', the poster' if videos else ''})"
                    + (f"; file <a href='{stem}.mp4'>{stem}.mp4</a>" if videos else "")
                    + "</p></div>"
                )
                cards.append("".join(card))
                sheet = keyframe_sheet(
                    v.original, r.motion, r.keyframes, out / f"{stem}_keyframes.png",
                    method=r.label, feet=feet, ground_z=ground,
                )  # fmt: skip
                sheets.append(
                    f"<p class='sheetcap' style='color:{colour}'>{html.escape(r.label)}</p>"
                    f"<img class='sheet' alt='{html.escape(r.label)} keyframes' "
                    f"src='{_data_uri('image/png', sheet.read_bytes())}'>"
                )
                bar.update()
            player = ("<h3>Videos</h3>" + _player(T, v.clip.fps)) if videos else ""
            # the player sticks to the top of the window while its videos are in view
            parts.append(
                f"<div class='vblock'>{player}<div class='videos'>{''.join(cards)}</div></div>"
            )
            plot = metrics_plot(v, colours)
            if plot is not None:
                write_atomic(out / f"clip{number:02d}_metrics.png", lambda f, b=plot: f.write(b))
                parts.append(
                    "<h3>Per frame, every method on one scale</h3>"
                    f"<img class='plot' alt='per-frame metrics' src='{_data_uri('image/png', plot)}'>"
                )
            parts.append(
                "<h3>Keyframes and the worst frame between each pair</h3>" + "".join(sheets)
            )
            parts.append("</section>")
    finally:
        stack.close()
    bar.close()
    parts.append(legend_html(full=True))
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>"
        + "\n".join(parts)
        + f"<script>{_JS}</script></body></html>"
    )
    path = out / "index.html"
    write_atomic(path, lambda f: f.write(page.encode()))
    return path


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
) -> Path:
    """Validate every clip in ``clips`` with every method (and decoded ``streams``) and write the
    report; returns ``out_dir/index.html``. ``clip_numbers``: the clips' numbers in their trial, for
    labels and file names (default 0, 1, ...). With ``model`` (the subject's humanoid) every motion
    also gets the :mod:`sim.physics` figures, on ``ground`` (default: estimated per clip) with the
    original's ``contacts`` labelled over the trial (:func:`trial_contacts_by_clip`), and with
    ``simulate`` (a :class:`sim.simulate.validate.ForwardValidation`) the forward simulation's. Clips are
    validated through ``sim.batch.run_batch`` (``workers`` processes or Ray); a clip that fails is
    listed in the report's ``failed`` field."""
    numbers = list(range(len(clips)) if clip_numbers is None else clip_numbers)
    job = physics_job(model, clips[0]) if model is not None and clips else None
    validate = partial(
        validate_clip, methods=list(methods), W=W, seed=seed, joint_ranges=joint_ranges,
        streams=streams, physics=job, ground=ground, contacts=contacts,
        simulate=simulate if job else None,
    )  # fmt: skip
    outcomes = run_batch(
        validate, clips, workers=workers, ray=ray, desc="replay", progress=progress
    )
    vals = [o.result for o in outcomes if o.ok]
    kept = [n for n, o in zip(numbers, outcomes, strict=True) if o.ok]
    failed = [f"clip {n}: {o.error}" for n, o in zip(numbers, outcomes, strict=True) if not o.ok]
    if not vals:
        raise ValueError("every clip failed: " + "; ".join(failed))
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
    amc: str | os.PathLike,
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
) -> Path:
    """Ingest a CMU trial, cut it into 60-frame clips at 30 fps and report the clips numbered
    ``clips`` (see :func:`report_clips`); joint limits come from the subject's humanoid.
    ``streams``: paths of ``.sidq`` files encoded from this trial, reported beside the methods.
    ``simulate``: also track every motion in forward simulation (the subject's torque-limited
    body, no assistance: :mod:`sim.simulate.validate`)."""
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
        raise ValueError(f"clip numbers {bad} out of range: the trial has {len(all_clips)} clips")
    skeleton, model = subject_model(asf)
    ground = trial_ground(all_clips)
    forward = None
    if simulate:
        names = from_clip(all_clips[0]).restrict(POINTS).names
        forward = ForwardValidation(sim_model(skeleton), names)
    return report_clips(
        [all_clips[c] for c in clips], out_dir, W=W, methods=methods, seed=seed,
        joint_ranges=joint_ranges(model), videos=videos, style=style,
        title=f"Replay checks: {Path(amc).stem}",
        meta={"asf": str(asf), "amc": str(amc), "clips": " ".join(map(str, clips))},
        progress=progress, clip_numbers=list(clips), streams=decoded, model=model,
        ground=ground, contacts=trial_contacts_by_clip(all_clips, ground), workers=workers,
        ray=ray, simulate=forward,
    )  # fmt: skip


def physics_job(model, clip: Clip):
    """A :class:`sim.physics.analysis.PhysicsJob` for the protocol points of ``clip``'s subject."""
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
