"""Rate and distortion: bytes per second of transmitted keyframes against reconstruction error.

Payload per keyframe (float32 values, one byte for the frame index within a 60-frame clip), as
registered in :mod:`sidql.keyframes.reconstructions`:

* ``hermite`` (the paper): pose and rates, ``2 (2 M + 3)`` floats (M = 22 bone angle pairs plus
  the root position, and the same again for their rates);
* ``linear`` and ``catmull_rom``: the pose only, ``2 M + 3`` floats;
* ``slerp`` (Li et al. 2015, the ``pitch`` method's own): 23 local rotations as quaternions plus the root position,
  ``23 * 4 + 3`` floats.

Bone lengths (or the pitch rig's offsets) are constant per subject and sent once: not counted.
The raw stream is the pose of every frame at 30 fps, ``30 (2 M + 3)`` floats per second.

For every clip and every W of a sweep we choose keyframes with each (method, reconstruction)
pair, among them the exact optimum of each reconstruction's own Q (for Catmull-Rom a dynamic
programme over keyframe triples), and average Q and MPJPE over clips.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
from tqdm import tqdm

from sidql.evaluation.cases import Case, clip_seed
from sidql.keyframes import reconstructions
from sidql.keyframes.methods import select
from sidql.keyframes.metrics import mpjpe_mm, q_from_angles, velocity_error_mm_s
from sidql.keyframes.reconstructions import FLOAT_BYTES, POSE_FLOATS
from sim.files import write_atomic

#: (method, reconstruction) pairs plotted; keyframes by ``methods.select(method, ...,
#: reconstruction=...)``, so "optimal" is the optimum of that reconstruction's own Q.
CURVES: tuple[tuple[str, str], ...] = (
    ("optimal", "hermite"),
    ("greedy", "hermite"),
    ("uniform", "hermite"),
    ("random", "hermite"),
    ("optimal", "linear"),
    ("uniform", "linear"),
    ("optimal", "catmull_rom"),
    ("uniform", "catmull_rom"),
    ("pitch", "slerp"),
)

DEFAULT_COUNTS: tuple[int, ...] = (2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30)


def raw_bytes_per_second(fps: float = 30.0) -> float:
    """Bytes per second [B/s] of the raw pose stream at ``fps``."""
    return fps * POSE_FLOATS * FLOAT_BYTES


def bytes_per_second(scheme: str, W: int, n_frames: int = 60, fps: float = 30.0) -> float:
    """Bytes per second [B/s] of sending W keyframes of reconstruction ``scheme`` per
    ``n_frames``-frame clip (its registered payload)."""
    return W * reconstructions.get(scheme).payload_bytes * fps / n_frames


def rate_distortion(
    cases: Sequence[Case],
    counts: Sequence[int] = DEFAULT_COUNTS,
    *,
    seed: int = 0,
    progress: bool = True,
) -> dict:
    """Mean Q [rad], MPJPE [mm] and velocity error [mm/s] against bytes per second for every
    curve of :data:`CURVES`.

    Returns:
        ``{"raw_bytes_per_second", "clips", "curves": [{"method", "scheme", "keyframes",
        "bytes_per_second", "mean_q", "mpjpe_mm", "velocity_error_mm_s"}]}``.
    """
    counts = sorted(counts)
    q = {c: np.zeros(len(counts)) for c in CURVES}
    e = {c: np.zeros(len(counts)) for c in CURVES}
    v = {c: np.zeros(len(counts)) for c in CURVES}
    for case in tqdm(cases, desc="rate/distortion", unit="clip", disable=not progress):
        s = case.series
        memo = {"chart": s, "w_max": max(counts)}  # one optimum table per clip serves every W
        for i, W in enumerate(counts):
            for method, scheme in CURVES:
                k = select(
                    method,
                    case.clip,
                    W,
                    seed=clip_seed(seed, case.index, W),
                    reconstruction=scheme,
                    memo=memo,
                )
                rec = reconstructions.rebuild(scheme, case.clip, k, s)
                q[(method, scheme)][i] += q_from_angles(s, rec.theta, rec.phi)
                e[(method, scheme)][i] += mpjpe_mm(case.pos, rec.positions)
                v[(method, scheme)][i] += velocity_error_mm_s(case.vel, rec.velocities)
    n = max(len(cases), 1)
    N = cases[0].series.n_frames if cases else 60
    fps = 1.0 / cases[0].series.dt if cases else 30.0
    curves = [
        {
            "method": method,
            "scheme": scheme,
            "keyframes": list(counts),
            "bytes_per_second": [bytes_per_second(scheme, W, N, fps) for W in counts],
            "mean_q": (q[(method, scheme)] / n).tolist(),
            "mpjpe_mm": (e[(method, scheme)] / n).tolist(),
            "velocity_error_mm_s": (v[(method, scheme)] / n).tolist(),
        }
        for method, scheme in CURVES
    ]
    return {
        "raw_bytes_per_second": raw_bytes_per_second(fps),
        "clips": len(cases),
        "curves": curves,
    }


_STYLE = {
    "hermite": "-",
    "linear": "--",
    "catmull_rom": "-.",
    "slerp": ":",
    "cartesian": (0, (1, 3)),
}
_COLOR = {"optimal": "C0", "greedy": "C1", "uniform": "C2", "random": "C3", "pitch": "C4"}


#: The panels of a rate/distortion figure: (key of the error, y-axis label).
PANELS: tuple[tuple[str, str], ...] = (
    ("mean_q", "mean Q, eq. 18 [rad]"),
    ("mpjpe_mm", "MPJPE [mm]"),
    ("velocity_error_mm_s", "mean velocity error [mm/s]"),
)


def write_rd_figure(path, title: str, draw) -> None:
    """Write a rate/distortion figure to ``path`` (PNG), atomically: one log-log panel per
    error of :data:`PANELS` against bytes per second, each drawn by ``draw(ax, key)``, with the
    first panel's legend and ``title`` above."""
    import matplotlib  # lazy: a heavy optional plotting dependency, only for the figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy, after choosing the headless backend

    fig, axes = plt.subplots(1, len(PANELS), figsize=(18, 5))
    for ax, (key, label) in zip(axes, PANELS, strict=True):
        draw(ax, key)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("bytes per second of motion")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    write_atomic(path, lambda f: f.write(buf.getvalue()))


def write_plot(rd: dict, path) -> None:
    """Write the rate/distortion figure of :func:`rate_distortion`'s ``rd`` (Q, MPJPE and
    velocity error of every curve against bytes per second) to ``path`` (PNG), atomically."""

    def draw(ax, key):
        for c in rd["curves"]:
            ax.plot(
                c["bytes_per_second"],
                c[key],
                _STYLE[c["scheme"]],
                color=_COLOR[c["method"]],
                marker="o",
                ms=3,
                label=f"{c['method']} / {c['scheme']}",
            )
        ax.axvline(rd["raw_bytes_per_second"], color="k", lw=0.8)
        ax.text(rd["raw_bytes_per_second"], ax.get_ylim()[1], " raw 30 fps", va="top", fontsize=8)

    write_rd_figure(
        path,
        f"Rate/distortion on {rd['clips']} CMU clips (60 frames, 30 fps), W = "
        f"{rd['curves'][0]['keyframes'][0]}..{rd['curves'][0]['keyframes'][-1]}",
        draw,
    )
