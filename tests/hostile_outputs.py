"""Hostile output folders, and the property every writer keeps (the output side of
``benchmarks/fuzz_campaign.py``, kind ``output``).

A :class:`OutCase` plants something where an output goes, in the out folder the user named: a
symbolic link (to a folder or a file outside, to ``/dev/null``, broken, a loop), a FIFO, a
character device (a ``/dev/null`` of its own), a socket, a folder, or a hard link to a file
outside; either at the target itself or at the folder between the out folder and the target.
Then one writer runs as a command would: a single output file (``ingest --out``), a file in a
subfolder (``dataset``), a clip (``save_npz``), a file another program writes (videos,
``written_by``), a fresh ``synth`` (its journal and clips), ``synth --resume`` with a crafted
journal (surplus kept clips, names leaving the folder, malformed lines), or the removal of a
clip the run names.

The property (:func:`run_case`): nothing outside the out folder is written or deleted (every
entry of a sibling folder ``outside`` is compared before and after, as is ``/dev/null``), no
temporary file is left in the out folder, and the run ends either cleanly or with one
printable line (a :class:`~sim.errors.SidqlError`). A broken property raises :class:`Breach`
(``write-outside``, ``delete-outside``, ``leftover``, ``bad-error``); any other exception
propagates (a foreign one).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import socket
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from acclaim_mutations import Breach

from sim.errors import SidqlError

ACTIONS = ("file", "subfolder", "clip", "video", "synth", "resume", "remove")
PLANTS = ("none", "link-dir-outside", "link-file-outside", "link-devnull", "fifo", "device",
          "socket", "dir", "broken-link", "loop-link", "hardlink-outside")  # fmt: skip
CANARY = b"CANARY-OUT-41c2"
#: Where each action writes, relative to the out folder (the folder between: its parent).
TARGETS = {"file": "x.npz", "subfolder": "02/02_01.npz", "clip": "02/02_01.npz",
           "video": "clip00_a.mp4", "synth": "journal.jsonl", "resume": "journal.jsonl",
           "remove": "procedural/procedural_00001.npz"}  # fmt: skip
SYNTH = dict(kinds=("procedural",), seconds=0.5, seed=0, workers=1, progress=False)


@dataclass
class OutCase:
    """One hostile output folder: the ``action`` run, what is ``plant``-ed and ``where`` (the
    target, or the folder between), the synth journal's ``journal`` lines (resume), ``ops``."""

    kind: str
    action: str
    plant: str
    where: str
    journal: list = field(default_factory=list)
    ops: list = field(default_factory=list)
    files: dict = field(default_factory=dict)  # (sizes for the campaign: none)


def _pick(rng, seq):
    return seq[rng.randrange(len(seq))]


def make_case(kind: str, seeds, rng) -> OutCase:
    """A random hostile output folder (deterministic in ``rng``'s choices; ``kind`` is
    ``"output"``, ``seeds`` unused: the signature of ``hostile_inputs.make_case``)."""
    action, plant = _pick(rng, ACTIONS), _pick(rng, PLANTS)
    nested = "/" in TARGETS[action] or action in ("synth", "resume")
    where = _pick(rng, ("target", "folder")) if nested else "target"
    journal = _journal(rng) if action == "resume" else []
    ops = [f"{action}:{plant}@{where}"] + ([f"journal:{journal[0]}"] if journal else [])
    return OutCase("output", action, plant, where, journal[1:], ops)


def seed_case(kind: str = "output", seeds=None) -> OutCase:
    """A good output folder: nothing planted (it must write)."""
    return OutCase("output", "clip", "none", "target", [], ["seed"])


def journal_params(n: int) -> dict:
    """The parameters a procedural ``synth`` run of ``n`` clips writes at its journal's head."""
    from sim.simulate.generate import synth_controller

    controller, samples = synth_controller()  # what synthesize resolves its default to
    return {"source": None, "n": n, "seed": 0, "kinds": ["procedural"], "seconds": 0.5,
            "fps": 30.0, "max_assistance": None, "max_tries": 20,
            **({"samples": samples} if samples else {}), "controller": controller,
            "assist": 0.0}  # fmt: skip


def kept_entry(i: int, **change) -> dict:
    """The ``kept`` entry a procedural run writes for task ``i``."""
    from sim.simulate.generate import SynthTask, task_dict
    from sim.simulate.journal import clip_name

    name = clip_name("procedural", i)
    from sim.simulate.generate import synth_controller

    controller, samples = synth_controller()  # what synthesize resolves its default to
    task = task_dict(SynthTask("procedural", 0, i, None, None, 0.5, 30.0, samples, controller,
                               terrain=False))  # a procedural run has no scene to infer  # fmt: skip
    return {"subject": "procedural", "trial": name.stem, "asf": None, "amc": None,
            "file": str(name), "frames": 15, "fps": 30.0, "notes": [], "task": task,
            "mean_assistance": 0.0, **change}  # fmt: skip


def _journal(rng) -> list:
    """``[label, line...]``: the lines after the head of a crafted journal."""
    how = _pick(rng, ("surplus", "leaving", "absolute", "malformed", "mutated", "long"))
    lines = [{"index": i, "kept": kept_entry(i)} for i in range(1 + rng.randrange(4))]
    if how == "leaving":
        lines.append(
            {"index": len(lines), "kept": kept_entry(len(lines), file="../outside/victim")}
        )
    elif how == "absolute":
        lines.append({"index": len(lines), "kept": kept_entry(len(lines), file="@outside/victim")})
    elif how == "malformed":
        lines.insert(rng.randrange(len(lines) + 1), _pick(rng, (
            '"kept"', "[1, 2]", {"kept": kept_entry(0)}, {"index": -1, "kept": kept_entry(0)},
            {"index": 0, "kept": "x.npz"}, {"index": 0, "kept": kept_entry(0, frames="15")},
            {"index": 0, "kept": kept_entry(0, notes=["\x1b[2J"])}, {"index": 0, "skipped": {}},
            {"index": 0, "rejected": "track"}, "{not json", {"index": 2**40, "kept": kept_entry(0)},
        )))  # fmt: skip
    elif how == "mutated":
        text = bytearray(json.dumps(lines[-1]).encode())
        for _ in range(1 + rng.randrange(4)):
            text[rng.randrange(len(text))] = rng.randrange(256)
        lines[-1] = text.decode("latin-1")
    elif how == "long":
        lines.append("x" * ((1 << 16) + 1 + rng.randrange(1 << 16)))
    return [how, *lines]


# ------------------------------------------------------------------------------ running


def materialise(case: OutCase, folder: Path) -> Path:
    """Make the out folder ``folder/out`` with the plant, and ``folder/outside`` (files and a
    folder holding :data:`CANARY`); returns the out folder."""
    out, outside = folder / "out", folder / "outside"
    (outside / "dir").mkdir(parents=True, exist_ok=True)
    (outside / "victim").write_bytes(CANARY)
    (outside / "dir" / "inner").write_bytes(CANARY)
    out.mkdir(parents=True, exist_ok=True)
    target = out / TARGETS[case.action]
    spot = target if case.where == "target" else target.parent
    if spot == out:  # the journal's folder is the out folder: plant at the clips' folder
        spot = out / "procedural"
    spot.parent.mkdir(parents=True, exist_ok=True)
    if case.action in ("resume", "remove"):
        _resume_state(case, out, outside)
    _plant(case.plant, spot, outside)
    return out


def _resume_state(case: OutCase, out: Path, outside: Path) -> None:
    (out / "procedural").mkdir(exist_ok=True)
    for i in range(3):
        (out / "procedural" / f"procedural_{i:05d}.npz").write_bytes(b"clip")
    lines = [{"params": journal_params(1)}, *case.journal]
    text = "".join((x if isinstance(x, str) else json.dumps(x)).replace(
        "@outside", str(outside)) + "\n" for x in lines)  # fmt: skip
    (out / "journal.jsonl").write_text(text, encoding="latin-1")


def _plant(plant: str, spot: Path, outside: Path) -> None:
    if plant == "none":
        return
    if spot.is_dir() and not spot.is_symlink():  # the folder between: replace it whole
        for p in sorted(spot.rglob("*"), reverse=True):
            p.unlink() if not p.is_dir() or p.is_symlink() else p.rmdir()
        spot.rmdir()
    elif spot.exists() or spot.is_symlink():
        spot.unlink()
    links = {"link-dir-outside": outside / "dir", "link-file-outside": outside / "victim",
             "link-devnull": Path("/dev/null"), "broken-link": outside / "missing",
             "loop-link": spot}  # fmt: skip
    if plant in links:
        os.symlink(links[plant], spot)
    elif plant == "fifo":
        os.mkfifo(spot)
    elif plant == "device":
        try:
            os.mknod(spot, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        except PermissionError:  # no CAP_MKNOD: a FIFO instead
            os.mkfifo(spot)
    elif plant == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(spot))
        s.close()
    elif plant == "dir":
        spot.mkdir()
    elif plant == "hardlink-outside":
        os.link(outside / "victim", spot)


def _snapshot(outside: Path) -> dict:
    """Every entry below ``outside``: kind, size, inode and content digest."""
    snap = {}
    for p in [outside, *sorted(outside.rglob("*"))]:
        st = p.lstat()
        digest = hashlib.sha1(p.read_bytes()).hexdigest() if stat.S_ISREG(st.st_mode) else ""
        snap[str(p.relative_to(outside))] = (stat.S_IFMT(st.st_mode), st.st_size, st.st_ino,
                                             digest)  # fmt: skip
    st = os.stat("/dev/null")
    snap["/dev/null"] = (stat.S_IFMT(st.st_mode), st.st_rdev)
    return snap


def run_case(case: OutCase, folder: Path, _args=None) -> str:
    """Materialise ``case`` in the empty ``folder`` and run its writer: ``"error"`` (one
    printable line) or ``"ok"``; :class:`Breach` when the property fails."""
    out = materialise(case, folder)
    before = _snapshot(folder / "outside")
    outcome = "ok"
    try:
        _ACTIONS[case.action](out, folder / "outside")
    except SidqlError as e:
        text = str(e)
        if "\n" in text or any(ch < " " or ch == "\x7f" for ch in text) or len(text) > 1200:
            raise Breach("bad-error", f"not one short printable line: {text[:200]!r}") from None
        outcome = "error"
    after = _snapshot(folder / "outside")
    gone = sorted(set(before) - set(after))
    if gone:
        raise Breach("delete-outside", f"deleted outside the out folder: {gone[:5]}")
    changed = sorted(k for k in after if before.get(k) != after[k])
    if changed:
        raise Breach("write-outside", f"written outside the out folder: {changed[:5]}")
    left = [str(p) for p in out.rglob(".*.tmp*")]
    if left:
        raise Breach("leftover", f"temporary files left: {left[:5]}")
    return outcome


def _tiny_clip():
    from sim.motion.clip import Clip

    z = np.zeros((2, 2, 3))
    return Clip(names=("root", "a"), parents=np.array([-1, 0]), positions=z, velocities=z,
                qpos=np.zeros((2, 7)), qvel=np.zeros((2, 6)), rotations=np.zeros((2, 2, 4)),
                fps=30.0)  # fmt: skip


def _npz_bytes() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, a=np.zeros(3))
    return buf.getvalue()


def _file(out: Path, _outside) -> None:
    from sim.files import write_atomic

    write_atomic(out / "x.npz", lambda f: f.write(_npz_bytes()))  # as `ingest --out` names it


def _subfolder(out: Path, _outside) -> None:
    from sim.files import make_folders, write_atomic

    make_folders(out, ["02"])
    write_atomic(out / "02" / "02_01.npz", lambda f: f.write(_npz_bytes()), root=out)


def _clip(out: Path, _outside) -> None:
    from sim.motion.clip import save_npz

    save_npz(_tiny_clip(), out / "02" / "02_01.npz", root=out)


def _video(out: Path, _outside) -> None:
    from sim.files import written_by

    with written_by(out / "clip00_a.mp4", root=out, suffix=".mp4") as path:
        Path(path).write_bytes(b"not really a video")


def _synth(out: Path, _outside, resume: bool = False) -> None:
    import sim.simulate.dataset as dataset

    def simulated(task):  # no physics: a tiny clip, as a worker would return it
        return _npz_clip(), {"frames": 2, "fps": 30.0, "mean_assistance": 0.0,
                             "mean_assist_torque": 0.0}  # fmt: skip

    saved, dataset.simulate_file = dataset.simulate_file, simulated
    try:
        dataset.synthesize(None, out, 2, resume=resume, **SYNTH)
    finally:
        dataset.simulate_file = saved


def _npz_clip() -> bytes:
    from sim.motion.clip import _write_npz

    clip = _tiny_clip()
    buf = io.BytesIO()
    payload = {k: getattr(clip, k) for k in ("parents", "positions", "velocities", "qpos",
                                              "qvel", "rotations")}  # fmt: skip
    payload.update(names=np.array(clip.names), joint_names=np.array([], dtype=str),
                   fps=np.float64(30), source=np.array(""), start_frame=np.int64(0),
                   source_fps=np.float64(30))  # fmt: skip
    _write_npz(buf, payload, "clip")
    return buf.getvalue()


def _remove(out: Path, _outside) -> None:
    from sim.files import remove_written

    remove_written(out / "procedural" / "procedural_00001.npz", root=out)


_ACTIONS = {"file": _file, "subfolder": _subfolder, "clip": _clip, "video": _video,
            "synth": _synth, "resume": lambda out, o: _synth(out, o, resume=True),
            "remove": _remove}  # fmt: skip
