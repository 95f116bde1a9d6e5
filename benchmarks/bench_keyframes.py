"""Keyframe-selection speed on 60-frame clips, as ratios against baselines measured in the same run.

    python benchmarks/bench_keyframes.py [--data ../shared/cmu] [--clips 20] [--repeats 5]
        [--baseline REV]

Per clip, single-threaded (median over clips of the best of ``--repeats`` runs):

* ``optimal, all W``: chart and segment-cost matrix in one compiled pass + the DP for every W
  from 2 to 60 (what the ``optimal`` method does for one clip); beside it, the same in two steps
  (chart, then the cost matrix from it);
* ``greedy W``: chart + the lazily evaluated greedy (numba) for W = 5 and 15;
* ``naive greedy W``: the paper's greedy, rebuilding the whole clip (numpy) for every candidate;
* ``cost matrix, numpy``: the segment-cost matrix written as plain vectorised numpy.

Also the optimum's parts alone (chart, cost matrix, programme), and the optimum for one W end to
end as ``select`` runs it (:mod:`end_to_end`: chart + only the costs the W-keyframe optimum can use
+ programme), beside the path it replaced. Targets: the exact optimum for
every W in at most 0.7 ms per clip, greedy under 1 ms. The paper reports 0.9 s for its greedy at
W = 5 and 4 ms for its network. The table goes to ``docs/results/keyframes_speed.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from sidql.keyframes.methods import naive_greedy  # noqa: E402
from sidql.keyframes.optimal import clip_optimal_table, solve  # noqa: E402
from sidql.keyframes.segment_costs import greedy_keyframes, segment_cost_matrix  # noqa: E402
from sidql.keyframes.spherical import chart  # noqa: E402
from sim.model.angles import wrap_angle  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402


def load(data: Path, n_clips: int):
    """Real 60-frame clips from ``data`` (spread over trials), or synthetic ones if absent."""
    if (data / "MANIFEST.tsv").exists():
        from baseline import same_clips

        return same_clips(data, n_clips), f"{data} (real CMU)"
    from sim.motion.synthetic import synthetic_motion

    clips = synthetic_motion(seconds=2.0 * n_clips, seed=0).split(60)[:n_clips]
    return clips, "synthetic motion (no CMU data found)"


def best_of(fn, repeats: int) -> float:
    """Best wall time of ``repeats`` calls [ms]."""
    out = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out = min(out, time.perf_counter() - t0)
    return 1000.0 * out


def numpy_cost_matrix(series) -> np.ndarray:
    """The segment-cost matrix in plain vectorised numpy (one (i, j) at a time)."""
    X = np.concatenate([series.theta, series.phi], axis=1)
    R = np.concatenate([series.dtheta, series.dphi], axis=1) * series.dt
    N = X.shape[0]
    C = np.zeros((N, N))
    for i in range(N):
        for j in range(i + 2, N):
            L = j - i
            s = (np.arange(1, L) / L)[:, None]
            s2, s3 = s * s, s * s * s
            rec = (
                (2 * s3 - 3 * s2 + 1) * X[i]
                + (-2 * s3 + 3 * s2) * X[j]
                + (s3 - 2 * s2 + s) * L * R[i]
                + (s3 - s2) * L * R[j]
            )
            C[i, j] = np.abs(wrap_angle(rec - X[i + 1 : j])).sum()
    return C


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--data", type=Path, default=default_data_dir())
    p.add_argument("--no-write", action="store_true", help="print only")
    p.add_argument("--clips", type=int, default=20)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument(
        "--baseline",
        default=None,
        help="a commit whose select to time in the same run (benchmarks/baseline.py)",
    )
    args = p.parse_args()
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    clips, what = load(args.data, args.clips)
    series = [chart(c) for c in clips]
    # compile the numba kernels outside the timings
    solve(segment_cost_matrix(series[0]), series[0].n_bones).all_keyframes()
    greedy_keyframes(series[0], 5)

    def all_w(clip):
        s = chart(clip)
        return solve(segment_cost_matrix(s), s.n_bones).all_keyframes()

    clip_optimal_table(clips[0]).all_keyframes()  # compile the one-pass kernel too
    rows = {
        "optimal, all W = 2..60": [
            best_of(lambda c=c: clip_optimal_table(c).all_keyframes(), args.repeats) for c in clips
        ],
        "  two steps: chart, then costs + programme": [
            best_of(lambda c=c: all_w(c), args.repeats) for c in clips
        ],
        "greedy, W = 5": [
            best_of(lambda c=c: greedy_keyframes(chart(c), 5), args.repeats) for c in clips
        ],
        "greedy, W = 15": [
            best_of(lambda c=c: greedy_keyframes(chart(c), 15), args.repeats) for c in clips
        ],
        "  chart alone": [best_of(lambda c=c: chart(c), args.repeats) for c in clips],
        "  programme, all W (given the matrix)": [
            best_of(lambda C=C, s=s: solve(C, s.n_bones).all_keyframes(), args.repeats)
            for C, s in zip([segment_cost_matrix(s) for s in series], series, strict=True)
        ],
        "segment-cost matrix, numba": [
            best_of(lambda s=s: segment_cost_matrix(s), args.repeats) for s in series
        ],
        "segment-cost matrix, numpy": [
            best_of(lambda s=s: numpy_cost_matrix(s), 1) for s in series
        ],
        "naive greedy, W = 5": [best_of(lambda s=s: naive_greedy(s, 5), 1) for s in series],
        "naive greedy, W = 15": [best_of(lambda s=s: naive_greedy(s, 15), 1) for s in series[:5]],
    }
    med = {k: float(np.median(v)) for k, v in rows.items()}
    load_avg = os.getloadavg()[0]
    lines = [
        f"{len(clips)} clips of 60 frames from {what}; one thread; median per clip of the best of "
        f"{args.repeats}; load average {load_avg:.1f} at the end.",
        "",
        "| | ms per clip |",
        "|---|---|",
        *[f"| {k.strip()} | {v:.3f} |" for k, v in med.items()],
        "",
        "| ratio | |",
        "|---|---|",
    ]
    for name, a, b in (
        ("naive greedy W=5 / greedy W=5", "naive greedy, W = 5", "greedy, W = 5"),
        ("naive greedy W=15 / greedy W=15", "naive greedy, W = 15", "greedy, W = 15"),
        (
            "numpy / numba segment-cost matrix",
            "segment-cost matrix, numpy",
            "segment-cost matrix, numba",
        ),
    ):
        lines.append(f"| {name} | {med[a] / med[b]:.0f}x |")
    lines.append(f"| paper greedy 0.9 s / our greedy W=5 | {900.0 / med['greedy, W = 5']:.0f}x |")
    lines.append(
        f"| paper network 4 ms / optimal all W | {4.0 / med['optimal, all W = 2..60']:.1f}x |"
    )
    lines += [
        "",
        f"Exact optimum for every W: {med['optimal, all W = 2..60']:.3f} ms (aim: at most "
        f"0.7 ms); greedy at W = 5 and 15: {med['greedy, W = 5']:.3f} and "
        f"{med['greedy, W = 15']:.3f} ms (aim: under 1 ms).",
    ]
    import contextlib

    from baseline import Baseline
    from end_to_end import end_to_end_table

    with contextlib.ExitStack() as stack:
        base = None
        if args.baseline:
            base = stack.enter_context(Baseline(args.baseline, args.data, args.clips))
        e2e = end_to_end_table(clips, (5, 15), args.repeats, with_dqn=False, baseline=base)

    lines += [
        "",
        "The exact optimum for one W as `select` (and so `eval`) runs it: chart + the costs it "
        "can use + programme in one compiled call after the method's checks, beside the paths "
        "it replaced (the same steps as separate calls with the programme's walk back in Python; "
        "the all-W table cut at W), median of single calls, CPU and wall time of one thread, "
        "same clips; the before / after ratios are against the same work without `select`'s "
        "checks (`clip_optimal_keyframes`); a 'baseline' row is `select` of the commit named "
        "(`--baseline`, its own code in another process, timed on each clip right after "
        "this process's rows):",
        "",
        e2e,
    ]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        from results import write_results

        print("wrote", write_results("keyframes_speed", "Keyframe selection speed", text,
                                     command=" ".join(["python benchmarks/bench_keyframes.py", *sys.argv[1:]])))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
