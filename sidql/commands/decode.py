"""``sidql decode F.sidq --out OUT.amc|OUT.npz``: rebuild every frame of an encoded trial."""

from __future__ import annotations

from sidql.codec.decode import decode_file

DESCRIPTION = (
    "Rebuild every frame of the trial at the stream's rate from its keyframes. .npz: the 23 "
    "protocol points in the 'sidql ingest' format (names, parents, positions, velocities, fps, "
    "...). .amc: angles of the source skeleton (give its ASF with --asf; its hash must match the "
    "stream's) fitted to the decoded points, one AMC frame per stream frame."
)


def register(p) -> None:
    p.add_argument("stream", metavar="F.sidq", help="input stream")
    p.add_argument(
        "--out", required=True, metavar="OUT.npz|OUT.amc", help="output points or angles"
    )
    p.add_argument("--asf", metavar="ASF", help="source skeleton (needed for .amc output)")
    p.set_defaults(func=run)


def run(args) -> int:
    path = decode_file(args.stream, args.out, asf=args.asf)
    print(f"wrote {path}")
    return 0
