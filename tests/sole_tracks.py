"""Sole tracks for the sole cost terms' tests (foot holding, footprints, swing clearance and
stance pivot): hand-made ones, and a reference's own."""

import mujoco
import numpy as np


def still_soles(K: int = 12) -> np.ndarray:
    """(K, 2, 2) two soles' horizontal positions [m], standing still 0.3 m apart."""
    xy = np.zeros((K, 2, 2))
    xy[:, 1, 1] = 0.3
    return xy


def reference_sole_boxes(model, ref_qpos: np.ndarray, ids: np.ndarray) -> tuple:
    """The sole boxes ``ids`` of ``model`` along ``ref_qpos`` (T, nq), as one rollout's record:
    positions (1, T, 2, 3) [m] and orientations (1, T, 2, 9)."""
    data = mujoco.MjData(model)
    pos, mat = np.empty((1, len(ref_qpos), 2, 3)), np.empty((1, len(ref_qpos), 2, 9))
    for t, q in enumerate(ref_qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pos[0, t], mat[0, t] = data.geom_xpos[ids], data.geom_xmat[ids]
    return pos, mat
