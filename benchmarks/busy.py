"""Other work on the machine, started by a benchmark: ``with busy(2): ...`` runs two processes
that spin on a core each for the duration, so a figure "under load" is measured in the same run
as its quiet baseline (the ratio is what a benchmark reports)."""

from __future__ import annotations

import subprocess
import sys
import time
from contextlib import contextmanager


@contextmanager
def busy(n: int):
    """``n`` spinning Python processes for the duration of the block (ended by their ids)."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(max(n, 0))]
    try:
        time.sleep(0.3 if procs else 0.0)  # let them start spinning
        yield
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()
