"""Angles on the circle: the one wrap of an angle into [-pi, pi).

:func:`wrap_angle` is compiled with numba so that numpy code (arrays) and numba kernels
(scalars, inlined into the caller and compiled with its flags) share one definition.
"""

from __future__ import annotations

import numba
import numpy as np

TWO_PI = 2.0 * np.pi
_INV_TWO_PI = 1.0 / TWO_PI


# inline="always": compiled into each kernel with the kernel's own flags (fastmath). Numba's disk
# cache of a kernel does not notice a change here: clear the __pycache__ *.nbi/*.nbc after one.
@numba.njit(cache=True, inline="always")
def wrap_angle(a):
    """Angles [rad] wrapped into [-pi, pi): ``a - 2 pi floor(a / 2 pi + 1/2)``.

    ``a``: a float or a numpy array of any shape (a new array is returned), from Python or from
    numba code. Branch-free, so a kernel's loop over it vectorises. The half-open end matters only
    for signs: ``|wrap_angle(a)|`` is the angular distance from 0 either way.
    """
    return a - TWO_PI * np.floor(a * _INV_TWO_PI + 0.5)
