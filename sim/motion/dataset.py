"""Folders of CMU files: find trials, and ingest them all in parallel worker processes.

Layout: subject folders holding ``SS.asf`` beside ``SS_TT.amc`` (any depth; names compared
case-insensitively). A trial whose ASF is missing is reported, not silently dropped.
"""

from __future__ import annotations

import json
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from sim.batch import run_batch
from sim.errors import MotionDataError

_TRIAL_RE = re.compile(r"^(?P<subject>[^_]+)_(?P<trial>.+)\.amc$", re.IGNORECASE)


@dataclass(frozen=True)
class Trial:
    """One motion of one subject: its ASF skeleton and AMC motion."""

    subject: str
    name: str  # e.g. "01_02"
    asf: Path
    amc: Path


@dataclass
class DatasetSummary:
    """Outcome of a batch ingest: what was written and what was skipped and why."""

    written: list[dict] = field(default_factory=list)
    skipped: list[dict] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.skipped


def find_trials(root: str | os.PathLike) -> list[Trial]:
    """All trials under ``root``, sorted by subject then trial.

    An AMC ``SS_TT.amc`` pairs with ``SS.asf`` in its own folder (or, failing that, the only ASF
    there). AMCs with no skeleton are returned with ``asf`` pointing at the expected path, so the
    ingest reports them as bad input instead of dropping them.
    """
    root = Path(root)
    if not root.is_dir():
        raise MotionDataError(str(root), None, "not a directory")
    trials = []
    for amc in sorted(p for p in root.rglob("*") if p.suffix.lower() == ".amc" and p.is_file()):
        m = _TRIAL_RE.match(amc.name)
        subject = m.group("subject") if m else amc.parent.name
        asfs = {p.name.lower(): p for p in amc.parent.iterdir() if p.suffix.lower() == ".asf"}
        asf = asfs.get(f"{subject.lower()}.asf")
        if asf is None and len(asfs) == 1:
            asf = next(iter(asfs.values()))
        if asf is None:
            asf = amc.parent / f"{subject}.asf"
        trials.append(Trial(subject=subject, name=amc.stem, asf=asf, amc=amc))
    return sorted(trials, key=lambda t: (t.subject, t.name))


def _ingest_one(trial: Trial, out_dir: str, skeleton: str, fps: float) -> dict:
    import warnings

    from sim.motion.clip import save_npz
    from sim.motion.ingest import load_motion

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        clip = load_motion(trial.asf, trial.amc, skeleton=skeleton, fps=fps)
    out = Path(out_dir) / trial.subject / f"{trial.name}.npz"
    save_npz(clip, out)
    return {
        "subject": trial.subject,
        "trial": trial.name,
        "asf": str(trial.asf),
        "amc": str(trial.amc),
        "file": str(out.relative_to(out_dir)),
        "frames": clip.n_frames,
        "fps": clip.fps,
        "notes": [str(w.message) for w in caught],
    }


def ingest_directory(
    root: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    skeleton: str = "subject",
    fps: float = 30.0,
    workers: int | None = None,
    progress: bool = True,
    ray: str | None = None,
) -> DatasetSummary:
    """Ingest every trial under ``root`` into ``out_dir/<subject>/<trial>.npz`` plus ``index.json``.

    Bad files are skipped and listed (with the error naming file, line and problem); every good
    result is kept. Each output, the index included, is written atomically.
    """

    from sim.motion.clip import write_atomic

    start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    trials = find_trials(root)
    summary = DatasetSummary()
    outcomes = run_batch(
        _ingest_task, [(t, str(out_dir), skeleton, fps) for t in trials],
        workers=workers, ray=ray, desc="ingest", progress=progress,
    )  # fmt: skip
    for t, o in zip(trials, outcomes, strict=True):
        if o.ok:
            summary.written.append(o.result)
        else:  # bad input or a bug: either way only this trial is lost
            summary.skipped.append({"amc": str(t.amc), "asf": str(t.asf), "error": o.error})
    summary.written.sort(key=lambda r: (r["subject"], r["trial"]))
    summary.skipped.sort(key=lambda r: r["amc"])
    summary.seconds = time.perf_counter() - start
    index = {
        "source": str(Path(root).resolve()),
        "skeleton": skeleton,
        "fps": fps,
        "trials": summary.written,
        "skipped": summary.skipped,
    }
    write_atomic(out_dir / "index.json", lambda f: f.write(json.dumps(index, indent=2).encode()))
    return summary


def _ingest_task(args) -> dict:
    return _ingest_one(*args)


def load_dataset_clips(out_dir: str | os.PathLike, length: int = 60):
    """Every ``length``-frame clip (non-overlapping, from frame 0) of a folder written by
    ``sidql dataset`` or ``sidql synth`` (its ``index.json``); returns (clips, subjects)."""
    from sim.motion.clip import load_npz

    out_dir = Path(out_dir)
    try:
        index = json.loads((out_dir / "index.json").read_text())
    except (OSError, ValueError) as e:
        raise MotionDataError(str(out_dir / "index.json"), None, f"not a dataset index: {e}") from e
    clips, subjects = [], []
    for entry in index.get("trials", []):
        for c in load_npz(out_dir / entry["file"]).split(length):
            clips.append(c)
            subjects.append(str(entry.get("subject", "")))
    return clips, subjects
