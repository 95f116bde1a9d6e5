"""``sidql train``: train the SIDQL keyframe policy (a DQN) on a folder of CMU trials."""

from __future__ import annotations

import argparse
import dataclasses

from sidql.commands.usage import UsageError
from sidql.learning.settings import Args, settings_problems


def register(sub) -> None:
    d = Args()
    p = sub.add_parser(
        "train",
        help="train the DQN keyframe policy (held-out subjects, CSV log, learning curve)",
        description="Train the SIDQL Deep Q-Network through the sidql/Keyframe-v0 environment on "
        "60-frame clips of the training subjects, evaluating every --eval-every steps on the "
        "held-out subjects' clips against greedy and the exact optimum. Writes OUT (the policy), "
        "OUT.ckpt (resumable state, atomically at every evaluation), OUT with .csv (log) and "
        ".png (learning curve). A killed run continues from its last checkpoint with --resume, "
        "which refuses a checkpoint written with other settings (only --steps, --out, "
        "--cache-dir, --eval-every, --threads, --data and --quiet may change). Policy and "
        "checkpoint files are read as tensors and plain values only (torch weights_only=True); "
        "anything else is refused with exit status 2.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--data", required=True, help="folder of CMU trials, e.g. ../shared/cmu")
    p.add_argument("--keyframes", type=int, nargs="+", default=list(d.keyframes), help="W values")
    p.add_argument("--steps", type=int, default=d.steps, help="environment steps in total")
    p.add_argument("--out", default=d.out, help="policy file to write")
    p.add_argument("--resume", action="store_true", help="continue from OUT.ckpt if present")
    p.add_argument("--seed", type=int, default=d.seed, help="seed (also picks the held-out split)")
    p.add_argument(
        "--test-subjects", nargs="+", default=None, help="held-out subject ids (default: by seed)"
    )
    p.add_argument("--cache-dir", default=None, help="cache of per-trial features and costs")
    p.add_argument(
        "--train-also", default=None, metavar="DIR",
        help="a `sidql synth`/`sidql dataset` folder whose clips join the training set only",
    )  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    tuned = p.add_argument_group("DQN hyper-parameters (see sidql.learning.settings.Args)")
    for f in dataclasses.fields(Args):
        if f.name in {"data", "keyframes", "steps", "out", "resume", "seed", "test_subjects",
                      "cache_dir", "progress", "extra", "synthetic_tasks", "train_also"}:  # fmt: skip
            continue
        flag = "--" + f.name.replace("_", "-")
        default = getattr(d, f.name)
        if isinstance(default, bool):
            tuned.add_argument(flag, type=_bool, default=default, metavar="BOOL")
        else:
            tuned.add_argument(flag, type=type(default), default=default)
    p.set_defaults(func=run)


def _bool(text: str) -> bool:
    if text.lower() in {"1", "true", "yes", "on"}:
        return True
    if text.lower() in {"0", "false", "no", "off"}:
        return False
    raise argparse.ArgumentTypeError(f"expected true/false; got {text!r}")


def run(args) -> int:
    bad = [w for w in args.keyframes if not 3 <= w <= 60]
    if bad:
        raise UsageError(f"--keyframes values must be in [3, 60]; got {bad}")
    values = {
        f.name: getattr(args, f.name) for f in dataclasses.fields(Args) if hasattr(args, f.name)
    }
    values["keyframes"] = tuple(args.keyframes)
    values["test_subjects"] = tuple(args.test_subjects) if args.test_subjects else None
    values["progress"] = not args.quiet
    problems = settings_problems(Args(**values))
    if problems:
        raise UsageError(problems[0])
    from sidql.learning.dqn import train  # lazy: imports torch, needed only when training starts

    result = train(Args(**values))
    print(f"held-out subjects: {', '.join(result['split']['test'])}")
    print("| W | dqn | greedy | optimal | dqn / optimal |")
    print("|---|---|---|---|---|")
    for w in args.keyframes:
        q, g, o = result["dqn"][w], result["greedy"][w], result["optimal"][w]
        print(f"| {w} | {q:.4f} | {g:.4f} | {o:.4f} | {q / o:.3f} |")
    return 0
