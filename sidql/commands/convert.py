"""``sidql convert ASF AMC OUT.bvh`` / ``sidql convert F.bvh OUT.amc``: a trial in the other format."""

from __future__ import annotations

from sidql.commands.usage import add_bvh_axes
from sim.errors import UsageError
from sim.motion.trial import convert_trial

DESCRIPTION = (
    "Write a trial in the other format. ASF + AMC -> BVH (CMU's BVH layout: one joint per bone, "
    "opens in Blender and MotionBuilder; --unit, default cm, and --up of the file written). "
    "BVH -> AMC, with its ASF beside it (OUT with .asf; --unit and --up of the file read). "
    "Every point of the result is the input's (docs/bvh.md)."
)


def register(p) -> None:
    p.add_argument(
        "files", nargs="+", metavar="IN... OUT",
        help="ASF AMC OUT.bvh, or F.bvh OUT.amc",
    )  # fmt: skip
    add_bvh_axes(p)
    p.set_defaults(func=run)


def run(args) -> int:
    *inputs, out = args.files
    if len(inputs) not in (1, 2):
        raise UsageError("give ASF AMC OUT.bvh, or F.bvh OUT.amc")
    asf, amc = inputs if len(inputs) == 2 else (inputs[0], None)
    for path in convert_trial(asf, amc, out, unit=args.unit, up=args.up):
        print(f"wrote {path}")
    return 0
