"""``sidql report``: replay every method's reconstruction in MuJoCo, measure it, render it."""

from __future__ import annotations

from sidql.commands.usage import (
    UsageError,
    add_flat_floor,
    add_keyframes,
    add_methods,
    add_quiet,
    add_ray,
    add_reconstruction,
    add_trial,
    add_workers,
    check_keyframes,
)
from sidql.evaluation.report import report_trial
from sidql.keyframes import reconstructions
from sidql.keyframes.methods import get
from sim.replay.render import RenderStyle

DEFAULT_METHODS = ("random", "uniform", "greedy", "optimal", "pitch")


DESCRIPTION = (
    "Cut a CMU trial into 60-frame clips at 30 fps; for the chosen clips, choose W keyframes with "
    "each method, reconstruct (spherical Hermite; a method meant for another reconstruction, e.g. "
    "pitch or cartesian, also with its own), replay original and reconstructions kinematically in "
    "MuJoCo, measure bone-length drift, floor and self-penetration, foot skating, joint limits, "
    "MPJPE and velocity error, fit the subject's humanoid for contacts and dynamics, and write "
    "DIR/index.html, DIR/checks.json, one mp4 and PNGs per method."
)


def register(p) -> None:
    add_trial(p)
    add_keyframes(p, "keyframes W per clip", default=10)
    add_methods(
        p, list(DEFAULT_METHODS),
        "methods, and/or .sidq files encoded from this trial (sidql encode): a decoded "
        "stream is checked and rendered like a method",
    )  # fmt: skip
    p.add_argument(
        "--clips", type=int, nargs="+", default=[0], metavar="N", help="60-frame clip numbers"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of random methods")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--no-video", action="store_true", help="skip the mp4 videos (faster)")
    p.add_argument(
        "--layout", choices=("overlay", "side"), default="overlay",
        help="reconstruction as a ghost over the original, or beside it",
    )  # fmt: skip
    p.add_argument(
        "--simulate", action="store_true",
        help="also track the original and every reconstruction in MuJoCo's forward simulation "
        "with the subject's human-strength body and no assistance: tracking error, falls and "
        "torque per method (could a body perform this motion?)",
    )  # fmt: skip
    add_flat_floor(p)
    add_reconstruction(p)
    add_workers(p, "validating clips")
    add_ray(p, "the clips' validation")
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    streams = [m for m in args.methods if m.endswith(".sidq")]
    methods = [m for m in args.methods if not m.endswith(".sidq")]
    for name in methods:  # unknown names fail before the (slow) ingest
        get(name)
    if args.reconstruction is not None:
        reconstructions.get(args.reconstruction)
    check_keyframes(args, 60)
    if args.flat_floor and not args.simulate:
        raise UsageError("--flat-floor needs --simulate")
    page = report_trial(
        args.asf, args.amc, args.out, W=args.W, methods=methods, streams=streams,
        clips=args.clips, seed=args.seed, videos=not args.no_video,
        style=RenderStyle(layout=args.layout), workers=args.workers, ray=args.ray,
        progress=not args.quiet, simulate=args.simulate, reconstruction=args.reconstruction,
        terrain=not args.flat_floor,
    )  # fmt: skip
    print(f"report: {page}")
    return 0
