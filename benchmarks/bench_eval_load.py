"""``evaluate`` (the Table 3 protocol) on the shipped policy's held-out clips, quiet and with other
work on the machine, measured in one run.

    python benchmarks/bench_eval_load.py [--data ../shared/cmu] [--load 2] [--repeats 3] [--write]

Each figure is the best of ``--repeats`` runs of ``evaluate(cases, methods, [5, 10, 15])`` in this
process (one worker): greedy, the exact optimum and the learned policy (``dqn``) together, and the
two compiled baselines alone (no torch anywhere on their path), first on the machine as it is and
then with ``--load`` extra processes spinning (:mod:`busy`). The ratio busy / quiet of the run
with the policy, against the same ratio of the baselines alone, says whether the learned method
adds a slow-down of its own under load (torch's thread pool oversubscribing the cores would):
aim, at most 1.5x of the quiet time.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from busy import busy  # noqa: E402

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.evaluate import evaluate  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

COUNTS = (5, 10, 15)


def best_seconds(fn, repeats: int) -> float:
    """Best wall time of ``repeats`` calls of ``fn()`` [s]."""
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--load", type=int, default=2, help="spinning processes for 'busy'")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="write docs/results/eval_load.md")
    args = ap.parse_args(argv)
    if args.data is None or not Path(args.data).is_dir():
        print("no CMU data: pass --data DIR or set SIDQL_DATA", file=sys.stderr)
        return 2
    from sidql.learning.policy import load_policy  # lazy: torch only for the held-out split

    subjects = list(load_policy().meta["split"]["test"])
    cases, _ = load_cases(args.data, progress=False, subjects=subjects)
    runs = {
        "greedy, optimal, dqn": ("greedy", "optimal", "dqn"),
        "greedy, optimal (baseline)": ("greedy", "optimal"),
    }
    for methods in runs.values():  # warm: compiled kernels, the policy's weights, caches
        evaluate(cases[:2], methods, COUNTS, progress=False)
    figures = {}
    for label, methods in runs.items():

        def run(methods=methods):
            return evaluate(cases, methods, COUNTS, progress=False)

        quiet = best_seconds(run, args.repeats)
        with busy(args.load):
            loaded = best_seconds(run, args.repeats)
        figures[label] = (quiet, loaded)
        print(f"{label}: quiet {quiet:.2f} s, busy {loaded:.2f} s, ratio {loaded / quiet:.2f}x")
    rows = [
        f"| methods | quiet (s) | with {args.load} spinning processes (s) | busy / quiet |",
        "|---|---:|---:|---:|",
    ]
    for label, (q, b) in figures.items():
        rows.append(f"| {label} | {q:.2f} | {b:.2f} | {b / q:.2f}x |")
    (q1, b1), (q0, b0) = figures.values()
    text = (
        f"`evaluate` on the {len(cases)} clips of the shipped policy's held-out subjects "
        f"({', '.join(subjects)}), W = {', '.join(map(str, COUNTS))}, one process, best of "
        f"{args.repeats} runs each; {os.cpu_count()} cores.\n\n" + "\n".join(rows) + "\n\n"
        f"With the learned policy the run slows down {b1 / q1:.2f}x under load, "
        f"{(b1 / q1) / (b0 / q0):.2f}x the slow-down of the compiled baselines alone (aim: at "
        "most 1.5x under load; on 2 cores with other processes spinning any one-thread "
        "computation gets part of a core, so the baselines' ratio in the same run is the "
        "yardstick)."
    )
    print(text)
    if args.write:
        from results import write_results

        cmd = "python benchmarks/bench_eval_load.py --write"
        print(write_results("eval_load", "Evaluation under load", text, cmd))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
