"""``evaluate --physics`` on a process pool and on a local two-node Ray cluster, in one run:
clips per second per CPU, and Ray's per-task overhead before and after shipping each trial's
physics set-up once per worker.

    python benchmarks/bench_ray.py [--data ../shared/cmu] [--clips 8] [--write]

The cluster is started the way docs/scale-out.md says (Ray >= 2.59: token authentication):
``ray start --head --port P --num-cpus 1`` with its own token file, then, for two nodes, a second
``ray start --address 127.0.0.1:P --num-cpus 1`` on the same machine (loopback only). Both run
``--block`` in their own process groups, and are torn down by their process ids at the end
whatever happens (not ``ray stop``, which would stop every Ray node of this user on the machine,
another job's too).

Every run evaluates the same clips (methods uniform and optimal at W = 5 and 15, with the
physics), after a warm-up batch on the same executor (worker start-up and imports are not in
the figure: Ray's start-up is reported apart). Runs, in this order: one process; a pool of 2;
the cluster with 1 node; with 2 nodes as ``sim.batch`` sent tasks before (each task carrying
its trial's set-up, each outcome carrying its task back); with 2 nodes as now
(:class:`sim.batch.Shared`: a set-up reaches each worker once; outcomes come back without
their inputs); a pool of 2 again (the load's drift). Wall times: on a shared machine read the
ratios between runs, and the load average printed with them.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from sim.paths import default_data_dir  # noqa: E402

METHODS = ("uniform", "optimal")
COUNTS = (5, 15)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_node(ray_exe: Path, args: list[str], env: dict) -> subprocess.Popen:
    return subprocess.Popen(
        [str(ray_exe), "start", "--block", "--num-cpus=1", "--node-ip-address=127.0.0.1",
         "--disable-usage-stats", *args],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip


def _stop(node: subprocess.Popen) -> None:
    """End a ``ray start --block`` node we started, by its process group."""
    if node.poll() is not None:
        return
    node.terminate()  # ray start --block stops the processes it started
    try:
        node.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(node.pid, signal.SIGKILL)
        node.wait(timeout=10)


def _token_env(tmp: Path) -> None:
    """This process (the driver, before it imports Ray, which reads the token once) and the
    nodes it starts: token authentication with a fresh token of their own."""
    token = tmp / "token"
    token.write_text(os.urandom(32).hex())
    token.chmod(0o600)
    for k in [k for k in os.environ if k.startswith("RAY_")]:
        del os.environ[k]
    os.environ.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN_PATH=str(token),
                      RAY_AUTH_TOKEN=token.read_text())  # fmt: skip


@contextmanager
def cluster(tmp: Path, sessions: set):
    """A head node (1 CPU, token authentication, loopback); yields (address, add_node)."""
    ray_exe = Path(sys.executable).parent / "ray"
    env = {**os.environ, "PYTHONPATH": str(REPO)}  # the token: see _token_env
    port = _free_port()
    nodes = [_start_node(ray_exe, ["--head", f"--port={port}", "--include-dashboard=false",
                                   f"--temp-dir={tmp / 'ray'}"], env)]  # fmt: skip
    sessions.add(nodes[0].pid)  # start_new_session: the node's processes are in its session
    try:
        deadline = time.monotonic() + 120
        while True:  # the head's GCS accepts connections
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if nodes[0].poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("the Ray head did not start") from None
                time.sleep(0.3)
        address = f"127.0.0.1:{port}"

        def add_node():
            nodes.append(_start_node(ray_exe, [f"--address={address}"], env))
            sessions.add(nodes[-1].pid)

        yield address, add_node
    finally:
        for node in reversed(nodes):
            _stop(node)


def _wait_cpus(n: int, timeout: float = 120) -> None:
    import ray

    deadline = time.monotonic() + timeout
    while ray.cluster_resources().get("CPU", 0) < n:
        if time.monotonic() > deadline:
            raise RuntimeError(f"the cluster did not reach {n} CPUs")
        time.sleep(0.5)


@contextmanager
def old_transport():
    """``sim.batch`` as it sent tasks before: shared set-ups by value with every task, each
    outcome carrying its item back (in this driver: the remote function and the pickling)."""
    import sim.batch as batch

    reduce, away = batch.Shared.__reduce__, batch._call_away
    batch.Shared.__reduce__ = lambda self: (batch.Shared, (self.value,))
    batch._call_away = batch._call
    try:
        yield
    finally:
        batch.Shared.__reduce__, batch._call_away = reduce, away


def session_cpu(sessions) -> float:
    """CPU seconds used so far by every live process of the given sessions (the Ray nodes we
    started: raylet, GCS, workers), from /proc."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # ended meanwhile
        if int(fields[3]) in sessions:  # fields after the name: state ppid pgrp session ...
            total += int(fields[11]) + int(fields[12])  # utime, stime
    return total / tick


def cpu_now(sessions) -> float:
    """CPU seconds of this process, its waited-for children (a pool's workers) and the Ray
    nodes' processes."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime + session_cpu(sessions)


def timed_eval(cases, sessions=(), **kw) -> tuple[float, float]:
    """(wall s, CPU s of every process involved) of one ``evaluate``."""
    from sidql.evaluation.evaluate import evaluate

    c, t = cpu_now(sessions), time.perf_counter()
    out = evaluate(cases, METHODS, COUNTS, physics=True, progress=False, **kw)
    if out["failed"]:
        raise RuntimeError(f"failed tasks: {out['failed'][:2]}")
    return time.perf_counter() - t, cpu_now(sessions) - c


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--clips", type=int, default=16)
    ap.add_argument("--chunk", type=int, default=2, help="clips per task (evaluate's chunk)")
    ap.add_argument("--write", action="store_true", help="write docs/results/ray_scaling.md")
    args = ap.parse_args(argv)
    if args.data is None or not Path(args.data).is_dir():
        print("no CMU data: pass --data DIR or set SIDQL_DATA", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="sidql-bray-", dir="/tmp"))  # short socket paths
    _token_env(tmp)
    import ray

    from sidql.evaluation.cases import load_cases
    from sim.batch import ray_session

    cases, _ = load_cases(args.data, progress=False)
    cases, warm = cases[: args.clips], cases[args.clips : args.clips + 4]
    tasks = -(-args.clips // args.chunk)
    rows = []  # (run, CPUs, seconds, load)

    sessions: set = set()

    def run(name, cpus, **kw):
        timed_eval(warm, sessions, chunk=1, **kw)  # start and warm every worker
        s, cpu = timed_eval(cases, sessions, chunk=args.chunk, **kw)
        rows.append((name, cpus, s, cpu, os.getloadavg()[0]))
        print(f"{name}: {s:.1f} s, {cpu:.1f} CPU s", flush=True)

    run("one process", 1, workers=1)
    run("pool of 2", 2, workers=2)
    try:
        with cluster(tmp, sessions) as (address, add_node):
            t = time.perf_counter()
            with ray_session(address):
                startup = time.perf_counter() - t
                run("Ray, 1 node", 1, ray=address)
                add_node()
                _wait_cpus(2)
                with old_transport():
                    run("Ray, 2 nodes, tasks as before", 2, ray=address)
                run("Ray, 2 nodes", 2, ray=address)
            assert not ray.is_initialized()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    run("pool of 2, again", 2, workers=2)
    text = table(rows, args, tasks, startup)
    print(text)
    if args.write:
        from results import write_results

        print("wrote", write_results("ray_scaling", "eval on a process pool and on a Ray cluster",
                                     text, command="python benchmarks/bench_ray.py --write"))  # fmt: skip
    return 0


def table(rows, args, tasks: int, startup: float) -> str:
    lines = [
        f"`evaluate` with the physics, methods {', '.join(METHODS)} at W = "
        f"{', '.join(map(str, COUNTS))}, on {args.clips} 60-frame clips of {args.data} in "
        f"{tasks} tasks of up to {args.chunk} clips, after a warm-up batch on the same "
        f"executor; joining the cluster took {startup:.1f} s (not counted). CPU: seconds used "
        "by the driver, the pool's workers or the Ray nodes' processes (raylet, GCS, workers), "
        "which other jobs on the machine do not change much; wall: "
        f"{os.cpu_count()} cores shared with other jobs (load average in the last column).",
        "",
        "| run | CPUs | wall s | CPU s | clips per CPU-second | clips / s / CPU (wall) "
        "| CPU s per task beyond one process | load |",
        "|---|---|---|---|---|---|---|---|",
    ]
    base = rows[0][3]
    for name, cpus, s, cpu, load in rows:
        lines.append(
            f"| {name} | {cpus} | {s:.1f} | {cpu:.1f} | {args.clips / cpu:.3f} | "
            f"{args.clips / s / cpus:.3f} | {(cpu - base) / tasks:+.2f} | {load:.1f} |"
        )
    cpu = {name: c for name, _, _, c, _ in rows}
    pool = min(cpu["pool of 2"], cpu["pool of 2, again"])
    lines += [
        "",
        f"CPU, Ray with 2 nodes / pool of 2: {cpu['Ray, 2 nodes'] / pool:.2f}x (aim: at most "
        f"1.3x); with tasks as before {cpu['Ray, 2 nodes, tasks as before'] / pool:.2f}x. "
        f"Ray 2 nodes / 1 node: {cpu['Ray, 2 nodes'] / cpu['Ray, 1 node']:.2f}x the CPU for "
        "the same clips.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
