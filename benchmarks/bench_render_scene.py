"""What drawing a clip's inferred scene costs the report's videos: CPU seconds per clip with and
without its boxes, in the same run.

Usage: .venv/bin/python benchmarks/bench_render_scene.py [--data ../shared/cmu] [--repeats 3]

The clip: CMU 01_02 clip 3 (source frame 720, the playground climb: one step inferred under the
subject's feet, ``sidql.evaluation.validation.clip_scene`` on the report's body). Its 60 frames
are rendered as the report's videos render them (640x480, the original with a ghost, captions:
:func:`sim.replay.video.render_frames`, no encoding) by one renderer with the clip's boxes and one
without, alternately ``--repeats`` times; the figure is the median CPU time of the process (the
renderer's llvmpipe threads included) and the wall time per pass. Inferring the scene (once per
clip) is timed as well.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen, before MuJoCo loads

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from results import write_results  # noqa: E402

from sidql.evaluation.validation import clip_scene, physics_job, trial_ground  # noqa: E402
from sidql.keyframes.spherical import POINTS  # noqa: E402
from sim.motion.ingest import load_motion  # noqa: E402
from sim.motion.trial import subject_model  # noqa: E402
from sim.replay.checks import PointMotion, from_clip  # noqa: E402
from sim.replay.render import DEFAULT_STYLE, SkeletonRenderer  # noqa: E402
from sim.replay.video import render_frames  # noqa: E402
from sim.simulate.validate import validation_model  # noqa: E402


def one_pass(orig, ghost, ground_z, boxes) -> tuple[float, float]:
    """(CPU s, wall s) of rendering every frame of ``orig`` with ``ghost``."""
    with SkeletonRenderer(orig.names, orig.parents, DEFAULT_STYLE, ground_z=ground_z,
                          boxes=boxes) as r:  # fmt: skip
        c0, w0 = time.process_time(), time.perf_counter()
        for _ in render_frames(orig, ghost, keyframes=[0, 59], method="bench", renderer=r,
                               ground_z=ground_z, boxes=boxes):  # fmt: skip
            pass
        return time.process_time() - c0, time.perf_counter() - w0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("SIDQL_DATA", "../shared/cmu"))
    ap.add_argument("--repeats", type=int, default=3, help="passes of each; the median counts")
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    asf, amc = Path(args.data) / "01" / "01.asf", Path(args.data) / "01" / "01_02.amc"
    clips = load_motion(asf, amc, fps=30.0).split(60)
    clip = clips[3]
    skeleton, model = subject_model(asf)
    qpos = physics_job(model, clip).analyse(clip, None, trial_ground(clips))["per_frame"]["qpos"]
    c0 = time.process_time()
    boxes, ground = clip_scene(validation_model(skeleton), qpos, clip.fps)
    infer = time.process_time() - c0
    orig = from_clip(clip).restrict(POINTS)
    ghost = PointMotion(orig.names, orig.parents, orig.positions + [0.0, 0.04, 0.0], orig.fps)
    load0 = os.getloadavg()[0]
    runs = {"with": [], "without": []}
    for _ in range(args.repeats):
        runs["with"].append(one_pass(orig, ghost, ground, boxes))
        runs["without"].append(one_pass(orig, ghost, ground, ()))
    cpu = {k: float(np.median([c for c, _ in v])) for k, v in runs.items()}
    wall = {k: float(np.median([w for _, w in v])) for k, v in runs.items()}
    lines = [
        f"01_02 clip 3, {clip.n_frames} frames at 640x480, {len(boxes)} box(es); "
        f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, {os.cpu_count()} CPUs, load average "
        f"{load0:.1f} at the start; median of {args.repeats} alternating passes.",
        "",
        "| | CPU s per clip | wall s per clip |",
        "|---|---|---|",
        f"| without the boxes | {cpu['without']:.2f} | {wall['without']:.2f} |",
        f"| with the boxes | {cpu['with']:.2f} | {wall['with']:.2f} |",
        f"| ratio with / without | {cpu['with'] / cpu['without']:.3f} | "
        f"{wall['with'] / wall['without']:.3f} |",
        "",
        f"Inferring the scene (once per clip, without --simulate): {infer:.3f} CPU s.",
    ]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        print("wrote", write_results("render_scene", "What drawing a clip's scene costs", text,
                                     command="python benchmarks/bench_render_scene.py "
                                     "--data /work/shared/cmu"))  # fmt: skip


if __name__ == "__main__":
    main()
