"""``sidql train``: train the SIDQL keyframe policy (a DQN) on a folder of CMU trials."""

from __future__ import annotations

import argparse
import dataclasses

from sidql.commands.usage import (
    UsageError,
    add_data,
    add_keyframes,
    add_quiet,
    add_test_subjects,
    data_folder,
)
from sidql.learning.settings import Args, field_docs, settings_problems

DESCRIPTION = (
    "Train the SIDQL Deep Q-Network through the sidql/Keyframe-v0 environment on 60-frame clips "
    "of the training subjects, evaluating every --eval-every steps on the held-out subjects' clips "
    "against greedy and the exact optimum. Writes OUT (the policy), OUT.ckpt (resumable state, "
    "atomically at every evaluation), OUT with .csv (log) and .png (learning curve). A killed run "
    "continues from its last checkpoint with --resume, which refuses a checkpoint written with "
    "other settings (only --steps, --out, --cache-dir, --eval-every, --threads, --data and --quiet "
    "may change). Policy and checkpoint files are read as tensors and plain values only (torch "
    "weights_only=True); anything else is refused with exit status 2."
)


def register(p) -> None:
    d = Args()
    docs = {k: v.replace("%", "%%") for k, v in field_docs().items()}  # help is %-formatted
    add_data(p)
    add_keyframes(p, docs["keyframe_counts"], default=list(d.keyframe_counts), many=True)
    p.add_argument("--steps", type=int, default=d.steps, metavar="N", help=docs["steps"])
    p.add_argument("--out", default=d.out, metavar="F.pt", help=docs["out"])
    p.add_argument("--resume", action="store_true", help=docs["resume"])
    p.add_argument("--seed", type=int, default=d.seed, help=docs["seed"])
    add_test_subjects(p, docs["test_subjects"])
    p.add_argument("--cache-dir", default=None, metavar="DIR", help=docs["cache_dir"])
    p.add_argument("--train-also", default=None, metavar="DIR", help=docs["train_also"])
    add_quiet(p)
    tuned = p.add_argument_group("DQN hyper-parameters (sidql.learning.settings.Args)")
    for f in dataclasses.fields(Args):
        if f.name in {"data", "keyframe_counts", "steps", "out", "resume", "seed", "test_subjects",
                      "cache_dir", "progress", "extra", "synthetic_tasks", "train_also"}:  # fmt: skip
            continue
        flag = "--" + f.name.replace("_", "-")
        default = getattr(d, f.name)
        if isinstance(default, bool):
            tuned.add_argument(flag, type=_bool, default=default, metavar="BOOL", help=docs[f.name])
        else:
            tuned.add_argument(flag, type=type(default), default=default, help=docs[f.name])
    p.set_defaults(func=run)


def _bool(text: str) -> bool:
    if text.lower() in {"1", "true", "yes", "on"}:
        return True
    if text.lower() in {"0", "false", "no", "off"}:
        return False
    raise argparse.ArgumentTypeError(f"expected true/false; got {text!r}")


def run(args) -> int:
    values = {
        f.name: getattr(args, f.name) for f in dataclasses.fields(Args) if hasattr(args, f.name)
    }
    values["data"] = str(data_folder(args))
    values["keyframe_counts"] = tuple(args.W)  # checked with the rest (settings_problems)
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
    for w in args.W:
        q, g, o = result["dqn"][w], result["greedy"][w], result["optimal"][w]
        print(f"| {w} | {q:.4f} | {g:.4f} | {o:.4f} | {q / o:.3f} |")
    return 0
