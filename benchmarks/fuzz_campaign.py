"""Fuzz campaign: hostile files of every type the commands read, each read in its own process
under a memory limit (``ulimit -v``) and a time limit, with its peak memory and time measured.

Usage: .venv/bin/python benchmarks/fuzz_campaign.py [--n 10500] [--seed 2026] [--workers 2]
           [--timeout 30] [--memory-limit-mb 2048] [--data ../shared/cmu] [--out fuzz.json]
           [--no-results] [--no-progress]

File types (``tests/hostile_inputs.py``, shared with the hypothesis tests): ASF and AMC (real
trials, byte/line/token/number/name mutations), ``.sidq`` streams (header fields, counts, bounds,
LZMA bombs, damaged records) and sequences of them (record lengths, counts, damaged or mismatched
streams, streams too long to join, thousands of records), clip ``.npz`` files (array types and shapes, lying npy headers,
deflate bombs, overlapping or encrypted zip members), dataset folders (``index.json`` entries
that are absolute, leave the folder or lead to FIFOs and ``/dev/zero``; nesting, width), policy
files (settings out of bounds, tampered weights, pickled objects, compressed or overlapping
archives) and checkpoints (every entry tampered with, settings matching). About one input in 25
is no regular file at all (a FIFO, a directory, a link to ``/dev/zero`` or out of the folder).
Inputs are a pure function of ``--seed`` and their index.

Every input runs in a fresh process forked from a warm one per file type (which has imported
what that type's command imports and read one good file): the child gets an address-space limit
(its size at the fork + ``--memory-limit-mb``, i.e. ``ulimit -v``), reads the input as the
command would (``run_case``) and reports; the parent kills it after ``--timeout`` seconds (a
hang) and takes its peak RSS and CPU time from ``wait4``. Outcomes: ``error`` (BadFileError:
one printable line naming the file), ``ok`` (finite values), and the failures ``foreign`` (any
other exception), ``non-finite``, ``bad-error``, ``bad-name``, ``read-outside``, ``over-memory``
(MemoryError under the limit), ``hang``. Separately, inputs over the targets (peak RSS above
384 MB or more than 5 s of CPU) are counted. Failing inputs are saved under ``<out>.repro/``.
Exit status 1 on any failure or any input over the targets.

The output side (kind ``output``, ``tests/hostile_outputs.py``): an out folder with a planted
symbolic link (to a folder or file outside, ``/dev/null``, broken, a loop), FIFO, character
device, socket, folder or hard link where an output goes or at the folder before it, then one
writer run as a command runs it (a single file, a file in a subfolder, a clip, a video-style
file another program writes, a fresh ``synth``, ``synth --resume`` with a crafted journal, the
removal of a clip the run names). Its failures: ``write-outside``, ``delete-outside`` (any
change to a folder beside the out folder or to ``/dev/null``) and ``leftover`` (a temporary
file left in the out folder), besides ``foreign`` and ``bad-error``.

A second table measures the AMC reader's peak memory against the file's size (target: at most
5x) on real trials repeated to ~20 MB and on hostile layouts of the same size; a third the
stated memory bound of ``ingest`` and of reading a dataset index (``benchmarks/memory_bounds.py``).

Counts go to ``docs/results/fuzz_campaign.md`` (``benchmarks/results.py``) unless
``--no-results``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import pickle
import random
import resource
import select
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter, defaultdict
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests"), str(REPO / "benchmarks")]

import memory_bounds  # noqa: E402
from results import write_results  # noqa: E402

from sim.paths import default_data_dir  # noqa: E402

#: Share of the inputs per file type.
MIX = {"asf": 15, "amc": 20, "sidq": 15, "sidm": 10, "npz": 15, "index": 10, "policy": 12.5,
       "checkpoint": 12.5, "output": 15, "bvh": 10}  # fmt: skip
FAILURES = ("foreign", "non-finite", "bad-error", "bad-name", "read-outside", "over-memory",
            "hang", "write-outside", "delete-outside", "leftover")  # fmt: skip
TARGET_RSS_MB = 384  # any input file of at most 1 MB decodes or fails within this peak RSS
TARGET_CPU_S = 5.0  # ... and this much time
AMC_TARGET_RATIO = 5.0
TARGET_INPUT_BYTES = 1 << 20  # the targets are for inputs of at most 1 MB


def kind_of(seed: int, i: int, mix: dict = MIX) -> str:
    rng = random.Random(f"{seed}:kind:{i}")
    x = rng.random() * sum(mix.values())
    for kind, share in mix.items():
        x -= share
        if x < 0:
            return kind
    return kind


def cases(kind: str):
    """The module making and running inputs of ``kind``: ``hostile_outputs`` for the output
    side (planted links, devices, FIFOs, crafted journals), ``hostile_inputs`` for the rest."""
    import hostile_inputs
    import hostile_outputs

    return hostile_outputs if kind == "output" else hostile_inputs


def make_input(seeds, seed: int, i: int, mix: dict = MIX):
    kind = kind_of(seed, i, mix)
    return cases(kind).make_case(kind, seeds, random.Random(f"{seed}:{kind}:{i}"))


# ------------------------------------------------------------------------------ the warm parents


def _vm_size() -> int:
    """This process's address-space size [bytes] (``VmSize``)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


#: What each file type's reader imports (as its command would, before reading anything).
READER_MODULES = {
    "asf": "sim.motion.ingest", "amc": "sim.motion.ingest", "sidq": "sidql.codec.decode",
    "npz": "sim.motion.clip", "index": "sim.motion.dataset", "policy": "sidql.learning.policy",
    "checkpoint": "sidql.learning.dqn", "output": "sim.simulate.dataset",
    "bvh": "sim.motion.ingest", "sidm": "sidql.codec.decode",
}  # fmt: skip


def zygote(conn, kind: str, seeds_path: str, memory_limit: int, timeout: float) -> None:
    """A warm parent for ``kind``: imports its reader (its RSS then is the kind's baseline),
    reads one good file, then forks one child per input it is sent and reports the child's
    outcome, memory growth and CPU time."""
    import importlib

    importlib.import_module(READER_MODULES[kind])
    imported = _rss_mb()
    H = cases(kind)

    seeds = pickle.loads(Path(seeds_path).read_bytes())
    scratch = Path(tempfile.mkdtemp(prefix=f"sidql-fuzz-{kind}-"))
    try:
        (scratch / "warm").mkdir()
        if H.run_case(H.seed_case(kind, seeds), scratch / "warm", seeds.checkpoint_args) != "ok":
            raise RuntimeError("the seed does not read")
    except Exception:  # the seed itself must read
        conn.send(("warm-up failed", traceback.format_exc(limit=-3)))
        return
    conn.send(("ready", imported))
    n = 0
    while True:
        job = conn.recv()
        if job is None:
            break
        n += 1
        folder = scratch / f"c{n}" / "case"
        folder.mkdir(parents=True)
        result = _run_child(job, folder, seeds, memory_limit, timeout)
        conn.send({**result, "import_mb": imported, "bytes": _size(job)})
        shutil.rmtree(folder.parent, ignore_errors=True)
    shutil.rmtree(scratch, ignore_errors=True)


def _size(case) -> int:
    """Bytes of a case's files (specials count 0)."""
    return sum(len(v) for v in case.files.values() if isinstance(v, bytes))


def _run_child(case, folder: Path, seeds, memory_limit: int, timeout: float) -> dict:
    H = cases(case.kind)

    read_fd, write_fd = os.pipe()
    baseline = _rss_mb()
    limit = _vm_size() + memory_limit
    start = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # the child: limits, read, report, exit without cleanup handlers
        os.close(read_fd)
        try:
            start_rss = _rss_mb()  # the pages copied at the fork
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            try:
                outcome, detail = H.run_case(case, folder, seeds.checkpoint_args), ""
            except H.Breach as e:
                outcome, detail = e.kind, str(e)
            except MemoryError as e:
                outcome, detail = "over-memory", f"{type(e).__name__}: {str(e)[:200]}"
            except Exception as e:
                tb = traceback.format_exc(limit=-3)
                outcome, detail = "foreign", f"{type(e).__name__}: {str(e)[:300]}\n{tb}"
            os.write(write_fd, json.dumps([outcome, detail[:4000], start_rss]).encode())
        finally:
            os._exit(0)
    os.close(write_fd)
    data, deadline, status, usage = b"", start + timeout, None, None
    while True:
        ready, _, _ = select.select([read_fd], [], [], max(0.0, deadline - time.perf_counter()))
        if ready:
            chunk = os.read(read_fd, 1 << 16)
            if chunk:
                data += chunk
                continue
            break  # the child closed the pipe: it has exited or is exiting
        break  # timed out
    wall = time.perf_counter() - start
    hung = not data and wall >= timeout
    if hung:
        os.kill(pid, signal.SIGKILL)
    _, status, usage = os.wait4(pid, 0)
    os.close(read_fd)
    start_rss = 0.0
    if hung:
        outcome, detail = "hang", f"no answer in {timeout:g} s"
    elif data:
        outcome, detail, start_rss = json.loads(data)
    else:
        outcome, detail = "foreign", f"the reader's process died (status {status})"
    # A forked child's peak counts only the pages it has touched: the growth over what it had at
    # the fork, on top of the warm parent's whole RSS, is the peak of a process reading the file.
    growth = max(0.0, usage.ru_maxrss / 1024 - start_rss)
    return {
        "outcome": outcome, "detail": detail, "peak_rss_mb": baseline + growth,
        "growth_mb": growth, "cpu_s": usage.ru_utime + usage.ru_stime, "wall_s": wall,
        "baseline_mb": baseline,
    }  # fmt: skip


class Zygote:
    """A warm parent process (started with ``spawn``: it imports only what its kind needs)."""

    def __init__(self, kind: str, seeds_path: str, memory_limit: int, timeout: float):
        ctx = mp.get_context("spawn")
        self.kind = kind
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(
            target=zygote, args=(child, kind, seeds_path, memory_limit, timeout), daemon=True
        )
        self.proc.start()
        child.close()
        status, info = self.conn.recv()
        if status != "ready":
            raise RuntimeError(f"{kind}: {status}\n{info}")
        self.baseline_mb = info
        self.job = None

    def submit(self, job) -> None:
        self.job = job
        self.conn.send(job[1])

    def close(self) -> None:
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.proc.join(timeout=10)
        if self.proc.is_alive():
            self.proc.kill()


def run_all(jobs, seeds_path: str, args, progress: bool):
    """Yield ``(index, case, result)`` for every job, ``args.workers`` at a time (results in the
    order they finish); ``args.workers`` warm parents per file type, started when first needed."""
    from multiprocessing.connection import wait

    from tqdm import tqdm

    pools: dict[str, list[Zygote]] = defaultdict(list)
    busy: dict = {}
    pending: list = []
    source = iter(jobs)
    bar = tqdm(total=args.n, disable=not progress, unit="input", smoothing=0.05)

    def idle(kind):
        for z in pools[kind]:
            if z.job is None:
                return z
        if len(pools[kind]) < args.workers:
            pools[kind].append(Zygote(kind, seeds_path, args.memory_limit_mb << 20, args.timeout))
            return pools[kind][-1]
        return None

    try:
        while True:
            while len(busy) < args.workers:
                chosen = next(((j, z) for j in pending if (z := idle(j[1].kind))), None)
                if chosen is None:
                    job = next(source, None) if len(pending) < 8 * args.workers else None
                    if job is None:
                        break
                    pending.append(job)
                    continue
                job, z = chosen
                pending.remove(job)
                z.submit(job)
                busy[z.conn] = z
            if not busy:
                return
            for conn in wait(list(busy)):
                z = busy.pop(conn)
                result = conn.recv()
                job, z.job = z.job, None
                bar.update()
                yield job[0], job[1], result
    finally:
        bar.close()
        for zs in pools.values():
            for z in zs:
                z.close()


# ------------------------------------------------------------------------------ AMC memory


def _amc_peaks(paths: list[str], asf: str, out) -> None:
    """In a small fresh process: for each AMC, fork a child that reads it; send (extra peak
    RSS over the child's RSS at the fork [KB], frames, CPU s) per file."""
    from sim.acclaim.amc import parse_amc
    from sim.acclaim.asf import parse_asf

    skeleton = parse_asf(asf)
    rows = []
    for path in paths:
        read_fd, write_fd = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                start = _rss_mb()
                motion = parse_amc(path, skeleton)
                os.write(write_fd, json.dumps([start, motion.n_frames]).encode())
            finally:
                os._exit(0)
        os.close(write_fd)
        data = b""
        while chunk := os.read(read_fd, 4096):
            data += chunk
        os.close(read_fd)
        _, _, usage = os.wait4(pid, 0)
        start, frames = json.loads(data)
        rows.append((usage.ru_maxrss / 1024 - start, frames, usage.ru_utime + usage.ru_stime))
    out.send(rows)


def amc_memory(cmu: Path, work: Path) -> list[dict]:
    """Peak RSS of reading AMCs of ~20 MB (a real trial repeated; hostile layouts) in a fresh
    process, less its RSS before reading, over the file's size."""
    sys.path.insert(0, str(REPO))
    from sim.acclaim.asf import parse_asf

    asf = cmu / "01" / "01.asf"
    bones = [(b.name, len(b.dofs)) for b in parse_asf(asf).bones if b.dofs]
    src = (cmu / "01" / "01_02.amc").read_bytes().splitlines(keepends=True)
    starts = [i for i, line in enumerate(src) if line.strip().isdigit()]
    head = src[: starts[0]]

    def frames(make, target=20_000_000, sep=b"\n"):
        out, size, n = [b":FULLY-SPECIFIED", b":DEGREES"], 0, 1
        while size < target:
            lines = make(n)
            out += lines
            size += sum(len(x) + len(sep) for x in lines)
            n += 1
        return sep.join(out) + sep

    real = src[: starts[0]] + [line for i in range(6) for line in src[starts[0] :]]
    k = 0
    renumbered = []
    for line in real[len(head) :]:
        if line.strip().isdigit():
            k += 1
            line = b"%d\n" % k
        renumbered.append(line)
    zeros = [nm.encode() + b" 0" * n for nm, n in bones]
    cases = {
        "real trial 01_01 as it is": (cmu / "01" / "01_01.amc").read_bytes(),
        "real trial 01_02 repeated": b"".join(head + renumbered),
        "root only (other bones absent)": frames(lambda n: [b"%d" % n, b"root 0 0 0 0 0 0"]),
        "every value 0 (2 bytes a value)": frames(
            lambda n: [b"%d" % n, b"root 0 0 0 0 0 0", *zeros]
        ),  # fmt: skip
        "bone order changing (checked path)": frames(
            lambda n: [b"%d" % n, b"root 0 0 0 0 0 0", *(zeros[::-1] if n % 2 else zeros)]
        ),
        "CR line ends": frames(lambda n: [b"%d" % n, b"root 0 0 0 0 0 0", *zeros], sep=b"\r"),
    }
    paths, sizes = [], []
    for k, data in enumerate(cases.values()):
        paths.append(str(work / f"amc-memory-{k}.amc"))
        Path(paths[-1]).write_bytes(data)
        sizes.append(len(data))
    del cases, data
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_amc_peaks, args=(paths, str(asf), send))
    p.start()
    measured = recv.recv()
    p.join()
    names = ["real trial 01_01 as it is", "real trial 01_02 repeated",
             "root only (other bones absent)",
             "every value 0 (2 bytes a value)", "bone order changing (checked path)",
             "CR line ends"]  # fmt: skip
    return [
        {"file": name, "mb": size / 2**20, "frames": frames, "peak_extra_mb": extra,
         "ratio": extra * 2**20 / size, "cpu_s": cpu}
        for name, size, (extra, frames, cpu) in zip(names, sizes, measured, strict=True)
    ]  # fmt: skip


# ------------------------------------------------------------------------------ main


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=10_500, help="number of hostile inputs")
    p.add_argument("--seed", type=int, default=2026, help="campaign seed")
    p.add_argument("--workers", type=int, default=2, help="inputs read at a time")
    p.add_argument("--timeout", type=float, default=30.0, help="seconds per input before a hang")
    p.add_argument(
        "--memory-limit-mb", type=int, default=2048,
        help="address space each reader may add (ulimit -v) [MB]",
    )  # fmt: skip
    p.add_argument(
        "--data",
        default=default_data_dir(),
        help="folder of CMU files (default: $SIDQL_DATA or ../shared/cmu)",
    )
    p.add_argument("--out", default="fuzz_campaign.json", help="JSON summary (repros beside it)")
    p.add_argument("--no-results", action="store_true", help="do not write docs/results/")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument(
        "--kinds", nargs="+", choices=sorted(MIX), default=None,
        help="only these file types (no results page, no memory tables)",
    )  # fmt: skip
    args = p.parse_args(argv)
    mix = {k: v for k, v in MIX.items() if args.kinds is None or k in args.kinds}
    args.no_results = args.no_results or args.kinds is not None
    cmu = Path(args.data)
    if not (cmu / "MANIFEST.tsv").exists():
        print(f"no CMU data at {cmu}", file=sys.stderr)
        return 2

    import hostile_inputs as H

    work = Path(tempfile.mkdtemp(prefix="sidql-fuzz-"))
    try:
        t0 = time.perf_counter()
        seeds = H.build_seeds(cmu, work / "seeds")
        seeds_path = work / "seeds.pkl"
        seeds_path.write_bytes(pickle.dumps(seeds))
        print(f"seeds built in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        amc_rows = amc_memory(cmu, work) if args.kinds is None else []
        bound_rows = memory_bounds.measure(cmu, work) if args.kinds is None else []
        counts: dict[str, Counter] = defaultdict(Counter)
        peaks: dict[str, list] = defaultdict(list)
        over: dict[str, Counter] = defaultdict(Counter)
        ops = Counter()
        failures = []
        start = time.perf_counter()
        jobs = ((i, make_input(seeds, args.seed, i, mix)) for i in range(args.n))
        repro = Path(args.out).with_suffix(".repro")
        for i, case, r in run_all(jobs, str(seeds_path), args, not args.no_progress):
            kind = case.kind
            counts[kind][r["outcome"]] += 1
            # peak of a process that imported the reader and read this file (the warm-up's
            # input-independent allocations left out): its RSS after imports + the growth
            r["peak_rss_mb"] = r["import_mb"] + r["growth_mb"]
            small = r["bytes"] <= TARGET_INPUT_BYTES
            peaks[kind].append((r["peak_rss_mb"], r["cpu_s"], r["import_mb"], i, small))
            for op in case.ops:
                ops[f"{kind}:{op.split(':')[0]}:{r['outcome']}"] += 1
            too_big = small and r["peak_rss_mb"] > TARGET_RSS_MB
            too_slow = small and r["cpu_s"] > TARGET_CPU_S
            if too_big:
                over[kind]["memory"] += 1
            if too_slow:
                over[kind]["time"] += 1
            if r["outcome"] in FAILURES or too_big or too_slow:
                failures.append({"index": i, "kind": kind, "outcome": r["outcome"],
                                 "ops": case.ops, "peak_rss_mb": round(r["peak_rss_mb"], 1),
                                 "cpu_s": round(r["cpu_s"], 2),
                                 "detail": r["detail"].splitlines()[0] if r["detail"] else ""})  # fmt: skip
                folder = repro / str(i)
                folder.mkdir(parents=True, exist_ok=True)
                cases(kind).materialise(case, folder / "case")
                (folder / "outcome.json").write_text(json.dumps({**failures[-1], **r}, indent=2))
        seconds = time.perf_counter() - start
    finally:
        shutil.rmtree(work, ignore_errors=True)

    summary = _summary(args, counts, peaks, over, ops, failures, amc_rows, seconds)
    summary["memory_bounds"] = bound_rows
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(summary, indent=2))
    table = _tables(summary) + "\n\n" + memory_bounds.table(bound_rows)
    print(table)
    if failures:
        print(f"\nreproductions: {repro}/<index>/", file=sys.stderr)
        for f in failures[:20]:
            print(f"  #{f['index']} {f['kind']} {f['outcome']} {' '.join(f['ops'])}: "
                  f"{f['detail'][:160]}", file=sys.stderr)  # fmt: skip
    if not args.no_results:
        command = "python benchmarks/fuzz_campaign.py " + " ".join(argv or sys.argv[1:])
        write_results("fuzz_campaign", "Hostile input campaign: every file type", table,
                      command=command.strip())  # fmt: skip
    bad = failures or any(r["ratio"] > AMC_TARGET_RATIO for r in amc_rows)
    bad = bad or not all(r["within"] for r in bound_rows)
    return 1 if bad else 0


def _summary(args, counts, peaks, over, ops, failures, amc_rows, seconds) -> dict:
    kinds = [k for k in MIX if k in counts]
    per_kind = {}
    for k in kinds:
        small = [p for p in peaks[k] if p[4]] or [(0.0, 0.0, 0.0, -1, True)]
        large = [p for p in peaks[k] if not p[4]]
        worst = max(small, key=lambda p: p[0])
        cpu = sorted(p[1] for p in small)
        per_kind[k] = {
            "inputs": sum(counts[k].values()),
            "outcomes": dict(counts[k]),
            "import_rss_mb": round(min(p[2] for p in peaks[k]), 1),
            "max_peak_rss_mb": round(worst[0], 1),
            "max_peak_input": worst[3],
            "max_cpu_s": round(cpu[-1], 2),
            "median_cpu_s": round(cpu[len(cpu) // 2], 3),
            "over_memory_target": over[k]["memory"],
            "over_time_target": over[k]["time"],
            "inputs_over_1mb": len(large),
            "max_peak_rss_mb_over_1mb": round(max((p[0] for p in large), default=0.0), 1),
        }
    return {
        "n": args.n, "seed": args.seed, "workers": args.workers, "timeout_s": args.timeout,
        "memory_limit_mb": args.memory_limit_mb, "seconds": round(seconds, 1),
        "targets": {"peak_rss_mb": TARGET_RSS_MB, "cpu_s": TARGET_CPU_S,
                    "amc_ratio": AMC_TARGET_RATIO},
        "per_kind": per_kind, "amc_memory": amc_rows, "by_mutation": dict(sorted(ops.items())),
        "failures": failures,
    }  # fmt: skip


def _tables(s: dict) -> str:
    cols = ("error", "ok", *FAILURES)
    lines = [
        f"{s['n']:,} hostile inputs (seed {s['seed']}), each read in its own process under "
        f"`ulimit -v` (+{s['memory_limit_mb']} MB) and a {s['timeout_s']:g} s limit, "
        f"{s['workers']} at a time: {s['seconds'] / 60:.0f} minutes.",
        "",
        "| file type | inputs | clean error | read ok | foreign | non-finite | bad error "
        "| bad name | read outside | over memory | hang | written outside | deleted outside "
        "| temporary left | peak RSS max (import baseline) MB "
        f"| CPU max (median) s | over {s['targets']['peak_rss_mb']} MB / "
        f"{s['targets']['cpu_s']:g} s |",
        "|---" * 17 + "|",
    ]
    total = Counter()
    for k, v in s["per_kind"].items():
        o = v["outcomes"]
        total.update({c: o.get(c, 0) for c in cols})
        total["inputs"] += v["inputs"]
        total["over"] += v["over_memory_target"] + v["over_time_target"]
        lines.append(
            f"| {k} | {v['inputs']:,} | "
            + " | ".join(f"{o.get(c, 0):,}" for c in cols)
            + f" | {v['max_peak_rss_mb']:.0f} ({v['import_rss_mb']:.0f}) "
            f"| {v['max_cpu_s']:.2f} ({v['median_cpu_s']:.2f}) "
            f"| {v['over_memory_target']} / {v['over_time_target']} |"
        )
    lines.append(
        f"| **all** | **{total['inputs']:,}** | "
        + " | ".join(f"**{total[c]:,}**" for c in cols)
        + f" | | | **{total['over']}** |"
    )
    lines += [
        "",
        f"Targets for inputs of at most 1 MB: peak RSS <= {s['targets']['peak_rss_mb']} MB, CPU "
        f"<= {s['targets']['cpu_s']:g} s. Peak RSS is that of a process that has imported the "
        "reader as its command does (the baseline in brackets: interpreter, numpy, MuJoCo or "
        "torch) and read the file: the baseline plus the most the input made the reading "
        "process grow (measured in a child forked from a warm parent, whose one good read and "
        "compiled kernels are left out). CPU is the reading process's user + system time. "
        + "; ".join(
            f"{k}: {v['inputs_over_1mb']} inputs over 1 MB, peak {v['max_peak_rss_mb_over_1mb']:.0f} MB"
            for k, v in s["per_kind"].items()
            if v["inputs_over_1mb"]
        )  # fmt: skip
        + ".",
        "",
        "AMC reader, peak memory over the file's size (fresh process; extra peak RSS beyond the "
        f"process before reading; target <= {s['targets']['amc_ratio']:g}x):",
        "",
        "| AMC file | size MB | frames | extra peak MB | ratio | CPU s |",
        "|---|---|---|---|---|---|",
    ]
    for r in s["amc_memory"]:
        lines.append(f"| {r['file']} | {r['mb']:.1f} | {r['frames']:,} | "
                     f"{r['peak_extra_mb']:.0f} | {r['ratio']:.2f}x | {r['cpu_s']:.2f} |")  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
