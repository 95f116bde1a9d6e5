"""Do reconstructions from few keyframes ask more of a body than the original? The decision of
``sidql eval --physics --simulate``: per method, a paired bootstrap over clips of its forward
simulation's falls and tracking errors against the original's.

Usage::

    python benchmarks/bench_simulate_decision.py --data ../shared/cmu [--keyframes 5]
        [--methods random pitch] [--every 5] [--samples 0] [--workers 1]

Every ``--every``-th 60-frame clip (30 fps) of the trials under ``--data`` is rebuilt by each
method at W = ``--keyframes``; the subject's torque-limited body tracks the IK fit of the
original and of every reconstruction with no assistance (``sim.simulate.validate``, its
default controller, or the sampling tracker with ``--samples N``), exactly as ``sidql eval
--physics --simulate`` does, and ``sidql.evaluation.significance.versus_original`` tests, per
method and figure (``sim_fell``, ``sim_error_mm``, ``sim_error_local_mm``), whether the method's
value exceeds the original's on the same clips (10,000 bootstrap resamples of the clips, the 95 %
interval of the mean difference, the one-sided p-value). Written to
``docs/results/simulate_decision.md`` (``--samples N``: ``simulate_decision_sampled.md``). Quality figures: the machine's load does not change them.
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
from sidql.evaluation.significance import versus_original_markdown  # noqa: E402
from sidql.evaluation.tables import simulate_markdown  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.simulate.validate import DEFAULT_CONTROLLER, DEFAULT_TERRAIN  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--data", "--cmu", dest="cmu", default=default_data_dir(),
        help="folder of CMU trials (default: $SIDQL_DATA or ../shared/cmu)",
    )  # fmt: skip
    ap.add_argument("--keyframes", type=int, nargs="+", default=[5])
    ap.add_argument("--methods", nargs="+", default=["random", "pitch"])
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--every", type=int, default=5, help="keep every N-th clip")
    ap.add_argument("--samples", type=int, default=0,
                    help="sampling tracker's rollouts per window (0: the default controller)")  # fmt: skip
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    command = "python benchmarks/bench_simulate_decision.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    cases, skipped = load_cases(args.cmu, progress=False, workers=args.workers)
    cases = cases[:: args.every]
    out = evaluate(cases, args.methods, args.keyframes, physics=True, simulate=True,
                   simulate_samples=args.samples, workers=args.workers,
                   progress=False)  # fmt: skip
    controller = (f"the sampling tracker, {args.samples} samples" if args.samples
                  else f"`{DEFAULT_CONTROLLER}`, the default controller")  # fmt: skip
    if DEFAULT_TERRAIN:  # eval's bodies stand in the scene inferred from the original motion
        controller += ", in the scene inferred from each clip's original motion"
    sampled = f" --samples {args.samples}" if args.samples else ""
    more = [r for r in out["versus_original"] if r["more"]]
    verdict = (
        "; ".join(f"{r['method']} (W = {r['keyframes']}) on {r['metric']}" for r in more) or "none"
    )
    text = (
        f"{len(cases)} clips of 60 frames (30 fps, 2 s) from "
        f"{len({c.clip.source for c in cases})} trials, one clip in {args.every} "
        f"({len(skipped)} bad inputs skipped); controller: {controller}, no assistance. The "
        f"equivalent command: `sidql eval --data {args.cmu} --keyframes "
        f"{' '.join(map(str, args.keyframes))} --methods {' '.join(args.methods)} --physics "
        f"--simulate{sampled}` on those clips.\n\n"
        "Each method against the original on the same clips: the mean of the paired "
        "differences (method - original), its 95 % bootstrap interval over clips (10,000 "
        "resamples) and the one-sided p-value of \"not more than the original\"; **yes** where "
        "the interval lies above 0.\n\n" + versus_original_markdown(out["versus_original"])
        + f"\n\nSignificantly more than the original: {verdict}.\n\n"
        "Means (and medians) over clips:\n\n" + simulate_markdown(out["results"])
        + f"\n\nWall time {time.perf_counter() - t0:.0f} s on {args.workers} worker(s).\n"
    )  # fmt: skip
    print(text)
    if not args.no_write:
        write_results(
            "simulate_decision_sampled" if args.samples else "simulate_decision",
            "Forward simulation: do the methods' reconstructions fall or stray more than the "
            "original?", text, command,
        )  # fmt: skip


if __name__ == "__main__":
    main()
