"""Validation by forward simulation, per keyframe method: could a body perform the motion?

Usage::

    python benchmarks/bench_simulate.py --data ../shared/cmu [--keyframes 10] [--workers 2]
        [--samples 64] [--every 5] [--max-clips N]

Every 60-frame clip (30 fps) of the trials under ``--data`` is rebuilt by each method; the
subject's humanoid is fitted to the original and to every reconstruction (``sim.physics``) and
the subject's torque-limited body tracks each fit in ``mj_step`` with no assistance
(``sim.simulate.validate``), exactly as ``sidql eval --physics --simulate`` does. Per method:
the tracking error against the motion tracked and against the original, the share of clips in
which the body fell and when, and the joint torque it used; the original's own row is the
baseline. Written to ``docs/results/simulate.md`` (with ``--samples N``, the sampling tracker
of ``sim.simulate.sampling``: ``docs/results/simulate_sampled.md``). Quality figures: the machine's load does not
change them.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from results import write_results  # noqa: E402

from sidql.evaluation.cases import load_cases  # noqa: E402
from sidql.evaluation.evaluate import evaluate  # noqa: E402
from sidql.evaluation.tables import simulate_markdown  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--data", "--cmu", dest="cmu", default=default_data_dir(),
        help="folder of CMU trials (default: $SIDQL_DATA or ../shared/cmu)",
    )  # fmt: skip
    ap.add_argument("--keyframes", type=int, nargs="+", default=[10])
    ap.add_argument("--methods", nargs="+",
                    default=["random", "uniform", "greedy", "optimal", "pitch"])  # fmt: skip
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-clips", type=int, default=None)
    ap.add_argument(
        "--every",
        type=int,
        default=1,
        help="keep every N-th clip (a subset spread over the trials)",
    )
    ap.add_argument(
        "--samples",
        type=int,
        default=0,
        help="sampling tracker's rollouts per window (0: the plain tracker)",
    )
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    command = "python benchmarks/bench_simulate.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    cases, skipped = load_cases(args.cmu, progress=False, workers=args.workers)
    cases = cases[:: args.every][: args.max_clips]
    out = evaluate(cases, args.methods, args.keyframes, physics=True, simulate=True,
                   simulate_samples=args.samples, workers=args.workers,
                   progress=False)  # fmt: skip
    trials = len({c.clip.source for c in cases})
    sampled = f" --samples {args.samples}" if args.samples else ""
    note = " (the sampling tracker, `sim.simulate.sampling`)" if args.samples else ""
    limited = f", one clip in {args.every} only (--every)" if args.every > 1 else ""
    if args.max_clips:
        limited += f", the first {args.max_clips} clips only (--max-clips)"
    text = (
        f"{len(cases)} clips of 60 frames from {trials} trials ({len(skipped)} skipped); the "
        f"equivalent command: `sidql eval --data {args.cmu} --keyframes "
        f"{' '.join(map(str, args.keyframes))} --methods {' '.join(args.methods)} --physics "
        f"--simulate{sampled}`{note}{limited}. Means over clips (fall time: over the clips that "
        "fell).\n\n" + simulate_markdown(out["results"])
    )
    if args.samples:  # what the sampling costs (the machine's load changes this one)
        text += (
            f"\nWall time {time.perf_counter() - t0:.0f} s for the whole run (loading, fits and "
            f"{len(cases) * (1 + len(args.methods) * len(args.keyframes))} simulations) on "
            f"{args.workers} workers.\n"
        )
    print(text)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if not args.no_write:
        name, title = (
            "simulate",
            "Forward simulation per method: the human-strength body, no assistance",
        )
        if args.samples:
            name, title = "simulate_sampled", title + ", the sampling tracker"
        write_results(name, title, text, command)


if __name__ == "__main__":
    main()
