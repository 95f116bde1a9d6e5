"""The points of a skeleton: the root, then every ASF bone's end, with their parents.

(The independent forward kinematics that checks retargeting lives with the tests,
``tests/acclaim_fk.py``: it shares no code with the model builder.)
"""

from __future__ import annotations

import numpy as np

from sim.acclaim.records import Skeleton


def point_names(skeleton: Skeleton) -> tuple[str, ...]:
    """Point names of a skeleton: ``"root"`` then the bones in topological order."""
    return ("root",) + skeleton.bone_names


def point_parents(skeleton: Skeleton) -> np.ndarray:
    """(J,) parent point index of every point (-1 for the root)."""
    names = point_names(skeleton)
    index = {n: i for i, n in enumerate(names)}
    return np.array([-1] + [index[b.parent] for b in skeleton.bones], dtype=np.int64)
