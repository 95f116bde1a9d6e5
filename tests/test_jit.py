"""Numba started without SciPy (``sim.jit.start_numba``): kernels run, BLAS still works."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

# In a fresh interpreter: what the command line does (start numba, then run cached kernels), then
# a kernel that needs BLAS compiled afterwards, checked against numpy.
CODE = """
import sys
import numba
import numpy as np
from sim.jit import start_numba
from sim.model.angles import wrap_angle
start_numba()
print('scipy.linalg' in sys.modules, 'scipy.linalg.cython_blas' in sys.modules)
a = np.array([4.0, -4.0, 0.5])
print(np.allclose(wrap_angle(a), a - 2 * np.pi * np.floor(a / (2 * np.pi) + 0.5)))
dot = numba.njit(lambda x, y: np.dot(x, y))
x = np.arange(6.0).reshape(2, 3)
print(np.allclose(dot(x, x.T), x @ x.T), 'scipy.linalg' in sys.modules)
conv = numba.njit(lambda x, y: np.convolve(x, y))
print(np.allclose(conv(a, a), np.convolve(a, a)))
start_numba()
"""


def run(code: str, cwd: Path = REPO) -> list[str]:
    """``code`` in a fresh interpreter on this checkout; its printed lines."""
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=cwd,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.split("\n")


def test_numba_starts_without_scipy_linalg_and_blas_kernels_still_compile():
    assert run(CODE)[:4] == [
        "False False",  # started: scipy.linalg never imported
        "True",  # a cached kernel runs
        "True True",  # np.dot compiled afterwards: SciPy's BLAS imported then, right answer
        "True",  # np.convolve: numba's own loop, right answer
    ]


# The plan's band costs (a parallel kernel whose compiled code calls numba's array
# implementations) and the position coding's closed loop, on a chart made from a seeded walk of
# angles; with START, numba started first. Prints a digest of the results, then which of numba's
# implementations and modules were loaded (polynomial: only ever loaded with all of them).
KERNELS = """
import hashlib, sys
import numpy as np
START
from sidql.codec.plan import position_band_costs
from sidql.codec.quantise import PositionQuantiser, aim_basis
rng = np.random.default_rng(7)
M = 4
parents = np.array([-1, 0, 1, 0, 3])
X = np.cumsum(rng.normal(0.0, 0.02, (40, 2 * M + 3)), axis=0) + 1.0
lengths = np.array([0.3, 0.25, 0.3, 0.25])
C = position_band_costs(X, X, None, 8, "linear", lengths, parents)
q = PositionQuantiser(M, lengths, parents, 1e-3, 0.5, exponent=0.25, gap_exponent=0.5,
                      partner=False)
keys = np.array([0, 3, 7, 12, 20, 39])
codes, values = q.encode_keyframes(X[keys], keys, True, aim_basis(X[keys], M))
h = hashlib.sha256()
for a in (C, codes, values, q.decode_keyframes(codes, keys)):
    h.update(np.ascontiguousarray(a).tobytes())
print(h.hexdigest())
print("numba.np.polynomial.polynomial_core" in sys.modules, "scipy.linalg" in sys.modules,
      "numba.np.arrayobj" in sys.modules)
"""


def test_started_numba_runs_cached_kernels_without_its_implementations_and_the_same_results():
    plain = run(KERNELS.replace("START", ""))  # compiles the kernels where they are not cached
    started = run(KERNELS.replace("START", "from sim.jit import start_numba; start_numba()"))
    assert plain[1] == "True True True"  # numba's own loader: every implementation, SciPy
    assert started[:2] == [plain[0], "False False False"]  # the same results; none loaded


# numba imported as the program does it; then SciPy and PyYAML still import.
IMPORT = """
import sys
from sim.jit import import_numba
import_numba()
import numba.core.config as config
print("scipy" in sys.modules, "yaml" in sys.modules, config._HAVE_YAML)
import scipy, yaml
print(scipy.__name__, yaml.__name__)
"""


def test_numba_imported_without_scipy_and_yaml_which_still_import(tmp_path):
    assert run(IMPORT)[:2] == ["False False False", "scipy yaml"]


def test_numba_reads_its_config_file_where_there_is_one(tmp_path):
    (tmp_path / ".numba_config.yaml").write_text("debug_cache: 0\n")
    assert run(IMPORT, cwd=tmp_path)[:2] == ["False True True", "scipy yaml"]


# A kernel cached in its own folder (numba functions compiled into it: np.zeros, np.argsort),
# run with numba started or not (START); prints its result and whether it came from the cache.
CACHED = """
import numpy as np
START
from kernel import sorted_twice
x = np.array([3.0, 1.0, 2.0])
print(sorted_twice(x).tolist(), sum(sorted_twice.stats.cache_hits.values()))
"""
KERNEL = """
import numba
import numpy as np

@numba.njit(cache=True)
def sorted_twice(x):
    out = np.zeros(x.shape[0])
    out[:] = 2.0 * x[np.argsort(x)]
    return out
"""


@pytest.mark.parametrize("first, second", [("start", "plain"), ("plain", "start")])
def test_a_cache_written_with_numba_started_or_not_loads_in_the_other(tmp_path, first, second):
    (tmp_path / "kernel.py").write_text(KERNEL)
    start = {"start": "from sim.jit import start_numba; start_numba()", "plain": ""}

    def once(how: str) -> list[str]:
        out = subprocess.run(
            [sys.executable, "-c", CACHED.replace("START", start[how])],
            cwd=tmp_path,
            env={"PYTHONPATH": f"{REPO}:{tmp_path}", "PATH": "/usr/bin:/bin"},
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert out.returncode == 0, out.stderr
        return out.stdout.split("\n")

    assert once(first)[0] == "[2.0, 4.0, 6.0] 0"  # compiled and cached
    cached = [p.read_bytes() for p in (tmp_path / "__pycache__").glob("kernel.*.nbc")]
    assert cached and not any(b"sim.jit" in data for data in cached)  # numba's names only
    assert once(second)[0] == "[2.0, 4.0, 6.0] 1"  # loaded from that cache
    assert once(first)[0] == "[2.0, 4.0, 6.0] 1"
