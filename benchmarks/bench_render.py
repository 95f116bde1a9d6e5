"""Offscreen rendering speed at 640x480, frames per second, against MuJoCo's default look.

Usage: .venv/bin/python benchmarks/bench_render.py [--frames 60] [--repeats 3]

Renders an original motion (31-point synthetic CMU figure) with its reconstruction as a ghost, as the
report does, under ``MUJOCO_GL=egl`` (Mesa's llvmpipe when there is no GPU). The baseline, measured in
the same run, is the same scene with MuJoCo's default quality: shadows, reflections, 4x multisampling
and capsule tessellation 28x16. Wall-clock figures (the renderer's own threads do the work), best of
``--repeats``; the machine's load average is printed because other jobs slow software rendering.
Target (issue 5): at least 30 frames per second for our defaults, rendering only.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault(
    "MUJOCO_GL", "egl"
)  # offscreen, before MuJoCo loads (importing sim sets nothing)

from sim.motion.synthetic import synthetic_motion
from sim.replay.checks import PointMotion, from_clip
from sim.replay.render import RenderStyle, SkeletonRenderer, annotate, camera_path, write_video

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
    args = ap.parse_args()
    clip = synthetic_motion(args.frames / 30.0, seed=0)
    orig = from_clip(clip)
    ghost = PointMotion(orig.names, orig.parents, orig.positions + [0.0, 0.04, 0.0], orig.fps)
    print(
        f"MUJOCO_GL={os.environ.get('MUJOCO_GL')}, {os.cpu_count()} CPUs, load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}, {args.frames} frames at 640x480, "
        f"{len(orig.names)} points + ghost"
    )
    base = frames_per_second(orig, ghost, MUJOCO_DEFAULTS, args.repeats)
    ours = frames_per_second(orig, ghost, OURS, args.repeats)
    print(f"{'':34s} {'render fps':>10s} {'+caption+mp4 fps':>17s}")
    print(f"{'baseline: MuJoCo default quality':34s} {base[0]:10.1f} {base[1]:17.1f}")
    print(f"{'ours: no shadow/reflection/MSAA':34s} {ours[0]:10.1f} {ours[1]:17.1f}")
    print(f"{'ratio ours / baseline':34s} {ours[0] / base[0]:10.2f} {ours[1] / base[1]:17.2f}")
    verdict = "meets" if ours[0] >= 30 else "MISSES"
    print(f"target >= 30 fps rendering at 640x480: {verdict} ({ours[0]:.1f} fps)")


if __name__ == "__main__":
    main()
