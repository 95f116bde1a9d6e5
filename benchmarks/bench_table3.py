"""Table 3 and the keyframe problem's quality figures, on a folder of CMU trials.

Usage: .venv/bin/python benchmarks/bench_table3.py [--data ../shared/cmu] [--parts ...] [--write]

The paper's protocol, as ``sidql eval`` runs it (the same library calls): every trial at 30 fps,
non-overlapping 60-frame clips from frame 0, W keyframes per clip counting both ends, mean Q
(eq. 18) per method. Parts (all by default):

* ``table3``: Table 3 at W = 5, 10, 15 beside the paper's figures, the chart-free errors of the
  same runs, our Q over the paper's, the optimum over greedy, the locomotion trials alone (MANIFEST
  description "walk" or "run"), W counting only the added keyframes (W + 2 = 7, 12, 17), and each
  bone's share of the optimum's Q at W = 5 -> ``docs/results/table3.md``;
* ``heldout``: the shipped DQN policy on the subjects it never trained on (its own split, stored
  in the policy file) beside the baselines -> ``docs/results/dqn_heldout.md``;
* ``rate``: bytes per second against Q, MPJPE and velocity error for every reconstruction
  (:mod:`sidql.evaluation.rate`), the equal-bytes comparison of pose-plus-rates against pose-only
  keyframes -> ``docs/results/rate_distortion.md`` and ``docs/rate_distortion.png``.

Quality figures only (errors do not depend on the machine's load); the decision-time column of
Table 3 is a timing and is as noisy as the machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sidql.evaluation.cases import load_cases
from sidql.evaluation.evaluate import evaluate
from sidql.evaluation.tables import PAPER_NAMES, PAPER_TABLE3, table3_markdown
from sidql.keyframes import reconstructions  # noqa: E402
from sidql.keyframes.methods import select  # noqa: E402
from sidql.keyframes.spherical import POINTS  # noqa: E402
from sim.files import write_atomic  # noqa: E402
from sim.model.angles import wrap_angle  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

DOCS = Path(__file__).resolve().parents[1] / "docs"
METHODS = ("random", "uniform", "greedy", "optimal", "pitch")
COUNTS = (5, 10, 15)


def mean_q(per_clip, method: str, W: int, keep=lambda source: True) -> float:
    """Mean Q of ``method`` at ``W`` over the per-clip rows whose source ``keep`` accepts."""
    q = [r["q"] for r in per_clip
         if r["method"] == method and r["keyframes"] == W and keep(r["source"])]  # fmt: skip
    return float(np.mean(q)) if q else float("nan")


def table(head, rows) -> str:
    """A Markdown table from a header and rows of cells."""
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def locomotion_trials(data: Path) -> set[str]:
    """AMC file names whose MANIFEST description names a walk or a run."""
    manifest = data / "MANIFEST.tsv"
    if not manifest.is_file():
        return set()
    with manifest.open(newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    return {
        Path(r["file"]).name for r in rows
        if r["file"].endswith(".amc") and any(w in r["description"] for w in ("walk", "run"))
    }  # fmt: skip


def bone_shares(cases, W: int = 5) -> list[tuple[str, float, float]]:
    """Per bone (name of its end point), its share of the optimum's Q at ``W`` (Hermite) and its
    mean |phi error| [rad], over every clip, largest share first."""
    err = np.zeros(len(POINTS) - 1)
    phi = np.zeros(len(POINTS) - 1)
    for c in cases:
        s = c.series
        rec = reconstructions.rebuild("hermite", c.clip, select("optimal", c.clip, W), s)
        e_phi = np.abs(wrap_angle(rec.phi - s.phi)).mean(axis=0)
        err += np.abs(wrap_angle(rec.theta - s.theta)).mean(axis=0) + e_phi
        phi += e_phi / len(cases)
    share = err / err.sum()
    order = np.argsort(-share)
    return [(POINTS[1 + b], float(share[b]), float(phi[b])) for b in order]


def table3_part(data: Path) -> str:
    cases, _ = load_cases(data, progress=False)
    out = evaluate(cases, METHODS, COUNTS, seed=0, progress=False)
    per_clip = out["per_clip"]
    trials = len({c.clip.source for c in cases})
    parts = [
        f"{trials} trials with at least one clip, {len(cases)} clips of 60 frames at 30 fps, seed 0. "
        "Mean Q (eq. 18, "
        "rad), the paper's figure in brackets; then the chart-free errors of the same runs "
        "(`Q of its keyframes, Hermite` scores a method's keyframes under the paper's "
        "reconstruction, which separates pitch's choice from its slerp; the decision time is a "
        "timing, as noisy as the machine).",
        table3_markdown(out["results"]),
    ]
    rows = []
    for m in METHODS:
        paper = PAPER_TABLE3.get(PAPER_NAMES.get(m, ""))
        if paper:
            rows.append([m] + [f"{mean_q(per_clip, m, W) / paper[W]:.2f}" for W in COUNTS])
    parts += ["### Our Q over the paper's", table(["method"] + [f"W = {W}" for W in COUNTS], rows)]
    rows = [["optimal / greedy"] + [
        f"{mean_q(per_clip, 'optimal', W) / mean_q(per_clip, 'greedy', W):.3f}" for W in COUNTS
    ]]  # fmt: skip
    parts += ["### The exact optimum against greedy", table(["Q ratio"] + [f"W = {W}" for W in COUNTS], rows)]  # fmt: skip
    walk = locomotion_trials(data)
    n_walk = sum(Path(c.clip.source).name in walk for c in cases)
    if n_walk:
        keep = lambda source: Path(source).name in walk  # noqa: E731
        rows = [[m] + [f"{mean_q(per_clip, m, W, keep):.4f}" for W in COUNTS] for m in METHODS]
        parts += [
            f"### Locomotion alone: the {n_walk} clips of walks and runs (MANIFEST descriptions)",
            table(["method"] + [f"Q, W = {W}" for W in COUNTS], rows),
        ]
    plus = tuple(W + 2 for W in COUNTS)
    extra = evaluate(cases, METHODS[:4], plus, seed=0, progress=False)["per_clip"]
    rows = [[m] + [f"{mean_q(extra, m, W):.4f}" for W in plus] for m in METHODS[:4]]
    parts += [
        "### If W counted only the added keyframes (both ends free: W + 2 in our convention)",
        table(["method"] + [f"Q, W = {W}" for W in plus], rows),
    ]
    shares = bone_shares(cases)
    rows = [[b, f"{100 * s:.1f} %", f"{p:.3f}"] for b, s, p in shares[:8]]
    parts += [
        "### Where the optimum's error sits, W = 5: each bone's share of Q (the 8 largest)",
        table(["bone", "share of Q", "mean abs. phi error (rad)"], rows),
    ]
    return "\n\n".join(parts)


def heldout_part(data: Path) -> str:
    from sidql.learning.policy import load_policy  # lazy: torch, only for this part

    policy = load_policy()
    subjects = list(policy.meta["split"]["test"])
    cases, _ = load_cases(data, progress=False, subjects=subjects)
    names = ("random", "uniform", "greedy", "optimal", "dqn")
    per_clip = evaluate(cases, names, COUNTS, seed=0, progress=False)["per_clip"]
    rows = [[m] + [f"{mean_q(per_clip, m, W):.4f}" for W in COUNTS] for m in names]
    for base in ("optimal", "greedy"):
        rows.append([f"dqn / {base}"] + [
            f"{mean_q(per_clip, 'dqn', W) / mean_q(per_clip, base, W):.3f}" for W in COUNTS
        ])  # fmt: skip
    paper = [PAPER_TABLE3["SIDQL"][W] / PAPER_TABLE3["Greedy"][W] for W in COUNTS]
    rows.append(["the paper's SIDQL / its greedy"] + [f"{r:.3f}" for r in paper])
    return (
        f"The shipped policy (`sidql/data/policy.pt`) on the {len(cases)} clips of the subjects "
        f"it never trained on ({', '.join(subjects)}; the split stored in the policy file). Mean "
        "Q (eq. 18, rad), seed 0.\n\n" + table(["method"] + [f"W = {W}" for W in COUNTS], rows)
    )


def rate_part(data: Path, write: bool) -> str:
    from sidql.evaluation.rate import rate_distortion, write_plot

    cases, _ = load_cases(data, progress=False)
    rd = rate_distortion(cases, seed=0, progress=False)
    if write:
        png = DOCS / "rate_distortion.png"
        write_plot(rd, png)
        text = json.dumps(rd, indent=1)
        write_atomic(png.with_suffix(".json"), lambda f: f.write(text.encode()))
    curve = {(c["method"], c["scheme"]): c for c in rd["curves"]}

    def cell(scheme: str, W: int) -> str:
        c = curve[("optimal", scheme)]
        i = c["keyframes"].index(W)
        return (f"W = {W}: Q {c['mean_q'][i]:.4f}, {c['mpjpe_mm'][i]:.1f} mm, "
                f"{c['velocity_error_mm_s'][i]:.0f} mm/s")  # fmt: skip

    def bytes_per_second(scheme: str, W: int) -> float:
        c = curve[("optimal", scheme)]
        return c["bytes_per_second"][c["keyframes"].index(W)]

    rows = [
        [f"{bytes_per_second('hermite', W):.0f} / {bytes_per_second('linear', 2 * W):.0f}",
         cell("hermite", W), cell("catmull_rom", 2 * W), cell("linear", 2 * W)]
        for W in COUNTS
    ]  # fmt: skip
    return (
        f"{rd['clips']} clips; each reconstruction with its own optimal keyframes; float32 values "
        f"and one index byte per keyframe; the raw 30 fps pose stream is "
        f"{rd['raw_bytes_per_second']:.0f} B/s. At (nearly) equal bytes per second, the paper's "
        "pose-plus-rates keyframes against twice as many pose-only keyframes:\n\n"
        + table(
            [
                "bytes/s",
                "Hermite, pose + rates (paper)",
                "Catmull-Rom, pose only",
                "linear, pose only",
            ],
            rows,
        )  # fmt: skip
        + "\n\nEvery curve and W: [../rate_distortion.json](../rate_distortion.json); the plot: "
        "[../rate_distortion.png](../rate_distortion.png)."
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--parts", nargs="+", choices=("table3", "heldout", "rate"),
                    default=["table3", "heldout", "rate"])  # fmt: skip
    ap.add_argument("--write", action="store_true", help="write docs/results/*.md")
    args = ap.parse_args()
    if args.data is None or not args.data.is_dir():
        sys.exit("no CMU data folder: pass --data DIR or set SIDQL_DATA")
    cmd = "python benchmarks/bench_table3.py --parts {} --write"
    done = {
        "table3": ("table3", "Table 3: mean Q of every method on the CMU trials",
                   lambda: table3_part(args.data)),
        "heldout": ("dqn_heldout", "The learned policy on held-out subjects",
                    lambda: heldout_part(args.data)),
        "rate": ("rate_distortion", "Rate and distortion of the reconstructions",
                 lambda: rate_part(args.data, args.write)),
    }  # fmt: skip
    for part in args.parts:
        name, title, run = done[part]
        text = run()
        print(f"## {title}\n\n{text}\n")
        if args.write:
            from results import write_results

            print("wrote", write_results(name, title, text, cmd.format(part)))


if __name__ == "__main__":
    main()
