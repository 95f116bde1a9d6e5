"""MuJoCo's warnings on standard error, never in a file.

Left alone, MuJoCo's ``mju_warning`` appends every warning to ``MUJOCO_LOG.TXT`` in the working
folder (a file written outside the folder the user named) and prints it with a blank line after
it. :func:`route_warnings` installs a handler that writes one line,
``MuJoCo warning: <text>``, on standard error instead, unless a handler is
installed already (a library user's own). MuJoCo's per-``MjData`` warning counts
(``data.warning``), which the simulation reads to find a diverging rollout, are kept either way.
The modules that step, invert or fit MuJoCo models import this one, which routes on import.
"""

from __future__ import annotations

import sys

import mujoco

#: what each routed warning's line begins with
PREFIX = "MuJoCo warning: "


def _to_stderr(message: str) -> None:
    try:
        sys.stderr.write(f"{PREFIX}{' '.join(message.split())}\n")
    except (OSError, ValueError):  # a closed standard error: the warning is dropped, not raised
        pass


def route_warnings() -> None:
    """MuJoCo's warnings from now on to standard error, one line each (module docstring); a
    handler already installed stays."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_to_stderr)


route_warnings()
