"""AMC frames -> MuJoCo ``qpos`` for a generated humanoid.

Two targets:
(a) the subject's own model (``sim.model.humanoid.build_mjcf`` of its ASF): body positions then equal the
    ASF/AMC forward kinematics exactly;
(b) the shared ``models/cmu_humanoid.xml``: joint angles are copied by name and the root
    translation is scaled by the ratio of leg lengths (femur + tibia).
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from sim.acclaim.records import Motion, Skeleton
from sim.errors import MotionDataError
from sim.model import quaternion as quat
from sim.model.angles import wrap_angle
from sim.model.humanoid import bone_frames
from sim.model.kinematics import local_rotations
from sim.model.rotations import (
    Y_UP_TO_Z_UP,
    continuous_euler,
    euler_angles_deg,
    euler_matrix,
    euler_twin,
    y_up_to_z_up,
    z_up_to_y_up,
)


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


#: CMU's BVH release (its joint names) -> the ASF bone whose segment starts at that joint.
CMU_BVH_NAMES = {
    "LHipJoint": "lhipjoint", "LeftUpLeg": "lfemur", "LeftLeg": "ltibia", "LeftFoot": "lfoot",
    "LeftToeBase": "ltoes", "RHipJoint": "rhipjoint", "RightUpLeg": "rfemur",
    "RightLeg": "rtibia", "RightFoot": "rfoot", "RightToeBase": "rtoes", "LowerBack": "lowerback",
    "Spine": "upperback", "Spine1": "thorax", "Neck": "lowerneck", "Neck1": "upperneck",
    "Head": "head", "LeftShoulder": "lclavicle", "LeftArm": "lhumerus",
    "LeftForeArm": "lradius", "LeftHand": "lwrist", "LeftFingerBase": "lhand",
    "LeftHandIndex1": "lfingers", "LThumb": "lthumb", "RightShoulder": "rclavicle",
    "RightArm": "rhumerus", "RightForeArm": "rradius", "RightHand": "rwrist",
    "RightFingerBase": "rhand", "RightHandIndex1": "rfingers", "RThumb": "rthumb",
}  # fmt: skip


def retarget_rotations(
    source: Skeleton, motion: Motion, target: Skeleton
) -> tuple[Skeleton, Motion]:
    """``motion`` of ``source`` as angles of ``target``'s bones of the same name (a BVH's
    skeleton, whose rotations turn about the file's axes, onto the shared humanoid's ASF bones).

    Each bone's rotation in the rest frame, ``L = C_s M_s C_s^-1``
    (:func:`sim.model.kinematics.local_rotations`), becomes ``M_t = C_t^-1 L C_t`` in the target
    bone's ``axis`` frame, as Euler angles in its dof order (a bone of fewer dofs keeps the first
    of the angles in the order its dofs, then the missing axes, give: exact when the rotation
    turns about those dofs only); the root's likewise. Source bones named as in CMU's BVH
    release (:data:`CMU_BVH_NAMES`) are renamed first, when that matches more target bones.
    Target bones the source lacks stay at 0.

    Returns:
        The source skeleton under the target's names (for :func:`leg_length`) and the motion of
        ``target`` (root translation [m] unchanged, angles [deg]).
    """
    names = {b.name: b.name for b in source.bones}
    mapped = {b.name: CMU_BVH_NAMES.get(b.name, b.name) for b in source.bones}
    if sum(target.has_bone(n) for n in mapped.values()) > sum(target.has_bone(n) for n in names):
        names = mapped
    names["root"] = "root"
    bones = tuple(replace(b, name=names[b.name], parent=names[b.parent]) for b in source.bones)
    renamed = replace(source, bones=bones, _index={})
    L = {names[k]: v for k, v in local_rotations(source, motion).items()}
    C = bone_frames(target)
    T = motion.n_frames
    angles = {}
    for b in target.bones:
        if not b.dofs:
            continue
        if b.name not in L:
            angles[b.name] = np.zeros((T, len(b.dofs)))
            continue
        order = "".join(d[1] for d in b.dofs).upper()
        order += "".join(a for a in "XYZ" if a not in order)
        M = C[b.name].T @ L[b.name] @ C[b.name]
        angles[b.name] = _dof_angles(M, order, len(b.dofs))
    M_root = C["root"].T @ L["root"] @ C["root"]
    root = np.concatenate(
        [motion.root[:, :3], euler_angles_deg(M_root, target.root_axis_order)], axis=1
    )
    return renamed, Motion(path=motion.path, root=root, angles=angles, notes=motion.notes)


def _dof_angles(M: np.ndarray, order: str, k: int) -> np.ndarray:
    """(T, k) the first ``k`` Euler angles [deg] of rotations ``M`` (T, 3, 3) in ``order``: of the
    triple and its twin (the same rotation), per frame the one whose dropped angles are nearer
    0 (a two-dof bone bent past 90 degrees in its middle axis stays exact)."""
    a = np.deg2rad(euler_angles_deg(M, order))
    if k == 3:
        return np.rad2deg(a)
    twin = wrap_angle(euler_twin(a))
    pick = np.abs(twin[:, k:]).sum(axis=1) < np.abs(wrap_angle(a[:, k:])).sum(axis=1)
    return np.rad2deg(np.where(pick[:, None], twin, a)[:, :k])


def qpos_to_motion(skeleton: Skeleton, qpos: np.ndarray, joint_names) -> Motion:
    """The inverse of :func:`motion_to_qpos` (root scale 1): the motion of ``skeleton`` whose
    ``qpos`` (T, 7 + len(joint_names)) this is, on a model of free root then one hinge per name
    ``<bone>_<dof>`` in ``qpos`` order (a clip's ``joint_names``).

    Returns:
        root (T, 6) as (tx, ty, tz [m], file axes y up; rx, ry, rz [deg] in the root's axis
        order), angles bone -> (T, dofs) [deg] (dofs without a hinge: 0).

    Raises:
        MotionDataError: a hinge name that is no dof of ``skeleton``, or a ``qpos`` of another
            width.
    """
    qpos = np.asarray(qpos, dtype=np.float64)
    names = tuple(joint_names)
    if qpos.ndim != 2 or qpos.shape[1] != 7 + len(names):
        raise MotionDataError(
            skeleton.path or None, None, f"qpos of shape {qpos.shape} for {len(names)} hinges"
        )
    column = {n: 7 + k for k, n in enumerate(names)}
    known = {f"{b.name}_{d}" for b in skeleton.bones for d in b.dofs}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise MotionDataError(
            skeleton.path or None, None, f"the skeleton has no hinge {unknown[0]!r}"
        )
    C_o = bone_frames(skeleton)["root"]
    M = C_o.T @ Y_UP_TO_Z_UP.T @ quat.to_matrix(qpos[:, 3:7])
    root = np.concatenate(
        [z_up_to_y_up(qpos[:, :3]), euler_angles_deg(M, skeleton.root_axis_order)], axis=1
    )
    T = len(qpos)
    angles = {
        b.name: np.column_stack(
            [np.rad2deg(qpos[:, column[f"{b.name}_{d}"]]) if f"{b.name}_{d}" in column
             else np.zeros(T) for d in b.dofs]
        )
        for b in skeleton.bones if b.dofs
    }  # fmt: skip
    return Motion(path=skeleton.path, root=root, angles=angles)
