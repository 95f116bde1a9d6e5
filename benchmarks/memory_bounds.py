"""Memory proportional to the input: the stated bounds of ``ingest`` (AMC -> clip) and of reading a
dataset folder, measured (used by ``benchmarks/fuzz_campaign.py``).

``ingest``: the AMC reader holds at most ~4x the file, and the arrays built from it at most
``sim.motion.ingest.ARRAY_BYTES_PER_INPUT_BYTE`` times the file's size or
``ARRAY_BYTES_FLOOR``, whichever is larger (checked from the frame count before they are built).
Each file is read in a child forked from a warm process (imports, the subject's model made and
a two-frame trial read: input-independent costs paid), whose peak RSS growth is compared with
that bound. A dataset index listing one clip file 200
times is read once (its peak against the clip file's inflated size).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CHUNK_SLACK = 16 << 20  # the reader's chunk and the interpreter's own growth


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


def _peaks(jobs: list, out) -> None:
    """In a fresh process: per job ``(kind, path, asf)``, fork a child that ingests the AMC
    (``"amc"``) or reads the dataset folder (``"index"``); send (outcome, frames, extra MB)."""
    sys.path.insert(0, str(REPO))
    from sim.errors import MotionDataError
    from sim.model.humanoid import subject_model
    from sim.motion.dataset import dataset_clips
    from sim.motion.ingest import load_motion

    rows = []
    warm = Path(jobs[0][1]).with_name("warm.amc")
    for kind, path, asf in jobs:
        if asf:  # warm: the subject's model (cached) and one small read, as in a batch
            subject_model(asf)
            warm.write_bytes(b":DEGREES\n1\nroot 0 0 0 0 0 0\n2\nroot 0 0 0 0 0 0\n")
            load_motion(asf, warm, fps=60.0)
        read_fd, write_fd = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                start = _rss_mb()
                try:
                    if kind == "amc":
                        outcome, frames = "built", load_motion(asf, path).n_frames
                    else:
                        outcome, frames = "read", sum(r[0].n_frames for r in dataset_clips(path))
                except MotionDataError:
                    outcome, frames = "refused", 0
                os.write(write_fd, json.dumps([start, outcome, frames]).encode())
            finally:
                os._exit(0)
        os.close(write_fd)
        data = b""
        while chunk := os.read(read_fd, 4096):
            data += chunk
        os.close(read_fd)
        _, _, usage = os.wait4(pid, 0)
        start, outcome, frames = json.loads(data)
        rows.append((outcome, frames, usage.ru_maxrss / 1024 - start))
    out.send(rows)


def measure(cmu: Path, work: Path) -> list[dict]:
    """Rows ``{"input", "mb", "outcome", "frames", "peak_extra_mb", "bound_mb", "within"}``."""
    sys.path.insert(0, str(REPO))
    from sim.motion.clip import read_arrays, save_npz
    from sim.motion.ingest import ARRAY_BYTES_FLOOR, ARRAY_BYTES_PER_INPUT_BYTE, load_motion

    asf = str(cmu / "01" / "01.asf")
    src = (cmu / "01" / "01_02.amc").read_bytes().splitlines(keepends=True)
    starts = [i for i, line in enumerate(src) if line.strip().isdigit()]
    body, k = [], 0
    for line in src[starts[0] :] * 6:
        if line.strip().isdigit():
            k += 1
            line = b"%d\n" % k
        body.append(line)

    def root_only(n: int) -> bytes:
        return b":DEGREES\n" + b"".join(b"%d\nroot 0 0 0 0 0 0\n" % i for i in range(1, n + 1))

    files = {
        "real trial 01_01": (cmu / "01" / "01_01.amc").read_bytes(),
        "real trial 01_02 x6 (20 MB)": b"".join(src[: starts[0]] + body),
        "root only, 2,000 frames": root_only(2_000),
        "root only, 11,000 frames": root_only(11_000),
        "root only, 200,000 frames": root_only(200_000),
        "root only, 400,000 frames": root_only(400_000),
    }
    jobs, sizes = [], []
    for i, data in enumerate(files.values()):
        path = work / f"mem-{i}.amc"
        path.write_bytes(data)
        jobs.append(("amc", str(path), asf))
        sizes.append(len(data))
    folder = work / "mem-index"
    clip = load_motion(cmu / "02" / "02.asf", cmu / "02" / "02_01.amc")
    save_npz(clip, folder / "c.npz")
    entries = [{"subject": "02", "file": "c.npz"}] * 200
    (folder / "index.json").write_text(json.dumps({"trials": entries}))
    jobs.append(("index", str(folder), ""))
    inflated = sum(a.nbytes for a in read_arrays(folder / "c.npz").values())
    sizes.append((folder / "c.npz").stat().st_size)
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_peaks, args=(jobs, send))
    p.start()
    measured = recv.recv()
    p.join()
    rows = []
    names = [*files, "index.json listing one clip 200 times"]
    for k, (name, size, (outcome, frames, extra)) in enumerate(zip(names, sizes, measured,
                                                                   strict=True)):  # fmt: skip
        if jobs[k][0] == "amc":
            bound = max(ARRAY_BYTES_FLOOR, ARRAY_BYTES_PER_INPUT_BYTE * size) + 4 * size
        else:  # one copy of the clip's arrays, read once
            bound = 2 * inflated
        bound += CHUNK_SLACK
        rows.append({"input": name, "mb": size / 2**20, "outcome": outcome, "frames": frames,
                     "peak_extra_mb": extra, "bound_mb": bound / 2**20,
                     "within": extra * 2**20 <= bound})  # fmt: skip
    return rows


def table(rows: list[dict]) -> str:
    from sim.motion.ingest import ARRAY_BYTES_FLOOR, ARRAY_BYTES_PER_INPUT_BYTE

    lines = [
        "Memory proportional to the input (fresh process; extra peak RSS beyond the warm process"
        f" before reading). Stated bound for `ingest`: the reader's 4x the file plus arrays of at"
        f" most {ARRAY_BYTES_PER_INPUT_BYTE}x the file or {ARRAY_BYTES_FLOOR >> 20} MB, whichever"
        f" is larger (+{CHUNK_SLACK >> 20} MB); for a dataset index: one copy of each clip file's"
        " arrays (x2 for the split).",
        "",
        "| input | size MB | outcome | frames | extra peak MB | stated bound MB | within |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['input']} | {r['mb']:.2f} | {r['outcome']} | {r['frames']:,} | "
                     f"{r['peak_extra_mb']:.0f} | {r['bound_mb']:.0f} | "
                     f"{'yes' if r['within'] else '**no**'} |")  # fmt: skip
    return "\n".join(lines)
