"""``synthesize``: a folder of simulated clips in the ``sidql dataset`` format.

Layout: ``OUT/<kind>/<kind>_<NNNNN>.npz`` (``sim.motion.clip.save_npz``, with the per-frame
learning labels of ``sim.simulate.generate.LABELS``) plus ``OUT/index.json`` whose ``trials``
entries hold the dataset fields (subject = the kind, trial, file, frames, fps, notes) and, per
clip, its task, ``generation`` parameters and seed and its scalar figures (mean assistance,
``physical``, tracking error, fall); per-frame arrays live in the clip file only, so the index
stays small however many clips there are.

Results are stored as they arrive: workers (processes or Ray tasks) return each clip file's
bytes (compressed where they were simulated) by value, this process writes each one atomically
at once and appends one line to ``OUT/journal.jsonl``
(the run's parameters first, then one line per finished task: kept, rejected or skipped), and
holds only a bounded window of tasks in flight (``sim.batch.iter_batch``). A run that stops
(a crash, a lost driver) keeps every clip written so far; ``resume=True`` continues it, skipping
the tasks its journal lists. ``index.json`` is written last, from the journal.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from sim.batch import iter_batch, ray_session, run_batch
from sim.errors import MotionDataError, UnknownNameError, UsageError, require_positive
from sim.files import remove_written, write_atomic
from sim.motion.clip import save_npz
from sim.motion.dataset import DatasetSummary, find_trials
from sim.motion.trial import read_trial
from sim.simulate.generate import (
    ALL_KINDS,
    CLIP_SECONDS,
    KINDS,
    SYNTH_CONTACT_REFERENCE,
    SYNTH_CONTROLLERS,
    SYNTH_DEFAULT_CONTROLLER,
    SYNTH_DRIFT,
    SYNTH_FOOT_LOCK,
    SYNTH_GAIN_CHOICE,
    SYNTH_LEAN,
    SYNTH_TERRAIN,
    TASK_OPTIONS,
    SynthTask,
    generate,
    synth_controller,
    task_dict,
)
from sim.simulate.journal import JOURNAL, clip_name, open_journal  # noqa: F401 (JOURNAL: its name)
from sim.simulate.journal import read as read_journal


def readable_trials(
    root, kinds: tuple[str, ...], *, workers: int | None = 1, ray: str | None = None
) -> tuple[list, list[dict]]:
    """The trials under ``root`` that parse (malformed ones are skipped and listed as
    ``{"amc", "asf", "error"}``), parsed by ``workers`` processes or Ray; none needed when
    every kind is procedural."""
    for k in kinds:
        if k not in ALL_KINDS:
            raise UnknownNameError("kind", k, ALL_KINDS)
    trials, skipped = [], []
    if any(k != "procedural" for k in kinds):
        if root is None:
            raise UsageError("kinds other than procedural need a folder of CMU trials (--data)")
        found = find_trials(root, skipped)  # links leaving root: listed, never read
        outcomes = run_batch(_parse, found, workers=workers, ray=ray, desc="read trials",
                             progress=False)  # fmt: skip
        for t, o in zip(found, outcomes, strict=True):
            if o.ok:
                trials.append(t)
            else:  # malformed files are skipped up front, not task by task
                skipped.append({"amc": str(t.amc), "asf": str(t.asf), "error": o.error})
        if not trials:
            raise MotionDataError(str(root), None, "no readable CMU trial to track")
    return trials, skipped


def _parse(trial) -> None:
    read_trial(trial.asf, trial.amc)  # ASF + AMC, or a BVH


def simulate_file(task: SynthTask) -> tuple[bytes, dict]:
    """One task in a worker: its clip file's bytes (``save_npz`` with the labels, compressed
    here rather than in the process that writes it) and its index record (frames, fps and the
    ``generate`` record without the per-frame labels)."""
    clip, record = generate(task)
    labels = record.pop("labels")
    with tempfile.TemporaryDirectory() as tmp:
        path = save_npz(clip, Path(tmp) / "clip.npz", extra=labels)
        data = path.read_bytes()
    return data, {"frames": clip.n_frames, "fps": clip.fps, **record}


def iter_tasks(
    trials: list,
    *,
    seed: int = 0,
    kinds: tuple[str, ...] = KINDS,
    seconds: float = CLIP_SECONDS,
    fps: float = 30.0,
    samples: int = 0,
    controller: str = SYNTH_DEFAULT_CONTROLLER,
    assist: float = 0.0,
    threads: int = 1,
    **options,
) -> Iterator[SynthTask]:
    """The plan: an endless stream of tasks cycling through ``kinds``; real-motion kinds take
    ``trials`` in seeded shuffled rounds (every trial once per round). Every prefix is the same
    whatever length is read, so a longer run extends a shorter one. ``options``: of
    ``generate.TASK_OPTIONS`` (``SynthTask``'s defaults where not named)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 2**20]))
    order: list = []
    i = 0
    while True:
        kind = kinds[i % len(kinds)]
        asf = amc = None
        if kind != "procedural":
            if not order:  # every trial once per round, in a seeded order
                order = [trials[j] for j in rng.permutation(len(trials))]
            t = order.pop()
            asf, amc = os.path.abspath(t.asf), os.path.abspath(t.amc)  # Ray: any worker's folder
        yield SynthTask(kind, seed, i, asf, amc, seconds, fps, samples, controller, assist,
                        threads, **options)  # fmt: skip
        i += 1


def plan_tasks(
    root: str | os.PathLike | None,
    n: int,
    *,
    seed: int = 0,
    kinds: tuple[str, ...] = KINDS,
    seconds: float = CLIP_SECONDS,
    fps: float = 30.0,
    samples: int = 0,
    controller: str = SYNTH_DEFAULT_CONTROLLER,
    assist: float = 0.0,
) -> tuple[list[SynthTask], list[dict]]:
    """The first ``n`` tasks of the plan (:func:`iter_tasks`) and the skipped trials."""
    trials, skipped = readable_trials(root, kinds)
    stream = iter_tasks(trials, seed=seed, kinds=kinds, seconds=seconds, fps=fps, samples=samples,
                        controller=controller, assist=assist)  # fmt: skip
    return [next(stream) for _ in range(n)], skipped


def synthesize(
    root: str | os.PathLike | None,
    out_dir: str | os.PathLike,
    n: int,
    *,
    seed: int = 0,
    kinds: tuple[str, ...] = KINDS,
    seconds: float = CLIP_SECONDS,
    fps: float = 30.0,
    samples: int = 0,
    controller: str | None = None,
    assist: float = 0.0,
    threads: int = 1,
    workers: int | None = None,
    ray: str | None = None,
    progress: bool = True,
    max_assistance: float | None = None,
    max_tries: int = 20,
    resume: bool = False,
    drift: bool | None = None,
    contact_reference: bool | None = None,
    lean: bool | None = None,
    gain_choice: float | None = None,
    foot_lock: bool | None = None,
    terrain: bool | None = None,
) -> DatasetSummary:
    """Generate ``n`` clips into ``out_dir`` (see the module docstring).

    ``max_assistance`` [body weight]: keep only clips whose mean root assistance, force [body
    weight] and torque [body weight x 1 m], is at most this (physical clips:
    ``sim.simulate.generate.PHYSICAL_BUDGET``); the plan's next tasks are
    simulated until ``n`` clips are kept or ``max_tries * n`` tasks were tried. The clips kept
    are the first ``n`` within the budget in plan order (whatever order tasks finish in);
    ``summary.rejected`` counts, per kind, the clips over the budget before the last one kept
    (also in ``index.json``).

    ``controller``: of the real-motion kinds (``sim.simulate.generate.SYNTH_CONTROLLERS``;
    None: ``SYNTH_DEFAULT_CONTROLLER``, ``eval --simulate``'s, the sampler); ``samples``: the
    sampler's rollouts per window (0: synth's default count, ``sim.simulate.generate.
    synth_controller``; > 0 with no ``controller``: the sampler); both are resolved here and
    recorded in the journal and the index. ``threads``: the sampler's rollout threads in each
    worker (the clips do not depend on it). ``assist``: the real-motion kinds' root assistance
    bound [body weight], 0 (none) unless asked for (with the plain tracker only). ``drift``,
    ``contact_reference``, ``lean``: ``SynthTask``'s options (None: ``generate.SYNTH_DRIFT``,
    ``SYNTH_CONTACT_REFERENCE``, ``SYNTH_LEAN``), recorded in the journal and the index;
    ``gain_choice``: the sampler's share of candidates on the stiff gains (None:
    ``SYNTH_GAIN_CHOICE`` with the sampler, 0 with another controller), likewise;
    ``foot_lock``: the contact-consistent reference foot-locked (None: ``SYNTH_FOOT_LOCK``);
    ``terrain``: real motion in the scene inferred from its trial (None: ``SYNTH_TERRAIN``;
    ``episode_scene``), off where every kind is procedural, recorded only where on.

    ``resume``: continue the run whose journal is in ``out_dir`` (same parameters but perhaps
    another ``n``, else a ``UsageError``); its finished tasks are not simulated again.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise UsageError(f"the number of clips must be a whole number >= 1; got {n!r}")
    require_positive(seconds, "seconds")
    require_positive(fps, "fps")
    if controller is not None and controller not in SYNTH_CONTROLLERS:
        raise UnknownNameError("controller", controller, SYNTH_CONTROLLERS)
    if samples and controller not in (None, "sampling"):
        raise UsageError(f"{samples} samples: only the sampling controller samples")
    controller, samples = synth_controller(samples, controller)
    if not 0 <= assist <= 1 or (assist and controller != "plain"):
        raise UsageError(f"assistance {assist} BW: 0 .. 1, and only for the plain tracker")
    require_positive(threads, "threads")
    if gain_choice is not None and not (0 <= gain_choice <= 1):
        raise UsageError(f"gain choice {gain_choice}: expected a share 0 .. 1")
    if gain_choice and controller != "sampling":
        raise UsageError(f"a gain choice is the sampler's; not for the {controller} controller")
    share = SYNTH_GAIN_CHOICE if gain_choice is None and controller == "sampling" else gain_choice
    real = any(k != "procedural" for k in kinds)  # a trial to infer a scene from
    task = {"samples": samples, "controller": controller, "assist": float(assist),
            "threads": int(threads), "gain_choice": float(share or 0.0),
            **_switches(drift, contact_reference, lean, foot_lock, terrain if real else False)}  # fmt: skip
    if task["foot_lock"] and not (controller == "wholebody" or task["contact_reference"]):
        raise UsageError("a foot lock needs the contact-consistent reference (--contact-reference)")
    with ray_session(ray, workers):  # Ray started or joined once for both batches
        return _synthesize(root, out_dir, n, seed, kinds, seconds, fps, task, workers, ray, progress,
                           max_assistance, max_tries, resume)  # fmt: skip


def _switches(*chosen) -> dict:
    """``SynthTask``'s switches ``drift``, ``contact_reference``, ``lean``, ``foot_lock`` and
    ``terrain`` as chosen (None: synth's default, ``generate.SYNTH_*``)."""
    names = ("drift", "contact_reference", "lean", "foot_lock", "terrain")
    defaults = (SYNTH_DRIFT, SYNTH_CONTACT_REFERENCE, SYNTH_LEAN, SYNTH_FOOT_LOCK, SYNTH_TERRAIN)
    return {k: bool(d if v is None else v) for k, v, d in zip(names, chosen, defaults, strict=True)}


def _synthesize(root, out_dir, n, seed, kinds, seconds, fps, task_kw, workers, ray, progress,
                max_assistance, max_tries, resume) -> DatasetSummary:  # fmt: skip
    start = time.perf_counter()
    out_dir = Path(out_dir)
    trials, skipped_inputs = readable_trials(root, kinds, workers=workers, ray=ray)
    threads = task_kw["threads"]
    task_kw = {k: v for k, v in task_kw.items() if k != "threads"}
    params = {
        "source": None if root is None else str(Path(root).resolve()),
        "n": n, "seed": seed, "kinds": list(kinds), "seconds": seconds, "fps": fps,
        "max_assistance": max_assistance, "max_tries": max_tries,
        **({"samples": task_kw["samples"]} if task_kw["samples"] else {}),
        "controller": task_kw["controller"], "assist": task_kw["assist"],
        **{k: task_kw[k] for k in TASK_OPTIONS if task_kw[k]},  # absent: off (runs before them)
    }  # fmt: skip
    out_dir.mkdir(parents=True, exist_ok=True)  # after the input checks: bad input leaves nothing
    done = read_journal(out_dir, params, trials) if resume else {}  # checked before any write
    limit = n if max_assistance is None else max_tries * n
    kept = {i for i, e in done.items() if "kept" in e}
    summary = DatasetSummary(skipped=list(skipped_inputs))

    def enough() -> bool:  # n kept (max_assistance: the plan's first n within the budget)
        return len(kept) >= n

    def pending_tasks() -> Iterator[SynthTask]:
        stream = iter_tasks(trials, seed=seed, kinds=kinds, seconds=seconds, fps=fps,
                            threads=threads, **task_kw)  # fmt: skip
        for task in stream:
            if task.index >= limit or enough():
                return
            if task.index not in done:
                yield task

    with open_journal(out_dir, params, fresh=not (resume and done)) as journal:
        for _, o in iter_batch(
            simulate_file, pending_tasks(), workers=workers, ray=ray, desc="synth",
            progress=progress, total=n if max_assistance is None else None,
        ):  # fmt: skip
            task: SynthTask = o.item
            if not o.ok:
                entry = {"skipped": {"task": task_dict(task), "amc": task.amc, "error": o.error}}
            else:
                data, record = o.result
                level = max(record["mean_assistance"], record["mean_assist_torque"])
                if max_assistance is not None and level > max_assistance:
                    entry = {"rejected": task.kind}
                else:
                    name = clip_name(task.kind, task.index)
                    path = out_dir / name
                    write_atomic(path, lambda f, data=data: f.write(data), root=out_dir)
                    entry = {"kept": _index_entry(task, name, path, out_dir, record)}
                    kept.add(task.index)
            done[task.index] = entry
            journal.write((json.dumps({"index": task.index, **entry}) + "\n").encode())
            journal.flush()  # a crash after this line loses nothing it names
    return _finish(out_dir, done, n, params, summary, start)


def _index_entry(task, name, path, out_dir, record) -> dict:
    record = dict(record)
    return {
        "subject": task.kind,
        "trial": name.stem,
        "asf": task.asf,
        "amc": task.amc,
        "file": str(name),
        "frames": record.pop("frames"),
        "fps": record.pop("fps"),
        "notes": [],
        "task": task_dict(task),
        **record,
    }


def _finish(out_dir: Path, done: dict, n: int, params: dict, summary, start) -> DatasetSummary:
    """Write ``index.json``: the first ``n`` kept clips in plan order; files of clips kept past
    them (tasks that were already running) are removed, so the folder does not depend on the
    order tasks finished in."""
    kept = sorted(i for i, e in done.items() if "kept" in e)
    last = kept[n - 1] if len(kept) >= n else max(done, default=-1)
    kinds = params["kinds"]
    for i in kept[n:]:  # only the names this run gives its clips (journal.read checked them)
        remove_written(out_dir / clip_name(kinds[i % len(kinds)], i), root=out_dir)
    rejected: dict[str, int] = {}
    for i in sorted(done):
        if i > last:
            break
        e = done[i]
        if "kept" in e:
            summary.written.append(e["kept"])
        elif "rejected" in e:
            rejected[e["rejected"]] = rejected.get(e["rejected"], 0) + 1
        else:
            summary.skipped.append(e["skipped"])
    summary.rejected = rejected
    summary.seconds = time.perf_counter() - start
    index = {
        "source": params["source"],
        "skeleton": "humanoid",
        "fps": params["fps"],
        "synthetic": {
            **{k: params[k] for k in ("n", "seed", "kinds", "seconds", "max_assistance")},
            "samples": params.get("samples", 0),
            "controller": params["controller"], "assist": params["assist"],
            **{k: params.get(k, False) for k in TASK_OPTIONS},
            "tasks_tried": last + 1, "rejected": rejected,
        },
        "trials": summary.written,
        "skipped": summary.skipped,
    }  # fmt: skip
    text = json.dumps(index, indent=1).encode()
    write_atomic(out_dir / "index.json", lambda f: f.write(text), root=out_dir)
    return summary
