"""The journal of a ``synth`` run (``OUT/journal.jsonl``), written as results arrive and read back
by ``--resume`` as hostile input.

Layout: one JSON object a line; the first ``{"params": {...}}`` (the run's parameters), then one
line per finished task: ``{"index": i, "kept": ENTRY}`` (its ``index.json`` entry),
``{"index": i, "rejected": KIND}`` or ``{"index": i, "skipped": {"task", "amc", "error"}}``.

Read back, every line is checked against what the run itself would have written (:func:`read`):
at most :data:`MAX_LINE_BYTES` a line and :data:`MAX_JOURNAL_BYTES` in all; task ``i`` of kind
``kinds[i % len(kinds)]`` (the plan's cycle); a kept clip's file named as the run names it
(:func:`clip_name`: ``<kind>/<kind>_<i:05d>.npz``), its task, trial and source files those of
the plan (a trial of the input folder), its frames and rate in range, every text printable.
Anything else is one line naming the journal and its line (exit 2), before anything is deleted
or written. The journal is never a link, FIFO or device (:func:`sim.files.open_append`).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path, PurePosixPath

from sim.errors import MotionDataError, UsageError
from sim.files import excerpt, open_append, open_inside
from sim.motion.clip import MAX_CLIP_FRAMES
from sim.simulate.generate import TASK_OPTIONS, SynthTask, task_dict

JOURNAL = "journal.jsonl"
#: A journal line (one task's record) longer than this is refused [bytes].
MAX_LINE_BYTES = 1 << 16
#: A journal larger than this is refused [bytes] (~10^5 tasks).
MAX_JOURNAL_BYTES = 256 << 20
#: An index of the plan beyond this is refused (2^31: far past any run).
MAX_TASK_INDEX = (1 << 31) - 1


def clip_name(kind: str, index: int) -> PurePosixPath:
    """The clip file of task ``index`` of ``kind``, relative to the output folder: the one name
    a run gives it, so the only kind of file a run deletes (:func:`sim.files.remove_written`)."""
    return PurePosixPath(kind, f"{kind}_{index:05d}.npz")


def open_journal(out_dir: Path, params: dict, *, fresh: bool):
    """The journal of ``out_dir`` open for appending; ``fresh``: a new one holding ``params``."""
    f = open_append(out_dir / JOURNAL, root=out_dir, fresh=fresh)
    if fresh:
        f.write((json.dumps({"params": params}) + "\n").encode())
        f.flush()
    return f


def read(out_dir: Path, params: dict, trials: list) -> dict[int, dict]:
    """Finished tasks of the run journalled in ``out_dir`` (task index -> its entry; the last
    line of a task wins), checked line by line (see the module docstring); a kept clip whose file
    is gone counts as not done. ``trials``: the readable trials of the input folder.

    Raises:
        UsageError: a run with other parameters than ``params`` (but ``n``).
        MotionDataError: a malformed journal or a link on the way to a clip (one line).
    """
    path = out_dir / JOURNAL
    f = open_inside(path, MAX_JOURNAL_BYTES, root=out_dir)
    if f is None:
        return {}
    sources = {(os.path.abspath(t.asf), os.path.abspath(t.amc)) for t in trials}
    done: dict[int, dict] = {}
    with f:
        head = _line(f, path, 1)
        if head is None:
            return {}
        old = head.get("params") if isinstance(head, dict) else None
        same = lambda a: {k: v for k, v in a.items() if k != "n"}  # noqa: E731
        if not isinstance(old, dict) or same(old) != same(params):
            raise UsageError(f"{path}: a run with other parameters ({excerpt(str(old), 300)}); "
                             "cannot resume")  # fmt: skip
        number = 1
        while (e := _line(f, path, number := number + 1)) is not None:
            i, entry = _task_line(e, params, sources, path, number)
            if "kept" in entry and not _clip_there(out_dir, entry["kept"]["file"]):
                continue
            done[i] = entry
    return done


def _line(f, path: Path, number: int):
    """The next line's object; None at the end or for a last line cut short by a crash."""
    raw = f.readline(MAX_LINE_BYTES + 1)
    if not raw:
        return None
    if len(raw) > MAX_LINE_BYTES:
        raise MotionDataError(str(path), number, f"a line of over {MAX_LINE_BYTES:,} bytes")
    try:
        return json.loads(raw)
    except (ValueError, RecursionError):
        if not raw.endswith(b"\n") and not f.read(1):  # the crash cut the last line: redone
            return None
        raise MotionDataError(str(path), number, "not a JSON line") from None


def _task_line(e, params: dict, sources: set, path: Path, number: int) -> tuple[int, dict]:
    """``(index, entry)`` of one task line, checked against the plan."""

    def bad(problem):
        return MotionDataError(str(path), number, f"{problem}; not a line this run writes")

    i = e.get("index") if isinstance(e, dict) else None
    if type(i) is not int or not 0 <= i <= MAX_TASK_INDEX:
        raise bad("no task index (an integer >= 0)")
    rest = {k: v for k, v in e.items() if k != "index"}
    if len(rest) != 1 or next(iter(rest)) not in ("kept", "rejected", "skipped"):
        raise bad("not one of kept, rejected, skipped")
    (what, value), = rest.items()  # fmt: skip
    kind = params["kinds"][i % len(params["kinds"])]
    if what == "rejected":
        if value != kind:
            raise bad(f"task {i} is of kind {kind}")
        return i, rest
    if not isinstance(value, dict) or not _printable(value):
        raise bad(f"{what}: not an object of printable values")
    task = value.get("task")
    source = (task.get("asf"), task.get("amc")) if isinstance(task, dict) else None
    if source != (None, None) or kind != "procedural":
        if source not in sources:
            raise bad(f"{what}: task {i} is not of a trial of the input folder")
    want = task_dict(SynthTask(kind, params["seed"], i, *source, params["seconds"],
                               params["fps"], params.get("samples", 0),
                               params.get("controller", "plain"), params.get("assist", 0.0),
                               **{k: params.get(k, False) for k in TASK_OPTIONS}))  # fmt: skip
    if task != want:
        raise bad(f"{what}: not task {i} of this run")
    if what == "skipped":
        if value.get("amc") != source[1] or not isinstance(value.get("error"), str):
            raise bad("skipped: no error message")
        return i, rest
    name = clip_name(kind, i)
    frames, fps = value.get("frames"), value.get("fps")
    checks = (
        (value.get("file") == str(name), f"the file of task {i} is {name}"),
        (value.get("subject") == kind and value.get("trial") == name.stem, "another trial"),
        ((value.get("asf"), value.get("amc")) == source, "source files not the task's"),
        (type(frames) is int and 2 <= frames <= MAX_CLIP_FRAMES, "frames out of range"),
        (fps == params["fps"], "another rate"),
    )
    for ok, problem in checks:
        if not ok:
            raise bad(f"kept: {problem}")
    return i, rest


def _printable(value, depth: int = 0) -> bool:
    """Whether every text in the JSON ``value`` is printable and every number finite."""
    if isinstance(value, str):
        return value.isprintable()
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return depth < 8 and all(_printable(k) and _printable(v, depth + 1)
                                 for k, v in value.items())  # fmt: skip
    if isinstance(value, list):
        return depth < 8 and all(_printable(v, depth + 1) for v in value)
    return value is None or isinstance(value, (bool, int))


def _clip_there(out_dir: Path, name: str) -> bool:
    """Whether the clip file ``name`` (checked) is a regular file below ``out_dir``, reached
    through no link (a link on the way: :class:`MotionDataError`)."""
    f = open_inside(out_dir / name, 1 << 62, root=out_dir)
    if f is None:
        return False
    f.close()
    return True
