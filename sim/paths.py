"""Where the project finds files it does not get from its caller: the files shipped inside the
packages (the shared humanoid, the canonical skeleton, the trained policy) and the folder of CMU
trials.

Shipped files are found through :mod:`importlib.resources`, so they are found the same way from a
checkout, an editable install and a wheel. The folder of CMU trials is one setting, read in this
order: a command's ``--data DIR``, the environment variable ``SIDQL_DATA``, and ``../shared/cmu``
beside a source checkout when it is there (the layout the tests and benchmarks use).

Pure standard library.
"""

from __future__ import annotations

import atexit
import contextlib
import os
from importlib.resources import as_file, files
from pathlib import Path

#: The environment variable naming the folder of CMU trials.
DATA_ENV = "SIDQL_DATA"

_extracted = contextlib.ExitStack()  # files extracted from a zipped install, removed at exit
atexit.register(_extracted.close)


def package_file(package: str, name: str) -> Path:
    """A file shipped inside ``package`` (e.g. ``package_file("sim", "data/canonical.asf")``) as a
    path on disk: the file itself for an ordinary install or a checkout; for a zipped install a
    temporary copy that lasts as long as the process."""
    ref = files(package).joinpath(*name.split("/"))
    return Path(_extracted.enter_context(as_file(ref)))


def checkout_root() -> Path | None:
    """The source checkout this package runs from (the folder holding ``pyproject.toml`` beside
    ``sim/``), or None for an installed package."""
    root = Path(__file__).resolve().parent.parent
    return root if (root / "pyproject.toml").is_file() and (root / "sim").is_dir() else None


def default_data_dir() -> Path | None:
    """The folder of CMU trials when a command is given none: ``$SIDQL_DATA`` if set (whether or
    not it exists: a typo should fail loudly, not fall back), else ``../shared/cmu`` beside a
    source checkout if that folder exists, else None."""
    named = os.environ.get(DATA_ENV)
    if named:
        return Path(named).expanduser()
    root = checkout_root()
    if root is not None and (root.parent / "shared" / "cmu").is_dir():
        return root.parent / "shared" / "cmu"
    return None


def data_dir(given: str | os.PathLike | None = None) -> Path | None:
    """``given`` (a command's ``--data``) if any, else :func:`default_data_dir`."""
    return Path(given).expanduser() if given else default_data_dir()
