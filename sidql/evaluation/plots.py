"""The report's plots of one clip, every method in its colour: a bar per method for each ranked
metric, and every per-frame metric over the clip's frames, with each method's keyframes as ticks.

Both return PNG bytes (``None`` when there is nothing to plot); matplotlib is imported lazily.
"""

from __future__ import annotations

import io

import numpy as np

from sidql.evaluation.metrics import (
    ARROW,
    BETTER_TEXT,
    best_in_clip,
    best_rows,
    metric_value,
    shown_metrics,
)
from sidql.evaluation.validation import ClipValidation, per_frame


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
        best = best_in_clip(v, m, vals)
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
        ax.set_title(f"{m.label}{unit} {ARROW[m.better]}", fontsize=8)
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
        ax.set_title(f"{m.label}{unit}  ({BETTER_TEXT[m.better]})", fontsize=9)
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
