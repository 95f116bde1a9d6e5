"""Fuzz campaign: many mutated real ASF/AMC files through the readers (and, for a share, the ingest).

Usage: .venv/bin/python benchmarks/fuzz_campaign.py [--n 10000] [--seed 0] [--timeout 20]
           [--workers 2] [--full-every 4] [--data ../shared/cmu] [--out fuzz.json]

Each input is one real trial (its ASF and the first 30 frames of its AMC) with 1 to 3 mutations
(``tests/acclaim_mutations.py``: byte flips, line deletions/duplications/swaps, token swaps,
truncations, nan/inf/1e308/huge integers/unicode digits, hostile names, very long lines, mixed line
ends) applied to the AMC (60 %), the ASF (30 %) or both (10 %). Every ``--full-every``-th input
also runs the full path (model build, retarget onto the subject's own or the shared humanoid,
velocities). Inputs are a pure function of ``--seed`` and their index.

Each input runs in a worker process with a per-input timeout: a worker that does not answer in
time is killed and the input counted as a hang. Outcomes: ``error`` (MotionDataError naming the
file), ``ok`` (all values finite), ``foreign`` (any other exception), ``non-finite``, ``bad-error``
(a MotionDataError naming neither file or a line that does not exist), ``bad-name``, ``hang``.
For every outcome of the last five kinds the input is saved under ``<out>.repro/<index>/`` and,
except for hangs, shrunk line by line to a minimal reproduction with the same outcome.
Exit status 1 when any such outcome occurred.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import random
import shutil
import sys
import tempfile
import time
import traceback
from collections import Counter
from multiprocessing.connection import wait
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the shared mutators

from acclaim_mutations import Breach, check_outcome, mutate, seed_amc  # noqa: E402
from tqdm import tqdm  # noqa: E402

from sim.motion.dataset import find_trials  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

BAD = ("foreign", "non-finite", "bad-error", "bad-name", "hang")


def make_input(seeds: list, seed: int, i: int) -> dict:
    """Input ``i`` of the campaign (deterministic in ``seed`` and ``i``)."""
    rng = random.Random(f"{seed}:{i}")
    name, asf, amc = seeds[rng.randrange(len(seeds))]
    r = rng.random()
    target = "amc" if r < 0.6 else "asf" if r < 0.9 else "both"
    ops = []
    if target in ("asf", "both"):
        asf, m = mutate(asf, rng)
        ops += [f"asf:{x}" for x in m]
    if target in ("amc", "both"):
        amc, m = mutate(amc, rng)
        ops += [f"amc:{x}" for x in m]
    return {"index": i, "trial": name, "target": target, "ops": ops, "asf": asf, "amc": amc}


def classify(asf: bytes, amc: bytes, full: bool, skeleton: str, folder: Path) -> tuple[str, str]:
    """(outcome, detail) of one input, run in this process."""
    (folder / "t.asf").write_bytes(asf)
    (folder / "t.amc").write_bytes(amc)
    try:
        return check_outcome(folder / "t.asf", folder / "t.amc", full=full, skeleton=skeleton), ""
    except Breach as e:
        return e.kind, str(e)
    except Exception as e:  # the campaign's whole point: report anything else
        tb = traceback.format_exc(limit=-3)
        return "foreign", f"{type(e).__name__}: {str(e)[:300]}\n{tb}"


def worker(conn, folder: Path) -> None:
    while True:
        job = conn.recv()
        if job is None:
            return
        conn.send(
            (job["index"], *classify(job["asf"], job["amc"], job["full"], job["skeleton"], folder))
        )


class Worker:
    """A worker process and its scratch folder (removed when the worker is)."""

    def __init__(self):
        self.folder = Path(tempfile.mkdtemp(prefix="sidql-fuzz-"))
        self.conn, child = mp.Pipe()
        self.proc = mp.Process(target=worker, args=(child, self.folder), daemon=True)
        self.proc.start()
        child.close()
        self.job = None
        self.deadline = 0.0

    def submit(self, job: dict, timeout: float) -> None:
        self.job = job
        self.deadline = time.monotonic() + timeout
        self.conn.send(job)

    def kill(self) -> None:
        self.proc.kill()
        self.proc.join()
        self.conn.close()
        shutil.rmtree(self.folder, ignore_errors=True)

    def ask(self, job: dict, timeout: float) -> tuple[str, str]:
        """Run one job and wait for it: (outcome, detail); after a hang, call :meth:`kill`."""
        self.submit(job, timeout)
        if not self.conn.poll(timeout):
            return "hang", f"no answer in {timeout} s"
        try:
            return tuple(self.conn.recv()[1:])
        except EOFError:
            return "foreign", f"worker died (exit code {self.proc.exitcode})"


def run_jobs(jobs, n_workers: int, timeout: float, progress: bool):
    """Yield (job, outcome, detail) for every job; a job past ``timeout`` yields ``hang``."""
    jobs = iter(jobs)
    workers = [Worker() for _ in range(n_workers)]
    busy = {}
    bar = tqdm(disable=not progress, unit="input", smoothing=0.05)
    try:
        for w in workers:
            job = next(jobs, None)
            if job is not None:
                w.submit(job, timeout)
                busy[w.conn] = w
        while busy:
            now = time.monotonic()
            ready = wait(list(busy), timeout=max(0.0, min(w.deadline for w in busy.values()) - now))
            for conn in list(busy):
                w = busy[conn]
                if conn in ready:
                    try:
                        _, outcome, detail = conn.recv()
                    except EOFError:  # the worker died (e.g. killed by the OS)
                        outcome, detail = "foreign", f"worker died (exit code {w.proc.exitcode})"
                elif time.monotonic() > w.deadline:
                    outcome, detail = "hang", f"no answer in {timeout} s"
                else:
                    continue
                done = w.job
                del busy[conn]
                if outcome == "hang" or "worker died" in detail:
                    w.kill()
                    workers.remove(w)
                    w = Worker()
                    workers.append(w)
                bar.update()
                yield done, outcome, detail
                job = next(jobs, None)
                if job is not None:
                    w.submit(job, timeout)
                    busy[w.conn] = w
    finally:
        bar.close()
        for w in workers:
            w.kill()


def shrink(job: dict, outcome: str, detail: str, timeout: float) -> dict:
    """Delete chunks of lines of the mutated file(s) while the outcome (for a foreign error: and
    its exception type) stays the same."""
    kind = detail.split(":", 1)[0]
    job = dict(job)
    attempts = 0
    w = Worker()
    for key in ("amc", "asf"):
        if job["target"] not in (key, "both"):
            continue
        lines = job[key].splitlines(keepends=True)
        chunk = max(len(lines) // 2, 1)
        while chunk >= 1 and attempts < 400:
            i, changed = 0, False
            while i < len(lines) and attempts < 400:
                trial = lines[:i] + lines[i + chunk :]
                attempts += 1
                candidate = dict(job, **{key: b"".join(trial), "index": -1})
                got, got_detail = w.ask(candidate, timeout)
                if got == "hang" or "worker died" in got_detail:
                    w.kill()
                    w = Worker()
                if got == outcome and got_detail.split(":", 1)[0] == kind:
                    lines, changed = trial, True
                else:
                    i += chunk
            job[key] = b"".join(lines)
            if not changed:
                chunk //= 2
    w.kill()
    return job


def save_repro(folder: Path, job: dict, outcome: str, detail: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "t.asf").write_bytes(job["asf"])
    (folder / "t.amc").write_bytes(job["amc"])
    info = {k: job[k] for k in ("index", "trial", "target", "ops", "full", "skeleton")}
    (folder / "outcome.json").write_text(
        json.dumps(dict(info, outcome=outcome, detail=detail), indent=2)
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=10_000, help="number of mutated inputs")
    p.add_argument(
        "--seed", type=int, default=0, help="campaign seed (inputs are a function of it)"
    )
    p.add_argument("--timeout", type=float, default=20.0, help="seconds per input before a hang")
    p.add_argument("--workers", type=int, default=2, help="worker processes")
    p.add_argument("--full-every", type=int, default=4, help="run the full ingest every k-th input")
    p.add_argument(
        "--data", default=default_data_dir(),
        help="folder of CMU files (the seeds)",
    )  # fmt: skip
    p.add_argument("--out", default="fuzz_campaign.json", help="JSON summary (repros beside it)")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)

    seeds = [
        (t.name, t.asf.read_bytes(), seed_amc(t.amc.read_bytes()))
        for t in find_trials(args.data)
        if t.asf.exists()
    ]
    if not seeds:
        print(f"no trials under {args.data}", file=sys.stderr)
        return 2

    def jobs():
        for i in range(args.n):
            job = make_input(seeds, args.seed, i)
            job["full"] = args.full_every > 0 and i % args.full_every == 0
            job["skeleton"] = (
                "humanoid" if job["full"] and (i // args.full_every) % 2 else "subject"
            )
            yield job

    out = Path(args.out)
    repro_dir = out.with_suffix(".repro")
    counts, by_op, failures = Counter(), Counter(), []
    full_counts = Counter()
    start = time.perf_counter()
    bad_jobs = []
    for job, outcome, detail in run_jobs(jobs(), args.workers, args.timeout, not args.no_progress):
        counts[outcome] += 1
        if job["full"]:
            full_counts[outcome] += 1
        for op in job["ops"]:
            by_op[f"{op}:{outcome}"] += 1
        if outcome in BAD:
            bad_jobs.append((job, outcome, detail))
    seconds = time.perf_counter() - start
    for job, outcome, detail in bad_jobs:
        folder = repro_dir / str(job["index"])
        save_repro(folder, job, outcome, detail)
        if outcome != "hang":
            save_repro(
                folder / "minimal", shrink(job, outcome, detail, args.timeout), outcome, detail
            )
        failures.append({"index": job["index"], "outcome": outcome, "ops": job["ops"],
                         "detail": detail.splitlines()[0] if detail else "", "repro": str(folder)})  # fmt: skip

    summary = {
        "n": args.n,
        "seed": args.seed,
        "timeout_s": args.timeout,
        "workers": args.workers,
        "seconds": round(seconds, 1),
        "counts": {k: counts.get(k, 0) for k in ("error", "ok", *BAD)},
        "full_path": dict(full_counts),
        "by_mutation": dict(sorted(by_op.items())),
        "failures": failures,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=2))
    c = summary["counts"]
    print(f"{args.n} mutated inputs in {seconds:.0f} s ({args.workers} workers, seed {args.seed})")
    print(f"  MotionDataError   {c['error']}")
    print(f"  clean loads       {c['ok']}")
    print(f"  foreign errors    {c['foreign']}")
    print(f"  non-finite output {c['non-finite']}")
    print(
        f"  bad errors        {c['bad-error'] + c['bad-name']}  (unnamed file / no such line / bad name)"
    )
    print(f"  hangs             {c['hang']}")
    print(f"  full path (parse + model + retarget + velocities): {dict(full_counts)}")
    if failures:
        print(f"reproductions: {repro_dir}/<index>/minimal/")
        for f in failures[:20]:
            print(f"  #{f['index']} {f['outcome']} {' '.join(f['ops'])}: {f['detail'][:200]}")
    print(f"summary: {out}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
