"""AMC frames -> MuJoCo ``qpos`` for a generated humanoid.

Two targets:
(a) the subject's own model (``sim.model.humanoid.build_mjcf`` of its ASF): body positions then equal the
    ASF/AMC forward kinematics exactly;
(b) the shared ``models/cmu_humanoid.xml``: joint angles are copied by name and the root
    translation is scaled by the ratio of leg lengths (femur + tibia).
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.acclaim.records import Motion, Skeleton
from sim.errors import MotionDataError
from sim.model import quaternion as quat
from sim.model.humanoid import bone_frames
from sim.model.rotations import Y_UP_TO_Z_UP, continuous_euler, euler_matrix, y_up_to_z_up


def root_pose(skeleton: Skeleton, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World root position (T, 3) [m] and orientation (T, 4) ``wxyz``, z up.

    The root body's frame is ``C_o M`` in the file's axes (``C_o`` the ASF root orientation,
    ``M`` the AMC root rotation), turned from y up to z up.
    """
    C_o = bone_frames(skeleton)["root"]
    M = euler_matrix(motion.root[:, 3:], skeleton.root_axis_order)
    pos = y_up_to_z_up(motion.root[:, :3])
    return pos, quat.from_matrix(Y_UP_TO_Z_UP @ C_o @ M)


def joint_qpos_addresses(model) -> dict[str, int]:
    """Hinge joint name -> its ``qpos`` address in ``model``."""
    out = {}
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            out[model.joint(j).name] = int(model.jnt_qposadr[j])
    return out


def motion_to_qpos(
    skeleton: Skeleton, motion: Motion, model, *, root_scale: float = 1.0
) -> np.ndarray:
    """(T, nq) ``qpos`` of ``motion`` on ``model`` (free root first, hinges ``<bone>_<dof>``).

    Each bone's hinge angles are continuous over the take (:func:`bone_hinge_angles`): the same
    rotations as the file's, without its Euler-angle flips. Joints of the model that the skeleton
    lacks stay at 0; dofs the model lacks are dropped, so the
    same call serves the subject's own model and the shared humanoid.

    Args:
        root_scale: factor on the root translation (leg-length ratio for the shared humanoid).
    """
    T = motion.n_frames
    qpos = np.zeros((T, model.nq))
    pos, quat = root_pose(skeleton, motion)
    qpos[:, :3] = pos * root_scale
    qpos[:, 3:7] = quat
    adr = joint_qpos_addresses(model)
    for b in skeleton.bones:
        if not b.dofs:
            continue
        values = bone_hinge_angles(
            b.dofs, motion.angles[b.name], [f"{b.name}_{d}" in adr for d in b.dofs]
        )
        for k, dof in enumerate(b.dofs):
            a = adr.get(f"{b.name}_{dof}")
            if a is not None:
                qpos[:, a] = values[:, k]
    return qpos


def bone_hinge_angles(dofs, angles_deg: np.ndarray, kept) -> np.ndarray:
    """(T, len(dofs)) hinge angles [rad] of one bone's AMC angles ``angles_deg`` [deg], continuous
    over the take (:func:`sim.model.rotations.continuous_euler`).

    Some AMC files switch a bone's Euler triple to its twin or by whole turns mid-take (the
    rotation stays smooth): as hinge angles those are jumps of up to 2 pi between frames, and
    ``qvel`` from them is meaningless. The twin is chosen only when the target keeps all three
    dofs (``kept``: per dof, whether the model has its hinge); otherwise each angle only loses
    its whole-turn jumps, so the target's pose never changes.
    """
    values = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    order = "".join(d[1] for d in dofs).upper()
    if all(kept):
        return continuous_euler(values, order)
    return np.column_stack(
        [continuous_euler(values[:, [k]], ax) for k, ax in enumerate(order)]
    ).reshape(values.shape)


MIN_LEG = 1e-3  # [m] shorter legs cannot scale a root translation


def leg_length(skeleton: Skeleton) -> float:
    """Mean femur + tibia length [m] of the two legs (the root-scaling yardstick).

    Raises:
        MotionDataError: a leg bone is missing, or the legs are shorter than ``MIN_LEG``.
    """
    try:
        legs = [skeleton.bone(f"{s}femur").length + skeleton.bone(f"{s}tibia").length for s in "lr"]
    except KeyError as e:
        raise MotionDataError(
            skeleton.path, None, f"cannot retarget to the humanoid: {e.args[0]}"
        ) from None
    length = float(np.mean(legs))
    if not length >= MIN_LEG:
        femur = skeleton.bone("lfemur")
        raise MotionDataError(
            skeleton.path,
            femur.line,
            f"cannot retarget to the humanoid: legs {length:g} m long (< {MIN_LEG:g} m)",
        )
    return length


def local_rotations_from_world(xquat: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(T, J, 4) rotation of each body relative to its parent body (root: world), ``wxyz``."""
    parent = np.where(parents < 0, 0, parents)
    local = quat.mul(quat.conj(xquat[:, parent]), xquat)
    local[:, parents < 0] = xquat[:, parents < 0]
    return quat.canonical(local)
