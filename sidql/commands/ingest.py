"""``sidql ingest ASF AMC`` (or ``F.bvh``): one trial -> one ``.npz`` of positions and true velocities."""

from __future__ import annotations

import numpy as np

from sidql.commands.usage import add_bvh_axes, add_skeleton, add_trial, cmu_rate, positive
from sim.motion.clip import save_npz
from sim.motion.ingest import load_motion

DESCRIPTION = (
    "Parse an ASF skeleton and AMC motion (or one BVH file), retarget onto a MuJoCo humanoid, and write positions "
    "(T, J, 3) [m, z up], true velocities [m/s], qpos, qvel at the output rate."
)


def register(p) -> None:
    add_trial(p)
    add_skeleton(p)
    add_bvh_axes(p)
    p.add_argument("--fps", type=cmu_rate, default=30.0, help="output frame rate (divides 120)")
    p.add_argument(
        "--source-fps", type=positive(float), default=120.0, metavar="FPS",
        help="frame rate of the AMC file (a whole multiple of --fps); a BVH gives its own",
    )  # fmt: skip
    p.add_argument("--out", required=True, metavar="F.npz", help="output clip file")
    p.set_defaults(func=run)


def run(args) -> int:
    clip = load_motion(
        args.asf, args.amc, skeleton=args.skeleton, fps=args.fps, source_fps=args.source_fps,
        unit=args.unit, up=args.up,
    )  # fmt: skip
    path = save_npz(clip, args.out)
    print(describe(clip))
    print(f"wrote {path}")
    return 0


def describe(clip) -> str:
    """A few lines a person can read: size, duration, extents, speeds."""
    T, J = clip.positions.shape[:2]
    speed = np.linalg.norm(clip.velocities, axis=-1)
    root = clip.positions[:, 0]
    travel = np.linalg.norm(np.diff(root[:, :2], axis=0), axis=-1).sum()
    return "\n".join(
        [
            f"source       {clip.source}",
            f"frames       {T} at {clip.fps:g} fps ({T / clip.fps:.2f} s), {J} points, "
            f"{T // 60} clips of 60 frames",
            f"height       {clip.positions[..., 2].min():.3f} .. {clip.positions[..., 2].max():.3f} m",
            f"root travel  {travel:.2f} m",
            f"point speed  median {np.median(speed):.2f} m/s, max {speed.max():.2f} m/s "
            f"({clip.names[int(np.unravel_index(speed.argmax(), speed.shape)[1])]})",
        ]
    )
