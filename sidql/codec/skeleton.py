"""The source skeleton of a stream: its hash, and its AMC angles fitted to decoded points.

Decoded points carry bone *directions* only (the chart has no twist about a bone), so the fit
writes, for every protocol bone with three dofs, the smallest rotation (no twist) taking the
bone's rest direction to the decoded one, decomposed into the bone's Euler order; bones with one
or two dofs get the least-squares angles (coordinate descent over their axes, closed form per
axis); bones outside the protocol (hands, fingers, thumbs, toes) and bones without dofs stay at
rest. The root's orientation is the rotation (Kabsch) that best takes the rest directions of the
root's dof-less children (CMU: the hip joints) to the decoded ones, or of all its protocol
children when fewer than two have no dofs.

Acclaim's rule: ``G_bone = G_parent C M C^T``, bone end =
parent end ``+ length * G_bone direction``, in the file's axes (y up).
"""

from __future__ import annotations

import hashlib

import numpy as np

from sim.acclaim.records import Motion, Skeleton
from sim.errors import MotionDataError
from sim.model.humanoid import bone_frames
from sim.model.rotations import Y_UP_TO_Z_UP, axis_rotation, euler_angles_deg


def skeleton_hash(skeleton: Skeleton) -> bytes:
    """8 bytes: SHA-256 of the skeleton's canonical text (bone names, parents, directions,
    lengths [m], axes, dofs, root order and orientation, rounded), so formatting does not count."""
    lines = [
        " ".join(skeleton.root_order),
        skeleton.root_axis_order,
        " ".join(f"{v:.4f}" for v in skeleton.root_orientation),
    ]
    for b in skeleton.bones:
        lines.append(
            f"{b.name} {b.parent} {' '.join(f'{v:.6f}' for v in b.direction)} {b.length:.6f} "
            f"{' '.join(f'{v:.4f}' for v in b.axis)} {b.axis_order} {' '.join(b.dofs)}"
        )
    return hashlib.sha256("\n".join(lines).encode()).digest()[:8]


def _swing(a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(T, 3, 3) smallest rotations taking unit vectors a (3,) to unit vectors t (T, 3)."""
    a = np.broadcast_to(a, t.shape)
    v = np.cross(a, t)
    c = np.sum(a * t, axis=-1)
    K = np.zeros(t.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    f = 1.0 / np.maximum(1.0 + c, 1e-9)
    return np.eye(3) + K + (K @ K) * f[..., None, None]


def _axis_angle(e: np.ndarray, p: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(T,) angle [rad] of the rotation about unit axis e that best takes p (T, 3) to r (T, 3)."""
    p_perp = p - np.sum(p * e, axis=-1, keepdims=True) * e
    r_perp = r - np.sum(r * e, axis=-1, keepdims=True) * e
    return np.arctan2(np.sum(np.cross(p_perp, r_perp) * e, axis=-1), np.sum(p_perp * r_perp, -1))


def _fit_dofs(a: np.ndarray, t: np.ndarray, order: str, sweeps: int = 12) -> np.ndarray:
    """(T, n) angles [rad] about ``order``'s axes (first applied first) taking a (3,) near t."""
    T = t.shape[0]
    n = len(order)
    ang = np.zeros((T, n))
    eye = np.eye(3)
    for _ in range(sweeps if n > 1 else 1):
        for q in range(n):
            B = np.broadcast_to(eye, (T, 3, 3)).copy()
            for m in range(q):
                B = axis_rotation(order[m], ang[:, m]) @ B
            A = np.broadcast_to(eye, (T, 3, 3)).copy()
            for m in range(q + 1, n):
                A = axis_rotation(order[m], ang[:, m]) @ A
            p = B @ a
            r = np.einsum("tji,tj->ti", A, t)  # A^T t
            ang[:, q] = _axis_angle(eye["XYZ".index(order[q])], p, r)
    return ang


def _kabsch(d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations R minimising sum_c |R d_c - u_c|^2; d (K, 3), u (T, K, 3)."""
    H = np.einsum("kd,tke->tde", d, u)
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    det = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    S = np.broadcast_to(np.eye(3), H.shape).copy()
    S[:, 2, 2] = det
    return V @ S @ np.swapaxes(U, -1, -2)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _rot_about(a: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations by psi (T,) [rad] about the unit axis a (3,)."""
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    c, s = np.cos(psi)[:, None, None], np.sin(psi)[:, None, None]
    return c * np.eye(3) + s * K + (1.0 - c) * np.outer(a, a)


class _Fit:
    """The per-bone fit of :func:`fit_motion` (state: targets, frames, children)."""

    def __init__(self, skeleton: Skeleton, u: dict, T: int):
        self.u, self.T = u, T
        self.C = bone_frames(skeleton)
        self.children: dict[str, list] = {}
        for b in skeleton.bones:
            self.children.setdefault(b.parent, []).append(b)

    @staticmethod
    def full(b) -> bool:
        return len(b.dofs) == 3 and len({d for d in b.dofs}) == 3

    def local(self, b, Gp: np.ndarray, psi: np.ndarray | None = None, sweeps: int = 12):
        """(angles [deg] (T, n) or None, M (T, 3, 3)) of bone b under parent rotation Gp."""
        T = self.T
        if not b.dofs:
            return None, np.broadcast_to(np.eye(3), (T, 3, 3))
        order = "".join(dof[1].upper() for dof in b.dofs)
        if b.name not in self.u:
            return np.zeros((T, len(order))), np.broadcast_to(np.eye(3), (T, 3, 3))
        Cb = self.C[b.name]
        a = Cb.T @ b.direction
        t = np.einsum("ji,tkj,tk->ti", Cb, Gp, self.u[b.name])  # C^T G_parent^T u
        if self.full(b):
            M = _swing(a, t)
            if psi is not None:
                M = M @ _rot_about(a, psi)
            return euler_angles_deg(M, order), M
        ang = _fit_dofs(a, t, order, sweeps)
        M = np.broadcast_to(np.eye(3), (T, 3, 3)).copy()
        for m, ax in enumerate(order):
            M = axis_rotation(ax, ang[:, m]) @ M
        return np.degrees(ang), M

    def global_rot(self, b, Gp, M):
        Cb = self.C[b.name]
        return Gp @ Cb @ M @ Cb.T

    def limited_residual(self, b, Gp) -> np.ndarray:
        """(T,) squared direction error of b and its limited-dof descendants (stopping at
        three-dof bones, which absorb any parent rotation) under parent rotation Gp."""
        if self.full(b):
            return np.zeros(self.T)
        _, M = self.local(b, Gp, sweeps=3)
        G = self.global_rot(b, Gp, M)
        res = np.zeros(self.T)
        if b.name in self.u:
            res += np.sum((G @ b.direction - self.u[b.name]) ** 2, axis=-1)
        for c in self.children.get(b.name, []):
            res += self.limited_residual(c, G)
        return res

    def twist(self, b, Gp) -> np.ndarray | None:
        """(T,) twist [rad] of a three-dof bone that best serves its limited-dof children."""
        kids = [c for c in self.children.get(b.name, []) if not self.full(c)]
        if not kids or b.name not in self.u:
            return None
        best = np.zeros(self.T)
        best_res = np.full(self.T, np.inf)
        centre, width, steps = np.zeros(self.T), np.pi, 36
        for _ in range(3):
            for psi0 in np.linspace(-width, width, steps, endpoint=width < np.pi):
                psi = centre + psi0
                _, M = self.local(b, Gp, psi)
                G = self.global_rot(b, Gp, M)
                res = sum(self.limited_residual(c, G) for c in kids)
                better = res < best_res
                best = np.where(better, psi, best)
                best_res = np.where(better, res, best_res)
            centre, width, steps = best.copy(), 2.0 * width / steps, 9
        return best

    def fit(self, b, Gp, angles: dict) -> None:
        psi = self.twist(b, Gp) if self.full(b) else None
        ang, M = self.local(b, Gp, psi)
        if ang is not None:
            angles[b.name] = ang
        G = self.global_rot(b, Gp, M)
        for c in self.children.get(b.name, []):
            self.fit(c, G, angles)


def fit_motion(skeleton: Skeleton, positions: np.ndarray, names) -> Motion:
    """AMC angles of ``skeleton`` that put its bones along decoded points (module docstring).

    Args:
        skeleton: the source ASF skeleton.
        positions: (T, J, 3) decoded point positions [m], world axes (z up); point ``"root"``
            and bone ends named by ``names`` (a subset of the skeleton's bones).

    Returns:
        A :class:`Motion` (root translation [m], rotations [deg]).

    Raises:
        MotionDataError: a point is not a bone of the skeleton, or its parent point differs.
    """
    names = tuple(names)
    P = np.asarray(positions, dtype=np.float64) @ Y_UP_TO_Z_UP  # world z up -> file axes y up
    T = P.shape[0]
    poses, inverse = np.unique(P.reshape(T, -1), axis=0, return_inverse=True)
    if 0 < len(poses) < T:  # each distinct pose fitted once (32,768 still frames: one fit)
        m = _fit_poses(skeleton, poses.reshape(len(poses), *P.shape[1:]), names)
        inverse = inverse.reshape(-1)
        return Motion(path="", root=m.root[inverse], first_frame=1,
                      angles={k: v[inverse] for k, v in m.angles.items()})  # fmt: skip
    return _fit_poses(skeleton, P, names)


def _fit_poses(skeleton: Skeleton, P: np.ndarray, names: tuple) -> Motion:
    """:func:`fit_motion` of (T, J, 3) points ``P`` in the file's axes (y up)."""
    T = P.shape[0]
    index = {n: i for i, n in enumerate(names)}
    bones = {b.name: b for b in skeleton.bones}
    if "root" not in index:
        raise MotionDataError(skeleton.path or None, None, "decoded points lack the root")
    for n in names[1:]:
        if n not in bones:
            raise MotionDataError(skeleton.path or None, None, f"skeleton lacks bone {n!r}")
        if bones[n].parent not in index:
            raise MotionDataError(
                skeleton.path or None, None, f"parent {bones[n].parent!r} of {n!r} not decoded"
            )
    u = {n: _unit(P[:, index[n]] - P[:, index[bones[n].parent]]) for n in names if n != "root"}
    fit = _Fit(skeleton, u, T)
    kids = fit.children.get("root", [])
    fixed = [b for b in kids if not b.dofs and b.name in u]
    use = fixed if len(fixed) >= 2 else [b for b in kids if b.name in u]
    if len(use) < 2:
        raise MotionDataError(skeleton.path or None, None, "cannot orient the root")
    d = np.stack([b.direction for b in use])
    G_root = _kabsch(d, np.stack([u[b.name] for b in use], axis=1))
    Co = fit.C["root"]
    root_rot = euler_angles_deg(Co.T @ G_root @ Co, skeleton.root_axis_order)
    angles: dict = {}
    for b in kids:
        fit.fit(b, G_root, angles)
    root = np.concatenate([P[:, 0], root_rot], axis=1)
    return Motion(path="", root=root, angles=angles, first_frame=1)
