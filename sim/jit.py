"""Numba's start, made cheaper: its implementations loaded without importing ``scipy.linalg``, and
its parallel kernels' idle threads asleep instead of spinning.

The first compile or cache load of a numba kernel in a process loads every implementation numba
has (``BaseContext.refresh``); one of them, ``numba.np.arraymath``, imports ``scipy.linalg``
(about 0.15 s of CPU, a third of that start) only to learn whether its ``np.convolve`` and
``np.correlate`` may call BLAS. :func:`start_numba` does that first load while
``scipy.linalg.cython_blas`` reads as absent, then forgets the absence: those two then use numba's
own loop in kernels compiled later in the process (the project's kernels use neither), and
every other use of BLAS or LAPACK in a kernel (``np.dot``, ``np.linalg``) imports SciPy when it
is compiled, as before. Nothing changes in a process that has imported ``scipy.linalg`` or
loaded numba's implementations already.

A parallel kernel (``parallel=True``) runs on numba's OpenMP threads, which by default spin for a
while after each kernel waiting for the next: CPU time taken from every other process of a
shared machine (measured 0.3-0.4 s of a 5-minute take's 5 s of encoding). :func:`start_numba`
sets ``OMP_WAIT_POLICY=PASSIVE`` (they sleep at once) unless the environment says otherwise; it
is read when the threads first start, so it acts only before the first parallel kernel runs.

The commands that run kernels call it first (``sidql encode``, ``sidql decode``); a library user
may too.
"""

from __future__ import annotations

import os
import sys
import threading

from numba.core.registry import cpu_target

_BLAS = "scipy.linalg.cython_blas"
_lock = threading.Lock()


def start_numba() -> None:
    """Load numba's implementations now, without ``scipy.linalg``; idle OpenMP threads sleep
    (see the module docstring)."""
    with _lock:
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        if "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
            return
        sys.modules[_BLAS] = None  # an import of it raises ImportError: no BLAS for convolve
        try:
            cpu_target.target_context.refresh()
        finally:
            if sys.modules.get(_BLAS, 0) is None:
                del sys.modules[_BLAS]
