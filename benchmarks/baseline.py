"""Another commit's ``select``, timed in the same run as today's (``--baseline REV`` of
bench_dqn.py and bench_keyframes.py).

``with Baseline(rev, data, n_clips) as base: base.times_ms("dqn", 5, clip)`` exports ``sim/`` and
``sidql/`` of commit ``rev`` (``git archive``) into a temporary folder and starts one Python
process on that code (this file, ``--serve``), which loads the same clips the benchmarks load
(:func:`same_clips`) with its own reader and times ``methods.select`` on one clip per request:
CPU time of that process (``time.process_time``) and wall time, after one warm-up call per
method and W (its numba kernels compile into the temporary folder, outside the timings). The
parent asks for each clip right after timing its own on that clip, so both see the same load.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def same_clips(data, n_clips: int) -> list:
    """The first two clips of each trial of ``data`` that have 60 frames, the first ``n_clips``
    of them (what the end-to-end tables time)."""
    from sim.motion.dataset import find_trials
    from sim.motion.ingest import load_clips

    clips = [c for t in find_trials(data) for c in load_clips(t.asf, t.amc)[:2]]
    return [c for c in clips if c.n_frames == 60][:n_clips]


class Baseline:
    """A process running commit ``rev``'s code on the clips of ``data`` (see the module doc)."""

    def __init__(self, rev: str, data, n_clips: int):
        # absolute: the baseline process runs in its own temporary folder
        self.rev, self.data, self.n_clips = rev, str(Path(data).resolve()), int(n_clips)

    def __enter__(self) -> Baseline:
        self._tmp = revision_tree(self.rev, "sidql-baseline-")
        root = Path(self._tmp.name)
        self._proc = serving_process(Path(__file__), root, self.data, self.n_clips)
        self.short = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", self.rev],
            check=True, capture_output=True, text=True,
        ).stdout.strip()  # fmt: skip
        return self

    def times_ms(self, method: str, W: int, clip: int, repeats: int = 5) -> list:
        """[(CPU ms, wall ms)] of ``repeats`` single calls of the baseline's
        ``select(method, clips[clip], W)`` (the clip's index in :func:`same_clips`)."""
        self._proc.stdin.write(json.dumps([method, int(W), int(clip), int(repeats)]) + "\n")
        self._proc.stdin.flush()
        line = self._proc.stdout.readline()
        if not line:
            raise RuntimeError(f"the baseline process ({self.rev}) ended early")
        return [tuple(t) for t in json.loads(line)]

    def __exit__(self, *exc) -> None:
        self._proc.stdin.close()
        self._proc.wait(timeout=60)
        self._tmp.cleanup()


def serving_process(script: Path, root: Path, data: str, n_clips: int, own_policy: bool = True):
    """``script --serve data n_clips`` in a new process on the code under ``root`` (in its own
    working folder, one numba thread), reading requests on its stdin, answering on its stdout;
    ``own_policy``: without ``SIDQL_POLICY``, so a commit's code uses its own shipped policy."""
    env = {**os.environ, "PYTHONPATH": str(root), "NUMBA_NUM_THREADS": "1"}
    if own_policy:
        env.pop("SIDQL_POLICY", None)
    return subprocess.Popen(
        [sys.executable, str(Path(script).resolve()), "--serve", data, str(n_clips)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=root, env=env,
    )  # fmt: skip


def revision_tree(rev: str, prefix: str) -> tempfile.TemporaryDirectory:
    """A new temporary folder (name starting ``prefix``) holding commit ``rev``'s ``sim`` and
    ``sidql`` packages (``git archive``): that commit's code, importable from the folder."""
    import io

    tmp = tempfile.TemporaryDirectory(prefix=prefix)
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", "--format=tar", rev, "sim", "sidql"],
        check=True, capture_output=True,
    ).stdout  # fmt: skip
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(tmp.name, filter="data")
    return tmp


def serve(data: str, n_clips: int) -> None:
    """The baseline side: one JSON request a line, ``[method, W, clip index, repeats]``, one
    answer a line, ``[[CPU ms, wall ms], ...]`` per call (the first request of a method and W
    warms it up first, untimed)."""
    from sidql.keyframes import methods

    clips = same_clips(data, n_clips)
    warm = set()
    for line in sys.stdin:
        method, W, index, repeats = json.loads(line)
        if (method, W) not in warm:
            methods.select(method, clips[0], W)  # compile and warm up
            warm.add((method, W))
        got = []
        for _ in range(repeats):
            c, w = time.process_time(), time.perf_counter()
            methods.select(method, clips[index], W)
            got.append((1e3 * (time.process_time() - c), 1e3 * (time.perf_counter() - w)))
        print(json.dumps(got), flush=True)


if __name__ == "__main__" and sys.argv[1:2] == ["--serve"]:
    import warnings

    warnings.simplefilter("ignore")  # the reader's warnings about the data go to the parent's run
    serve(sys.argv[2], int(sys.argv[3]))
