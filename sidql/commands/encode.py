"""``sidql encode ASF AMC --out F.sidq``: compress a whole trial into a keyframe stream."""

from __future__ import annotations

from sidql.codec.encode import CHOICES, encode_files
from sidql.codec.plan import DEFAULT_MAX_GAP
from sidql.commands.usage import HelpFormatter, positive


def register(sub) -> None:
    p = sub.add_parser(
        "encode",
        help="encode one CMU trial (ASF + AMC) into a .sidq keyframe stream",
        description="Chart the trial's 22 bones and root at --fps, choose keyframes over the whole "
        "trial by dynamic programming (max gap --max-gap, distortion + lambda x bytes, lambda by "
        "bisection to meet --rate or --max-q), quantise them (offline: 9 to 16 bits per channel, "
        "differenced and LZMA-packed; with --latency: fixed 16-bit records a live sender emits one "
        "by one) and write the .sidq container (format: README, section 'Motion codec'). With "
        "--latency L the keyframes are decided with at most L frames of look-ahead (fixed-lag "
        "programme), so a decoder outputs every frame within L frames.",
        formatter_class=HelpFormatter,
    )
    p.add_argument("asf", help="subject skeleton, e.g. ../shared/cmu/02/02.asf")
    p.add_argument("amc", help="motion, e.g. ../shared/cmu/02/02_01.amc")
    p.add_argument("--out", required=True, help="output .sidq file")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument(
        "--rate", type=positive(float), help="byte budget [bytes per second], whole file"
    )
    target.add_argument(
        "--max-q", type=positive(float), help="largest mean angle error Q (eq. 18) [rad]"
    )
    p.add_argument(
        "--reconstruction",
        choices=CHOICES,
        default="auto",
        help="curve between keyframes; auto tries all and keeps the best",
    )
    p.add_argument(
        "--latency",
        type=int,
        default=0,
        help="look-ahead in frames for live streaming (0: offline, the whole trial)",
    )
    p.add_argument("--max-gap", type=int, default=DEFAULT_MAX_GAP, help="largest keyframe gap G")
    p.add_argument("--fps", type=positive(float), default=30.0, help="stream rate (divides 120)")
    p.set_defaults(func=run, parser=p)


def run(args) -> int:
    if not 0 <= args.latency <= 65535 or not 1 <= args.max_gap <= 255:
        args.parser.error("--latency must be in 0..65535 and --max-gap in 1..255")
    enc = encode_files(
        args.asf,
        args.amc,
        args.out,
        fps=args.fps,
        rate=args.rate,
        max_q=args.max_q,
        reconstruction=args.reconstruction,
        latency=args.latency,
        max_gap=args.max_gap,
    )
    s = enc.stream
    n = s.n_frames
    print(f"frames        {n} at {s.fps:g} fps ({n / s.fps:.2f} s)")
    print(f"keyframes     {len(s.keyframes)} ({s.reconstruction}, latency {s.latency})")
    print(f"size          {len(enc.data)} bytes, {enc.bytes_per_second:.1f} B/s")
    print(f"Q             {enc.q:.5f} rad (decoded, quantisation included)")
    if len(enc.candidates) > 1:
        tried = ", ".join(f"{r} Q {q:.5f} / {b} B" for r, (q, b) in enc.candidates.items())
        print(f"tried         {tried}")
    print(f"wrote {args.out}")
    return 0
