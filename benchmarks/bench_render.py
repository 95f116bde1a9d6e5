"""Offscreen rendering speed at 640x480, frames per second, against MuJoCo's default look.

Usage: .venv/bin/python benchmarks/bench_render.py [--frames 60] [--repeats 3]

Renders an original motion (31-point synthetic CMU figure) with its reconstruction as a ghost, as the
report does, under ``MUJOCO_GL=egl`` (Mesa's llvmpipe when there is no GPU). The baseline, measured in
the same run, is the same scene with MuJoCo's default quality: shadows, reflections, 4x multisampling
and capsule tessellation 28x16. Wall-clock figures (the renderer's own threads do the work), best of
``--repeats``; the machine's load average is printed because other jobs slow software rendering.
Our defaults are measured twice in the same run: on the machine as it is, and with ``--load``
extra processes spinning (:mod:`busy`), as when other work shares the machine. Target: at least 30
frames per second for the report's videos (640x480, captions, H.264 mp4) under that load.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault(
    "MUJOCO_GL", "egl"
)  # offscreen, before MuJoCo loads (importing sim sets nothing)

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from busy import busy  # noqa: E402
from results import write_results  # noqa: E402

from sim.motion.synthetic import synthetic_motion
from sim.replay.annotate import annotate
from sim.replay.checks import PointMotion, from_clip
from sim.replay.render import RenderStyle, SkeletonRenderer, camera_path
from sim.replay.video import write_video

MUJOCO_DEFAULTS = RenderStyle(shadows=True, reflections=True, multisample=4, slices=28, stacks=16)
OURS = RenderStyle()


def frames_per_second(orig: PointMotion, ghost: PointMotion, style: RenderStyle, repeats: int):
    """(rendering only, rendering + caption + H.264 encoding) frames per second, best of repeats."""
    T = orig.n_frames
    lookat, az = camera_path(orig.positions[:, 0], orig.fps)
    best_draw, best_all = 0.0, 0.0
    with SkeletonRenderer(orig.names, orig.parents, style) as r:
        r.draw(orig.positions[0], ghost.positions[0], lookat=lookat[0], azimuth=az)  # warm-up
        for _ in range(repeats):
            t0 = time.perf_counter()
            for t in range(T):
                r.draw(orig.positions[t], ghost.positions[t], lookat=lookat[t], azimuth=az)
            best_draw = max(best_draw, T / (time.perf_counter() - t0))

            def frames():
                for t in range(T):
                    img = r.draw(
                        orig.positions[t], ghost.positions[t], lookat=lookat[t], azimuth=az
                    )
                    yield annotate(
                        img, [f"bench frame {t}"], t=t, n=T, keyframes=[0, T - 1], key=False
                    )

            with tempfile.TemporaryDirectory() as d:
                t0 = time.perf_counter()
                write_video(frames(), Path(d) / "bench.mp4", orig.fps)
                best_all = max(best_all, T / (time.perf_counter() - t0))
    return best_draw, best_all


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=60, help="frames per pass")
    ap.add_argument("--repeats", type=int, default=3, help="passes; the best counts")
    ap.add_argument("--load", type=int, default=2, help="spinning processes for 'busy'")
    ap.add_argument("--no-write", action="store_true", help="print only")
    args = ap.parse_args()
    clip = synthetic_motion(args.frames / 30.0, seed=0)
    orig = from_clip(clip)
    ghost = PointMotion(orig.names, orig.parents, orig.positions + [0.0, 0.04, 0.0], orig.fps)
    head = (
        f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, {os.cpu_count()} CPUs, load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at the start, {args.frames} frames at "
        f"640x480, {len(orig.names)} points + ghost; busy = {args.load} more processes spinning."
    )
    base = frames_per_second(orig, ghost, MUJOCO_DEFAULTS, args.repeats)
    ours = frames_per_second(orig, ghost, OURS, args.repeats)
    with busy(args.load):
        loaded = frames_per_second(orig, ghost, OURS, args.repeats)
    lines = [
        head,
        "",
        "| | render fps | + caption + mp4 fps |",
        "|---|---|---|",
        f"| baseline: MuJoCo default quality | {base[0]:.1f} | {base[1]:.1f} |",
        f"| ours: no shadow/reflection/MSAA | {ours[0]:.1f} | {ours[1]:.1f} |",
        f"| ours, busy | {loaded[0]:.1f} | {loaded[1]:.1f} |",
        f"| ratio ours / baseline | {ours[0] / base[0]:.2f} | {ours[1] / base[1]:.2f} |",
        f"| ratio busy / quiet | {loaded[0] / ours[0]:.2f} | {loaded[1] / ours[1]:.2f} |",
        "",
        f"Report video (captions + mp4) under load: {loaded[1]:.1f} fps (aim: at least 30).",
    ]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        print("wrote", write_results("render", "Offscreen rendering speed", text,
                                     command="python benchmarks/bench_render.py"))  # fmt: skip


if __name__ == "__main__":
    main()
