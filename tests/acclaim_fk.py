"""An independent Acclaim ASF/AMC forward kinematics, the oracle for retargeting (test-only).

Shares no code with the model builder: rotations come from scipy's ``Rotation`` (extrinsic
Euler angles, lower-case axis strings: the first axis applied first, Acclaim's convention) and the
y-up -> z-up change is written out here by hand.

Acclaim's rule: a bone's global rotation is ``G = G_parent C M C^-1`` (C its ``axis`` frame, M its
AMC rotation) and its end lies at ``end_parent + length * G direction``; the root sits at the AMC
root translation with ``G_root = C_root M_root C_root^-1``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def euler(order: str, angles_deg) -> np.ndarray:
    """(..., 3, 3) rotation applying ``angles_deg[..., i]`` about ``order[i]`` (extrinsic), first
    axis first."""
    angles_deg = np.asarray(angles_deg, dtype=float)
    shape = angles_deg.shape[:-1]
    flat = angles_deg.reshape(-1, len(order))
    return (
        Rotation.from_euler(order.lower(), flat, degrees=True).as_matrix().reshape(shape + (3, 3))
    )


def acclaim_points(skeleton, motion) -> np.ndarray:
    """(T, J, 3) world positions [m], z up, of the root and every bone end (point order: root,
    then ``skeleton.bones``)."""
    T = motion.n_frames
    C_root = euler(skeleton.root_axis_order, skeleton.root_orientation)
    G = {"root": C_root @ euler(skeleton.root_axis_order, motion.root[:, 3:]) @ C_root.T}
    ends = {"root": motion.root[:, :3]}
    for b in skeleton.bones:
        C = euler(b.axis_order, b.axis)
        if b.dofs:
            M = euler("".join(d[1] for d in b.dofs), motion.angles[b.name])
        else:
            M = np.broadcast_to(np.eye(3), (T, 3, 3))
        G[b.name] = G[b.parent] @ C @ M @ C.T
        ends[b.name] = ends[b.parent] + b.length * (G[b.name] @ b.direction)
    y_up = np.stack([ends["root"]] + [ends[b.name] for b in skeleton.bones], axis=1)
    return np.stack([y_up[..., 0], -y_up[..., 2], y_up[..., 1]], axis=-1)  # (x, y, z) -> (x, -z, y)
