"""BVH round trip: every CMU trial written as BVH and ingested back, against its AMC.

Usage: .venv/bin/python benchmarks/bench_bvh.py [--data CMU_DIR] [--write]

Per trial: the largest distance [mm] between a point of the AMC's clip and the same point of the
BVH's (``load_motion``, 30 fps), on the subject's own humanoid and on the shared one (the issue's
target: 0.1 mm), and the BVH's size against the AMC's. Reading speed: the BVH reader (skeleton
and motion, ``parse_bvh`` + ``to_acclaim``) against the AMC readers (``parse_asf`` +
``parse_amc``) on the same trials in the same run, source frames per second of this process's CPU
time. ``--write`` writes ``docs/results/bvh.md``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from sim.acclaim.amc import parse_amc  # noqa: E402
from sim.acclaim.asf import parse_asf  # noqa: E402
from sim.bvh.convert import to_acclaim  # noqa: E402
from sim.bvh.reader import parse_bvh  # noqa: E402
from sim.bvh.writer import write_bvh  # noqa: E402
from sim.errors import MotionDataWarning  # noqa: E402
from sim.motion.dataset import find_trials  # noqa: E402
from sim.motion.ingest import load_motion  # noqa: E402
from sim.motion.trial import read_trial  # noqa: E402
from sim.paths import default_data_dir  # noqa: E402


def point_error_mm(a, b) -> float:
    return float(np.linalg.norm(a.positions - b.positions, axis=-1).max() * 1000)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=default_data_dir())
    ap.add_argument("--write", action="store_true", help="write docs/results/bvh.md")
    args = ap.parse_args()
    warnings.simplefilter("ignore", MotionDataWarning)
    trials = find_trials(args.data)
    rows, frames, t_bvh, t_amc = [], 0, 0.0, 0.0
    worst = {"subject": 0.0, "humanoid": 0.0}
    with tempfile.TemporaryDirectory() as tmp:
        for t in trials:
            skeleton, motion, fps = read_trial(t.asf, t.amc)
            path = write_bvh(Path(tmp) / f"{t.name}.bvh", skeleton, motion, fps)
            errors = []
            for which in worst:
                a = load_motion(t.asf, t.amc, skeleton=which, derivatives=False)
                b = load_motion(path, skeleton=which, derivatives=False)
                assert a.names == b.names
                errors.append(point_error_mm(a, b))
                worst[which] = max(worst[which], errors[-1])
            start = time.process_time()
            to_acclaim(parse_bvh(path))
            t_bvh += time.process_time() - start
            start = time.process_time()
            parse_amc(t.amc, parse_asf(t.asf))
            t_amc += time.process_time() - start
            frames += motion.n_frames
            ratio = path.stat().st_size / Path(t.amc).stat().st_size
            rows.append(
                f"| {t.name} | {motion.n_frames:,} | {errors[0]:.6f} | {errors[1]:.6f} | {ratio:.2f} |"
            )
            print(rows[-1], flush=True)
    text = (
        f"{len(trials)} CMU trials ({frames:,} frames at 120 Hz), each written as BVH (centimetres, "
        "y up, `sim.bvh.writer`) and ingested back at 30 fps; the largest distance of any point in "
        "any frame from the AMC's clip. Target (issue 29): 0.1 mm.\n\n"
        "| trial | frames | subject [mm] | shared humanoid [mm] | BVH / AMC size |\n|---|---|---|---|---|\n"
        + "\n".join(rows)
        + f"\n| **worst** | | **{worst['subject']:.6f}** | **{worst['humanoid']:.6f}** | |\n\n"
        f"Reading (one process, CPU time): BVH {frames / t_bvh:,.0f} frames/s, ASF + AMC "
        f"{frames / t_amc:,.0f} frames/s in the same run (ratio {t_amc / t_bvh:.2f}x)."
    )
    print(text)
    if args.write:
        from results import write_results

        cmd = "python benchmarks/bench_bvh.py --write"
        print("wrote", write_results("bvh", "BVH round trip", text, cmd))


if __name__ == "__main__":
    main()
