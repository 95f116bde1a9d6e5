"""``sidql convert ASF AMC OUT.bvh`` / ``F.bvh OUT.amc`` / ``CLIP.npz [SKELETON] OUT.bvh``: a
trial in the other format, or a clip as BVH."""

from __future__ import annotations

from sidql.commands.usage import add_bvh_axes
from sim.errors import UsageError
from sim.motion.trial import convert_trial

DESCRIPTION = (
    "Write a trial in the other format. ASF + AMC -> BVH (CMU's BVH layout: one joint per bone, "
    "opens in Blender and MotionBuilder; --unit, default cm, and --up of the file written). "
    "BVH -> AMC, with its ASF beside it (OUT with .asf; --unit and --up of the file read). "
    "A clip (.npz of ingest, synth or decode) -> BVH on the skeleton its qpos is of: give its ASF "
    "or BVH after it (default: the shared humanoid, as synth's clips). Every point of the result "
    "is the input's (docs/bvh.md)."
)


def register(p) -> None:
    p.add_argument("inputs", nargs="+", metavar="IN", help="ASF AMC, F.bvh, or CLIP.npz [ASF|BVH]")
    p.add_argument(
        "out", metavar="OUT", help="OUT.bvh (from ASF AMC or a clip), OUT.amc (from a BVH)"
    )
    add_bvh_axes(p)
    p.set_defaults(func=run)


def run(args) -> int:
    inputs, out = args.inputs, args.out
    if len(inputs) not in (1, 2):
        raise UsageError("give ASF AMC OUT.bvh, F.bvh OUT.amc, or CLIP.npz [ASF|BVH] OUT.bvh")
    asf, amc = inputs if len(inputs) == 2 else (inputs[0], None)
    for path in convert_trial(asf, amc, out, unit=args.unit, up=args.up):
        print(f"wrote {path}")
    return 0
