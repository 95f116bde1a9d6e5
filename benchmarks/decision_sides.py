"""What a caller of ``select`` waits for, timed as ``sidql eval`` times it, on the working tree's
code and on other commits', each in its own process, in alternating rounds (the end-to-end
sections of bench_dqn.py).

A *side* is one Python process running one version of ``sim/`` and ``sidql/`` (the working
tree's, or a commit's exported by ``git archive`` into a temporary folder), started with this
file (``--serve``); every timing loop runs inside the side, on that side's own code:

* ``eval``: eval's own loop (``_evaluate_chunk`` in sidql/evaluation/evaluate.py): clip by clip,
  method by method, W by W, one ``select`` call timed, then that clip scored (``score``: the
  reconstruction and its errors) before the next call, so every decision starts with the caches
  as eval leaves them; eval's warm-up only (one call of each method before the loop).
* ``hot``: per method and W, each clip's ``select`` called ``repeats`` times back to back after
  one warm-up call: what a caller looping over ``select`` alone would see.
* ``evaluate``: ``sidql.evaluation.evaluate.evaluate`` itself on the same clips; its
  ``median_decision_ms`` (wall time only) checks that the ``eval`` loop times what eval reports.

Each call is timed in CPU time of the side (``time.process_time``) and in wall time. The parent
runs every side's loops in turn, round after round, the order of the sides reversed every other
round: the machine's speed drifts by up to 1.5x within a minute when other jobs share it, so a
figure is the median over rounds of each round's median over clips, with its range, and a ratio
between sides is paired within rounds (same minute) before its median is taken.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from baseline import revision_tree, serving_process

REPO = Path(__file__).resolve().parent.parent
LOOPS = ("eval", "hot", "evaluate")


class Side:
    """A process timing ``select`` on commit ``rev``'s code (None: the working tree), on the
    first ``n_clips`` clips eval would cut from ``data``."""

    def __init__(self, rev: str | None, data, n_clips: int):
        self.rev, self.data, self.n_clips = rev, str(Path(data).resolve()), int(n_clips)
        self.name = "this tree" if rev is None else _short(rev)

    def __enter__(self) -> Side:
        root = REPO
        if self.rev is not None:
            self._tmp = revision_tree(self.rev, "sidql-side-")
            root = Path(self._tmp.name)
        own_policy = self.rev is not None  # a commit's code with its own shipped policy
        self._proc = serving_process(Path(__file__), root, self.data, self.n_clips, own_policy)
        return self

    def send(self, request: list) -> None:
        self._proc.stdin.write(json.dumps(request) + "\n")
        self._proc.stdin.flush()

    def receive(self):
        line = self._proc.stdout.readline()
        if not line:
            raise RuntimeError(f"the side running {self.name} ended early")
        return json.loads(line)

    def ask(self, request: list):
        self.send(request)
        return self.receive()

    def __exit__(self, *exc) -> None:
        self._proc.stdin.close()
        self._proc.wait(timeout=120)
        if self.rev is not None:
            self._tmp.cleanup()


def _short(rev: str) -> str:
    return subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--short", rev],
        check=True, capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip


def warm(sides) -> None:
    """Compile every side's kernels (a commit's compile into its temporary folder), all sides
    at once, untimed."""
    for s in sides:
        s.send(["warm"])
    for s in sides:
        s.receive()


def run_rounds(sides, methods, counts, n_rounds: int, loops=LOOPS, repeats: int = 3,
               wrap=None) -> list[dict]:  # fmt: skip
    """Per round, ``{(side name, loop, method, W): (CPU ms, wall ms)}``: each side's median
    over clips of each loop, the sides' order reversed every other round (``wrap``: a context
    manager factory put around every request, e.g. ``lambda: busy(1)``)."""
    import contextlib

    out = []
    for r in range(n_rounds):
        got = {}
        for side in sides if r % 2 == 0 else sides[::-1]:
            for loop in loops:
                with wrap() if wrap else contextlib.nullcontext():
                    answer = side.ask([loop, list(methods), list(counts), repeats])
                for key, times in answer.items():
                    m, W = key.split()
                    got[(side.name, loop, m, int(W))] = tuple(np.median(np.array(times), axis=0))
        out.append(got)
    return out


def summary(rounds: list[dict], key) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(median over rounds, min, max) of ``(CPU ms, wall ms)`` at ``key``."""
    a = np.array([r[key] for r in rounds], dtype=float)
    return np.median(a, axis=0), a.min(axis=0), a.max(axis=0)


def paired_ratio(rounds: list[dict], top, bottom) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(median, min, max) over rounds of ``rounds[r][top] / rounds[r][bottom]`` (CPU, wall):
    a ratio taken within each round, where both saw the same minute of the machine."""
    a = np.array([np.divide(r[top], r[bottom]) for r in rounds], dtype=float)
    return np.median(a, axis=0), a.min(axis=0), a.max(axis=0)


def busy_rounds(side, methods, counts, n_rounds: int, n_busy: int = 1) -> list[dict]:
    """Per round, ``{(condition, method, W): (CPU ms, wall ms)}`` of ``side``'s eval loop on the
    machine as it is ("quiet") and with ``n_busy`` more processes spinning ("busy"), in turn,
    which first alternating round by round."""
    from busy import busy

    out = []
    for r in range(n_rounds):
        got = {}
        for extra in (0, n_busy) if r % 2 == 0 else (n_busy, 0):
            with busy(extra):
                answer = side.ask(["eval", list(methods), list(counts), 1])
            for key, times in answer.items():
                m, W = key.split()
                got[("busy" if extra else "quiet", m, int(W))] = tuple(
                    np.median(np.array(times), axis=0)
                )
        out.append(got)
    return out


AIMS = {"optimal": 0.7, "dqn": 1.0}  # ms per clip, quiet, as eval measures it


def _fig(rounds, key, i: int = 0) -> str:
    med, lo, hi = summary(rounds, key)
    return f"{med[i]:.3f} [{lo[i]:.3f}, {hi[i]:.3f}]"


def sides_table(rounds: list[dict], names: list[str], methods, counts) -> str:
    """Markdown: per W, method and side, eval's loop (CPU and wall), the hot loop (CPU),
    eval's own median (wall) and eval loop / hot loop paired; then per W and method the
    verdict against :data:`AIMS` and the first side over each other side, paired (eval's loop,
    and the hot loop in brackets)."""
    lines = [
        "| W | method | code | eval's loop, CPU ms [range over rounds] | eval's loop, wall ms | "
        "hot loop, CPU ms | `evaluate` itself, wall ms | eval's loop / hot loop, CPU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    notes = []
    for W in counts:
        for m in methods:
            for n in names:
                ev, hot = (n, "eval", m, W), (n, "hot", m, W)
                r = paired_ratio(rounds, ev, hot)
                lines.append(
                    f"| {W} | {m} | {n} | {_fig(rounds, ev)} | {_fig(rounds, ev, 1)} | "
                    f"{_fig(rounds, hot)} | {_fig(rounds, (n, 'evaluate', m, W), 1)} | "
                    f"{r[0][0]:.2f}x [{r[1][0]:.2f}, {r[2][0]:.2f}] |"
                )
            med = summary(rounds, (names[0], "eval", m, W))[0]
            verdict = "met" if med[0] <= AIMS[m] else "UNMET"
            against = "; ".join(
                f"/ {o}: {paired_ratio(rounds, (names[0], 'eval', m, W), (o, 'eval', m, W))[0][0]:.2f}x"
                f" (hot loop {paired_ratio(rounds, (names[0], 'hot', m, W), (o, 'hot', m, W))[0][0]:.2f}x)"
                for o in names[1:]
            )  # fmt: skip
            notes.append(
                f"W = {W}, {m}: {med[0]:.3f} ms CPU per clip in eval's loop, {med[1]:.3f} ms wall "
                f"(aim: at most {AIMS[m]} ms, quiet: {verdict}){'; ' + against if against else ''}."
            )
    return "\n".join(lines + [""] + notes)


def busy_table(rounds: list[dict], methods, counts) -> str:
    """Markdown: eval's loop quiet and with a core busy (median over rounds, range), and busy /
    quiet paired within rounds, in CPU and wall time (aim: at most 1.5x)."""
    lines = [
        "| W | method | quiet CPU ms | busy CPU ms | busy / quiet CPU | quiet wall ms | "
        "busy wall ms | busy / quiet wall | busy wall: aim (1.5x the quiet aim) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for W in counts:
        for m in methods:
            q, b = ("quiet", m, W), ("busy", m, W)
            r = paired_ratio(rounds, b, q)
            wall = summary(rounds, b)[0][1]
            verdict = "met" if wall <= 1.5 * AIMS[m] else "UNMET"
            lines.append(
                f"| {W} | {m} | {_fig(rounds, q)} | {_fig(rounds, b)} | {r[0][0]:.2f}x | "
                f"{_fig(rounds, q, 1)} | {_fig(rounds, b, 1)} | {r[0][1]:.2f}x | "
                f"{wall:.3f} <= {1.5 * AIMS[m]:.2f}: {verdict} |"
            )
    return "\n".join(lines)


# --- the side's process ------------------------------------------------------------------------


def _timed(fn) -> tuple[float, float]:
    c, w = time.process_time(), time.perf_counter()
    fn()
    return 1e3 * (time.process_time() - c), 1e3 * (time.perf_counter() - w)


def eval_loop(cases, methods, counts, select, score) -> dict:
    """``{"method W": [(CPU ms, wall ms) per case]}`` of eval's loop: per case, per method, per
    W, ``select(case, method, W)`` timed, then ``score(case, keyframes, method)`` untimed; eval's
    warm-up first (one ``select`` of each method on the first case at ``counts[0]``)."""
    for m in methods:
        select(cases[0], m, counts[0])
    got: dict[str, list] = {f"{m} {W}": [] for m in methods for W in counts}
    for case in cases:
        for m in methods:
            for W in counts:
                c, w = time.process_time(), time.perf_counter()
                keys = select(case, m, W)
                c, w = time.process_time() - c, time.perf_counter() - w
                got[f"{m} {W}"].append((1e3 * c, 1e3 * w))
                score(case, keys, m)
    return got


def hot_loop(cases, methods, counts, select, repeats: int) -> dict:
    """``{"method W": [(CPU ms, wall ms)...]}``: per method and W, one warm-up call, then each
    case's ``select`` ``repeats`` times back to back."""
    got = {}
    for m in methods:
        for W in counts:
            select(cases[0], m, W)
            got[f"{m} {W}"] = [
                _timed(lambda c=c, m=m, W=W: select(c, m, W)) for c in cases for _ in range(repeats)
            ]
    return got


def serve(data: str, n_clips: int) -> None:
    """The side: one JSON request a line, ``[loop, methods, counts, repeats]`` or ``["warm"]``;
    one answer a line (see :func:`eval_loop`; ``evaluate``: ``{"method W": [[nan, median
    decision ms]]}``)."""
    from sidql.evaluation.cases import clip_seed, load_cases
    from sidql.evaluation.evaluate import evaluate
    from sidql.evaluation.scoring import score
    from sidql.keyframes import methods as registry

    cases = load_cases(data, progress=False)[0][:n_clips]

    def select(case, m, W):  # as _evaluate_chunk calls it
        return registry.select(m, case.clip, W, seed=clip_seed(0, case.index, W))

    def scored(case, keys, m):
        return score(case, keys, m, None, None, None, None)

    for line in sys.stdin:
        request = json.loads(line)
        if request[0] == "warm":
            for m in ("optimal", "dqn"):
                scored(cases[0], select(cases[0], m, 5), m)
            answer = {}
        elif request[0] == "eval":
            answer = eval_loop(cases, request[1], request[2], select, scored)
        elif request[0] == "hot":
            answer = hot_loop(cases, request[1], request[2], select, request[3])
        else:
            rows = evaluate(cases, request[1], request[2], progress=False)["results"]
            answer = {f"{r['method']} {r['keyframes']}": [[float("nan"), r["median_decision_ms"]]]
                      for r in rows}  # fmt: skip
        print(json.dumps(answer), flush=True)


if __name__ == "__main__" and sys.argv[1:2] == ["--serve"]:
    import warnings

    warnings.simplefilter("ignore")  # the reader's warnings about the data go to the parent's run
    serve(sys.argv[2], int(sys.argv[3]))
