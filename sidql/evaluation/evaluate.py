"""Evaluate keyframe methods on the paper's protocol: every method at every W on every clip.

Protocol: every CMU trial at 30 fps (every 4th frame of 120 fps), cut into non-overlapping 60-frame
clips from frame 0 (:mod:`sidql.evaluation.cases`); each method chooses W keyframes per clip (both
ends included); the clip is rebuilt with the reconstruction the method declares and scored
(:mod:`sidql.evaluation.scoring`); with physics, the original, its noise floor and every
reconstruction get the physics figures (:mod:`sidql.evaluation.trial_physics`). The tables:
:mod:`sidql.evaluation.tables`.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Sequence
from functools import partial

import numpy as np

from sidql.evaluation.cases import Case, clip_seed
from sidql.evaluation.floors import floor_report
from sidql.evaluation.scoring import (
    NOISE_FLOOR,
    PHYSICS_KEYS,
    noise_figures,
    physics_figures,
    score,
)
from sidql.evaluation.significance import paired_comparisons, versus_original
from sidql.evaluation.trial_physics import physics_setup, simulate_setup
from sidql.keyframes import methods, reconstructions
from sidql.keyframes.counts import check_counts
from sim.batch import Shared, iter_batch, shared_value
from sim.errors import UsageError
from sim.simulate.validate import DEFAULT_TERRAIN, SIMULATE_KEYS


def evaluate(
    cases: Sequence[Case],
    method_names: Iterable[str],
    keyframe_counts: Iterable[int],
    *,
    seed: int = 0,
    progress: bool = True,
    physics: bool = False,
    simulate: bool = False,
    simulate_samples: int = 0,
    simulate_threads: int = 1,
    simulate_terrain: bool = DEFAULT_TERRAIN,
    workers: int = 1,
    ray: str | None = None,
    chunk: int = 4,
    reconstruction: str | None = None,
) -> dict:
    """Run every method at every W on every case (``reconstruction``: rebuild every method's
    keyframes with this registered reconstruction instead of its own).

    The per-clip work (each method's choice and reconstruction, the physics of the original and
    of every reconstruction, the forward simulations) runs through ``sim.batch.iter_batch``:
    in this process (``workers=1``), ``workers`` processes or Ray (``ray``), in tasks of up to
    ``chunk`` clips of one trial that carry their trial's physics set-up; the rows come back in
    the same order whatever the executor (decision times are measured where the method ran).

    Returns:
        ``{"results": [row...], "per_clip": [row...], "comparisons": ..., "failed": [...]}``
        (``"floors"`` too with ``physics``, ``"versus_original"`` with ``simulate``:
        :func:`sidql.evaluation.significance.versus_original`, each method's simulation figures
        against the original's, paired over clips); a task that fails (bad input or a bug in one clip)
        is reported on stderr and listed in ``failed`` (``source``, ``start_frames`` of its
        clips, ``problem``), its clips left out of every row: the others are kept. A result row
        holds method, keyframes, clips, mean_q, mean_q_hermite, mean_geodesic_deg, mpjpe_mm,
        velocity_error_mm_s, mean_li_error_mm, median_decision_ms; a per-clip row holds source,
        start_frame, method, keyframes, indices, q and the other scores. With ``physics`` every
        row also carries the :mod:`sim.physics` figures (means over clips: ``PHYSICS_KEYS``), and one
        result row (and per-clip rows) for method ``original``, the clip itself (all frames
        kept: ``keyframes`` = clip length, errors 0). With ``simulate`` (needs ``physics``)
        every row also carries the forward-simulation figures of
        :mod:`sim.simulate.validate` (result rows: means over clips; ``simulate_samples``,
        ``simulate_threads``, ``simulate_terrain``: ``trial_physics.simulate_setup``'s
        ``samples``, ``threads``, ``terrain``).
    """
    if simulate and not physics:
        raise UsageError("simulate needs physics (the IK fit it tracks)")
    method_names = list(method_names)
    counts = list(keyframe_counts)
    check_counts(counts, min((c.clip.n_frames for c in cases), default=2**31 - 1))
    _check_names(cases, method_names, counts, reconstruction)
    setup = physics_setup(cases) if physics else {}
    bodies = (simulate_setup(cases, simulate_samples, simulate_threads, simulate_terrain)
              if simulate else {})  # fmt: skip
    items = _tasks(cases, chunk, setup, bodies)
    task = partial(_evaluate_chunk, method_names=tuple(method_names), counts=tuple(counts),
                   seed=seed, reconstruction=reconstruction)  # fmt: skip
    by_case: dict[int, list[dict]] = {}
    failed: list[dict] = []
    for _, o in iter_batch(task, items, workers=workers, ray=ray, desc="evaluate",
                           progress=progress, total=len(items)):  # fmt: skip
        if o.ok:
            by_case.update(o.result)
        else:
            failed.append(_failure(o.item[0], o.error))
    done = [i for i in range(len(cases)) if i in by_case]
    rows = [by_case[i] for i in done]
    n_frames = cases[0].clip.n_frames if cases else 0
    per_clip, results, originals = _collect(
        rows, n_frames, method_names, counts, physics=physics, simulate=simulate
    )
    out = {"results": results, "per_clip": per_clip}
    out["comparisons"] = paired_comparisons(per_clip, method_names, seed=seed)
    if physics:
        out["floors"] = floor_report(setup, originals)
    if simulate:  # could a body do each method's motion as well as the original?
        out["versus_original"] = versus_original(per_clip, method_names, seed=seed)
    out["failed"] = failed
    return out


def _check_names(cases, method_names: list, counts: list, reconstruction: str | None) -> None:
    """Fail before any work, here and not in a worker, on an unknown method or reconstruction
    name (listing the known ones) or a method that cannot choose (a learned one's missing
    file)."""
    for name in method_names:
        methods.get(name)
        if cases and counts:
            methods.select(name, cases[0].clip, counts[0], seed=0)
    if reconstruction is not None:
        reconstructions.get(reconstruction)


def _collect(
    rows: Sequence[list[dict]], n_frames: int, method_names, counts, *, physics, simulate
) -> tuple[list[dict], list[dict], list[dict]]:
    """The per-clip rows, result rows and the original's rows of :func:`evaluate` from each
    evaluated case's rows (``rows``: per case, the original's and the noise floor's with
    ``physics``, then each method at each W; ``n_frames``: the clips' length)."""
    per_clip: list[dict] = []
    results: list[dict] = []
    originals: list[dict] = []
    if physics and rows:
        originals = [r[0] for r in rows]
        noise = [r[1] for r in rows]
        per_clip.extend(originals + noise)
        for name, group in (("original", originals), (NOISE_FLOOR, noise)):
            with_sim = simulate and name == "original"
            results.append(_baseline_result(name, n_frames, group, with_sim))
    first = 2 if physics else 0
    for j, (name, W) in enumerate((m, W) for m in method_names for W in counts):
        group = [r[first + j] for r in rows]
        per_clip.extend(group)
        if group:
            results.append(_method_result(name, W, group, physics, simulate))
    return per_clip, results, originals


def _failure(chunk: list, error: str) -> dict:
    """The record of a task of :func:`evaluate` that failed (its clips are left out of every
    row), also reported on stderr."""
    clip = chunk[0][1].clip
    starts = [case.clip.start_frame for _, case in chunk]
    print(f"failed {clip.source} (clips from frames {starts}): {error}", file=sys.stderr)
    return {"source": clip.source, "start_frames": starts, "problem": error}


def _baseline_result(name: str, n_frames: int, rows: Sequence[dict], simulate: bool) -> dict:
    """The result row of the original (every frame kept) or of its noise floor: errors 0, the
    physics means (and the simulation's, with ``simulate``) over ``rows``."""
    zero = ("mean_q", "mean_q_hermite", "mean_geodesic_deg", "mpjpe_mm", "velocity_error_mm_s")
    return {
        "method": name, "keyframes": n_frames, "clips": len(rows),
        **dict.fromkeys(zero, 0.0), "mean_li_error_mm": 0.0,
        "median_decision_ms": 0.0, **_physics_means(rows),
        **(_simulate_means(rows) if simulate else {}),
    }  # fmt: skip


def _method_result(name: str, W: int, rows: Sequence[dict], physics: bool, simulate: bool) -> dict:
    """The result row of method ``name`` at ``W``: means over its per-clip ``rows``."""
    return {
        "method": name,
        "keyframes": W,
        "clips": len(rows),
        "mean_q": float(np.mean([r["q"] for r in rows])),
        "mean_q_hermite": float(np.mean([r["q_hermite"] for r in rows])),
        "mean_geodesic_deg": float(np.mean([r["geodesic_deg"] for r in rows])),
        "mpjpe_mm": float(np.mean([r["mpjpe_mm"] for r in rows])),
        "velocity_error_mm_s": float(np.mean([r["velocity_error_mm_s"] for r in rows])),
        "mean_li_error_mm": float(np.mean([r["li_error_mm"] for r in rows])),
        "median_decision_ms": float(np.median([r["decision_ms"] for r in rows])),
        "reconstruction": rows[0]["reconstruction"],
        "mean_side_bytes": float(np.mean([r["side_bytes"] for r in rows])),
        **(_physics_means(rows) if physics else {}),
        **(_simulate_means(rows) if simulate else {}),
    }


def _tasks(cases: Sequence[Case], chunk: int, setup: dict, bodies: dict) -> list[tuple]:
    """The tasks of :func:`evaluate`: ``([(position, case)...], physics set-up or None, simulated
    body or None)`` per chunk of up to ``chunk`` consecutive cases of one trial, the last two
    wrapped in :class:`sim.batch.Shared` (one per trial: Ray ships each to a worker once)."""
    shared = {}  # one handle per trial: on Ray its set-up reaches each worker once
    items = []
    for group in _trial_chunks(cases, chunk):
        source = cases[group[0]].clip.source
        if source not in shared:
            shared[source] = (Shared(setup.get(source)), Shared(bodies.get(source)))
        items.append(([(i, cases[i]) for i in group], *shared[source]))
    return items


def _trial_chunks(cases: Sequence[Case], size: int) -> list[list[int]]:
    """Positions of consecutive cases of one trial, at most ``size`` per chunk (the tasks of
    :func:`evaluate`)."""
    out: list[list[int]] = []
    for i, c in enumerate(cases):
        if out and cases[out[-1][0]].clip.source == c.clip.source and len(out[-1]) < size:
            out[-1].append(i)
        else:
            out.append([i])
    return out


def _evaluate_chunk(
    item, *, method_names, counts, seed, reconstruction=None
) -> list[tuple[int, list[dict]]]:
    """One task of :func:`evaluate`: per case of ``item = ([(position, case)...], physics set-up
    or None, simulated body or None)``, its position and rows: the original's (with physics),
    then each method at each W."""
    cases, phys, body = item[0], shared_value(item[1]), shared_value(item[2])
    out = []
    for position, case in cases:
        rows, original_qpos = [], None
        if phys is not None:  # the original's row, then the noise floor's
            analysis = phys.analyse(case.clip)
            original_qpos = analysis["per_frame"]["qpos"]
            sim = body.run(original_qpos, case.clip.fps) if body is not None else {}
            key = {"source": case.clip.source, "start_frame": case.clip.start_frame}
            rows.append(
                {**key, "method": "original", "keyframes": case.clip.n_frames,
                 **physics_figures(analysis), **sim}
            )  # fmt: skip
            noisy = phys.noise_floor(case.clip, seed=clip_seed(seed, case.index, 0))
            rows.append(
                {**key, "method": NOISE_FLOOR, "keyframes": case.clip.n_frames,
                 **noise_figures(physics_figures(noisy, analysis), rows[-1])}
            )  # fmt: skip
        for name in method_names:
            for W in counts:
                t0 = time.perf_counter()
                k = methods.select(name, case.clip, W, seed=clip_seed(seed, case.index, W))
                ms = 1000.0 * (time.perf_counter() - t0)
                rows.append(
                    {
                        "source": case.clip.source,
                        "start_frame": case.clip.start_frame,
                        "method": name,
                        "keyframes": W,
                        "indices": k.tolist(),
                        **score(case, k, name, phys, body, original_qpos, reconstruction),
                        "decision_ms": ms,
                    }
                )
        out.append((position, rows))
    return out


def _simulate_means(rows: Sequence[dict]) -> dict:
    """Mean over clips of each :data:`sim.simulate.validate.SIMULATE_KEYS` figure (the fall
    time: over the clips that fell, None if none did), and its median (``<key>_median``)."""
    return _means(rows, SIMULATE_KEYS)


def _physics_means(rows: Sequence[dict]) -> dict:
    """Mean over clips of each :data:`sidql.evaluation.scoring.PHYSICS_KEYS` figure, and its median (``<key>_median``:
    a few violent clips dominate the dynamics means), over ``<key>_clips`` clips with a value."""
    return _means(rows, PHYSICS_KEYS, counts=True)


def _means(rows: Sequence[dict], keys, *, counts: bool = False) -> dict:
    """Per key, the mean and the median over the rows with a finite value (None where none has
    one), and with ``counts`` how many rows had one (``<key>_clips``)."""
    out = {}
    for k in keys:
        v = np.array([np.nan if r.get(k) is None else r[k] for r in rows], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = float(v.mean()) if v.size else None
        out[f"{k}_median"] = float(np.median(v)) if v.size else None
        if counts:
            out[f"{k}_clips"] = int(v.size)
    return out
