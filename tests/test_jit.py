"""Numba started without SciPy (``sim.jit.start_numba``): kernels run, BLAS still works."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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


def test_numba_starts_without_scipy_linalg_and_blas_kernels_still_compile():
    out = subprocess.run(
        [sys.executable, "-c", CODE],
        cwd=REPO,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[:4] == [
        "False False",  # started: scipy.linalg never imported
        "True",  # a cached kernel runs
        "True True",  # np.dot compiled afterwards: SciPy's BLAS imported then, right answer
        "True",  # np.convolve: numba's own loop, right answer
    ]
