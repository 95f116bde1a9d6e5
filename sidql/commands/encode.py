"""``sidql encode ASF AMC --out F.sidq``: compress a whole trial into a keyframe stream."""

from __future__ import annotations

from functools import partial

from sidql.codec.contact_coding import encode_with_contacts, streamed_contacts
from sidql.codec.encode import CHOICES, encode_files
from sidql.codec.plan import DEFAULT_MAX_GAP
from sidql.codec.windows import WINDOW_FRAMES
from sidql.commands.usage import add_trial, positive
from sim.jit import start_numba

DESCRIPTION = (
    "Chart the trial's 22 bones and root at --fps, choose keyframes by dynamic programming (max "
    "gap --max-gap, distortion + lambda x bytes, lambda by bisection) and write the .sidq "
    "container (format: docs/codec.md). The take is read and encoded --window frames at a time "
    "(bounded memory, any length): a longer take is written as a sequence of streams. --rate and --max-error (offline, linear "
    "or catmull_rom): keyframes and bits where they lower the mean joint position error most "
    "(each value's step by its effect on positions, predicted along the keyframes, range-coded). "
    "--max-q, hermite or --latency: the angle-error coding (offline: 9 to 16 bits per channel, "
    "LZMA-packed; with --latency: fixed 16-bit records a live sender emits one by one, decided "
    "with at most L frames of look-ahead, so a decoder outputs every frame within L frames)."
)


def register(p) -> None:
    add_trial(p)
    p.add_argument("--out", required=True, metavar="F.sidq", help="output stream")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument(
        "--rate",
        type=positive(float),
        metavar="B/S",
        help="byte budget [bytes per second], whole file",
    )
    target.add_argument(
        "--max-q",
        type=positive(float),
        metavar="Q",
        help="largest mean angle error Q (eq. 18) [rad]",
    )
    target.add_argument(
        "--max-error",
        type=positive(float),
        metavar="MM",
        help="largest mean joint position error [mm] (the smallest stream that meets it)",
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
        metavar="L",
        help="look-ahead in frames for live streaming (0: offline, the whole trial)",
    )
    p.add_argument(
        "--max-gap", type=int, default=DEFAULT_MAX_GAP, metavar="G", help="largest keyframe gap G"
    )
    p.add_argument("--fps", type=positive(float), default=30.0, help="stream rate (divides 120)")
    p.add_argument(
        "--window",
        type=int,
        default=WINDOW_FRAMES,
        metavar="FRAMES",
        help="frames encoded at a time (memory grows with it); a longer take is written as a "
        "sequence of streams",
    )
    p.add_argument(
        "--contacts",
        action="store_true",
        help="send the foot-contact bits and floor (offline): the decoder pins each foot in "
        "contact (docs/codec.md); the take is read twice (the floor and the bits first, on "
        "every frame), memory stays bounded",
    )
    p.add_argument(
        "--physics",
        action="store_true",
        help="also choose keyframes with the physical cost (implies --contacts; --rate or "
        "--max-error, linear or catmull_rom; the take is read and encoded whole)",
    )
    p.set_defaults(func=run, parser=p)


def run(args) -> int:
    if args.window < 2:
        args.parser.error("--window must be at least 2 frames")
    if not 0 <= args.latency <= 65535 or not 1 <= args.max_gap <= 255:
        args.parser.error("--latency must be in 0..65535 and --max-gap in 1..255")
    if args.max_error is not None and (args.latency or args.reconstruction == "hermite"):
        args.parser.error("--max-error needs an offline stream (--latency 0), not hermite")
    if (args.contacts or args.physics) and args.latency:
        args.parser.error("--contacts and --physics need an offline stream (--latency 0)")
    start_numba()
    enc = encode_files(
        args.asf,
        args.amc,
        args.out,
        fps=args.fps,
        rate=args.rate,
        max_q=args.max_q,
        max_error=args.max_error,
        reconstruction=args.reconstruction,
        latency=args.latency,
        max_gap=args.max_gap,
        window=args.window,
        encoder=partial(encode_with_contacts, physics=True) if args.physics else None,
        contacts=streamed_contacts if args.contacts and not args.physics else None,
    )
    print_summary(enc, args.physics)
    print(f"wrote {args.out}")
    return 0


def print_summary(enc, physics: bool = False) -> None:
    """The figures of a :class:`~sidql.codec.windows.TakeEncoding`, one per line."""
    s = enc.first.stream
    n = enc.n_frames
    recon = ", ".join(f"{r} x{k}" for r, k in enc.reconstructions.items())
    if enc.streams == 1:
        recon = s.reconstruction
    print(f"frames        {n} at {s.fps:g} fps ({n / s.fps:.2f} s)")
    print(f"keyframes     {enc.keyframes} ({recon}, latency {s.latency})")
    if s.contacts is not None:
        what = "physics-aware keyframes, " * physics + "feet pinned"
        first = "" if enc.streams == 1 else " in the first stream"
        print(f"foot contacts {s.contacts.n_bytes} bytes{first} ({what}; the figures below are "
              "after the pinning, a --max-error or --max-q target is met before it)")  # fmt: skip
    streams = "" if enc.streams == 1 else f", a sequence of {enc.streams} streams"
    print(f"size          {enc.n_bytes} bytes, {enc.bytes_per_second:.1f} B/s{streams}")
    print(f"Q             {enc.q:.5f} rad (decoded, quantisation included)")
    if s.coding == 2:
        p95 = "p95" if enc.streams == 1 else "p95 at most"
        print(
            f"position      mean error {enc.mean_error_mm:.2f} mm, {p95} {enc.p95_error_mm:.2f} mm"
        )
    if enc.streams == 1 and len(enc.first.candidates) > 1:
        what = "mean error [mm]" if s.coding == 2 else "Q"
        tried = ", ".join(f"{r} {e:.5f} / {b} B" for r, (e, b) in enc.first.candidates.items())
        print(f"tried ({what}) {tried}")
