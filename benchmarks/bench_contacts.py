"""The floor and the original's foot contacts on every trial of a CMU folder, and the contact labels
against MuJoCo's own contacts in simulated motion.

Usage: .venv/bin/python benchmarks/bench_contacts.py [--data ../shared/cmu] [--write]

Part 1, per trial (whole take at 30 fps, labelled once): the fitted floor
(:mod:`sim.physics.ground`: a robust tilted plane through the footprints of the soles' lowest
points) - its slope, how far the planted feet sit from it (spread, drift, depth below), whether it
fits (deviation within ``FLAT_TOLERANCE``) - and the original's own mean float and penetration
against it (:func:`sim.physics.contact_metrics.contact_metrics` of the original against its own labels),
the share of frames with no foot in contact, beside the same figures on a horizontal floor (the
plane may not tilt) as the baseline. Target: float and penetration <= 10 mm, or the trial flagged.

Part 2: CMU walks tracked by the simulated humanoid (``sim.simulate`` "follow" tasks at 120 Hz),
labelled from their 30 fps points, against MuJoCo's foot-floor contacts (a foot is truly in
contact in a frame when MuJoCo reports a force on its foot or toes at any control tick of the
frame's interval): precision and recall per foot. Target: >= 0.95 each.

``--write`` writes ``docs/results/contacts.md``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from sim.motion.ingest import load_motion  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402
from sim.physics.contact_metrics import contact_metrics  # noqa: E402
from sim.physics.contacts import trial_contacts  # noqa: E402
from sim.physics.ground import FLAT_TOLERANCE, estimate_ground  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: CMU walks tracked in simulation (subject, trial, seconds): the label test's and more.
SIMULATED = (("02", "02_01", 2.8), ("02", "02_02", 2.4), ("07", "07_01", 2.6),
             ("07", "07_04", 3.7), ("35", "35_01", 2.9), ("05", "05_01", 4.9),
             ("16", "16_24", 2.4), ("16", "16_25", 2.3), ("60", "60_01", 4.0))  # fmt: skip


def original_figures(clip, ground) -> dict:
    """The original's float/penetration [mm] against ``ground``, labelled once over the take, the
    share of frames without any foot in contact, and of those with nothing on the floor (body
    points other than the feet, :func:`sim.physics.contacts.body_contacts`, included)."""
    c = trial_contacts(clip.positions, clip.names, clip.fps, ground, clip.velocities, clip.parents)
    m = contact_metrics(c.contact, c)
    return {
        "float_mm": m["float_mm"], "penetration_mm": m["penetration_mm"],
        "no_contact": float((~c.contact.any(axis=1)).mean()),
        "unsupported": float((~c.supported).mean()), "parts": c.body.shares(),
    }  # fmt: skip


def fit_word(g) -> str:
    if g.fits:
        return "yes"
    if g.frames == 0:
        return "**no: no planted foot**"
    return f"**no: {1e3 * g.deviation:.0f} mm**"


def trials(data: Path):
    with open(data / "MANIFEST.tsv") as f:
        for row in csv.DictReader(f, delimiter="\t"):
            if row["file"].endswith(".amc"):
                amc = data / row["file"]
                yield amc, data / row["subject"] / f"{row['subject']}.asf", row["description"]


def floors(data: Path) -> str:
    head = (
        "| trial | description | frames | slope (mm/m) | spread mm | drift mm | below mm | fits "
        "| float mm | pen. mm | no foot down | nothing down | body on the floor "
        "| horizontal: float mm | horizontal: pen. mm |\n"
        "|---|---|---:|---|---:|---:|---:|---|---:|---:|---:|---:|---|---:|---:|"
    )
    print(head)
    rows, lines = [], []
    for amc, asf, desc in trials(data):
        try:
            clip = load_motion(asf, amc, fps=30.0)
        except Exception as e:  # noqa: BLE001 - a benchmark lists bad trials and goes on
            print(f"{amc}: skipped: {e}", file=sys.stderr)
            continue
        g = estimate_ground(clip.positions, clip.names, clip.fps)
        flat = estimate_ground(clip.positions, clip.names, clip.fps, min_span=np.inf)
        o, of = original_figures(clip, g), original_figures(clip, flat)
        ok = o["float_mm"] <= 10 and o["penetration_mm"] <= 10
        rows.append((g, o, ok))

        def mm(x):
            return "-" if not np.isfinite(x) else f"{1e3 * x:.1f}"

        line = (
            f"| {amc.stem} | {desc[:40]} | {clip.n_frames} | "
            f"{1e3 * g.slope[0]:+.1f}, {1e3 * g.slope[1]:+.1f} | {mm(g.spread)} | {mm(g.drift)} "
            f"| {mm(g.below)} | {fit_word(g)} | {o['float_mm']:.1f} | {o['penetration_mm']:.1f} "
            f"| {o['no_contact']:.2f} | {o['unsupported']:.2f} "
            f"| {', '.join(f'{k} {100 * v:.1f} %' for k, v in o['parts'].items()) or '-'} "
            f"| {of['float_mm']:.1f} | {of['penetration_mm']:.1f} |"
        )
        print(line, flush=True)
        lines.append(line)
    n = len(rows)
    met = sum(ok or not g.fits for g, _, ok in rows)
    fl = [o["float_mm"] for _, o, _ in rows]
    pe = [o["penetration_mm"] for _, o, _ in rows]
    summary = (
        f"\n{n} trials; the floor fits (deviation <= {1e3 * FLAT_TOLERANCE:.0f} mm) on "
        f"{sum(g.fits for g, *_ in rows)}; the original's float and penetration both <= 10 mm on "
        f"{sum(ok for *_, ok in rows)}; <= 10 mm or flagged: {met}/{n}. Mean float "
        f"{np.mean(fl):.1f} mm, mean penetration {np.mean(pe):.1f} mm (trials whose floor fits: "
        f"{np.mean([f for f, (g, *_) in zip(fl, rows, strict=True) if g.fits]):.1f} and "
        f"{np.mean([p for p, (g, *_) in zip(pe, rows, strict=True) if g.fits]):.1f} mm)."
    )
    print(summary)
    return head + "\n" + "\n".join(lines) + "\n" + summary + "\n"


def simulated_labels(data: Path) -> str:
    from sim.simulate.generate import SynthTask, generate

    head = "| walk | frames | left P | left R | right P | right R |\n|---|---:|---:|---:|---:|---:|"
    print(head)
    counts = {s: np.zeros(3, int) for s in "lr"}
    lines = []
    for subject, trial, seconds in SIMULATED:
        task = SynthTask(
            "follow", 0, 0, str(data / subject / f"{subject}.asf"),
            str(data / subject / f"{trial}.amc"), seconds, 120.0, controller="plain", assist=0.5,
        )  # fmt: skip
        clip, record = generate(task)
        if record["fell"]:
            print(f"{trial}: fell in simulation, left out", file=sys.stderr)
            continue
        truth120 = np.asarray(record["labels"]["sim_foot_contact"], bool)
        pos, vel = clip.positions[::4], clip.velocities[::4]
        T = len(pos)
        truth = np.stack(
            [[truth120[max(0, 4 * i - 2) : 4 * i + 2, k].any() for i in range(T)] for k in (0, 1)],
            axis=1,
        )
        g = estimate_ground(pos, clip.names, 30.0)
        c = trial_contacts(pos, clip.names, 30.0, g, vel)
        cells = []
        for k, s in enumerate("lr"):
            lab, tru = c.contact[:, c.sides.index(s)], truth[:, k]
            tp = int((lab & tru).sum())
            counts[s] += [tp, int(lab.sum()), int(tru.sum())]
            cells += [f"{tp / max(lab.sum(), 1):.3f}", f"{tp / max(tru.sum(), 1):.3f}"]
        line = f"| {trial} | {T} | " + " | ".join(cells) + " |"
        print(line, flush=True)
        lines.append(line)
    pooled = [f"{tp / n_lab:.3f}" for s in "lr" for tp, n_lab in [counts[s][:2]]]
    pooled_r = [f"{counts[s][0] / counts[s][2]:.3f}" for s in "lr"]
    line = (
        f"| **pooled** | {sum(int(c[2]) for c in counts.values())} foot-frames in contact | "
        f"{pooled[0]} | {pooled_r[0]} | {pooled[1]} | {pooled_r[1]} |"
    )
    print(line)
    return head + "\n" + "\n".join(lines) + "\n" + line + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--write", action="store_true", help="write docs/results/contacts.md")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    part1 = floors(a.data)
    part2 = simulated_labels(a.data)
    took = f"{time.perf_counter() - t0:.0f} s, load average {os.getloadavg()[0]:.1f}."
    print(took)
    if a.write:
        from results import write_results

        body = (
            "## The floor and the original's contacts, per trial\n\n" + part1
            + "\n## Contact labels against MuJoCo's contacts in simulated walks\n\n"
            "Precision (P) and recall (R) per foot of the labels from the 30 fps points against "
            "MuJoCo's foot-floor contacts within each frame's interval (the humanoid tracking the "
            "walk at 120 Hz, `sim.simulate` follow tasks).\n\n" + part2
        )  # fmt: skip
        cmd = "python benchmarks/bench_contacts.py --write"
        print(write_results("contacts", "Floor fit and foot contacts", body, cmd))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
