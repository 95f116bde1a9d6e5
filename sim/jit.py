"""Numba's start, made cheaper: cached kernels loaded without numba's implementations, numba
imported without the packages it only checks for, and idle parallel threads asleep.

Loading a kernel from numba's cache (``FunctionCache.load_overload``) first loads every
implementation numba has (``BaseContext.refresh``: about 0.18 s of CPU, a fifth of
``sidql encode``'s start-up), which only compiling uses: a cached kernel is machine code, linked
against numba's runtime alone. After :func:`start_numba`, loading a kernel starts that runtime
only (``rtsys.initialize``, what ``refresh`` does first); the first compilation in the process
(a kernel not in the cache) still loads every implementation, as numba always does. The
kernels, their machine code and their results are the same.

A cached kernel also names the environments of the numba functions compiled into it (array
allocation, sorting, ...: numba's own implementations, always compiled without Python objects),
and numba rebuilds each from its module's globals, importing that module (``numba.np.arrayobj``
and the like: about 0.06 s of CPU). Code compiled without Python objects never reads those
globals: after :func:`start_numba`, the environment of a numba module not yet imported is
rebuilt from its name alone (:func:`_rebuild_env`; the project's own modules as before). Its
constants, which such code does read, are restored as before, and a cache written afterwards
names numba's own rebuilder, as any other does.

That load imports ``scipy.linalg`` (about 0.15 s of CPU) from ``numba.np.arraymath`` only to
learn whether its ``np.convolve`` and ``np.correlate`` may call BLAS: after :func:`start_numba`
it runs while ``scipy.linalg.cython_blas`` reads as absent, then forgets the absence. Those two
then use numba's own loop in kernels compiled later in the process (the project's kernels use
neither), and every other use of BLAS or LAPACK in a kernel (``np.dot``, ``np.linalg``) imports
SciPy when it is compiled, as before. Nothing changes in a process that has imported
``scipy.linalg`` or loaded numba's implementations already.

A parallel kernel (``parallel=True``) runs on numba's OpenMP threads, which by default spin for a
while after each kernel waiting for the next: CPU time taken from every other process of a
shared machine (measured 0.3-0.4 s of a 5-minute take's 5 s of encoding). :func:`start_numba`
sets ``OMP_WAIT_POLICY=PASSIVE`` (they sleep at once) unless the environment says otherwise; it
is read when the threads first start, so it acts only before the first parallel kernel runs.

:func:`import_numba` imports numba without SciPy and PyYAML (about 0.03 s of CPU), which its
import only looks for: SciPy to check its version, PyYAML to read a ``.numba_config.yaml`` in
the working folder (where there is one, PyYAML is imported as usual).

The commands that run kernels call :func:`start_numba` first (``sidql encode``, ``sidql
decode``), and ``sidql`` as a program calls :func:`import_numba` before it imports them; a
library user may too.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import threading

_BLAS = "scipy.linalg.cython_blas"
#: numba's configuration file, read from the working folder with PyYAML (``numba.core.config``)
NUMBA_CONFIG = ".numba_config.yaml"
_lock = threading.Lock()
_started = False


def import_numba() -> None:
    """Import numba without importing SciPy or PyYAML (see the module docstring); nothing to do
    once numba is imported. Call it before other threads start: while numba is imported, an
    import of SciPy elsewhere fails."""
    if "numba" in sys.modules:
        return
    unseen = [name for name in ("scipy", "yaml") if name not in sys.modules]
    if os.path.exists(NUMBA_CONFIG):
        unseen = [name for name in unseen if name != "yaml"]
    for name in unseen:
        sys.modules[name] = None  # an import of it raises ImportError: "not installed"
    try:
        import numba  # noqa: F401  # lazy: with SciPy and PyYAML hidden
    finally:
        for name in unseen:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]


@contextlib.contextmanager
def _without_blas():
    """``scipy.linalg.cython_blas`` reads as absent inside (unless ``scipy.linalg`` or numba's
    implementations are loaded already): ``numba.np.arraymath`` imported here learns that there
    is no BLAS for ``np.convolve`` without importing ``scipy.linalg``."""
    if "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
        yield
        return
    sys.modules[_BLAS] = None  # an import of it raises ImportError
    try:
        yield
    finally:
        if sys.modules.get(_BLAS, 0) is None:
            del sys.modules[_BLAS]


def _rebuild_env(modname, consts, env_name):
    """``numba.core.environment._rebuild_env`` (a cached kernel's environment ``env_name`` of
    module ``modname``, its constants ``consts``), except that the globals of a numba module
    not yet imported are its name alone (see the module docstring)."""
    from numba.core.environment import Environment  # lazy: after import_numba

    env = Environment._memo.get(env_name)
    if env is not None:
        return env
    if modname.startswith("numba.") and modname not in sys.modules:
        env = Environment({"__name__": modname})  # nopython code never reads its globals
    else:
        env = Environment(importlib.import_module(modname).__dict__)
    env.consts[:] = consts
    env.env_name = env_name
    Environment._memo[env_name] = env
    return env


# pickled, as numba's own is, by the name a cache written anywhere finds it under
_rebuild_env.__module__, _rebuild_env.__qualname__ = "numba.core.environment", "_rebuild_env"


def start_numba() -> None:
    """Cached kernels load without numba's implementations (and the environments of numba's
    functions in them without their modules); numba's modules load without ``scipy.linalg``;
    idle OpenMP threads sleep (see the module docstring). Once per process;
    later calls only set ``OMP_WAIT_POLICY`` if unset."""
    global _started
    with _lock:
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        if _started:
            return
        _started = True
        from numba.core import environment  # lazy: after import_numba
        from numba.core.caching import FunctionCache  # lazy: after import_numba
        from numba.core.cpu import CPUContext  # lazy: after import_numba
        from numba.core.runtime import rtsys  # lazy: after import_numba

        registries = CPUContext.load_additional_registries
        guard = getattr(FunctionCache, "_guard_against_spurious_io_errors", None)
        load = getattr(FunctionCache, "_load_overload", None)

        def load_additional_registries(self):
            with _without_blas():
                return registries(self)

        def load_overload(self, sig, target_context):
            rtsys.initialize(target_context)  # the runtime the kernel's code calls
            with _without_blas(), guard(self):  # its environments import numba's modules
                return load(self, sig, target_context)

        CPUContext.load_additional_registries = load_additional_registries
        if guard is not None and load is not None:  # numba's own loader otherwise
            FunctionCache.load_overload = load_overload
        if callable(getattr(environment, "_rebuild_env", None)):
            environment._rebuild_env = _rebuild_env
