"""The validation report: every method's reconstruction replayed, measured, rendered, on one page.

:func:`validate_clip` chooses keyframes with each method, reconstructs, replays the original and
every reconstruction (:mod:`sim.replay.checks`) and returns JSON-ready figures with each method's excess
over the original. :func:`write_report` renders the videos and keyframe contact sheets
(:mod:`sim.replay.render`), plots per-frame error with the keyframes marked, and writes ``index.html`` (one
self-contained page: images and videos embedded as base64, copies beside it), the ``.mp4`` and
``.png`` files and ``checks.json`` atomically.

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
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from sim.batch import run_batch
from sim.motion.clip import Clip, write_atomic
from sim.replay.checks import (
    PHYSICAL_KEYS,
    FrameChecks,
    PointMotion,
    excess,
    from_clip,
    from_reconstruction,
    replay,
    summarise,
)
from sim.replay.render import DEFAULT_STYLE, RenderStyle, keyframe_sheet, render_frames, write_video

# Reconstructions shown for a method: the project's spherical Hermite for every method, and Li et
# al.'s own slerp reconstruction for their keyframes.
OWN_RECONSTRUCTION = {"pitch": "slerp"}


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


def joint_ranges(model) -> dict[str, tuple[float, float]]:
    """Hinge name -> (lo, hi) [rad] of every limited hinge of a MuJoCo model."""
    out = {}
    for j in range(model.njnt):
        if model.jnt_limited[j] and model.jnt_type[j] == 3:  # mjJNT_HINGE
            out[model.joint(j).name] = (float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1]))
    return out


def reconstruct_with(clip: Clip, keyframes, reconstruction: str):
    """``"hermite"`` (spherical Hermite, :func:`sidql.keyframes.reconstruct.reconstruct`; also ``"linear"``,
    ``"catmull_rom"``) or ``"slerp"`` (Li et al.'s, :func:`sidql.keyframes.pitch.reconstruct`)."""
    if reconstruction == "slerp":
        from sidql.keyframes.pitch import reconstruct
    else:
        from sidql.keyframes.reconstruct import reconstruct

        return reconstruct(clip, keyframes, reconstruction)
    return reconstruct(clip, keyframes)


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
) -> ClipValidation:
    """Keyframes by every method, reconstruction, replay and figures for one clip.

    Args:
        clip: the original (T frames, any CMU point set containing the 23 protocol points).
        methods: names registered in :mod:`sidql.keyframes.methods`.
        W: keyframes per clip, both ends included.
        joint_ranges: hinge ranges [rad] for the joint-limit check of motions with joint angles.
    """
    from sidql.keyframes.methods import select
    from sidql.keyframes.spherical import POINTS

    kw = dict(floor_z=floor_z, contact_height=contact_height, hops=hops, joint_ranges=joint_ranges)
    full = from_clip(clip)
    orig = full.restrict(POINTS)
    base_checks = replay(orig, full, **kw)
    out = ClipValidation(clip, W, orig, base_checks, summarise(base_checks))
    for m in methods:
        keys = np.asarray(select(m, clip, W, seed=seed))
        for variant in ["hermite"] + ([OWN_RECONSTRUCTION[m]] if m in OWN_RECONSTRUCTION else []):
            rec = from_reconstruction(reconstruct_with(clip, keys, variant), clip.fps)
            checks = replay(rec, full, **kw)
            s = summarise(checks)
            out.runs.append(MethodRun(m, variant, keys, rec, checks, s, excess(s, out.baseline)))
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
                "original": {"summary": v.baseline, "per_frame": per_frame(v.baseline_checks)},
                "methods": [
                    {
                        "method": r.method,
                        "reconstruction": r.reconstruction,
                        "indices": r.keyframes,
                        "summary": r.summary,
                        "excess": r.excess,
                        "per_frame": per_frame(r.checks),
                    }
                    for r in v.runs
                ],
            }
        )
    return _clean({**meta, "clips": clips})


def _slug(s: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in s)


def error_plot(v: ClipValidation, run: MethodRun) -> bytes:
    """PNG of per-frame MPJPE and velocity error, floor and self-penetration depth, keyframes as
    vertical lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    T = v.clip.n_frames
    t = np.arange(T)
    c, b = run.checks, v.baseline_checks
    fig, ax = plt.subplots(2, 1, figsize=(6.4, 3.6), sharex=True, dpi=100)
    ax[0].plot(t, 1e3 * c.mpjpe, color="tab:orange", label="MPJPE [mm]")
    ax0b = ax[0].twinx()
    ax0b.plot(t, 1e3 * c.velocity_error, color="tab:purple", lw=0.8, label="velocity error [mm/s]")
    ax0b.set_ylabel("mm/s", fontsize=8)
    ax[0].set_ylabel("mm", fontsize=8)
    ax[1].plot(t, 1e3 * c.floor_depth, color="tab:red", label="floor depth")
    ax[1].plot(t, 1e3 * b.floor_depth, color="tab:red", ls=":", label="floor depth, original")
    ax[1].plot(t, 1e3 * c.self_depth, color="tab:blue", label="self-penetration depth")
    ax[1].plot(t, 1e3 * b.self_depth, color="tab:blue", ls=":", label="self-pen., original")
    ax[1].set_ylabel("mm", fontsize=8)
    ax[1].set_xlabel("frame", fontsize=8)
    for a in ax:
        for k in run.keyframes:
            a.axvline(k, color="tab:green", lw=0.8, alpha=0.7)
        a.tick_params(labelsize=7)
    h0, l0 = ax[0].get_legend_handles_labels()
    h1, l1 = ax0b.get_legend_handles_labels()
    ax[0].legend(h0 + h1, l0 + l1, fontsize=7, loc="upper left")
    ax[1].legend(fontsize=6, loc="upper left", ncol=2)
    ax[0].set_title(f"{run.label}: per-frame error (green: keyframes)", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


_COLUMNS = (
    ("mpjpe_mm", "MPJPE mm", "{:.1f}"),
    ("velocity_error_mm_s", "vel. err mm/s", "{:.0f}"),
    ("bone_drift_max_mm", "bone drift mm", "{:.2g}"),
    ("floor_depth_max_mm", "floor depth mm", "{:+.1f}"),
    ("floor_frames", "floor frames", "{:+d}"),
    ("self_pen_frames", "self-pen frames", "{:+d}"),
    ("self_pen_depth_max_mm", "self-pen depth mm", "{:+.1f}"),
    ("skate_mean_mm_s", "skate mm/s", "{:+.0f}"),
    ("joint_limit_max_deg", "joint limit deg", "{:+.1f}"),
)


def _cell(key: str, fmt: str, value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if "d}" in fmt:
        value = int(value)
    return fmt.format(value)


def _table(v: ClipValidation) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for _, h, _ in _COLUMNS)
    rows = []
    base = []
    for key, _, fmt in _COLUMNS:
        val = v.baseline[key]
        base.append(f"<td>{html.escape(_cell(key, fmt.replace('+', ''), val))}</td>")
    rows.append(f"<tr class='orig'><td>original (baseline)</td><td>-</td>{''.join(base)}</tr>")
    for r in v.runs:
        cells = []
        for key, _, fmt in _COLUMNS:
            val = r.excess[key] if key in PHYSICAL_KEYS and key != "bone_drift_max_mm" else None
            val = r.summary[key] if val is None else val
            cells.append(f"<td>{html.escape(_cell(key, fmt, val))}</td>")
        keys = " ".join(str(int(k)) for k in r.keyframes)
        rows.append(
            f"<tr><td>{html.escape(r.label)}</td><td class='k'>{keys}</td>{''.join(cells)}</tr>"
        )
    return (
        f"<table><tr><th>method</th><th>keyframes</th>{head}</tr>{''.join(rows)}</table>"
        "<p class='note'>Original row: its own figures. Method rows: MPJPE, velocity error and bone "
        "drift against the original; the other columns are the excess over the original (+ is "
        "worse). Joint limits need joint angles: reconstructions are point sets (n/a).</p>"
    )


_CSS = """
body{font-family:system-ui,sans-serif;margin:20px;color:#222;max-width:1400px}
table{border-collapse:collapse;font-size:13px;margin:8px 0}
td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}
td:first-child,th:first-child{text-align:left}
td.k{font-family:monospace;font-size:11px;text-align:left}
tr.orig{background:#eef}
.note{font-size:12px;color:#555}
.method{display:inline-block;vertical-align:top;margin:6px;border:1px solid #ddd;padding:6px}
.method h3{margin:2px 0 6px 0;font-size:15px}
video,img{display:block;max-width:640px}
"""


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
) -> Path:
    """Write ``index.html``, ``checks.json``, one ``.mp4`` and one keyframe ``.png`` per clip and
    method, and the error plots, into ``out_dir``. Returns the page's path."""
    from tqdm import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    meta = dict(meta or {})
    doc = checks_document(validations, meta)
    text = json.dumps(doc, indent=1)
    write_atomic(out / "checks.json", lambda f: f.write(text.encode()))

    parts = [f"<h1>{html.escape(title)}</h1>"]
    if meta:
        parts.append(
            "<p class='note'>"
            + "; ".join(f"{html.escape(str(k))}: {html.escape(str(v))}" for k, v in meta.items())
            + "</p>"
        )
    jobs = [(ci, r) for ci, v in enumerate(validations) for r in v.runs]
    bar = tqdm(total=len(jobs), desc="report", unit="video", disable=not progress)
    for ci, v in enumerate(validations):
        T = v.clip.n_frames
        start = v.clip.start_frame
        parts.append(
            f"<h2>Clip {ci}: {html.escape(Path(v.clip.source).name or 'synthetic')} from source "
            f"frame {start}, {T} frames at {v.clip.fps:g} fps, W = {v.W}</h2>"
        )
        parts.append(_table(v))
        for r in v.runs:
            stem = f"clip{ci:02d}_{_slug(r.label)}"
            block = [f"<div class='method'><h3>{html.escape(r.label)}</h3>"]
            if videos:
                mp4 = write_video(
                    render_frames(
                        v.original, r.motion, keyframes=r.keyframes, method=r.label, style=style
                    ),
                    out / f"{stem}.mp4",
                    v.clip.fps,
                )
                block.append(
                    f"<video controls loop muted playsinline preload='auto' width='{style.width}' "
                    f"data-file='{mp4.name}' src='{_data_uri('video/mp4', mp4.read_bytes())}'>"
                    f"</video><p class='note'>video: <a href='{mp4.name}'>{mp4.name}</a> "
                    "(orange ghost: reconstruction; green: keyframe)</p>"
                )
            sheet = keyframe_sheet(
                v.original, r.motion, r.keyframes, out / f"{stem}_keyframes.png",
                method=r.label, style=RenderStyle(320, 240, layout=style.layout),
            )  # fmt: skip
            png = error_plot(v, r)
            write_atomic(out / f"{stem}_error.png", lambda f, png=png: f.write(png))
            block.append(f"<img alt='per-frame error' src='{_data_uri('image/png', png)}'>")
            block.append(
                f"<img alt='keyframes' src='{_data_uri('image/png', sheet.read_bytes())}'></div>"
            )
            parts.append("".join(block))
            bar.update()
    bar.close()
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>"
        + "\n".join(parts)
        + "</body></html>"
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
    workers: int = 1,
    ray: str | None = None,
) -> Path:
    """Validate every clip in ``clips`` with every method and write the report; returns
    ``out_dir/index.html``. Clips are validated through ``sim.batch.run_batch`` (``workers``
    processes or Ray); a clip that fails is listed in the report's ``failed`` field."""
    validate = partial(
        validate_clip, methods=list(methods), W=W, seed=seed, joint_ranges=joint_ranges
    )
    outcomes = run_batch(
        validate, clips, workers=workers, ray=ray, desc="replay", progress=progress
    )
    vals = [o.result for o in outcomes if o.ok]
    failed = [f"clip {i}: {o.error}" for i, o in enumerate(outcomes) if not o.ok]
    if not vals:
        raise ValueError("every clip failed: " + "; ".join(failed))
    meta = {"keyframes": W, "methods": " ".join(methods), "seed": seed, **(meta or {})}
    if failed:
        meta["failed"] = "; ".join(failed)
    return write_report(
        vals, out_dir, title=title, meta=meta, videos=videos, style=style, progress=progress
    )


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
    workers: int = 1,
    ray: str | None = None,
) -> Path:
    """Ingest a CMU trial, cut it into 60-frame clips at 30 fps and report the clips numbered
    ``clips`` (see :func:`report_clips`); joint limits come from the subject's humanoid."""
    from sim.errors import MotionDataError
    from sim.model.humanoid import subject_model
    from sim.motion.ingest import load_clips

    all_clips = load_clips(asf, amc)
    if not all_clips:
        raise MotionDataError(str(amc), None, "trial is shorter than one 60-frame clip")
    bad = [c for c in clips if not 0 <= c < len(all_clips)]
    if bad:
        raise ValueError(f"clip numbers {bad} out of range: the trial has {len(all_clips)} clips")
    _, model = subject_model(asf)
    return report_clips(
        [all_clips[c] for c in clips], out_dir, W=W, methods=methods, seed=seed,
        joint_ranges=joint_ranges(model), videos=videos, style=style,
        title=f"Replay checks: {Path(amc).stem}",
        meta={"asf": str(asf), "amc": str(amc), "clips": " ".join(map(str, clips))},
        progress=progress, workers=workers, ray=ray,
    )  # fmt: skip
