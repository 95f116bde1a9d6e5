"""``sidql extract ASF AMC -W W ... --methods NAME ...``: keyframes of every 60-frame clip of one
trial."""

from __future__ import annotations

import json
from pathlib import Path

from sidql.commands.usage import (
    add_keyframes,
    add_methods,
    add_skeleton,
    add_trial,
    check_keyframes,
    cmu_rate,
    positive,
)
from sidql.evaluation.cases import clip_seed, make_case
from sidql.evaluation.scoring import score
from sidql.keyframes.methods import get, select
from sim.files import write_atomic
from sim.motion.ingest import load_clips

DESCRIPTION = (
    "Ingest one trial at --fps, cut it into clips of --length frames (30 fps, 60 frames by default) "
    "and choose W keyframes per clip (first and last frame included) with each method and each W; print them with the paper's Q (eq. 18) "
    "of the Hermite reconstruction, and optionally write JSON."
)


def register(p) -> None:
    add_trial(p)
    add_keyframes(p, "keyframes W per clip (several: each in turn)", many=True)
    add_methods(p, ["optimal"], old_option="--method")
    p.add_argument("--seed", type=int, default=0, help="seed of randomised methods")
    p.add_argument("--fps", type=cmu_rate, default=30.0, help="clip frame rate (divides 120)")
    p.add_argument("--length", type=positive(int), default=60, metavar="N", help="frames per clip")
    add_skeleton(p)
    p.add_argument("--out", default=None, metavar="F.json", help="write the keyframes here as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    for name in args.methods:  # an unknown name fails before the (slow) ingest
        get(name)
    counts = check_keyframes(args, args.length)
    clips = load_clips(args.asf, args.amc, fps=args.fps, length=args.length, skeleton=args.skeleton)
    rows = []
    for i, clip in enumerate(clips):
        case = make_case(clip, i)
        for method in args.methods:
            for W in counts:
                k = select(method, clip, W, seed=clip_seed(args.seed, i, W))
                s = score(case, k, method)
                rows.append(
                    {
                        "source": clip.source,
                        "start_frame": clip.start_frame,
                        "method": method,
                        "keyframes": W,
                        "indices": k.tolist(),
                        "q": s["q"],
                        "mpjpe_mm": s["mpjpe_mm"],
                    }
                )
                print(
                    f"frame {clip.start_frame:6d}  {method:>8s}  W {W:2d}  Q {s['q']:.4f}  "
                    f"keyframes {' '.join(map(str, k))}"
                )
    if not rows:
        print(f"no {args.length}-frame clips in {args.amc or args.asf}")
    if args.out:
        path = Path(args.out)
        write_atomic(path, lambda f: f.write(json.dumps({"clips": rows}, indent=1).encode()))
        print(f"wrote {path}")
    return 0
