"""Evaluate keyframe methods on the paper's protocol and tabulate them like its Table 3.

Protocol: every CMU trial at 30 fps (every 4th frame of 120 fps), cut into non-overlapping 60-frame
clips from frame 0; each method chooses W keyframes per clip (both ends included); the clip is
rebuilt (spherical cubic Hermite for every method except ``pitch``, which uses its own slerp
reconstruction) and scored by

* ``q``: the paper's eq. 18 [rad] on the reconstruction's angles (22 bones);
* ``q_hermite``: eq. 18 of the same keyframes under the Hermite reconstruction (equal to ``q``
  except for pitch: it separates the choice of keyframes from the way they are interpolated);
* ``geodesic_deg``: mean angle between true and rebuilt bone directions [deg];
* ``mpjpe_mm``: mean joint position error over the 23 points [mm];
* ``velocity_error``: mean joint velocity error over the 23 points [m/s];
* ``li_error_mm``: Li et al. 2015's error as we read it (:func:`sidql.keyframes.pitch.pitch_error`) [mm];
* ``decision_ms``: wall time of the method's choice, chart included [ms].

Loading needs ``sim.motion.ingest`` (MuJoCo); everything after it is pure numpy.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sidql.keyframes import methods as methods_mod
from sidql.keyframes import pitch as pitch_mod
from sidql.keyframes.metrics import geodesic_deg, mpjpe_mm, q_error, q_from_angles, velocity_error
from sidql.keyframes.reconstruct import reconstruct_series
from sidql.keyframes.spherical import SphericalSeries, chart, protocol_indices
from sim.motion.clip import Clip

#: The paper's Table 3 (mean Q at W = 5, 10, 15); "SIDQL" is its DQN.
PAPER_TABLE3: dict[str, dict[int, float]] = {
    "RC": {5: 0.1437, 10: 0.0833, 15: 0.0549},
    "UC": {5: 0.0945, 10: 0.0490, 15: 0.0328},
    "Greedy": {5: 0.0536, 10: 0.0311, 15: 0.0200},
    "SIDQL": {5: 0.0844, 10: 0.0443, 15: 0.0297},
}

#: Our method name -> the paper's row.
PAPER_NAMES = {"random": "RC", "uniform": "UC", "greedy": "Greedy", "dqn": "SIDQL"}


@dataclass(frozen=True)
class Case:
    """One evaluation clip with what every method's scoring needs.

    Attributes:
        clip: the 60-frame clip; series: its chart; pos, vel: (N, 23, 3) true protocol points
        [m, m/s]; index: position in the dataset (seeds the random method).
    """

    clip: Clip
    series: SphericalSeries
    pos: np.ndarray
    vel: np.ndarray
    index: int


def make_case(clip: Clip, index: int = 0) -> Case:
    idx = protocol_indices(clip)
    return Case(clip, chart(clip), clip.positions[:, idx], clip.velocities[:, idx], index)


def load_cases(
    data_dir,
    *,
    fps: float = 30.0,
    length: int = 60,
    skeleton: str = "subject",
    progress: bool = True,
    subjects=None,
    workers: int = 1,
    ray: str | None = None,
) -> tuple[list[Case], list[dict]]:
    """Every ``length``-frame clip of every trial under ``data_dir``.

    ``subjects``: keep only these subject ids (e.g. a policy's held-out subjects); None keeps all.
    A folder with an ``index.json`` (written by ``sidql dataset`` or ``sidql synth``) is read from
    its ``.npz`` clips. Trials load through ``sim.batch.run_batch`` (``workers``, ``ray``).

    Returns:
        The cases, and ``{"amc", "problem"}`` for each trial skipped as bad input (also reported
        on stderr); good trials are kept.
    """
    from functools import partial

    from sim.batch import run_batch
    from sim.motion.dataset import find_trials, load_dataset_clips
    from sim.motion.ingest import load_clips

    cases: list[Case] = []
    skipped: list[dict] = []
    if (Path(data_dir) / "index.json").is_file():
        clips, subj = load_dataset_clips(data_dir, length)
        keep = [c for c, s in zip(clips, subj, strict=True) if subjects is None or s in subjects]
        return [make_case(c, i) for i, c in enumerate(keep)], skipped
    trials = find_trials(data_dir)
    if subjects is not None:
        trials = [t for t in trials if t.subject in set(subjects)]
    load = partial(_trial_clips, fps=fps, length=length, skeleton=skeleton, load=load_clips)
    outcomes = run_batch(
        load, trials, workers=workers, ray=ray, desc="load trials", progress=progress
    )
    for trial, o in zip(trials, outcomes, strict=True):
        if not o.ok:
            skipped.append({"amc": str(trial.amc), "problem": o.error})
            print(f"skipped {trial.amc}: {o.error}", file=sys.stderr)
            continue
        cases.extend(make_case(c, len(cases) + i) for i, c in enumerate(o.result))
    return cases, skipped


def _trial_clips(trial, *, fps, length, skeleton, load):
    return load(trial.asf, trial.amc, fps=fps, length=length, skeleton=skeleton)


def clip_seed(seed: int, index: int, W: int) -> int:
    """Deterministic per-clip, per-W seed for randomised methods."""
    return int(np.random.SeedSequence([seed, index, W]).generate_state(1)[0])


def score(case: Case, keyframes: np.ndarray, method: str) -> dict:
    """Every error measure of one clip rebuilt from ``keyframes`` (see the module docstring)."""
    s = case.series
    q_h = q_error(s, keyframes, "hermite")
    if method == "pitch":
        rec = pitch_mod.reconstruct(case.clip, keyframes)
        q = q_from_angles(s, rec.theta, rec.phi)
    else:
        rec = reconstruct_series(s, keyframes, "hermite")
        q = q_h
    return {
        "q": q,
        "q_hermite": q_h,
        "geodesic_deg": geodesic_deg(case.pos, rec.positions, rec.parents),
        "mpjpe_mm": mpjpe_mm(case.pos, rec.positions),
        "velocity_error": velocity_error(case.vel, rec.velocities),
        "li_error_mm": 1000.0 * pitch_mod.pitch_error(case.pos, rec.positions),
    }


def evaluate(
    cases: Sequence[Case],
    method_names: Iterable[str],
    keyframe_counts: Iterable[int],
    *,
    seed: int = 0,
    progress: bool = True,
) -> dict:
    """Run every method at every W on every case.

    Returns:
        ``{"results": [row...], "per_clip": [row...]}``; a result row holds method, keyframes,
        clips, mean_q, mean_q_hermite, mean_geodesic_deg, mpjpe_mm, mean_velocity_error,
        mean_li_error_mm, median_decision_ms; a per-clip row holds source, start_frame, method,
        keyframes, indices, q and the other scores.
    """
    from tqdm import tqdm

    method_names = list(method_names)
    counts = list(keyframe_counts)
    for name in method_names:
        methods_mod.get(name)  # fail early, listing the known methods
    per_clip: list[dict] = []
    results: list[dict] = []
    jobs = [(m, W) for m in method_names for W in counts]
    for name, W in tqdm(jobs, desc="evaluate", unit="run", disable=not progress):
        rows = []
        for case in cases:
            t0 = time.perf_counter()
            k = methods_mod.select(name, case.clip, W, seed=clip_seed(seed, case.index, W))
            ms = 1000.0 * (time.perf_counter() - t0)
            row = {
                "source": case.clip.source,
                "start_frame": case.clip.start_frame,
                "method": name,
                "keyframes": W,
                "indices": k.tolist(),
                **score(case, k, name),
                "decision_ms": ms,
            }
            rows.append(row)
        per_clip.extend(rows)
        if rows:
            results.append(
                {
                    "method": name,
                    "keyframes": W,
                    "clips": len(rows),
                    "mean_q": float(np.mean([r["q"] for r in rows])),
                    "mean_q_hermite": float(np.mean([r["q_hermite"] for r in rows])),
                    "mean_geodesic_deg": float(np.mean([r["geodesic_deg"] for r in rows])),
                    "mpjpe_mm": float(np.mean([r["mpjpe_mm"] for r in rows])),
                    "mean_velocity_error": float(np.mean([r["velocity_error"] for r in rows])),
                    "mean_li_error_mm": float(np.mean([r["li_error_mm"] for r in rows])),
                    "median_decision_ms": float(np.median([r["decision_ms"] for r in rows])),
                }
            )
    return {"results": results, "per_clip": per_clip}


def table3_markdown(results: Sequence[dict]) -> str:
    """Markdown table of mean Q per method (rows) and W (columns), the paper's figure beside ours
    where it has one, then the chart-free errors."""
    counts = sorted({r["keyframes"] for r in results})
    names = list(dict.fromkeys(r["method"] for r in results))
    by = {(r["method"], r["keyframes"]): r for r in results}
    head = "| method | " + " | ".join(f"Q, W={W} (paper)" for W in counts) + " |"
    lines = [head, "|---|" + "---|" * len(counts)]
    for name in names:
        paper = PAPER_TABLE3.get(PAPER_NAMES.get(name, ""), {})
        cells = []
        for W in counts:
            r = by.get((name, W))
            ours = f"{r['mean_q']:.4f}" if r else "-"
            cells.append(f"{ours} ({paper[W]:.4f})" if W in paper else ours)
        label = f"{name} ({PAPER_NAMES[name]})" if name in PAPER_NAMES else name
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        "| method | W | clips | Q | Q of its keyframes, Hermite | geodesic (deg) | MPJPE (mm) "
        "| velocity error (m/s) | Li error (mm) | median decision (ms) |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        lines.append(
            f"| {r['method']} | {r['keyframes']} | {r['clips']} | {r['mean_q']:.4f} "
            f"| {r['mean_q_hermite']:.4f} | {r['mean_geodesic_deg']:.2f} | {r['mpjpe_mm']:.1f} "
            f"| {r['mean_velocity_error']:.3f} | {r['mean_li_error_mm']:.1f} "
            f"| {r['median_decision_ms']:.2f} |"
        )
    return "\n".join(lines)
