"""The points of a skeleton: the root, then every ASF bone's end, with their parents; which of
them stand for the feet; the bones' rotations relative to their parents.

(The independent forward kinematics that checks retargeting lives with the tests,
``tests/acclaim_fk.py``: it shares no code with the model builder.)
"""

from __future__ import annotations

import numpy as np

from sim.acclaim.records import Motion, Skeleton
from sim.model.rotations import euler_matrix


def point_names(skeleton: Skeleton) -> tuple[str, ...]:
    """Point names of a skeleton: ``"root"`` then the bones in topological order."""
    return ("root",) + skeleton.bone_names


def point_parents(skeleton: Skeleton) -> np.ndarray:
    """(J,) parent point index of every point (-1 for the root)."""
    names = point_names(skeleton)
    index = {n: i for i, n in enumerate(names)}
    return np.array([-1] + [index[b.parent] for b in skeleton.bones], dtype=np.int64)


def local_rotations(skeleton: Skeleton, motion: Motion) -> dict[str, np.ndarray]:
    """(T, 3, 3) every bone's rotation relative to its parent in the rest frame, ``C M C^-1``
    (``C`` its ``axis`` frame, ``M`` its motion's Euler angles), and the root's (``"root"``:
    ``C_o M_o C_o^-1``), file axes: Acclaim's rule, the bone's global rotation is its parent's
    times this."""
    T = motion.n_frames
    C = {"root": euler_matrix(skeleton.root_orientation, skeleton.root_axis_order)}
    M = euler_matrix(motion.root[:, 3:], skeleton.root_axis_order)
    out = {"root": C["root"] @ M @ C["root"].T}
    for b in skeleton.bones:
        C = euler_matrix(b.axis, b.axis_order)
        if b.dofs:
            M = euler_matrix(motion.angles[b.name], "".join(d[1] for d in b.dofs).upper())
        else:
            M = np.broadcast_to(np.eye(3), (T, 3, 3))
        out[b.name] = C @ M @ C.T
    return out


#: Foot points, in the order metrics use them: (ankle, ball, toes) per side. Each names the bone
#: whose *end* is the point: ``ltibia`` ends at the ankle, ``lfoot`` at the ball (toe base),
#: ``ltoes`` at the toe tip.
FOOT_POINTS: tuple[str, ...] = ("ltibia", "lfoot", "ltoes", "rtibia", "rfoot", "rtoes")
#: The sole's points (balls, then toes), which rest on the floor in flat stance; the bones whose
#: capsules are the humanoid's foot geoms (the simulator's feet, :mod:`sim.simulate`).
SOLE_POINTS: tuple[str, ...] = ("lfoot", "rfoot", "ltoes", "rtoes")
SIDES: tuple[str, ...] = ("l", "r")


def side(point: str) -> str:
    """``"l"`` or ``"r"``: the foot a foot point belongs to."""
    return point[0]


def foot_points(names) -> tuple[str, ...]:
    """The foot points among ``names``, in :data:`FOOT_POINTS` order."""
    return tuple(n for n in FOOT_POINTS if n in names)
