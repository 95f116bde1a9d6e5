"""Hand-made sole tracks for the sole cost terms' tests (foot holding, footprints)."""

import numpy as np


def still_soles(K: int = 12) -> np.ndarray:
    """(K, 2, 2) two soles' horizontal positions [m], standing still 0.3 m apart."""
    xy = np.zeros((K, 2, 2))
    xy[:, 1, 1] = 0.3
    return xy
