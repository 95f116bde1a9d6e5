"""The ``sidql`` command line: a thin layer over library functions.

Each subcommand lives in its own module under ``sidql.commands`` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a callable taking the parsed
arguments and returning an exit code. Adding a command = one module + one line in
:data:`COMMAND_MODULES` + its one-line summary in :data:`SUMMARIES`.

Start-up stays short: only the module of the command being run is imported (its libraries, e.g.
MuJoCo, torch or numba, load with it); ``sidql --help`` and an unknown command import none.
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


#: each command's line in ``sidql --help`` (the command module's own parser has the details).
SUMMARIES = {
    "ingest": "read one CMU trial (ASF + AMC) into a clip file (.npz)",
    "dataset": "ingest a folder of CMU trials into clip files with an index",
    "demo": "run the main job on the embedded default motion",
    "report": "replay, check and render reconstructions of one trial as a report",
    "eval": "evaluate keyframe methods on a folder of trials",
    "extract": "choose keyframes of one trial with one method",
    "train": "train the DQN keyframe policy",
    "encode": "encode one CMU trial (ASF + AMC) into a .sidq keyframe stream",
    "decode": "decode a .sidq stream to points (.npz) or the source skeleton's angles (.amc)",
    "synth": "generate simulated, velocity-rich motion clips",
}


def _command_in(argv: list[str]) -> str | None:
    """The command named on the command line (the first argument that is not an option)."""
    for a in argv:
        if not a.startswith("-"):
            return a
    return None


def build_parser(only: str | None = None) -> ArgumentParser:
    """The whole parser; with ``only``, just that command's module is imported and registered
    (the others are listed by their summaries), which keeps start-up short."""
    parser = ArgumentParser(
        prog="sidql",
        description="MuJoCo testbed for motion-capture keyframe extraction and reconstruction.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMAND_MODULES:
        name = module.rsplit(".", 1)[1]
        if only is None or only == name:
            importlib.import_module(module).register(sub)
        else:
            sub.add_parser(name, help=SUMMARIES.get(name, ""))
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; bad input exits 2 with one line (see :mod:`sidql.commands.usage`)."""
    # Offscreen rendering: EGL (Mesa's llvmpipe without a GPU) unless the user chose another
    # backend. Set here, before any command module imports MuJoCo; library users set it themselves.
    os.environ.setdefault("MUJOCO_GL", "egl")
    with warnings.catch_warnings():
        warnings.showwarning = one_line_warning
        argv = sys.argv[1:] if argv is None else list(argv)
        name = _command_in(argv)
        known = {m.rsplit(".", 1)[1] for m in COMMAND_MODULES}
        args = build_parser(only=name if name in known else "").parse_args(argv)
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
