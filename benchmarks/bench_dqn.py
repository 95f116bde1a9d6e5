"""Decision time of the shipped DQN policy per 60-frame clip, one core, against baselines
measured in the same run (greedy and the exact optimum on the same cost matrices).

    python benchmarks/bench_dqn.py [--data ../shared/cmu] [--keyframes 15] [--policy FILE]

The policy needs the clip's features and its segment-cost matrix; the cost matrix is issue 3's
(also what greedy and optimal need), so it is timed separately and reported alongside. Without
data the benchmark uses synthetic tasks of the same shape (60 frames, 88 feature channels).
Target (issue 4): at most 1 ms per clip for W = 15 (paper: 4 ms for W = 5).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import torch  # noqa: E402

from sim.paths import default_data_dir  # noqa: E402


def per_clip_ms(fn, n_clips: int, repeat: int = 5) -> float:
    """Best of ``repeat`` timings of ``fn()`` (which handles ``n_clips`` clips), per clip [ms]."""
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return 1e3 * best / n_clips


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(default_data_dir() or ""))
    parser.add_argument("--keyframes", type=int, nargs="+", default=[5, 15])
    parser.add_argument("--policy", default=None, help="policy file (default: the shipped one)")
    args = parser.parse_args()
    torch.set_num_threads(1)

    from sidql.keyframes.methods import greedy_from_costs
    from sidql.keyframes.optimal import solve
    from sidql.learning.policy import load_policy

    policy = load_policy(args.policy)
    if Path(args.data).is_dir():
        from sidql.learning.tasks import load_tasks

        trials = load_tasks(args.data, stride=60, progress=False)
        feats = np.concatenate([t.features for t in trials])
        costs = np.concatenate([t.costs for t in trials])
        source = f"{len(feats)} clips of {args.data}"
    else:
        rng = np.random.default_rng(0)
        feats = rng.normal(size=(100, 60, policy.net.config["n_features"])).astype(np.float32)
        costs = np.triu(rng.uniform(0, 1, (100, 60, 60)), 1)
        source = "100 synthetic clips (no data found)"
    n = len(feats)
    print(f"decision time per clip, one core, {source}")
    print("| W | dqn batched [ms] | dqn one clip [ms] | greedy [ms] | optimal DP [ms] | "
          "greedy / dqn batched |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for w in args.keyframes:
        policy.decide(feats[:2], costs[:2], w)  # warm-up
        batched = per_clip_ms(lambda w=w: policy.decide(feats, costs, w), n)
        m = min(n, 20)
        single = per_clip_ms(
            lambda w=w, m=m: [
                policy.decide(feats[i : i + 1], costs[i : i + 1], w) for i in range(m)
            ],
            m,
        )
        greedy = per_clip_ms(lambda w=w: [greedy_from_costs(c, w) for c in costs], n)
        solve(costs[0], 22, w)
        optimal = per_clip_ms(lambda w=w: [solve(c, 22, w).keyframes(w) for c in costs], n)
        print(f"| {w} | {batched:.3f} | {single:.3f} | {greedy:.3f} | {optimal:.3f} | "
              f"{greedy / batched:.2f} |")  # fmt: skip
    if Path(args.data).is_dir():
        from sidql.keyframes.segment_costs import segment_cost_matrix
        from sidql.keyframes.spherical import chart
        from sim.motion.dataset import find_trials
        from sim.motion.ingest import load_clips

        trial = find_trials(args.data)[0]
        clips = load_clips(trial.asf, trial.amc)[:10]
        series = [chart(c) for c in clips]
        segment_cost_matrix(series[0])
        ms = per_clip_ms(lambda: [segment_cost_matrix(s) for s in series], len(series))
        print(f"\nsegment-cost matrix (needed by dqn, greedy and optimal alike): {ms:.3f} ms/clip")
    return 0


if __name__ == "__main__":
    sys.exit(main())
