"""``sidql decode F.sidq --out OUT.npz|OUT.amc|OUT.bvh``: rebuild every frame of an encoded trial."""

from __future__ import annotations

from sidql.codec.decode import decode_file
from sim.jit import start_numba

DESCRIPTION = (
    "Rebuild every frame of the trial at the stream's rate from its keyframes. .npz: the 23 "
    "protocol points in the 'sidql ingest' format (names, parents, positions, velocities, fps, "
    "...). .amc: angles of the source skeleton (give its ASF with --asf; its hash must match the "
    "stream's) fitted to the decoded points, one AMC frame per stream frame. .bvh: the same angles "
    "as a BVH file (opens in Blender; --asf: the ASF, or the BVH the stream was encoded from)."
)


def register(p) -> None:
    p.add_argument("stream", metavar="F.sidq", help="input stream")
    p.add_argument(
        "--out", required=True, metavar="OUT.npz|OUT.amc|OUT.bvh", help="output points or angles"
    )
    p.add_argument(
        "--asf", metavar="ASF|BVH", help="source skeleton (needed for .amc and .bvh output)"
    )
    p.set_defaults(func=run)


def run(args) -> int:
    start_numba()
    path = decode_file(args.stream, args.out, asf=args.asf)
    print(f"wrote {path}")
    return 0
