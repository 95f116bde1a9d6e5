"""What every command shares: one vocabulary of options, one-line errors and warnings.

Options: every command declares the options it shares with others through the helpers below, so
one idea has one spelling (and one default) everywhere: ``--data DIR`` (the folder of CMU trials,
:func:`add_data`), ``-W/--keyframes`` (the keyframe count W, :func:`add_keyframes`, checked by
:func:`check_keyframes`), ``--methods`` (:func:`add_methods`), ``--test-subjects``
(:func:`add_test_subjects`), ``--samples`` (the sampling tracker, :func:`add_samples`),
``--workers`` (:func:`add_workers`), ``--ray`` (:func:`add_ray`), ``--quiet`` (:func:`add_quiet`).
Old spellings (``dataset DIR``, ``synth --from``, ``extract --method``, ``eval --subjects``,
``eval --simulate-samples``, method ``xyz``) still work and warn (:class:`OldSpelling`,
:func:`method_name`). ``--help`` shows a default only where there is one (:class:`HelpFormatter`).

Every bad input exits 2 with one line on stderr: ``sidql COMMAND: error: PROBLEM``, for any
:class:`sim.errors.SidqlError` (PROBLEM names the file and line when there is one). Warnings print as
one line ``warning: FILE:LINE: MESSAGE`` (no Python source line).
"""

from __future__ import annotations

import argparse
import re
import socket
import sys
import warnings
from pathlib import Path

from sidql.keyframes.counts import LEAST_W, check_counts
from sidql.keyframes.old_names import RENAMED
from sim.errors import MotionDataWarning, UsageError
from sim.files import excerpt
from sim.paths import DATA_ENV, data_dir

# UsageError lives in sim.errors (the one hierarchy); commands import it from here too.


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a parse error is one line ``PROG: error: MESSAGE`` (exit 2), no usage dump."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


class UsageWarning(UserWarning):
    """A command line that works but should be spelled otherwise (an old option name)."""


def one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` replacement: ``warning: FILE:LINE: MESSAGE`` on one line.

    A :class:`~sim.errors.MotionDataWarning` already starts with the data file and line it is
    about, and a :class:`UsageWarning` is about the command line; any other warning gets the
    Python file and line that raised it.
    """
    text = str(message).replace("\n", " ")
    if not issubclass(category, (MotionDataWarning, UsageWarning)):
        text = f"{filename}:{lineno}: {text}"
    print(f"warning: {text}", file=sys.stderr if file is None else file)


def positive(kind):
    """An argparse ``type``: ``kind(text)`` that must be > 0 (else a one-line usage error)."""

    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"must be positive: {text!r}")
        return v

    return parse


def cmu_rate(text):
    """An argparse ``type``: an output frame rate that divides CMU's 120 fps (30 takes every 4th
    frame)."""
    v = positive(float)(text)
    if abs(120.0 / v - round(120.0 / v)) > 1e-9:
        raise argparse.ArgumentTypeError(f"must divide 120 (CMU's rate): {text!r}")
    return v


class HelpFormatter(argparse.HelpFormatter):
    """``--help`` with ``(default: X)`` where there is a default to show (a list as ``a b c``, as
    it is typed), and not on required options, not ``None`` (the help says what happens then),
    not a flag's ``False``."""

    def _get_help_string(self, action):
        help, d = action.help or "", action.default
        if (
            action.required
            or d is None
            or d is False
            or d is argparse.SUPPRESS
            or "%(default)" in help
            or not action.option_strings
        ):
            return help
        shown = " ".join(map(str, d)) if isinstance(d, list | tuple) else str(d)
        return f"{help} (default: {shown.replace('%', '%%')})".lstrip()


class OldSpelling(argparse.Action):
    """An old spelling of an option, still accepted: it warns (one line naming the new spelling)
    and stores its value where the new option does. Hidden from ``--help``.

    ``new``: the new spelling, e.g. ``"--data DIR"``; ``as_list``: store ``[value]`` (a single
    ``--method X`` for ``--methods X ...``).
    """

    def __init__(self, option_strings, dest, *, new: str, as_list: bool = False, **kwargs):
        kwargs["help"] = argparse.SUPPRESS
        super().__init__(option_strings, dest, **kwargs)
        self.new, self.as_list = new, as_list

    def __call__(self, parser, namespace, values, option_string=None):
        if values is None:  # an optional positional that was not given
            return
        old = option_string or (self.metavar or self.dest.upper())
        warnings.warn(
            UsageWarning(f"{parser.prog} {old}: an old spelling, use {self.new}"), stacklevel=2
        )
        setattr(namespace, self.dest, [values] if self.as_list else values)


def add_data(
    parser: argparse.ArgumentParser,
    help: str = "folder of CMU trials (SS/SS.asf, SS/SS_TT.amc) and/or .bvh files",
    *,
    old_option: str | None = None,
    old_positional: bool = False,
) -> None:
    """``--data DIR``, the folder of CMU trials (read it with :func:`data_folder`); optionally the
    old spellings ``--from DIR`` (``old_option="--from"``) or a positional ``DIR``."""
    parser.add_argument(
        "--data",
        metavar="DIR",
        default=None,
        help=f"{help}; default: ${DATA_ENV}, else ../shared/cmu beside the checkout if present",
    )
    if old_option:
        parser.add_argument(old_option, dest="data", metavar="DIR", action=OldSpelling,
                            new="--data DIR")  # fmt: skip
    if old_positional:
        parser.add_argument("data", nargs="?", metavar="DIR", action=OldSpelling, new="--data DIR")


def data_folder(args: argparse.Namespace, *, required: bool = True) -> Path | None:
    """The folder of CMU trials of a command: ``--data``, else :func:`sim.paths.default_data_dir`.

    Raises:
        UsageError: none is given nor found and ``required``.
    """
    folder = data_dir(args.data)
    if folder is None and required:
        raise UsageError(
            f"no folder of CMU trials: pass --data DIR or set {DATA_ENV} (../shared/cmu beside "
            "the checkout is used when present)"
        )
    return folder


def add_keyframes(
    parser: argparse.ArgumentParser,
    help: str = "keyframes W per clip (both end frames included)",
    *,
    default=None,
    many: bool = False,
) -> None:
    """``-W/--keyframes W``, the keyframe count, stored as ``args.W`` (check it with
    :func:`check_keyframes`); several values (``many``) where a command sweeps W. Required when
    there is no ``default``."""
    parser.add_argument(
        "-W",
        "--keyframes",
        dest="W",
        type=int,
        nargs="+" if many else None,
        default=default,
        required=default is None,
        metavar="W",
        help=help,
    )


def check_keyframes(args: argparse.Namespace, n_frames: int, *, least: int = LEAST_W) -> list[int]:
    """``args.W`` as a list, each checked against the one rule (:mod:`sidql.keyframes.counts`):
    ``least <= W <= n_frames``.

    Raises:
        UsageError: a value out of range (the message names ``--keyframes``).
    """
    counts = list(args.W) if isinstance(args.W, list | tuple) else [args.W]
    check_counts(counts, n_frames, least=least, name="--keyframes")
    return counts


def add_methods(
    parser: argparse.ArgumentParser,
    default,
    help: str = "keyframe methods (registered in sidql.keyframes.methods)",
    *,
    old_option: str | None = None,
) -> None:
    """``--methods NAME [NAME ...]`` (an old method name is taken and warns:
    :func:`method_name`); optionally an old single-valued spelling (``--method``)."""
    parser.add_argument(
        "--methods", nargs="+", type=method_name, default=default, metavar="NAME", help=help
    )
    if old_option:
        parser.add_argument(old_option, dest="methods", metavar="NAME", action=OldSpelling,
                            type=method_name, new="--methods NAME [NAME ...]", as_list=True)  # fmt: skip


def method_name(text: str) -> str:
    """An argparse ``type`` for a method: its name now, with a one-line warning for an old one
    (:data:`sidql.keyframes.old_names.RENAMED`; unknown names pass through: the command lists the
    known ones before any work starts)."""
    if text in RENAMED:
        warnings.warn(
            UsageWarning(f"method {text}: an old name, use {RENAMED[text]}"), stacklevel=2
        )
        return RENAMED[text]
    return text


def add_test_subjects(
    parser: argparse.ArgumentParser, help: str, *, old_option: str | None = None
) -> None:
    """``--test-subjects SS [SS ...]``: the subjects a command evaluates on (``eval``: only these;
    ``train``: held out from training); optionally an old spelling (``--subjects``)."""
    parser.add_argument("--test-subjects", nargs="+", default=None, metavar="SS", help=help)
    if old_option:
        parser.add_argument(old_option, dest="test_subjects", nargs="+", metavar="SS",
                            action=OldSpelling, new="--test-subjects SS [SS ...]")  # fmt: skip


def add_samples(
    parser: argparse.ArgumentParser, lead: str, *, old_option: str | None = None
) -> None:
    """``--samples N``: track with the sampling tracker (``sim.simulate.sampling``), N rollouts per
    window; without it the command's default controller. ``lead`` begins the help (what is tracked, and when);
    optionally an old spelling (``eval --simulate-samples``)."""
    parser.add_argument(
        "--samples", type=positive(int), default=None, metavar="N",
        help=f"{lead} with the sampling tracker (sim/simulate/sampling.py): N rollouts per 0.1 s "
        "window, each judged 0.3 s on, and no assistance at all; without it the default "
        "controller (the sampler at its default count). Its cost per simulated second: "
        "docs/results/synth.md",
    )  # fmt: skip
    if old_option:
        parser.add_argument(old_option, dest="samples", type=positive(int), metavar="N",
                            action=OldSpelling, new="--samples N")  # fmt: skip


def add_flat_floor(
    parser: argparse.ArgumentParser, lead: str = "with --simulate: track", what: str = "clip"
) -> None:
    """``--flat-floor``: the body on the empty floor instead of the scene inferred from each
    ``what``'s original motion (``sim.simulate.terrain``; the default); ``lead`` begins the
    help (when, and what is tracked)."""
    parser.add_argument(
        "--flat-floor", action="store_true",
        help=f"{lead} on the empty floor, without the scene inferred from each {what}'s "
        "original motion (static steps under feet that stand on something, the default: "
        "docs/synthetic.md)",
    )  # fmt: skip


def add_workers(parser: argparse.ArgumentParser, what: str) -> None:
    """``--workers N``: ``what`` in N worker processes; 1, the default everywhere, runs them in
    this process (no pool: predictable memory and undisturbed timings)."""
    parser.add_argument(
        "--workers", type=positive(int), default=1, metavar="N",
        help=f"worker processes for {what}; 1 runs them in this process",
    )  # fmt: skip


def add_trial(parser: argparse.ArgumentParser) -> None:
    """``ASF AMC`` or ``F.bvh``: one trial's files (a BVH holds its skeleton and its motion)."""
    parser.add_argument(
        "asf", metavar="ASF|BVH",
        help="subject skeleton, e.g. ../shared/cmu/02/02.asf; or a .bvh file (skeleton and motion)",
    )  # fmt: skip
    parser.add_argument(
        "amc", metavar="AMC", nargs="?", default=None,
        help="motion, e.g. ../shared/cmu/02/02_01.amc (none after a .bvh)",
    )  # fmt: skip


def add_bvh_axes(parser: argparse.ArgumentParser) -> None:
    """``--unit`` and ``--up``: a BVH file's length unit and up axis (``sim.bvh.convert``)."""
    parser.add_argument(
        "--unit", choices=("m", "cm", "mm", "in"), default=None,
        help="a BVH's length unit (default: read from its skeleton's size; written BVH: cm)",
    )  # fmt: skip
    parser.add_argument("--up", choices=("y", "z"), default="y", help="a BVH's up axis")


def add_skeleton(parser: argparse.ArgumentParser) -> None:
    """``--skeleton subject|humanoid``: the model a trial is retargeted onto."""
    parser.add_argument(
        "--skeleton",
        choices=("subject", "humanoid"),
        default="subject",
        help="the subject's own humanoid generated from its ASF, or the shared one "
        "(sim/data/cmu_humanoid.xml)",
    )


def add_ray(parser: argparse.ArgumentParser, what: str = "the tasks") -> None:
    """``--ray [ADDRESS]``: ``what`` as Ray tasks, in a local runtime or on the cluster at
    ADDRESS (checked by :func:`ray_address` before any work starts)."""
    parser.add_argument(
        "--ray", nargs="?", const="local", default=None, metavar="ADDRESS", type=ray_address,
        help=f"run {what} as Ray tasks: a local runtime, or the cluster at ADDRESS",
    )  # fmt: skip


def add_reconstruction(parser: argparse.ArgumentParser) -> None:
    """``--reconstruction NAME``: rebuild every method's keyframes with this registered
    reconstruction (:mod:`sidql.keyframes.reconstructions`) instead of the method's own (an
    unknown name is refused, listing the known ones, before any work starts)."""
    parser.add_argument(
        "--reconstruction", default=None, metavar="NAME",
        help="rebuild every method's keyframes with this reconstruction instead of its own "
        "(selection and reconstruction measured apart), e.g. hermite, linear, slerp, contacts",
    )  # fmt: skip


def add_quiet(parser: argparse.ArgumentParser) -> None:
    """``-q/--quiet``: no progress bars."""
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")


#: Seconds ``--ray HOST:PORT`` waits for the cluster to answer before it is refused.
RAY_CONNECT_TIMEOUT_S = 3.0
_HOST = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252})|\[[0-9A-Fa-f:.]{2,45}\]")


def ray_address(text):
    """An argparse ``type`` for ``--ray ADDRESS``: ``local``, ``auto`` (Ray finds the cluster), or
    ``[ray://]HOST:PORT`` that answers on that port within :data:`RAY_CONNECT_TIMEOUT_S` seconds;
    anything else is a one-line usage error before any work starts (instead of Ray's traceback,
    or its 20 s of retries for an address nobody answers on)."""
    if text in ("local", "auto"):
        return text
    bare = text.removeprefix("ray://")
    host, sep, port = bare.rpartition(":")
    if not (sep and _HOST.fullmatch(host) and port.isascii() and port.isdigit()
            and 1 <= int(port) <= 65535):  # fmt: skip
        raise argparse.ArgumentTypeError(
            f"not a Ray address: {excerpt(text)} (expected local, auto, HOST:PORT or "
            "ray://HOST:PORT)"
        )
    try:
        _answers_grpc(host.strip("[]"), int(port))
    except OSError as e:
        why = e.strerror or str(e) or type(e).__name__
        raise argparse.ArgumentTypeError(
            f"no Ray cluster answers at {excerpt(text)} ({why})"
        ) from None
    return text


def _answers_grpc(host: str, port: int) -> None:
    """Raise OSError unless ``host:port`` answers the HTTP/2 preface with a SETTINGS frame, as
    Ray's gRPC servers (the GCS, the client server) do: an open port alone is not enough (a
    proxy or firewall may accept any connection)."""
    with socket.create_connection((host, port), RAY_CONNECT_TIMEOUT_S) as s:
        s.settimeout(RAY_CONNECT_TIMEOUT_S)
        s.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))
        head = b""
        while len(head) < 9:
            part = s.recv(9 - len(head))
            if not part:
                break
            head += part
    if len(head) < 9 or head[3] != 4:
        raise OSError("it does not speak gRPC")
