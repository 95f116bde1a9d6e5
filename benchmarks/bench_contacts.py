"""The floor and the original's foot contacts on every trial of a CMU folder.

Usage: .venv/bin/python benchmarks/bench_contacts.py [--data ../shared/cmu] [--fps 30] [--write]

Per trial (whole take at ``--fps``, labelled once): the fitted floor (:mod:`sim.physics.ground`:
a robust tilted plane through the planted sole points) - its slope, how far the planted feet sit
from it (spread: 90th percentile |residual|; drift: range of the median residual over the take's
quarters), whether it fits (deviation within ``FLAT_TOLERANCE``) - and the original's own mean
float and penetration against it (``sim.physics.contacts.contact_metrics`` of the original
against its own labels), beside the same figures on a horizontal floor (``min_span`` infinite:
the plane may not tilt) as the baseline. ``--write`` writes ``docs/results/contacts.md``.
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
from sim.physics.contacts import contact_metrics, trial_contacts  # noqa: E402
from sim.physics.ground import FLAT_TOLERANCE, estimate_ground, horizontal_speed  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def original_figures(clip, ground) -> dict:
    """The original's float/penetration [mm] against ``ground``, labelled once over the take."""
    feet, contact = trial_contacts(clip.positions, clip.names, clip.fps, ground)
    pf = clip.positions[:, [clip.names.index(n) for n in feet]]
    h = ground.heights(pf, feet)
    m = contact_metrics(contact, h, horizontal_speed(pf, clip.fps), contact)
    return {"float_mm": m["float_mm"], "penetration_mm": m["penetration_mm"],
            "contact_share": float(contact.mean())}  # fmt: skip


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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--write", action="store_true", help="write docs/results/contacts.md")
    a = ap.parse_args(argv)
    rows, t0 = [], time.perf_counter()
    head = (
        "| trial | description | frames | slope (mm/m) | spread mm | drift mm | tilt mm | fits "
        "| float mm | pen. mm | horizontal: float mm | horizontal: pen. mm |\n"
        "|---|---|---:|---|---:|---:|---:|---|---:|---:|---:|---:|"
    )
    print(head)
    for amc, asf, desc in trials(a.data):
        try:
            clip = load_motion(asf, amc, fps=a.fps)
        except Exception as e:  # noqa: BLE001 - a benchmark lists bad trials and goes on
            print(f"{amc}: skipped: {e}", file=sys.stderr)
            continue
        g = estimate_ground(clip.positions, clip.names, clip.fps)
        flat = estimate_ground(clip.positions, clip.names, clip.fps, min_span=np.inf)
        o, of = original_figures(clip, g), original_figures(clip, flat)
        ok = o["float_mm"] <= 10 and o["penetration_mm"] <= 10
        rows.append((g, o, ok))
        line = (
            f"| {amc.stem} | {desc[:40]} | {clip.n_frames} | "
            f"{1e3 * g.slope[0]:+.1f}, {1e3 * g.slope[1]:+.1f} | {1e3 * g.spread:.1f} | "
            f"{1e3 * g.drift:.1f} | {1e3 * g.tilt:.1f} | "
            f"{fit_word(g)} | "
            f"{o['float_mm']:.1f} | {o['penetration_mm']:.1f} | {of['float_mm']:.1f} | "
            f"{of['penetration_mm']:.1f} |"
        )
        print(line, flush=True)
        rows[-1] = (*rows[-1], line)
    n = len(rows)
    met = sum(ok or not g.fits for g, _, ok, _ in rows)
    summary = (
        f"\n{n} trials; the floor fits (deviation <= {1e3 * FLAT_TOLERANCE:.0f} mm) on "
        f"{sum(g.fits for g, *_ in rows)}; original float and penetration both <= 10 mm on "
        f"{sum(ok for _, _, ok, _ in rows)}; <= 10 mm or flagged: {met}/{n}. "
        f"Mean float {np.mean([o['float_mm'] for _, o, _, _ in rows]):.1f} mm, "
        f"mean penetration {np.mean([o['penetration_mm'] for _, o, _, _ in rows]):.1f} mm. "
        f"{time.perf_counter() - t0:.0f} s, load average {os.getloadavg()[0]:.1f}."
    )
    print(summary)
    if a.write:
        from results import write_results

        body = head + "\n" + "\n".join(r[3] for r in rows) + "\n" + summary + "\n"
        cmd = "python benchmarks/bench_contacts.py --write"
        print(write_results("contacts", "Floor fit and the original's contacts", body, cmd))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
