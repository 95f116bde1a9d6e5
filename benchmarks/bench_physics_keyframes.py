"""Physics-aware keyframes: the Q / physics curve over the weight, the weight's rule, decision time.

For every 60-frame clip of the data (30 fps) and every weight on the grid, the exact optimum of
``C_Q + weight * P`` (:mod:`sidql.keyframes.physical_costs`) at each W, rebuilt with ``contacts``:
mean Q (eq. 18 on the rebuilt angles) over the Q-optimum's mean Q (Hermite, its own
reconstruction), and the physical proxy's three terms per inner frame (skating in contact
[mm/s], floor [mm], residual [BW]) of the chosen keyframes against the Q-optimum's. Weight 0 is
the Q-optimum's keyframes rebuilt with ``contacts``.

**The weight's rule**: the largest weight on the grid whose mean Q stays within
:data:`Q_BUDGET` x the Q-optimum's at every W measured (the target itself: no margin is left
for clips this data does not hold, which the pinning of ``contacts`` alone already costs).
The decision time (``methods.select("physics")``, one clip, everything included: the clip's
floor, its contact bits, the chart, both cost matrices and the programme) is the median CPU time
over clips (wall time beside it: the machine is shared), beside the Q-optimum's measured in the
same run.

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

from sidql.evaluation.cases import load_cases  # noqa: E402
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
WEIGHTS = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)
#: The rule: the largest weight whose mean Q is within this factor of the Q-optimum's at every W
#: (the target itself).
Q_BUDGET = 1.15


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
    """Median CPU time [ms] per clip of ``physics`` and ``optimal`` (no memo: all included),
    and of the sender's floor alone (part of physics'): CPU time of this process (one thread),
    not wall time, so that other jobs on a shared machine do not count; ``wall_*`` beside it."""
    from sidql.keyframes.contact_pinning import sender_ground

    names = ("physics", "optimal", "floor")
    times: dict[str, list[float]] = {k: [] for k in names + tuple(f"wall_{n}" for n in names)}
    for case in cases:
        for name in names:
            t0, w0 = time.process_time(), time.perf_counter()
            if name == "floor":  # the sender's floor alone, part of physics' time
                sender_ground(case.clip)
            else:
                methods.select(name, case.clip, W)
            times[name].append(1e3 * (time.process_time() - t0))
            times[f"wall_{name}"].append(1e3 * (time.perf_counter() - w0))
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


#: The measured figures whose excess over the original the targets bound, with their units.
EXCESS = (("residual_force_bw", "residual force (BW)", ".3f"),
          ("skate_mm_s", "skating in contact (mm/s)", ".0f"),
          ("penetration_mm", "penetration (mm)", ".2f"))  # fmt: skip
#: The eval runs the comparison reads: (label, methods, reconstruction override).
RUNS = (("Q-optimum", ("optimal",), None), ("physics-aware", ("physics",), None),
        ("Q-optimum + contacts", ("optimal",), "contacts"))  # fmt: skip


def supported_sources(out: dict) -> set[str]:
    """Trials whose floor fits and whose support is found on it (``eval --physics`` floors)."""
    return {f["source"] for f in out["floors"] if f["floor_fits"] and not f["support_off_floor"]}


def excess_rows(outs: dict, counts, sources=None) -> list[dict]:
    """Per (label, W): mean Q, and per figure of :data:`EXCESS` the mean over clips of (method -
    original) with the clips counted, and the noise floor's mean (over ``sources`` only, if
    given)."""
    rows = []
    for label, (method, out) in outs.items():
        per = [r for r in out["per_clip"] if sources is None or r["source"] in sources]
        key = lambda r: (r["source"], r["start_frame"])  # noqa: E731
        orig = {key(r): r for r in per if r["method"] == "original"}
        noise = [r for r in per if r["method"] == "noise floor"]
        for W in counts:
            mine = [r for r in per if r["method"] == method and r["keyframes"] == W]
            row = {"label": label, "W": W, "clips": len(mine),
                   "q": float(np.mean([r["q"] for r in mine]))}  # fmt: skip
            for k, _, _ in EXCESS:
                d = [r[k] - orig[key(r)][k] for r in mine
                     if r.get(k) is not None and orig[key(r)].get(k) is not None]  # fmt: skip
                row[k] = float(np.mean(d)) if d else float("nan")
                row[f"{k}_n"] = len(d)
                nf = [r[k] for r in noise if r.get(k) is not None]
                row[f"{k}_noise"] = float(np.mean(nf)) if nf else float("nan")
            rows.append(row)
    return rows


def excess_markdown(rows, counts) -> str:
    """The targets' table: excess per figure and its ratio to the Q-optimum's, Q ratio."""
    head = " | ".join(f"{t} excess | x Q-opt" for _, t, _ in EXCESS)
    lines = [f"| method | W | clips | mean Q | Q / Q-opt | {head} |",
             "|---|---:|---:|---:|---:|" + "---:|---:|" * len(EXCESS)]  # fmt: skip
    base = {r["W"]: r for r in rows if r["label"] == "Q-optimum"}
    for r in rows:
        b = base[r["W"]]
        cells = [f"{r['q']:.4f}", f"{r['q'] / b['q']:.3f}"]
        for k, _, f in EXCESS:
            ratio = r[k] / b[k] if b[k] > 0 else float("nan")
            cells += [format(r[k], f), f"{ratio:.2f}"]
        lines.append(f"| {r['label']} | {r['W']} | {r['clips']} | " + " | ".join(cells) + " |")
    noise = rows[0]
    lines.append("")
    lines.append("Noise floor (1.5 mm of marker noise on the original, mean |noisy - original|): "
                 + ", ".join(f"{t} {format(noise[f'{k}_noise'], f)}" for k, t, f in EXCESS) + ".")  # fmt: skip
    return "\n".join(lines)


def run_evals(cases, counts, workers: int) -> dict:
    """``{label: (method, evaluate(...) output)}`` of :data:`RUNS` with the physics."""
    from sidql.evaluation.evaluate import evaluate

    return {
        label: (names[0], evaluate(cases, names, counts, physics=True, progress=False,
                                   workers=workers, reconstruction=rec))
        for label, names, rec in RUNS
    }  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--keyframes", type=int, nargs="+", default=[5, 10])
    ap.add_argument("--weights", type=float, nargs="+", default=list(WEIGHTS))
    ap.add_argument("--subjects", nargs="+", default=None)
    ap.add_argument("--write", action="store_true", help="write docs/results/physics_keyframes.md")
    ap.add_argument(
        "--eval", action="store_true",
        help="also run eval --physics for the Q-optimum, physics-aware and the Q-optimum rebuilt "
        "with contacts, and tabulate the targets (slow: minutes per run)",
    )  # fmt: skip
    ap.add_argument("--workers", type=int, default=1, help="processes of the --eval runs")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    cases, _ = load_cases(a.data, fps=30.0, length=60, progress=False, subjects=a.subjects)
    curves = [clip_curve(c, a.keyframes, a.weights) for c in cases]
    table, chosen = curve_markdown(curves, a.keyframes, a.weights)
    ms = decision_ms(cases, 5)
    measured = ""
    if a.eval:
        outs = run_evals(cases, a.keyframes, a.workers)
        ok = supported_sources(outs["Q-optimum"][1])
        measured = (
            "\n\n## Measured (`eval --physics`): excess over the original\n\n"
            "Means over clips of (method - original) on the same clip; *x Q-opt*: that excess "
            "over the Q-optimum's (target <= 0.5, or within the noise floor). Physics-aware is "
            "rebuilt with `contacts` (its own); *Q-optimum + contacts* is the Q-optimum's "
            "keyframes rebuilt with `contacts` (`--reconstruction contacts`), which separates the "
            "choice from the reconstruction.\n\n### All clips\n\n"
            + excess_markdown(excess_rows(outs, a.keyframes), a.keyframes)
            + "\n\n### Clips whose floor fits and whose support is found on it "
            f"({len(ok)} trials)\n\n"
            + excess_markdown(excess_rows(outs, a.keyframes, ok), a.keyframes)
        )
    took = time.perf_counter() - t0
    body = (
        f"{len(cases)} clips of {a.data.name}, 60 frames at 30 fps. Per inner frame, means over "
        "clips, of the physical proxy (`sidql.keyframes.physical_costs`: the centre of mass and "
        "the sole spheres on the cubic Hermite through their keyframe values) for the keyframes "
        "each weight chooses; Q of those keyframes rebuilt with `contacts`.\n\n"
        f"{table}\n\n"
        f"**Rule**: the largest weight whose mean Q stays within {Q_BUDGET:.2f}x the Q-optimum's "
        f"at every W: **{chosen:g}** (the method uses `PHYSICS_WEIGHT` = {PHYSICS_WEIGHT:g}).\n\n"
        "Decision per clip (median CPU time of this process, one thread, W = 5, everything "
        f"included): physics {ms['physics']:.1f} ms (of which the sender's floor estimate "
        f"{ms['floor']:.1f} ms), the Q-optimum {ms['optimal']:.1f} ms (target: <= 50 ms; wall "
        f"time on this shared machine: {ms['wall_physics']:.1f}, {ms['wall_floor']:.1f} and "
        f"{ms['wall_optimal']:.1f} ms).\n\n"
        f"{measured}\n\n{took:.0f} s, load average {os.getloadavg()[0]:.1f}."
    )
    print(body)
    if a.write:
        from results import write_results

        cmd = "python benchmarks/bench_physics_keyframes.py" + (" --eval" if a.eval else "")
        cmd += " --write"
        print(
            write_results(
                "physics_keyframes", "Physics-aware keyframes: Q against physics", body, cmd
            )
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
