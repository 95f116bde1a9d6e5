"""The report page: one self-contained ``index.html`` per report, with its files beside it.

:func:`write_report` writes ``checks.json`` (:func:`sidql.evaluation.validation.checks_document`),
per clip and method a video (``.mp4``, :mod:`sim.replay.render`), its poster and a keyframe
filmstrip (``.png``), per clip the two plots (:mod:`sidql.evaluation.plots`), and the page, which
embeds every image and video as base64 so it can be mailed or archived alone. Every file is
written atomically.

Every video and filmstrip of a clip draws its scene (:attr:`ClipValidation.scene`: the steps
inferred under the original's feet, the boxes its simulated bodies stood on, on the scene's
ground: :func:`drawn_floor`). Per clip the page shows the trial's floor in a sentence, one
table per metric group (:data:`sidql.evaluation.metrics.GROUPS`) with the original's row, its
noise floor and the best method per column, a legend of the shown metrics, the plots, the videos under one control that
plays, pauses and seeks them together, and the filmstrips. Clips are labelled by their real
numbers in the trial, frames are numbered from 0 everywhere, and every video's poster is its
worst-error frame. The page's style sheet and script are package files (``sidql/data/report.css``,
``sidql/data/report.js``).
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from contextlib import ExitStack
from importlib.resources import files
from pathlib import Path

import numpy as np
from PIL import Image
from tqdm import tqdm

from sidql.evaluation.metrics import (
    ARROW,
    BETTER_TEXT,
    GROUPS,
    METRICS,
    Metric,
    best_in_clip,
    format_value,
    metric_value,
    shown_metrics,
)
from sidql.evaluation.plots import metrics_plot, summary_plot
from sidql.evaluation.validation import ClipValidation, MethodRun, checks_document
from sim.errors import UsageError
from sim.files import write_atomic
from sim.motion.points import PointMotion
from sim.physics.foot_state import FootState, foot_states
from sim.physics.ground import estimate_ground
from sim.physics.noise import NOISE_MM
from sim.physics.support import SUPPORT_MISSING_BW, capture_unsupported
from sim.replay.render import DEFAULT_STYLE, RenderStyle, SkeletonRenderer
from sim.replay.sheets import keyframe_sheet
from sim.replay.video import render_frames, write_video

#: Method colours shared by plots, table swatches and video cards.
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf",
           "#bcbd22", "#ff7f0e", "#7f7f7f")  # fmt: skip


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
        "against the original; columns marked \u2248o: closest to the original's own value is "
        "best.</p>"
    )


def _table(v: ClipValidation, colours, ms: list[Metric]) -> str:
    head = "".join(
        f"<th title='{html.escape(m.description)} ({BETTER_TEXT[m.better]})'>{html.escape(m.label)}"
        f"{'<br><small>' + html.escape(m.unit) + '</small>' if m.unit else ''}"
        f"<span class='dir'>{ARROW[m.better]}</span></th>"
        for m in ms
    )
    vals = {m.key: [metric_value(m, r.figures, r.excess) for r in v.runs] for m in ms}
    nf = v.noise_floor
    best = {m.key: best_in_clip(v, m, vals[m.key]) for m in ms}
    base = "".join(
        f"<td>{html.escape(format_value(m.fmt.replace('+', ''), metric_value(m, v.baseline_figures)))}</td>"
        for m in ms
    )
    rows = [f"<tr class='orig'><td>original (baseline)</td><td>-</td>{base}</tr>"]
    if any(nf.get(m.key) is not None for m in ms):
        noise = "".join(
            f"<td>{html.escape(format_value(m.fmt.replace('+', ''), nf.get(m.key)))}</td>"
            for m in ms
        )
        rows.append(
            f"<tr class='noise'><td>noise floor</td><td class='k'>original + {NOISE_MM:g} mm "
            f"noise</td>{noise}</tr>"
        )
    for i, (r, colour) in enumerate(zip(v.runs, colours, strict=True)):
        cells = "".join(
            f"<td{' class=best' if i in best[m.key] else ''}>"
            f"{html.escape(format_value(m.fmt, vals[m.key][i]))}</td>"
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
        f"<span class='dir'>{ARROW[m.better]} {BETTER_TEXT[m.better]}</span>: "
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


def support_sentence(physics: dict) -> str:
    """One sentence when a clip's original capture lacks support on the floor
    (:func:`sim.physics.support.capture_unsupported` of its ``support_missing_share``), saying
    that a fall of the simulated original there is the capture's; "" when it has support."""
    missing = physics.get("support_missing_share")
    if not capture_unsupported(missing):
        return ""
    fell = physics.get("sim_fall_s")
    then = "" if fell is None else f" (the original's fell at {fell:.2f} s)"
    return (
        f"The capture lacks support on this floor: in {100 * missing:.0f} % of its measured "
        f"frames the original needs more than {SUPPORT_MISSING_BW:g} body weight from outside "
        "with nothing on the floor (sim.physics inverse dynamics: a squat held up by nothing, a "
        "climb on equipment, a partner's hold). As captured, no body performs those frames on "
        f"this floor: a fall of the simulated original here{then} is the capture's, and the "
        "methods' simulated figures on this clip are measured against an original that needs "
        "help (docs/results/capture_support.md: such clips, fallen or not)."
    )


def scene_sentence(v: ClipValidation) -> str:
    """One sentence on a clip's inferred scene (:attr:`ClipValidation.scene`)."""
    tops = ", ".join(f"{b.top - v.scene_ground:.2f}" for b in v.scene)
    return (
        f"Scene inferred from the original's feet (sim.simulate.terrain): {len(v.scene)} "
        f"step(s), tops {tops} m above its ground at z = {v.scene_ground:.3f} m; drawn in every "
        "video and filmstrip (sand-coloured boxes, the floor at that ground), the scene "
        "report --simulate's bodies are simulated in."
    )


def trial_floor(v: ClipValidation):
    """The floor the page draws: the trial's ground (:mod:`sim.physics.ground`), or one estimated
    from the clip when the report had no trial ground."""
    return v.ground or estimate_ground(v.clip.positions, v.clip.names, v.clip.fps)


def drawn_floor(v: ClipValidation) -> float:
    """[m] the height of the floor a clip's videos draw: its scene's ground where it has a scene
    (:attr:`ClipValidation.scene_ground`: what the boxes stand on and the simulated bodies
    walked on), else :func:`trial_floor`'s."""
    return trial_floor(v).floor_z if v.scene_ground is None else v.scene_ground


def ground_and_feet(v: ClipValidation, run: MethodRun) -> tuple[float, FootState]:
    """Floor height [m] and foot states drawn for one method's video: :func:`drawn_floor` and
    the contact labels and flags of :func:`sim.physics.foot_state.foot_states` (on
    :func:`trial_floor`, as the figures are measured)."""
    return drawn_floor(v), foot_states(v.original, run.motion, trial_floor(v))


def _data_uri(mime: str, data: bytes) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _slug(s: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in s)


def _asset(name: str) -> str:
    """A file of the page shipped in ``sidql/data`` (its style sheet and script), as text."""
    return files("sidql").joinpath("data", name).read_text(encoding="utf-8")


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
        raise UsageError(f"{len(numbers)} clip numbers for {len(validations)} clips")
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
    total = sum(len(v.runs) for v in validations)
    with tqdm(total=total, desc="report", unit="video", disable=not progress) as bar:
        for number, v in zip(numbers, validations, strict=True):
            parts.append(_clip_section(v, number, out, videos, style, bar.update))
    parts.append(legend_html(full=True))
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title><style>{_asset('report.css')}</style></head><body>"
        + "\n".join(parts)
        + f"<script>{_asset('report.js')}</script></body></html>"
    )
    path = out / "index.html"
    write_atomic(path, lambda f: f.write(page.encode()))
    return path


def _clip_section(
    v: ClipValidation, number: int, out: Path, videos: bool, style: RenderStyle, done
) -> str:
    """One clip's ``<section>``: floor, tables, legend, plots, videos and filmstrips; writes the
    clip's files into ``out`` and calls ``done()`` after each method's media."""
    T = v.clip.n_frames
    colours = [PALETTE[i % len(PALETTE)] for i in range(len(v.runs))]
    parts = [
        f"<section class='clip' data-fps='{v.clip.fps:g}' data-frames='{T}'>"
        f"<h2>Clip {number}: {html.escape(Path(v.clip.source).name or 'synthetic')} from "
        f"source frame {v.clip.start_frame}, {T} frames (0-{T - 1}) at {v.clip.fps:g} fps, "
        f"W = {v.W}</h2>"
    ]
    if v.physics:
        parts.append(f"<p class='note'>{html.escape(floor_sentence(v.physics))}</p>")
        if support_sentence(v.physics):
            parts.append(f"<p class='note'>{html.escape(support_sentence(v.physics))}</p>")
    if v.scene:
        parts.append(f"<p class='note'>{html.escape(scene_sentence(v))}</p>")
    parts.append(_tables(v, colours))
    parts.append(legend_html(shown_metrics(v)))
    bars = summary_plot(v, colours)
    if bars is not None:
        write_atomic(out / f"clip{number:02d}_summary.png", lambda f: f.write(bars))
        parts.append(
            "<h3>Per metric, every method on one scale (dashed: the original; \u2605 best)</h3>"
            f"<img class='plot' alt='metrics per method' src='{_data_uri('image/png', bars)}'>"
        )
    cards, sheets = [], []
    with ExitStack() as stack:
        # one MuJoCo renderer per clip for the videos, reused by every method
        renderer = None
        if videos and v.runs:
            renderer = stack.enter_context(
                SkeletonRenderer(
                    v.original.names,
                    v.original.parents,
                    style,
                    ground_z=drawn_floor(v),
                    boxes=v.scene,
                )  # fmt: skip
            )
        if videos:  # the original as the simulated body performed it
            cards.append(_simulated_card(v, "original", v.physics, "#555555",
                                         out / f"clip{number:02d}_original", style, renderer))  # fmt: skip
        for r, colour in zip(v.runs, colours, strict=True):
            stem = f"clip{number:02d}_{_slug(r.label)}"
            card, sheet = _method_media(v, r, colour, out / stem, videos, style, renderer)
            cards.append(card)
            if videos:  # beside the reconstruction: the simulated body that tracked it
                cards.append(_simulated_card(v, r.label, r.physics, colour, out / stem, style,
                                             renderer))  # fmt: skip
            sheets.append(sheet)
            done()
    player = ("<h3>Videos</h3>" + _player(T, v.clip.fps)) if videos else ""
    # the player sticks to the top of the window while its videos are in view
    parts.append(f"<div class='vblock'>{player}<div class='videos'>{''.join(cards)}</div></div>")
    plot = metrics_plot(v, colours)
    if plot is not None:
        write_atomic(out / f"clip{number:02d}_metrics.png", lambda f: f.write(plot))
        parts.append(
            "<h3>Per frame, every method on one scale</h3>"
            f"<img class='plot' alt='per-frame metrics' src='{_data_uri('image/png', plot)}'>"
        )
    parts.append("<h3>Keyframes and the worst frame between each pair</h3>" + "".join(sheets))
    parts.append("</section>")
    return "\n".join(parts)


def _simulated_card(
    v: ClipValidation, label: str, physics: dict, colour: str, stem: Path, style: RenderStyle,
    renderer: SkeletonRenderer | None,
) -> str:  # fmt: skip
    """The video card of the simulated body that tracked ``label``'s motion (``report
    --simulate``: ``physics["per_frame"]["sim_positions"]``) with the original as the ghost;
    writes ``stem_simulated.mp4``. Empty without a simulation."""
    pos = (physics or {}).get("per_frame", {}).get("sim_positions")
    if pos is None:
        return ""
    body = PointMotion(v.original.names, v.original.parents, np.asarray(pos, dtype=float),
                       v.clip.fps)  # fmt: skip
    name = f"{label}, simulated"
    frames = render_frames(v.original, body, method=name, style=style,
                           ground_z=drawn_floor(v), renderer=renderer,
                           boxes=v.scene)  # fmt: skip
    mp4 = write_video(frames, stem.with_name(stem.name + "_simulated.mp4"), v.clip.fps)
    fell = physics.get("sim_fall_s")
    note = "did not fall" if fell is None else f"fell at {fell:.2f} s"
    error = physics.get("sim_error_mm")
    error = "" if error is None else f"; {error:.0f} mm from the motion it tracked"
    return (
        f"<div class='card' style='--c:{colour}'><h3>{html.escape(name)}</h3>"
        f"<video loop muted playsinline preload='auto' width='{style.width}' "
        f"height='{style.height}' data-file='{mp4.name}' "
        f"src='{_data_uri('video/mp4', mp4.read_bytes())}'></video>"
        f"<p class='note'>the human-strength body tracking {html.escape(label)} in MuJoCo "
        f"with no assistance (the original as the ghost): {note}{error}; file "
        f"<a href='{mp4.name}'>{mp4.name}</a></p></div>"
    )


def _method_media(
    v: ClipValidation,
    r: MethodRun,
    colour: str,
    stem: Path,
    videos: bool,
    style: RenderStyle,
    renderer: SkeletonRenderer | None,
) -> tuple[str, str]:
    """One method's video card and filmstrip as HTML; writes ``stem.mp4``, ``stem_poster.jpg``
    (the worst-error frame) and ``stem_keyframes.png``."""
    ground, feet = ground_and_feet(v, r)
    err = 1e3 * r.checks.mpjpe
    worst = int(np.argmax(err)) if err.size else 0
    card = [f"<div class='card' style='--c:{colour}'><h3>{html.escape(r.label)}</h3>"]
    if videos:
        poster = {}

        def keep(frames):  # pass the frames on, keeping the worst one as the poster
            for t, f in enumerate(frames):
                if t == worst:
                    poster["jpg"] = _jpeg(f)
                yield f

        frames = render_frames(
            v.original, r.motion, keyframes=r.keyframes, method=r.label, style=style, feet=feet,
            ground_z=ground, renderer=renderer, boxes=v.scene,
        )  # fmt: skip
        mp4 = write_video(keep(frames), stem.with_name(stem.name + ".mp4"), v.clip.fps)
        jpg = poster["jpg"]
        write_atomic(stem.with_name(stem.name + "_poster.jpg"), lambda f: f.write(jpg))
        card.append(
            f"<video loop muted playsinline preload='auto' width='{style.width}' "
            f"height='{style.height}' data-file='{mp4.name}' data-worst='{worst}' "
            f"poster='{_data_uri('image/jpeg', jpg)}' "
            f"src='{_data_uri('video/mp4', mp4.read_bytes())}'></video>"
        )
    card.append(
        f"<p class='note'>mean MPJPE {float(err.mean()):.1f} mm; "
        f"<a data-goto='{worst}' href='#'>worst frame {worst}</a> "
        f"({float(err[worst]):.1f} mm{', the poster' if videos else ''})"
        + (f"; file <a href='{stem.name}.mp4'>{stem.name}.mp4</a>" if videos else "")
        + "</p></div>"
    )
    png = keyframe_sheet(
        v.original, r.motion, r.keyframes, stem.with_name(stem.name + "_keyframes.png"),
        method=r.label, feet=feet, ground_z=ground, boxes=v.scene,
    )  # fmt: skip
    sheet = (
        f"<p class='sheetcap' style='color:{colour}'>{html.escape(r.label)}</p>"
        f"<img class='sheet' alt='{html.escape(r.label)} keyframes' "
        f"src='{_data_uri('image/png', png.read_bytes())}'>"
    )
    return "".join(card), sheet
