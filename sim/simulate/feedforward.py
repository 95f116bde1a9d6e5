"""The tracking controller's feed-forward: inverse dynamics of the reference and the floor's
share of it.

``mujoco.mj_inverse`` of the reference, free-floating (no contacts), gives hinge torques and the
6-d root wrench the motion needs from outside; :func:`contact_feedforward` moves that root force
onto the feet near the floor (upward only, inside a friction cone; with soles,
:func:`balanced_support` solves force and moment by non-negative least squares): the stance legs
carry the body, and the root keeps only what the floor cannot give. Used by
``sim.simulate.controller.track`` and the sampler; the whole-body controller reads
:func:`reference_derivatives` only.

Units: metres, seconds, newtons, radians.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.optimize import nnls

from sim.model.kinematics import SOLE_POINTS
from sim.motion.velocities import qvel_from_qpos
from sim.simulate.model import CONTROL_HZ, FLOOR_BITS, SOLE_GEOMS, TOE_GEOMS

FLOOR_CONTYPE = FLOOR_BITS[0]  # a geom touches the floor where its conaffinity has this bit


def reference_derivatives(model, qpos: np.ndarray, rate: float = CONTROL_HZ):
    """(T, nv) velocity and (T, nv) acceleration of a reference ``qpos`` stream at ``rate``.

    The reference is a target, not an output: differencing it is fine (central differences on the
    configuration manifold for velocities, ``np.gradient`` of those for accelerations).
    """
    qvel = qvel_from_qpos(model, qpos, rate)
    qacc = np.gradient(qvel, 1.0 / rate, axis=0) if len(qpos) > 1 else np.zeros_like(qvel)
    return qvel, qacc


def inverse_dynamics(model, qpos, qvel, qacc, *, contacts: bool = True, data=None) -> np.ndarray:
    """(T, nv) generalised force that produces ``qacc`` at each (``qpos``, ``qvel``):
    ``mujoco.mj_inverse``, floor contacts of that pose included (MuJoCo's soft-contact inverse).
    The first 6 columns are the root wrench nothing inside the body can supply. ``data``: an
    ``MjData`` of ``model`` to work in (its state is overwritten), a new one if None."""
    data = data if data is not None else mujoco.MjData(model)
    out = np.empty((len(qpos), model.nv))
    flags = int(model.opt.disableflags)
    try:  # the model's flags as they were, however this ends
        if not contacts:
            model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        for t in range(len(qpos)):
            data.qpos[:], data.qvel[:], data.qacc[:] = qpos[t], qvel[t], qacc[t]
            mujoco.mj_inverse(model, data)
            out[t] = data.qfrc_inverse
    finally:
        model.opt.disableflags = flags
    return out


def _support_points(model, data, ids, contact_height: float):
    """[(point (3,), body id)] of ``ids``' geoms near the floor: a capsule's lowest end point,
    a box's (a sole's, ``sim.simulate.model.add_soles``) bottom corners, those within
    ``contact_height`` of z = 0."""
    out = []
    for g in ids:
        R, c, size = data.geom_xmat[g].reshape(3, 3), data.geom_xpos[g], model.geom_size[g]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            corners = c + (_CORNERS * size) @ R.T
            pts = corners[np.argsort(corners[:, 2])[:4]]  # the face nearest the floor
        else:
            axis = R[:, 2] * size[1]
            p = c - axis if axis[2] > 0 else c + axis
            pts = [p - [0.0, 0.0, size[0]]]
        out += [(p, int(model.geom_bodyid[g])) for p in pts if p[2] < contact_height]
    return out


def _support_jacobians(model, qpos, ids, contact_height: float, data=None):
    """For each frame ``t`` of ``qpos`` (T, nq) with some support point of ``ids``' geoms near
    the floor (:func:`_support_points`): ``(t, [(nv, 3) transposed point Jacobian, ...])``.
    ``data``: an ``MjData`` of ``model`` to work in (its state is overwritten), a new one if
    None."""
    data = data if data is not None else mujoco.MjData(model)
    jacp = np.zeros((3, model.nv))
    for t in range(len(qpos)):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        cols = []
        for p, body in _support_points(model, data, ids, contact_height):
            mujoco.mj_jac(model, data, jacp, None, p, body)
            cols.append(jacp.T.copy())
        if cols:
            yield t, cols


_CORNERS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
#: weight of the squared edge forces [N^2] against the squared wrench error [N^2, N^2 m^2] in
#: :func:`balanced_support`'s least squares: among the supports that give the root wrench, the
#: one with the smallest forces (spread over the points)
SUPPORT_REGULARISATION = 1e-6


def contact_feedforward(
    model, qpos, force, *, contact_height: float = 0.03, friction: float = 0.8, data=None
) -> np.ndarray:
    """Move the root wrench of a free-floating inverse dynamics onto the feet that touch the floor.

    ``force`` (T, nv) comes from :func:`inverse_dynamics` without contacts: its root rows are the
    whole external wrench the motion needs (body weight included). In each frame the foot and toe
    capsules whose lowest point is within ``contact_height`` of z = 0 take point forces ``F`` at
    that point: the root force shared equally, upward only and inside a friction cone (a
    quasi-static support); the hinges get ``tau - J_hinge^T F`` (the stance legs now carry the body) and the
    root keeps the residual the floor cannot give, which is what the assistance has to supply.
    A model with soles (``sim.simulate.model.add_soles``) gets :func:`balanced_support` instead.

    Returns:
        (T, nv) feed-forward: root rows = residual wrench, hinge rows = joint torques.
    ``data``: an ``MjData`` of ``model`` to work in (its state is overwritten), a new one if None.
    """
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, SOLE_GEOMS[0]) >= 0:
        return balanced_support(
            model, qpos, force, contact_height=contact_height, friction=friction, data=data
        )
    ids = [model.geom(n).id for n in SOLE_POINTS]  # the foot and toe capsules
    out = force.copy()
    for t, cols in _support_jacobians(model, qpos, ids, contact_height, data):
        JT = np.concatenate(cols, axis=1)  # (nv, 3k)
        F = np.tile(force[t, :3] / len(cols), (len(cols), 1))  # shared by the touching points
        F[:, 2] = np.maximum(F[:, 2], 0.0)  # the floor only pushes
        h = np.linalg.norm(F[:, :2], axis=1)
        cap = friction * F[:, 2]
        F[:, :2] *= np.minimum(1.0, cap / np.maximum(h, 1e-12))[:, None]  # friction cone
        out[t] = force[t] - JT @ F.reshape(-1)
    return out


def balanced_support(
    model, qpos, force, *, contact_height: float = 0.03, friction: float = 0.8, data=None
) -> np.ndarray:
    """:func:`contact_feedforward` for a model with soles: the support points near the floor
    (the sole boxes' bottom corners and the toe capsules' lowest points, within
    ``contact_height`` of z = 0) take point forces ``F``, upward only and inside a friction
    pyramid (four edges, coefficient ``friction``), that best give the root wrench, force and
    moment (non-negative least squares over the pyramid edges, slightly regularised:
    :data:`SUPPORT_REGULARISATION`): the centre of pressure lies under the body where the
    support polygon allows it, instead of the force shared equally by the touching points
    (whose moment tips the body). Same arguments and result as :func:`contact_feedforward`."""
    names = [
        n
        for n in SOLE_POINTS + SOLE_GEOMS + TOE_GEOMS
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) >= 0
    ]
    ids = [model.geom(n).id for n in names if int(model.geom(n).conaffinity[0]) & FLOOR_CONTYPE]
    s = friction / np.sqrt(2.0)
    edges = np.array([[s, s, 1.0], [s, -s, 1.0], [-s, s, 1.0], [-s, -s, 1.0]]).T  # (3, 4)
    out = force.copy()
    for t, cols in _support_jacobians(model, qpos, ids, contact_height, data):
        JE = np.concatenate([JT @ edges for JT in cols], axis=1)  # (nv, 4k): each edge's force
        A = np.vstack([JE[:6], np.sqrt(SUPPORT_REGULARISATION) * np.eye(JE.shape[1])])
        b = np.concatenate([force[t, :6], np.zeros(JE.shape[1])])
        c, _ = nnls(A, b)
        out[t] = force[t] - JE @ c
    return out


def reference_feedforward(model, ref_qpos: np.ndarray, data=None):
    """(T, nv) reference velocity and (T, nv) feed-forward of ``ref_qpos`` (T, nq) at
    ``CONTROL_HZ``: :func:`inverse_dynamics` without contacts, its root force moved onto the
    feet by :func:`contact_feedforward` (root rows: residual wrench [N, N m]; hinge rows: joint
    torques [N m]). ``data``: an ``MjData`` of ``model`` to work in (overwritten)."""
    data = data if data is not None else mujoco.MjData(model)
    ref_qvel, ref_qacc = reference_derivatives(model, ref_qpos)
    force = inverse_dynamics(model, ref_qpos, ref_qvel, ref_qacc, contacts=False, data=data)
    return ref_qvel, contact_feedforward(model, ref_qpos, force, data=data)
