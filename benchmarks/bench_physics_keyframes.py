"""Physics-aware keyframes: the Q / physics curve over the weight, the weight's rule, decision time.

For every 60-frame clip of the data (30 fps) and every weight on the grid, the exact optimum of
``C_Q + weight * P`` (:mod:`sidql.keyframes.physical_costs`) at each W, rebuilt with ``contacts``:
mean Q (eq. 18 on the rebuilt angles) over the Q-optimum's mean Q (Hermite, its own
reconstruction), and the physical proxy's three terms per inner frame (skating in contact
[mm/s], floor [mm], residual [BW]) of the chosen keyframes against the Q-optimum's. Weight 0 is
the Q-optimum's keyframes rebuilt with ``contacts``.

**The weight's rule**: the largest weight on the grid whose mean Q stays within
:data:`Q_BUDGET` x the Q-optimum's at every W measured (the target allows 1.15x; the margin is
for clips this data does not hold). The decision time (``methods.select("physics")``, one clip,
everything included: the clip's floor, its contact bits, the chart, both cost matrices and the
programme) is the median over clips, beside the Q-optimum's measured in the same run.

    python benchmarks/bench_physics_keyframes.py --write   # docs/results/physics_keyframes.md
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from sidql.evaluation.evaluate import load_cases  # noqa: E402
from sidql.keyframes import methods, reconstructions  # noqa: E402
from sidql.keyframes.metrics import q_from_angles  # noqa: E402
from sidql.keyframes.optimal import solve  # noqa: E402
from sidql.keyframes.physical_costs import (  # noqa: E402
    PHYSICS_WEIGHT,
    physical_costs,
    scaled,
    segment_inputs,
)
from sidql.keyframes.segment_costs import clip_cost_matrix  # noqa: E402
from sidql.keyframes.spherical import M_BONES  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402

#: The weights of the curve [rad of Q per unit of the physical cost].
WEIGHTS = (0.0, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)
#: The rule: the largest weight whose mean Q is within this factor of the Q-optimum's at every W.
Q_BUDGET = 1.10


def clip_curve(case, counts, weights) -> dict:
    """Per (weight, W): Q of the rebuilt keyframes and the proxy terms' sums; the Q-optimum's Q."""
    clip, series = case.clip, case.series
    terms = physical_costs(segment_inputs(clip))
    CQ = clip_cost_matrix(clip, "hermite")
    P = scaled(terms)
    N = clip.n_frames
    base = solve(CQ, M_BONES, max(counts))
    out = {"q_opt": {W: base.q(W) for W in counts}, "rows": {}}
    rebuilt: dict[tuple, float] = {}
    for lam in weights:
        table = solve(CQ + lam * P, M_BONES, max(counts))
        for W in counts:
            k = table.keyframes(W)
            if tuple(k) not in rebuilt:
                rec = reconstructions.rebuild("contacts", clip, k, series)
                rebuilt[tuple(k)] = q_from_angles(series, rec.theta, rec.phi)
            seg = (k[:-1], k[1:])
            sums = terms[:, seg[0], seg[1]].sum(axis=1) / N  # per frame
            out["rows"][(lam, W)] = (rebuilt[tuple(k)], *sums)
    return out


def decision_ms(cases, W: int) -> dict[str, float]:
    """Median wall time [ms] per clip of ``physics`` and ``optimal`` (no memo: all included)."""
    times: dict[str, list[float]] = {"physics": [], "optimal": []}
    for case in cases:
        for name in times:
            t0 = time.perf_counter()
            methods.select(name, case.clip, W)
            times[name].append(1e3 * (time.perf_counter() - t0))
    return {k: float(np.median(v)) for k, v in times.items()}


def curve_markdown(curves, counts, weights) -> tuple[str, float]:
    """The curve's table and the weight its rule chooses."""
    q_opt = {W: np.mean([c["q_opt"][W] for c in curves]) for W in counts}
    lines = [
        "| weight | W | mean Q (contacts) | Q / Q-optimum's | skating in contact (mm/s) "
        "| floor (mm) | residual (BW) |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    ratio = {}
    for W in counts:
        lines.append(f"| Q-optimum (Hermite) | {W} | {q_opt[W]:.4f} | 1.000 | | | |")
        for lam in weights:
            rows = np.array([c["rows"][(lam, W)] for c in curves])
            m = rows.mean(axis=0)
            ratio[(lam, W)] = m[0] / q_opt[W]
            lines.append(
                f"| {lam:g} | {W} | {m[0]:.4f} | {ratio[(lam, W)]:.3f} | {1e3 * m[1]:.1f} "
                f"| {1e3 * m[2]:.2f} | {m[3]:.4f} |"
            )
    ok = [lam for lam in weights if all(ratio[(lam, W)] <= Q_BUDGET for W in counts)]
    return "\n".join(lines), max(ok) if ok else 0.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--keyframes", type=int, nargs="+", default=[5, 10])
    ap.add_argument("--weights", type=float, nargs="+", default=list(WEIGHTS))
    ap.add_argument("--subjects", nargs="+", default=None)
    ap.add_argument("--write", action="store_true", help="write docs/results/physics_keyframes.md")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    cases, _ = load_cases(a.data, fps=30.0, length=60, progress=False, subjects=a.subjects)
    curves = [clip_curve(c, a.keyframes, a.weights) for c in cases]
    table, chosen = curve_markdown(curves, a.keyframes, a.weights)
    ms = decision_ms(cases, 5)
    took = time.perf_counter() - t0
    body = (
        f"{len(cases)} clips of {a.data.name}, 60 frames at 30 fps. Per inner frame, means over "
        "clips, of the physical proxy (`sidql.keyframes.physical_costs`: the centre of mass and "
        "the sole spheres on the cubic Hermite through their keyframe values) for the keyframes "
        "each weight chooses; Q of those keyframes rebuilt with `contacts`.\n\n"
        f"{table}\n\n"
        f"**Rule**: the largest weight whose mean Q stays within {Q_BUDGET:.2f}x the Q-optimum's "
        f"at every W: **{chosen:g}** (the method uses `PHYSICS_WEIGHT` = {PHYSICS_WEIGHT:g}).\n\n"
        f"Decision per clip (median, W = 5, everything included): physics {ms['physics']:.1f} ms, "
        f"the Q-optimum {ms['optimal']:.1f} ms (target: <= 50 ms).\n\n"
        f"{took:.0f} s, load average {os.getloadavg()[0]:.1f}."
    )
    print(body)
    if a.write:
        from results import write_results

        cmd = "python benchmarks/bench_physics_keyframes.py --write"
        print(
            write_results(
                "physics_keyframes", "Physics-aware keyframes: Q against physics", body, cmd
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
