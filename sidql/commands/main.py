"""The ``sidql`` command line: a thin layer over library functions.

Each subcommand lives in its own module under ``sidql.commands`` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a callable taking the parsed
arguments and returning an exit code. Adding a command = one module + one line below.
"""

from __future__ import annotations

import importlib
import os
import sys
import warnings

from sidql import __version__
from sidql.commands.usage import ArgumentParser, one_line_warning
from sim.errors import SidqlError

COMMAND_MODULES = (
    "sidql.commands.ingest",
    "sidql.commands.dataset",
    "sidql.commands.demo",
    "sidql.commands.report",
    "sidql.commands.eval",
    "sidql.commands.extract",
    "sidql.commands.train",
    "sidql.commands.encode",
    "sidql.commands.decode",
    "sidql.commands.synth",
)


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="sidql",
        description="MuJoCo testbed for motion-capture keyframe extraction and reconstruction.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; bad input exits 2 with one line (see :mod:`sidql.commands.usage`)."""
    # Offscreen rendering: EGL (Mesa's llvmpipe without a GPU) unless the user chose another
    # backend. Set here, before any command module imports MuJoCo; library users set it themselves.
    os.environ.setdefault("MUJOCO_GL", "egl")
    with warnings.catch_warnings():
        warnings.showwarning = one_line_warning
        args = build_parser().parse_args(argv)
        try:
            return int(args.func(args) or 0)
        except SidqlError as e:  # bad input, a bad file, an unmet target, an unknown name
            print(f"sidql {args.command}: error: {e}", file=sys.stderr)
            return 2
        except OSError as e:  # an output path that cannot be written (a folder, no permission)
            print(f"sidql {args.command}: error: {e}", file=sys.stderr)
            return 2


if __name__ == "__main__":
    sys.exit(main())
