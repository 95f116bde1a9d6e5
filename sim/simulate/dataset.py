"""``synthesize``: a folder of simulated clips in the ``sidql dataset`` format.

Layout: ``OUT/<kind>/<kind>_<NNNNN>.npz`` (``sim.motion.clip.save_npz``) plus ``OUT/index.json``
whose ``trials`` entries hold the dataset fields (subject = the kind, trial, file, frames, fps,
notes) and, per clip, its task, ``generation`` parameters and seed, per-frame ``assistance``,
``tracking_mpjpe_mm`` and ``fell``. Workers return clips by value; this process writes every file
atomically, so a failed task leaves nothing behind and is listed under ``skipped``.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from sim.acclaim.reader import parse_amc, parse_asf
from sim.batch import run_batch
from sim.errors import MotionDataError, UnknownNameError
from sim.files import write_atomic
from sim.motion.clip import save_npz
from sim.motion.dataset import DatasetSummary, find_trials
from sim.simulate.generate import ALL_KINDS, KINDS, SynthTask, generate, task_dict


def plan_tasks(
    root: str | os.PathLike | None,
    n: int,
    *,
    seed: int = 0,
    kinds: tuple[str, ...] = KINDS,
    seconds: float = 4.0,
    fps: float = 30.0,
) -> tuple[list[SynthTask], list[dict]]:
    """``n`` tasks cycling through ``kinds``; real-motion kinds take the trials under ``root`` in
    seeded shuffled rounds (every trial once per round).

    Trials that fail to parse are skipped and listed (``{"amc", "asf", "error"}``).
    """
    for k in kinds:
        if k not in ALL_KINDS:
            raise UnknownNameError("kind", k, ALL_KINDS)
    trials, skipped = [], []
    if any(k != "procedural" for k in kinds):
        if root is None:
            raise MotionDataError(
                None, None, "kinds other than procedural need a folder of CMU trials"
            )
        for t in find_trials(root, skipped):  # links leaving root: listed, never read
            try:
                parse_amc(t.amc, parse_asf(t.asf))  # malformed files are skipped up front
                trials.append(t)
            except MotionDataError as e:
                skipped.append({"amc": str(t.amc), "asf": str(t.asf), "error": str(e)})
        if not trials:
            raise MotionDataError(str(root), None, "no readable CMU trial to track")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 2**20]))
    order: list = []
    tasks = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        asf = amc = None
        if kind != "procedural":
            if not order:  # every trial once per round, in a seeded order
                order = [trials[j] for j in rng.permutation(len(trials))]
            t = order.pop()
            asf, amc = os.path.abspath(t.asf), os.path.abspath(t.amc)  # Ray: any worker's folder
        tasks.append(SynthTask(kind, seed, i, asf, amc, seconds, fps))
    return tasks, skipped


def synthesize(
    root: str | os.PathLike | None,
    out_dir: str | os.PathLike,
    n: int,
    *,
    seed: int = 0,
    kinds: tuple[str, ...] = KINDS,
    seconds: float = 4.0,
    fps: float = 30.0,
    workers: int | None = None,
    ray: str | None = None,
    progress: bool = True,
    max_assistance: float | None = None,
    max_tries: int = 20,
) -> DatasetSummary:
    """Generate ``n`` clips into ``out_dir`` (see the module docstring).

    ``max_assistance`` [body weight]: keep only clips whose mean root assistance is at most this
    (physical clips: ``sim.simulate.generate.PHYSICAL_BUDGET``); the others are dropped and more
    tasks of the same plan (the next indices) are simulated until ``n`` clips are kept or
    ``max_tries * n`` tasks were tried. ``summary.rejected`` counts the dropped clips per kind
    (also in ``index.json``).
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    planned, skipped = plan_tasks(root, n, seed=seed, kinds=kinds, seconds=seconds, fps=fps)
    out_dir.mkdir(parents=True, exist_ok=True)  # after the input checks: bad input leaves nothing
    summary = DatasetSummary(skipped=skipped)
    rejected: dict[str, int] = {}
    tried = 0
    while True:
        tasks = planned[tried:]
        tried = len(planned)
        for task, o in zip(
            tasks,
            run_batch(generate, tasks, workers=workers, ray=ray, desc="synth", progress=progress),
            strict=True,
        ):  # fmt: skip
            if len(summary.written) >= n:
                continue  # enough kept: the rest of this round is not written
            if not o.ok:
                summary.skipped.append({"task": task_dict(task), "amc": task.amc, "error": o.error})
                continue
            clip, record = o.result
            if max_assistance is not None and record["mean_assistance"] > max_assistance:
                rejected[task.kind] = rejected.get(task.kind, 0) + 1
                continue
            labels = record.pop("labels", None)  # per-frame arrays: the clip file, not the index
            name = f"{task.kind}_{task.index:05d}"
            path = out_dir / task.kind / f"{name}.npz"
            save_npz(clip, path, extra=labels)
            summary.written.append(
                {
                    "subject": task.kind,
                    "trial": name,
                    "asf": task.asf,
                    "amc": task.amc,
                    "file": str(path.relative_to(out_dir)),
                    "frames": clip.n_frames,
                    "fps": clip.fps,
                    "notes": [],
                    "task": task_dict(task),
                    **record,
                }
            )
        missing = n - len(summary.written)
        if max_assistance is None or missing <= 0 or tried >= max_tries * n:
            break
        # the next tasks of the same plan, as many as the acceptance so far suggests (+1)
        kept = max(len(summary.written), 1)
        more = min(max_tries * n, tried + int(np.ceil(missing * tried / kept)) + 1)
        planned, _ = plan_tasks(root, more, seed=seed, kinds=kinds, seconds=seconds, fps=fps)
    summary.seconds = time.perf_counter() - start
    summary.rejected = rejected
    index = {
        "source": None if root is None else str(Path(root).resolve()),
        "skeleton": "humanoid",
        "fps": fps,
        "synthetic": {
            "n": n, "seed": seed, "kinds": list(kinds), "seconds": seconds,
            "max_assistance": max_assistance, "tasks_tried": tried, "rejected": rejected,
        },
        "trials": summary.written,
        "skipped": summary.skipped,
    }  # fmt: skip
    write_atomic(out_dir / "index.json", lambda f: f.write(json.dumps(index, indent=1).encode()))
    return summary
