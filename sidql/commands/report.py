"""``sidql report``: replay every method's reconstruction in MuJoCo, measure it, render it."""

from __future__ import annotations

import argparse

DEFAULT_METHODS = ("random", "uniform", "greedy", "optimal", "pitch")


def register(sub) -> None:
    p = sub.add_parser(
        "report",
        help="replay, check and render reconstructions of a trial into an HTML report",
        description="Cut a CMU trial into 60-frame clips at 30 fps; for the chosen clips, choose W "
        "keyframes with each method, reconstruct (spherical Hermite; the pitch method also with its "
        "own slerp), replay original and reconstructions kinematically in MuJoCo, measure bone-length "
        "drift, floor and self-penetration, foot skating, joint limits, MPJPE and velocity error, "
        "and write DIR/index.html, DIR/checks.json, one mp4 and PNGs per method.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("asf", help="the subject's skeleton (.asf)")
    p.add_argument("amc", help="one of its motions (.amc)")
    p.add_argument("--keyframes", "-W", type=int, default=10, help="keyframes per clip (W)")
    p.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS), help="methods")
    p.add_argument("--clips", type=int, nargs="+", default=[0], help="60-frame clip numbers")
    p.add_argument("--seed", type=int, default=0, help="seed of random methods")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-video", action="store_true", help="skip the mp4 videos (faster)")
    p.add_argument(
        "--layout", choices=("overlay", "side"), default="overlay",
        help="reconstruction as a ghost over the original, or beside it",
    )  # fmt: skip
    p.add_argument("--workers", type=int, default=1, help="processes validating clips")
    p.add_argument(
        "--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
        help="validate the clips as Ray tasks: a local runtime, or the cluster at ADDRESS",
    )  # fmt: skip
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    from sidql.evaluation.report import report_trial
    from sim.errors import MotionDataError
    from sim.replay.render import RenderStyle

    try:
        page = report_trial(
            args.asf, args.amc, args.out, W=args.keyframes, methods=args.methods,
            clips=args.clips, seed=args.seed, videos=not args.no_video,
            style=RenderStyle(layout=args.layout), workers=args.workers, ray=args.ray,
        )  # fmt: skip
    except MotionDataError:
        raise
    except (ValueError, KeyError) as e:  # bad clip number, W or method name: say which
        print(f"sidql report: error: {e}", file=sys.stderr)
        return 2
    print(f"report: {page}")
    return 0
