"""The command line run as a user runs it (a fresh process), and the bad-input contract its
answers must keep: exit status 2 and one line on stderr."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def cli(*argv, timeout=120):
    """``sidql ARGV...`` in a fresh interpreter on this checkout; the completed process."""
    return subprocess.run(
        [sys.executable, "-m", "sidql.commands.main", *argv], capture_output=True, text=True,
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=timeout,
    )  # fmt: skip


def one_line_exit_2(res, *needles):
    """``res`` failed as bad input should: exit 2, one line on stderr holding every needle."""
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1, res.stderr
    for n in needles:
        assert n in res.stderr, res.stderr
