"""The clips an evaluation scores (:class:`Case`): every ``length``-frame clip of every trial of
a data folder (:func:`load_cases`), with its chart and true protocol points; and the per-clip
seeds of randomised methods (:func:`clip_seed`).

Loading needs ``sim.motion.ingest`` (MuJoCo); units: metres, seconds.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from sidql.keyframes.spherical import SphericalSeries, chart, protocol_indices
from sim.batch import run_batch
from sim.errors import MotionDataError
from sim.motion.clip import Clip
from sim.motion.dataset import dataset_clips, find_trials
from sim.motion.ingest import load_clips


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
    asf: str = ""


def make_case(clip: Clip, index: int = 0, asf: str = "") -> Case:
    """``asf``: the subject's skeleton file (needed by ``evaluate(..., physics=True)``)."""
    idx = protocol_indices(clip)
    return Case(clip, chart(clip), clip.positions[:, idx], clip.velocities[:, idx], index, asf)


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
    cases: list[Case] = []
    skipped: list[dict] = []
    if (Path(data_dir) / "index.json").is_file():
        rows = dataset_clips(data_dir, length, skipped)  # each file read once, named as read
        for s in skipped:
            print(f"skipped {s['amc']}: {s['problem']}", file=sys.stderr)
        rates = sorted({r[0].fps for r in rows} - {float(fps)})
        if rates:  # the clips are what they are: a different rate would be mislabelled
            raise MotionDataError(
                str(Path(data_dir) / "index.json"), None,
                f"clips at {', '.join(f'{r:g}' for r in rates)} fps, not {fps:g} (pass --fps)",
            )  # fmt: skip
        bad: dict[str, str] = {}
        for c, s, a, file in rows:  # a clip without the protocol's bones: its file listed once
            if subjects is not None and s not in subjects:
                continue
            try:
                cases.append(make_case(c, len(cases), a))
            except MotionDataError as e:
                bad.setdefault(str(file), f"{e.problem if e.path == c.source else e}")
        for source, problem in bad.items():
            skipped.append({"amc": source, "problem": problem})
            print(f"skipped {source}: {problem}", file=sys.stderr)
        return cases, skipped
    outside: list[dict] = []  # symbolic links leaving data_dir: listed, never read
    trials = find_trials(data_dir, outside)
    for o in outside:
        skipped.append({"amc": o["amc"], "problem": o["error"]})
        print(f"skipped {o['amc']}: {o['error']}", file=sys.stderr)
    if subjects is not None:
        trials = [t for t in trials if t.subject in set(subjects)]
    load = partial(_trial_clips, fps=fps, length=length, skeleton=skeleton, load=load_clips)
    outcomes = run_batch(
        load, trials, workers=workers, ray=ray, desc="load trials", progress=progress
    )
    for trial, o in zip(trials, outcomes, strict=True):
        error = o.error
        if o.ok:
            first = len(cases)  # case index = position in the whole run (seeds depend on it)
            asf = str(trial.asf) if skeleton == "subject" else ""  # physics: the subject's model
            try:  # e.g. a skeleton without the protocol's bones: this trial only is bad
                cases += [make_case(c, first + i, asf) for i, c in enumerate(o.result)]
            except MotionDataError as e:
                error = str(e)
        if error is not None:
            skipped.append({"amc": str(trial.amc), "problem": error})
            print(f"skipped {trial.amc}: {error}", file=sys.stderr)
    return cases, skipped


def _trial_clips(trial, *, fps, length, skeleton, load):
    return load(trial.asf, trial.amc, fps=fps, length=length, skeleton=skeleton)


def clip_seed(seed: int, index: int, W: int) -> int:
    """Deterministic per-clip, per-W seed for randomised methods."""
    return int(np.random.SeedSequence([seed, index, W]).generate_state(1)[0])
