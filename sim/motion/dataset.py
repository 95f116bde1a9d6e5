"""Folders of CMU files: find trials, and ingest them all in parallel worker processes.

Layout: subject folders holding ``SS.asf`` beside ``SS_TT.amc`` (any depth; names compared
case-insensitively), and BVH files (``SS_TT.bvh``, each a trial of its own) beside or instead of
them. A trial whose ASF is missing is reported, not silently dropped.

Outputs go to ``OUT/<subject>/<trial>.npz`` with both names made safe (:func:`output_paths`): they
can never leave ``OUT`` and two inputs never share an output. Worker processes watch their parent
and exit when it dies (even by SIGKILL), finishing at most the file they are writing.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import stat
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from sim.acclaim.writer import asf_text
from sim.batch import WRITE_LOCK, run_batch
from sim.errors import MotionDataError, MotionDataWarning
from sim.files import (
    MAX_ASF_BYTES,
    MAX_INDEX_BYTES,
    excerpt,
    inside,
    make_folders,
    read_regular,
    write_atomic,
)
from sim.folders import MAX_DEPTH, walk
from sim.motion.clip import load_npz, save_npz
from sim.motion.ingest import load_motion
from sim.motion.trial import is_bvh, read_skeleton

_TRIAL_RE = re.compile(r"^(?P<subject>[^_]+)_(?P<trial>.+)\.(amc|bvh)$", re.IGNORECASE)
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]")


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
    rejected: dict[str, int] = field(default_factory=dict)  # synth --max-assistance: per kind

    @property
    def ok(self) -> bool:
        return not self.skipped


def find_trials(root: str | os.PathLike, skipped: list | None = None) -> list[Trial]:
    """All trials under ``root``, sorted by subject then trial.

    An AMC ``SS_TT.amc`` pairs with ``SS.asf`` in its own folder (or, failing that, the only ASF
    there). AMCs with no skeleton are returned with ``asf`` pointing at the expected path, so the
    ingest reports them as bad input instead of dropping them. A BVH file ``SS_TT.bvh`` (any
    name: its subject is then its folder's) is a trial of its own, ``asf`` and ``amc`` both it.

    Nothing outside ``root`` is read: a trial whose AMC or ASF is a symbolic link (or lies under
    one) resolving outside ``root`` is left out and listed, as ``{"amc", "asf", "error"}``, in
    ``skipped`` (or, when no list is given, reported as a :class:`MotionDataWarning`).
    """
    root = Path(root)
    if not root.is_dir():
        raise MotionDataError(str(root), None, "not a directory")

    def skip(amc, asf, problem):
        if skipped is None:
            warnings.warn(problem, MotionDataWarning, stacklevel=3)
        else:
            skipped.append({"amc": excerpt(str(amc), 300, quote=False),
                            "asf": excerpt(str(asf), 300, quote=False), "error": problem})  # fmt: skip

    trials = []
    try:
        entries, too_deep = walk(root)  # iterative, depth-limited: no RecursionError
    except OverflowError as e:
        raise MotionDataError(str(root), None, f"{e}; not searched") from None
    for folder in too_deep[:20]:
        skip(folder, "", f"{excerpt(str(folder), 300, quote=False)}: nested over {MAX_DEPTH} "
             "folders deep; not searched")  # fmt: skip
    named = [p for p in entries if p.suffix.lower() in (".amc", ".bvh")]
    for amc in named:
        if not str(amc.relative_to(root)).isprintable():  # control characters: not echoed
            skip(amc, "", f"{excerpt(str(amc))}: a name that cannot be printed; skipped")
            continue
        if not amc.is_file():  # FIFOs, devices, sockets, broken links: never opened
            skip(amc, "", f"{amc}: not a regular file ({_kind(amc)}); skipped")
            continue
        m = _TRIAL_RE.match(amc.name)
        subject = m.group("subject") if m else amc.parent.name
        if is_bvh(amc):  # skeleton and motion in one file
            if not inside(amc, root):
                skip(amc, amc, f"{amc}: a symbolic link to a file outside {root}; skipped")
                continue
            trials.append(Trial(subject=subject, name=amc.stem, asf=amc, amc=amc))
            continue
        asfs = {p.name.lower(): p for p in amc.parent.iterdir() if p.suffix.lower() == ".asf"}
        asf = asfs.get(f"{subject.lower()}.asf")
        if asf is None and len(asfs) == 1:
            asf = next(iter(asfs.values()))
        if asf is None:
            asf = amc.parent / f"{subject}.asf"
        if not asf.name.isprintable():
            skip(amc, asf, f"{excerpt(str(asf))}: a name that cannot be printed; skipped")
            continue
        leaving = [p for p in (amc, asf) if p.exists() and not inside(p, root)]
        if leaving:
            skip(amc, asf, f"{leaving[0]}: a symbolic link to a file outside {root}; skipped")
            continue
        trials.append(Trial(subject=subject, name=amc.stem, asf=asf, amc=amc))
    return sorted(trials, key=lambda t: (t.subject, t.name))


def _kind(path: Path) -> str:
    """What a path that is no regular file is, in words."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return "a broken symbolic link" if path.is_symlink() else "unreadable"
    for test, what in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):  # fmt: skip
        if test(mode):
            return what
    return "not a file"


def safe_name(name: str, max_len: int = 100) -> str:
    """``name`` as one harmless path component: characters outside ``[A-Za-z0-9_.-]`` become
    ``_``, a leading dot gets a ``_`` before it (so never ``.``, ``..`` or a hidden file), and a
    name longer than ``max_len`` is cut, keeping it distinct with a hash of the whole name."""
    safe = _UNSAFE.sub("_", name) or "_"
    safe = "_" + safe if safe.startswith(".") else safe
    if len(safe) > max_len:
        digest = hashlib.sha1(name.encode("utf-8", "surrogateescape")).hexdigest()[:8]
        safe = f"{safe[: max_len - 9]}-{digest}"
    return safe


def output_paths(trials: list[Trial], root: str | os.PathLike) -> list[PurePosixPath]:
    """Relative output path of each trial: ``<safe subject>/<safe trial>.npz``.

    Safe: both parts pass :func:`safe_name`, so the path stays inside the output folder (a subject
    called ``..`` writes to ``_../``). Unique: trials whose paths would coincide (compared
    case-insensitively, for case-insensitive file systems), e.g. ``a/09/09_06.amc`` and
    ``b/09/09_06.amc``, each get ``-<8 hex digits>`` after the trial name, a hash of the AMC's path
    relative to ``root``, so every input keeps its own file (the index maps files to inputs).

    Raises:
        MotionDataError: (before anything is written) if names still coincide after that.
    """
    root = Path(root)
    base = []
    for t in trials:
        subject = safe_name(t.subject)
        if subject.lower() == "index.json":  # the one file at the top of OUT
            subject = "_" + subject
        base.append(PurePosixPath(subject, safe_name(t.name)))
    count: dict[str, int] = {}
    for b in base:
        count[str(b).lower()] = count.get(str(b).lower(), 0) + 1
    out = []
    for t, b in zip(trials, base, strict=True):
        if count[str(b).lower()] > 1:
            try:
                rel = t.amc.relative_to(root).as_posix()
            except ValueError:
                rel = t.amc.as_posix()
            tag = hashlib.sha1(rel.encode("utf-8", "surrogateescape")).hexdigest()[:8]
            b = b.with_name(f"{b.name}-{tag}")
        out.append(b.with_name(b.name + ".npz"))
    seen: dict[str, Trial] = {}
    for t, p in zip(trials, out, strict=True):
        if str(p).lower() in seen:
            raise MotionDataError(
                str(t.amc), None, f"output {p} would also hold {seen[str(p).lower()].amc}"
            )
        seen[str(p).lower()] = t
    return out


def _ingest_one(
    trial: Trial, out_dir: str, rel: str, skeleton: str, fps: float, write: bool = True
):
    """The trial's index record; it writes the ``.npz`` itself (``write``) or returns
    ``(record, clip)`` for the caller to write (a Ray worker may sit on another machine)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        clip = load_motion(trial.asf, trial.amc, skeleton=skeleton, fps=fps)
    out = Path(out_dir) / rel
    if Path(os.path.abspath(out)).parent.parent != Path(os.path.abspath(out_dir)):
        # output_paths makes this impossible; a second line of defence against leaving out_dir
        raise MotionDataError(str(trial.amc), None, f"unsafe output path {rel}")
    if write:
        with WRITE_LOCK:  # a worker whose parent died exits only between writes
            save_npz(clip, out, root=out_dir)
    record = {
        "subject": trial.subject,
        "trial": trial.name,
        "asf": str(trial.asf),  # made relative by ingest_directory (_relative)
        "amc": str(trial.amc),
        "file": rel,
        "frames": clip.n_frames,
        "fps": clip.fps,
        "notes": [str(w.message) for w in caught],
    }
    return record if write else (record, clip)


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
    result is kept. Each output, the index included, is written atomically. Output names are safe
    and unique (:func:`output_paths`: same-named trials get a hash suffix); the index's ``file``
    says which input each one holds. Workers exit if this process dies.
    """
    start = time.perf_counter()
    out_dir = Path(out_dir)
    outside: list[dict] = []  # symbolic links leaving root: listed, never read
    trials = find_trials(root, outside)
    rels = [str(p) for p in output_paths(trials, root)]
    # after the input checks (bad input leaves nothing), before any work: no link below out_dir
    make_folders(out_dir, sorted({str(PurePosixPath(r).parent) for r in rels}))
    summary = DatasetSummary(skipped=outside)
    here = ray is None  # Ray workers may run on other machines: their clips come back to be written
    items = [
        (t, str(out_dir), rel, skeleton, fps, here) for t, rel in zip(trials, rels, strict=True)
    ]
    outcomes = run_batch(
        _ingest_task, items, workers=workers, ray=ray, desc="ingest", progress=progress
    )
    skeletons: dict[str, str] = {}  # ASF path -> its copy in out_dir
    for t, o in zip(trials, outcomes, strict=True):
        if o.ok and not here:
            record, clip = o.result
            save_npz(clip, out_dir / record["file"], root=out_dir)
            summary.written.append(_relative(record, t, root, out_dir, skeletons))
        elif o.ok:
            summary.written.append(_relative(o.result, t, root, out_dir, skeletons))
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
    write_atomic(
        out_dir / "index.json",
        lambda f: f.write(json.dumps(index, indent=2).encode()),
        root=out_dir,
    )
    return summary


def _relative(record: dict, trial: Trial, root, out_dir: Path, skeletons: dict) -> dict:
    """``record`` with paths an index may hold: ``amc`` relative to the input ``root`` (recorded
    once as the index's ``source``; information only, never read back) and ``asf`` a copy of the
    subject's skeleton inside ``out_dir`` (``<subject>/skeleton-<8 hex of its bytes>.asf``; a
    BVH's skeleton written as an ASF), so
    a dataset folder is self-contained and its readers never leave it."""
    key = os.path.realpath(trial.asf)
    if key not in skeletons:
        if is_bvh(trial.asf):  # its skeleton as an ASF (read by the worker: a valid file)
            data = asf_text(read_skeleton(trial.asf)).encode("ascii")
        else:
            data = read_regular(trial.asf, MAX_ASF_BYTES)  # parsed by the worker: small, regular
        rel = PurePosixPath(record["file"]).parent / (
            f"skeleton-{hashlib.sha1(data).hexdigest()[:8]}.asf"
        )
        write_atomic(out_dir / rel, lambda f: f.write(data), root=out_dir)
        skeletons[key] = str(rel)
    try:
        amc = Path(trial.amc).relative_to(root).as_posix()
    except ValueError:  # unreachable: find_trials only finds files under root
        amc = Path(trial.amc).name
    return {**record, "asf": skeletons[key], "amc": amc}


def _ingest_task(args) -> dict:
    return _ingest_one(*args)


def load_dataset_clips(out_dir: str | os.PathLike, length: int = 60, *, skeletons: bool = False):
    """Every ``length``-frame clip (non-overlapping, from frame 0) of a folder written by
    ``sidql dataset`` or ``sidql synth`` (its ``index.json``); returns (clips, subjects), and with
    ``skeletons`` a third list: each clip's subject ASF when the clips are on the subject's own
    skeleton (a ``sidql dataset --skeleton subject`` folder), else ``""``."""
    rows = dataset_clips(out_dir, length)
    clips, subjects, asfs = ([r[i] for r in rows] for i in range(3))
    return (clips, subjects, asfs) if skeletons else (clips, subjects)


def dataset_clips(out_dir, length: int = 60, skipped: list | None = None) -> list[tuple]:
    """``(clip, subject, asf, file)`` for every ``length``-frame clip of a dataset/synth folder
    (see :func:`load_dataset_clips`; ``file``: the clip file read). Each file is read once: an
    entry naming a file listed before (hard links included) is left out and, with ``skipped``,
    listed there as ``{"amc", "problem"}``."""
    index, entries = _read_dataset(out_dir, length, skipped)
    own = index.get("skeleton") == "subject"
    out_dir = Path(out_dir)
    rows = []
    for i, (c, entry, file) in enumerate(entries):
        asf = entry.get("asf")
        if own and isinstance(asf, str):  # a copy inside the folder (ingest_directory)
            asf = str(confined(out_dir, asf, f"clip {i} asf", out_dir / "index.json"))
        subject = excerpt(str(entry.get("subject", "")), 100, quote=False)
        rows.append((c, subject, asf if own and isinstance(asf, str) else "", file))
    return rows


def dataset_entries(out_dir: str | os.PathLike, length: int = 60) -> list[tuple]:
    """``(clip, index entry)`` for every ``length``-frame clip of a dataset/synth folder (see
    :func:`load_dataset_clips`; each file read once, as :func:`dataset_clips`)."""
    return [(c, e) for c, e, _ in _read_dataset(out_dir, length)[1]]


#: Bound [bytes] on what parsing an ``index.json`` may allocate, estimated from its bytes before
#: parsing (:func:`read_index`).
MAX_INDEX_ALLOCATION = 512 << 20


def read_index(path: str | os.PathLike) -> dict:
    """The ``index.json`` at ``path`` (``sidql dataset`` / ``sidql synth``), read within stated
    limits: a regular file of at most :data:`~sim.files.MAX_INDEX_BYTES` whose parsing allocates
    (estimated from its bytes before parsing: Python objects cost up to ~24x the characters that
    spell them) at most :data:`MAX_INDEX_ALLOCATION`, nested within Python's recursion limit; a
    JSON object with a list of ``trials``, each an object.

    Raises:
        MotionDataError: one line naming the file and the problem.
    """
    path = str(path)
    data = read_regular(path, MAX_INDEX_BYTES)  # a regular file of bounded size
    # containers ([ {) cost ~64-232 bytes, other values (, :) ~32-60, characters one or more
    estimate = 232 * (data.count(b"{") + data.count(b"[")) + 60 * data.count(b",") + len(data)
    if estimate > MAX_INDEX_ALLOCATION:
        raise MotionDataError(
            path, None, f"not a dataset index: parsing would take ~{estimate >> 20} MB; at most "
            f"{MAX_INDEX_ALLOCATION >> 20} MB",
        )  # fmt: skip
    try:
        index = json.loads(data)
    except (ValueError, RecursionError) as e:  # RecursionError: nested too deeply
        problem = str(e) if isinstance(e, ValueError) else "nested too deeply"
        problem = excerpt(problem, 120, quote=False)
        raise MotionDataError(path, None, f"not a dataset index: {problem}") from None
    trials = index.get("trials", []) if isinstance(index, dict) else None
    if not isinstance(trials, list):
        raise MotionDataError(path, None, "not a dataset index: no list of 'trials'")
    for i, entry in enumerate(trials):
        if not isinstance(entry, dict):
            raise MotionDataError(path, None, f"not a dataset index: trials[{i}] is no object")
    index["trials"] = trials
    return index


def _read_dataset(out_dir, length, skipped=None) -> tuple[dict, list[tuple]]:
    """The index and ``(clip, entry, file)`` per clip; one file at a time, each file once."""
    out_dir = Path(out_dir)
    path = out_dir / "index.json"
    index = read_index(path)
    out, seen = [], {}
    for i, entry in enumerate(index.get("trials", [])):
        file = entry_file(out_dir, index, i)
        try:
            st = os.stat(file)
            key = (st.st_dev, st.st_ino)
        except OSError:
            key = None  # load_npz names the problem
        if key in seen:
            if skipped is not None:
                skipped.append({"amc": str(file), "problem": f"listed again in {path} (trials["
                                f"{seen[key]}] and [{i}]); read once"})  # fmt: skip
            continue
        seen[key] = i
        out += [(c, entry, file) for c in load_npz(file).split(length)]
    return index, out


def entry_file(folder: str | os.PathLike, index: dict, i: int) -> Path:
    """The clip file of entry ``i`` of a :func:`read_index` index of ``folder``: its ``file``,
    a relative path confined to ``folder`` (:func:`confined`).

    Raises:
        MotionDataError: no ``file`` name, or one that is absolute or leaves the folder."""
    folder = Path(folder)
    name = index["trials"][i].get("file")
    if not isinstance(name, str):
        raise MotionDataError(str(folder / "index.json"), None, f"trials[{i}] has no 'file' name")
    return confined(folder, name, f"trials[{i}].file", folder / "index.json")


def confined(folder: Path, name: str, what: str, index: Path) -> Path:
    """``folder / name`` for an index entry ``name`` that is a relative path staying inside
    ``folder`` once every symbolic link is resolved.

    Raises:
        MotionDataError: an absolute name, or one leaving ``folder`` (``..``, a link); the
            message quotes at most a short printable excerpt of the name.
    """
    path = folder / name
    if not name or PurePosixPath(name).is_absolute() or Path(name).is_absolute():
        problem = "is absolute"
    elif not name.isprintable():  # control characters would reach terminals through messages
        problem = "holds characters that cannot be printed"
    elif not inside(path, folder):
        problem = "leaves the dataset folder"
    else:
        return path
    shown = "".join(ch if ch.isprintable() else "?" for ch in name[:60])
    raise MotionDataError(str(index), None, f"{what} {shown!r} {problem}; refused")


def origin_subject(entry: dict) -> str | None:
    """The CMU subject whose recorded motion an index entry was made from: the subject of its
    ``amc`` (as :func:`find_trials` names it; a synthetic clip's source trial), else its
    ``subject``; None for motion made from no recording (procedural)."""
    amc = entry.get("amc")
    if isinstance(amc, str) and amc:
        amc = PurePosixPath(amc)
        m = _TRIAL_RE.match(amc.name)
        return m.group("subject") if m else amc.parent.name
    if entry.get("task") is not None:  # synthetic without a source trial
        return None
    return str(entry.get("subject", "")) or None
