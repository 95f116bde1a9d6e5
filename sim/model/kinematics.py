"""Independent forward kinematics of ASF/AMC in numpy (no MuJoCo): the oracle for retargeting.

Acclaim's rule: a bone's global rotation is ``G = G_parent C M C^-1`` and its end lies at
``end_parent + length * G direction``; the root sits at the AMC root translation.
"""

from __future__ import annotations

import numpy as np

from sim.acclaim.reader import Motion, Skeleton
from sim.model.rotations import Y_UP_TO_Z_UP
from sim.motion.retarget import acclaim_matrices


def point_names(skeleton: Skeleton) -> tuple[str, ...]:
    """Point names of a skeleton: ``"root"`` then the bones in topological order."""
    return ("root",) + skeleton.bone_names


def point_parents(skeleton: Skeleton) -> np.ndarray:
    """(J,) parent point index of every point (-1 for the root)."""
    names = point_names(skeleton)
    index = {n: i for i, n in enumerate(names)}
    return np.array([-1] + [index[b.parent] for b in skeleton.bones], dtype=np.int64)


def forward_kinematics(skeleton: Skeleton, motion: Motion) -> np.ndarray:
    """(T, J, 3) world positions [m], z up, of the root and every bone end."""
    G = acclaim_matrices(skeleton, motion)
    T = motion.n_frames
    ends = {"root": motion.root[:, :3]}
    for b in skeleton.bones:
        ends[b.name] = ends[b.parent] + b.length * (G[b.name] @ b.direction)
    pts = np.stack([ends[n] for n in point_names(skeleton)], axis=1).reshape(T, -1, 3)
    return pts @ Y_UP_TO_Z_UP.T
