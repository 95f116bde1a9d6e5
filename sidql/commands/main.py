"""The ``sidql`` command line: a thin layer over library functions.

Each command lives in its own module ``sidql.commands.<name>``, which holds its
``DESCRIPTION`` (the paragraph of ``sidql <name> --help``) and ``register(parser)``: it adds the
command's options and sets ``func`` to a callable taking the parsed arguments and returning an
exit code. The one-line summary of each command is kept once, in :data:`COMMANDS` (``sidql
--help`` and the README's table read it). Adding a command = one module + one line in
:data:`COMMANDS`.

Start-up stays short: only the module of the command being run is imported (its libraries, e.g.
MuJoCo, torch or numba, load with it); ``sidql --help`` and an unknown command import none. Run as
a program (:func:`program`), the codec's commands (:data:`LEAN`) also skip what a process that
ends when they return does not need (see :func:`program`).
"""

from __future__ import annotations

import atexit
import gc
import importlib
import os
import sys
import threading
import warnings
from typing import NoReturn

from sidql import __version__
from sidql.commands.usage import ArgumentParser, HelpFormatter, one_line_warning
from sim.errors import SidqlError
from sim.jit import import_numba

#: Every command, in the order ``sidql --help`` lists them, with its one-line summary.
COMMANDS = {
    "ingest": "read one trial (ASF + AMC, or BVH) into a clip file (.npz): positions, true "
    "velocities, qpos, qvel",
    "dataset": "ingest every trial under a folder in parallel, with an index; bad files skipped "
    "and listed",
    "demo": "ingest CMU trial 02_01 (without data: motion generated on the humanoid) and report "
    "its first clip: every method, replayed, checked and rendered (what ./run.sh demo runs)",
    "report": "replay, check (IK, contacts, dynamics; --simulate: forward simulation) and render "
    "reconstructions of one trial into one HTML page; .sidq streams are reported like methods",
    "eval": "the paper's Table 3: every method on every 60-frame clip of a folder of trials; "
    "--physics adds contacts and dynamics with noise floors and paired comparisons, --simulate "
    "forward simulation without assistance",
    "extract": "choose the keyframes of every 60-frame clip of one trial, per method and W, with "
    "their Q",
    "train": "train the DQN keyframe policy, split by subject: held-out evaluation, CSV log, "
    "learning curve, checkpoints",
    "encode": "encode a whole trial into a .sidq keyframe stream at a byte budget, a joint "
    "position error or an angle error",
    "decode": "decode a .sidq stream to points (.npz) or the source skeleton's angles (.amc, .bvh)",
    "convert": "write a trial in the other format (ASF + AMC -> BVH, BVH -> ASF + AMC) or a clip "
    "(.npz) as BVH",
    "synth": "simulate clips (tracking with perturbations, falls, procedural) in the dataset "
    "format with learning labels; stored as they arrive, resumable",
}

#: Commands that never render and leave no thread behind once they return (their files written and
#: closed): run as a program they import MuJoCo without its GL context and end the process
#: without the interpreter's teardown (:func:`program`).
LEAN = frozenset({"encode", "decode"})
#: The cyclic garbage collector's first threshold in a :data:`LEAN` command's process (Python's
#: default: 700 allocations): start-up makes hundreds of thousands of long-lived objects (numba's
#: and LLVM's), which collections walk again and again (measured on a 5-minute take: 0.07 s of
#: CPU in collections at 10,000, 0.002 s at 200,000, the same peak memory).
LEAN_GC_THRESHOLD = 200_000

#: The module of each command (kept for callers that list them).
COMMAND_MODULES = tuple(f"sidql.commands.{name}" for name in COMMANDS)


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
    for name, summary in COMMANDS.items():
        if only is None or only == name:
            module = importlib.import_module(f"sidql.commands.{name}")
            p = sub.add_parser(
                name, help=summary, description=module.DESCRIPTION, formatter_class=HelpFormatter
            )
            module.register(p)
        else:
            sub.add_parser(name, help=summary)
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
        args = build_parser(only=name if name in COMMANDS else "").parse_args(argv)
        try:
            return int(args.func(args) or 0)
        except SidqlError as e:  # bad input, a bad file, an unmet target, an unknown name
            print(f"sidql {args.command}: error: {e}", file=sys.stderr)
            return 2
        except OSError as e:  # an output path that cannot be written (a folder, no permission)
            print(f"sidql {args.command}: error: {e}", file=sys.stderr)
            return 2


def program() -> NoReturn:
    """``sidql`` as a program (the installed command, ``python -m sidql.commands.main``):
    :func:`main` on ``sys.argv``, then exit with its code.

    A :data:`LEAN` command's process is its own: MuJoCo is imported without its GL context
    (``MUJOCO_GL=disable``: about 0.03 s of CPU), numba without the packages its import only
    checks for (:func:`sim.jit.import_numba`: about 0.03 s), the cyclic collector runs less often
    (:data:`LEAN_GC_THRESHOLD`: about 0.1 s), and once the command has returned with no other
    thread alive, the process flushes its standard streams, runs its exit handlers and ends
    (``os._exit``) without the interpreter's teardown, which frees numba's and LLVM's objects one
    by one (0.25 s of CPU measured, a quarter of ``sidql encode``'s start-up). Any other command,
    or a flush that fails, ends the ordinary way (``sys.exit``)."""
    lean = _command_in(sys.argv[1:]) in LEAN
    if lean and "mujoco" not in sys.modules:
        os.environ["MUJOCO_GL"] = "disable"
    if lean:
        gc.set_threshold(LEAN_GC_THRESHOLD, *gc.get_threshold()[1:])
        import_numba()
    code = main()
    if lean and threading.active_count() == 1:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except (OSError, ValueError):  # e.g. a closed pipe: reported as Python reports it
            sys.exit(code)
        atexit._run_exitfuncs()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    program()
