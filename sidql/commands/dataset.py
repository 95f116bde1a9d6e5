"""``sidql dataset --data DIR --out DIR``: ingest a whole folder tree of CMU files in parallel."""

from __future__ import annotations

from sidql.commands.usage import (
    add_data,
    add_quiet,
    add_ray,
    add_skeleton,
    add_workers,
    cmu_rate,
    data_folder,
)
from sim.motion.dataset import ingest_directory

DESCRIPTION = (
    "Ingest every SS_TT.amc (with SS.asf beside it) and every .bvh under --data, in worker "
    "processes with --workers: one .npz per trial under OUT/<subject>/, plus OUT/index.json. Bad files are "
    "skipped and listed; every good result is kept; every file is written atomically. Output "
    "names are made safe (never outside OUT) and unique (same-named trials from different folders "
    "get a hash suffix; index.json maps each file to its input)."
)


def register(p) -> None:
    add_data(p, old_positional=True)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    add_skeleton(p)
    p.add_argument("--fps", type=cmu_rate, default=30.0, help="output frame rate (divides 120)")
    add_workers(p, "the trials")
    add_ray(p, "the trials")
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    s = ingest_directory(
        data_folder(args), args.out, skeleton=args.skeleton, fps=args.fps, workers=args.workers,
        ray=args.ray, progress=not args.quiet,
    )  # fmt: skip
    frames = sum(r["frames"] for r in s.written)
    print(
        f"ingested {len(s.written)} trials ({frames} frames at {args.fps:g} fps) in "
        f"{s.seconds:.1f} s -> {args.out}/index.json"
    )
    for r in s.written:
        for note in r["notes"]:
            print(f"note: {note}")
    if s.skipped:
        print(f"skipped {len(s.skipped)} bad trial(s):")
        for r in s.skipped:
            print(f"  {r['error']}")
    return 1 if s.skipped and not s.written else 0
