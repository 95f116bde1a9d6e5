"""``sidql demo``: the main job on an embedded default (what ``./run.sh demo`` runs)."""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "cmu"
DEFAULT_TRIAL = ("02", "02_01")


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job on the embedded default",
        description="Ingest a real CMU trial (from ../shared/cmu when present, else a motion "
        "generated on the humanoid) and print its summary.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--data", default=str(DEFAULT_DATA), help="folder of CMU files")
    p.add_argument("--out", default="out/demo", help="output folder")
    p.set_defaults(func=run)


def default_clip(data: str | Path):
    """The demo's motion: CMU trial 02_01 (walk) if present, else synthetic motion."""
    from sim.ingest import load_motion
    from sim.synthetic import synthetic_motion

    subject, trial = DEFAULT_TRIAL
    asf, amc = Path(data) / subject / f"{subject}.asf", Path(data) / subject / f"{trial}.amc"
    if asf.exists() and amc.exists():
        return load_motion(asf, amc)
    print(f"no CMU data at {data}: using synthetic motion generated on the humanoid")
    return synthetic_motion(8.0, seed=0)


def run(args) -> int:
    from sim.clip import save_npz

    from .ingest import describe

    clip = default_clip(args.data)
    print(describe(clip))
    path = save_npz(clip, Path(args.out) / "motion.npz")
    print(f"wrote {path}")
    return 0
