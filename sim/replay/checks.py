"""Kinematic replay of a motion (original or reconstruction) in MuJoCo, and what a person would see.

Each frame's points are mapped onto bone-aligned capsules on mocap bodies
(:mod:`sim.model.capsules`); MuJoCo's collision detection then measures floor penetration and
self-penetration between non-adjacent bones (touching bones). Foot-floor contact is read from
:mod:`sim.physics.contacts` (the sole's geometry against the trial's floor, rolling contact
allowed), as everywhere else. Together with bone-length drift,
foot skating, joint-limit violations (where the motion carries joint angles), MPJPE and velocity
error against the original, these are the per-frame :class:`FrameChecks`; :func:`summarise`
condenses them per clip and :func:`excess` subtracts the original clip's own figures (the
baseline).

Why capsules on mocap bodies rather than inverse kinematics onto the humanoid: the checks must judge
the reconstruction's points themselves. IK would first move the points (to satisfy the humanoid's
fixed bone lengths and hinge axes) and then measure the IK's result, hiding exactly the defects
(stretched bones, feet through the floor) the checks exist to find. Capsules placed bone by bone
reproduce every point exactly, for any point set (23 protocol points, 31 CMU points, synthetic).

Units: metres, seconds, radians; world z up; the capsules' floor is the plane z = ``floor_z``.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim import mujoco_log  # noqa: F401  # MuJoCo's warnings on stderr, not in a file
from sim.errors import UsageError, require_type
from sim.model.capsules import Bones, adjacent_pairs, bone_poses, bones_of, scene_xml
from sim.model.kinematics import SIDES
from sim.motion.clip import Clip
from sim.motion.points import PointMotion, finite_velocity  # noqa: F401 (re-exported)
from sim.physics.contacts import motion_contacts
from sim.physics.ground import Ground


def from_clip(clip) -> PointMotion:
    """A :class:`sim.motion.clip.Clip` as a point motion (exact velocities and joint angles kept)."""
    require_type(clip, Clip, "clip")
    return PointMotion(
        tuple(clip.names), np.asarray(clip.parents), np.asarray(clip.positions), float(clip.fps),
        np.asarray(clip.velocities), np.asarray(clip.qpos), tuple(clip.joint_names),
    )  # fmt: skip


def from_reconstruction(rec, fps: float) -> PointMotion:
    """Any reconstruction with ``names`` (P,), ``parents`` (P,), ``positions`` (N, P, 3) [m] and
    optionally ``velocities`` (N, P, 3) [m/s] and ``qpos``/``joint_names``, at ``fps``."""
    vel = getattr(rec, "velocities", None)
    qpos = getattr(rec, "qpos", None)
    return PointMotion(
        tuple(str(n) for n in rec.names), np.asarray(rec.parents), np.asarray(rec.positions),
        float(fps), None if vel is None else np.asarray(vel),
        None if qpos is None else np.asarray(qpos),
        tuple(getattr(rec, "joint_names", ())) if qpos is not None else (),
    )  # fmt: skip


@dataclass(frozen=True)
class FrameChecks:
    """Per-frame figures of one replayed motion. Every array has T rows.

    Attributes:
        bone_drift: (T,) max over bones of |length - true length| [m].
        floor_depth: (T,) deepest penetration of any bone capsule below the floor [m] (0 if none).
        floor_bones: (T,) number of bone capsules below the floor.
        self_count: (T,) number of penetrating pairs of non-adjacent bone capsules.
        self_depth: (T,) deepest such penetration [m] (0 if none).
        foot_names: (F,) the feet found in the motion (``"l"``, ``"r"``: ankle and ball present).
        foot_contact: (T, F) the foot touches the floor (:mod:`sim.physics.contacts`).
        foot_speed: (T, F) horizontal speed of the foot's lowest sole point [m/s].
        skate_speed: (T,) max horizontal speed of a foot in contact [m/s] (0 if none in contact).
        mpjpe: (T,) mean point position error against the reference [m].
        velocity_error: (T,) mean |v - v_ref| over points [m/s].
        joint_limit: (T,) max violation of a hinge range [rad] (NaN: no joint angles).
        joint_limit_count: (T,) hinges out of range (-1: no joint angles).
        self_pairs: (T,) per frame ``{(bone_a, bone_b): depth [m]}`` of the penetrating pairs, by
            bone (end point) name, ``bone_a < bone_b``: what :func:`self_penetration_excess`
            compares frame by frame.
    """

    bone_drift: np.ndarray
    floor_depth: np.ndarray
    floor_bones: np.ndarray
    self_count: np.ndarray
    self_depth: np.ndarray
    foot_names: tuple[str, ...]
    foot_contact: np.ndarray
    foot_speed: np.ndarray
    skate_speed: np.ndarray
    mpjpe: np.ndarray
    velocity_error: np.ndarray
    joint_limit: np.ndarray
    joint_limit_count: np.ndarray
    self_pairs: tuple = ()


class CollisionScene:
    """Owns the MuJoCo model and data of one capsule skeleton plus floor; measures frames.

    The MuJoCo state of the replay job: build one per clip (:meth:`for_reference`) and pass it to
    every :func:`replay` of that clip's motions on the same points.

    Args:
        bones: the point set's bones.
        floor_z: floor height [m].
        contact_height: MuJoCo's floor margin [m]: bones nearer the floor than this are measured.
        hops: bones this close in the tree are adjacent and never tested: 1 = bones sharing a
            point (parent/child, siblings from one joint); 2 (default) also bones joined through one
            bone, because the short, thick capsules of the spine and neck overlap at rest.
    """

    def __init__(self, bones: Bones, *, floor_z=0.0, contact_height=0.02, hops: int = 2):
        self.bones = bones
        self.settings = (float(floor_z), float(contact_height), int(hops))
        pairs = {(a, b) for a in range(len(bones.child)) for b in range(a + 1, len(bones.child))}
        self.pairs = sorted(pairs - adjacent_pairs(bones, hops))
        xml = scene_xml(
            bones, collision_pairs=set(self.pairs), floor_z=floor_z, floor_margin=contact_height
        )
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
        B = len(bones.child)
        self._geom = np.arange(1, B + 1)  # geom 0 is the floor; then one capsule per bone
        self._bone_of_geom = np.full(self.model.ngeom, -1)
        self._bone_of_geom[self._geom] = np.arange(B)

    def move_floor(self, floor_z: float) -> None:
        """Put the floor plane at height ``floor_z`` [m] (one scene serves every ground)."""
        self.model.geom_pos[0, 2] = floor_z  # geom 0 is the floor plane
        self.settings = (float(floor_z), *self.settings[1:])

    @classmethod
    def for_reference(
        cls, reference: PointMotion, *, floor_z=0.0, contact_height=0.02, hops: int = 2
    ) -> CollisionScene:
        """The scene of ``reference``'s points with its mean bone lengths (what :func:`replay`
        builds for a motion on those points checked against ``reference``)."""
        bones = bones_of(reference.names, reference.parents, _lengths(reference))
        return cls(bones, floor_z=floor_z, contact_height=contact_height, hops=hops)

    def measure(self, positions: np.ndarray):
        """Collisions of one frame.

        Args:
            positions: (P, 3) point positions [m].
        Returns:
            floor_gap (B,) signed distance of each bone capsule to the floor [m] (``inf`` beyond the
            contact margin; negative = below the floor) and self_pen, a list of
            ``(bone_a, bone_b, depth [m])`` for penetrating non-adjacent pairs (depth > 0).
        """
        m, d = self.model, self.data
        centre, quat, half = bone_poses(self.bones, positions)
        d.mocap_pos[:] = centre
        d.mocap_quat[:] = quat
        m.geom_size[self._geom, 1] = half
        m.geom_rbound[self._geom] = half + self.bones.radius
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        floor_gap = np.full(len(self.bones.child), np.inf)
        deepest: dict[tuple[int, int], float] = {}
        if d.ncon:
            geoms = np.array(d.contact.geom).reshape(-1, 2)
            dist = np.array(d.contact.dist).reshape(-1)
            for (g1, g2), dd in zip(geoms.tolist(), dist.tolist(), strict=True):
                if g1 == 0 or g2 == 0:
                    b = int(self._bone_of_geom[g1 + g2])
                    floor_gap[b] = min(floor_gap[b], dd)
                elif dd < 0:
                    key = tuple(sorted((int(self._bone_of_geom[g1]), int(self._bone_of_geom[g2]))))
                    deepest[key] = max(deepest.get(key, 0.0), -dd)
        return floor_gap, [(a, b, dd) for (a, b), dd in sorted(deepest.items())]


def joint_limit_violation(qpos: np.ndarray, joint_names, ranges: dict[str, tuple[float, float]]):
    """Per-frame hinge-range violations.

    Args:
        qpos: (T, 7 + H) free root then H hinge angles [rad].
        joint_names: (H,) hinge names.
        ranges: hinge name -> (lo, hi) [rad]; hinges without an entry are unlimited.
    Returns:
        worst (T,) max over hinges of the distance outside its range [rad], count (T,) hinges out of
        range.
    """
    q = np.asarray(qpos)[:, 7:]
    lo = np.array([ranges.get(n, (-np.inf, np.inf))[0] for n in joint_names])
    hi = np.array([ranges.get(n, (-np.inf, np.inf))[1] for n in joint_names])
    out = np.maximum(lo - q, 0.0) + np.maximum(q - hi, 0.0)
    if out.shape[1] == 0:
        return np.zeros(len(q)), np.zeros(len(q), dtype=int)
    return out.max(axis=1), (out > 1e-9).sum(axis=1)


def replay(
    motion: PointMotion,
    reference: PointMotion | None = None,
    *,
    floor_z: float = 0.0,
    contact_height: float = 0.02,
    hops: int = 2,
    joint_ranges: dict[str, tuple[float, float]] | None = None,
    scene: CollisionScene | None = None,
    ground: Ground | None = None,
) -> FrameChecks:
    """Replay ``motion`` frame by frame and measure it.

    Args:
        motion: the motion to check, (T, P, 3) points.
        reference: the original on a superset of ``motion``'s points (restricted to them here), T
            frames: true bone lengths, MPJPE and velocity error come from it. Default: ``motion``.
        floor_z, contact_height, hops: see :class:`CollisionScene`.
        joint_ranges: hinge name -> (lo, hi) [rad], used when ``motion`` has ``qpos``.
        scene: the clip's :class:`CollisionScene` (:meth:`CollisionScene.for_reference` of the
            restricted reference), reused across calls; built here when None. ValueError when it
            was built for other bones or other floor settings.
        ground: the trial's floor for the foot contacts (:mod:`sim.physics.contacts`); default a
            horizontal floor at ``floor_z``.
    """
    ref = motion if reference is None else reference.restrict(motion.names)
    if ref.n_frames != motion.n_frames:
        raise UsageError(f"reference has {ref.n_frames} frames, motion {motion.n_frames}")
    if not np.array_equal(ref.parents, motion.parents):
        raise UsageError("reference and motion disagree on the tree of points")
    T = motion.n_frames
    bones = bones_of(motion.names, motion.parents, _lengths(ref))
    if scene is None:
        scene = CollisionScene(bones, floor_z=floor_z, contact_height=contact_height, hops=hops)
    elif not (
        scene.bones.names == bones.names
        and np.array_equal(scene.bones.parents, bones.parents)
        and np.array_equal(scene.bones.radius, bones.radius)
        and scene.settings == (float(floor_z), float(contact_height), int(hops))
    ):
        raise UsageError("the scene was built for other bones or floor settings than this replay")
    true_len = _lengths(ref)[bones.child]
    cur_len = np.linalg.norm(
        motion.positions[:, bones.child] - motion.positions[:, bones.parent], axis=-1
    )
    drift = np.abs(cur_len - true_len).max(axis=1) if len(bones.child) else np.zeros(T)

    floor_depth, floor_bones = np.zeros(T), np.zeros(T, dtype=int)
    self_count, self_depth = np.zeros(T, dtype=int), np.zeros(T)
    bname = bones.bone_names
    pairs = []
    for t in range(T):
        gap, pen = scene.measure(motion.positions[t])
        pairs.append({tuple(sorted((bname[a], bname[b]))): float(dd) for a, b, dd in pen})
        below = gap < 0
        floor_bones[t] = int(below.sum())
        floor_depth[t] = float(-gap[below].min()) if below.any() else 0.0
        self_count[t] = len(pen)
        self_depth[t] = max((p[2] for p in pen), default=0.0)

    if any(x + "tibia" in motion.names and x + "foot" in motion.names for x in SIDES):
        c = motion_contacts(
            motion.positions, motion.names, motion.fps,
            Ground(float(floor_z)) if ground is None else ground, velocities=motion.velocities,
        )  # fmt: skip
        feet, contact, speed = c.sides, c.contact, c.foot_speed
        skate = np.where(contact, speed, 0.0).max(axis=1)
    else:
        feet, contact, speed, skate = (), np.zeros((T, 0), bool), np.zeros((T, 0)), np.zeros(T)

    mpjpe = np.linalg.norm(motion.positions - ref.positions, axis=-1).mean(axis=1)
    verr = np.linalg.norm(motion.velocity() - ref.velocity(), axis=-1).mean(axis=1)
    if motion.qpos is not None and joint_ranges is not None:
        jl, jn = joint_limit_violation(motion.qpos, motion.joint_names, joint_ranges)
    else:
        jl, jn = np.full(T, np.nan), np.full(T, -1)
    return FrameChecks(
        drift, floor_depth, floor_bones, self_count, self_depth, feet, contact, speed, skate,
        mpjpe, verr, jl, jn, tuple(pairs),
    )  # fmt: skip


def self_penetration_excess(
    checks: FrameChecks, baseline: FrameChecks, *, tol: float = 1e-3
) -> dict[str, float]:
    """Self-penetration of a motion beyond the original's, pair by pair and frame by frame.

    For every frame and pair of bones, ``excess = max(0, d_rec - d_orig)`` with ``d`` the pair's
    penetration depth [m] (0 when apart): overlaps the original has too (the thick capsules of
    thorax, neck and head touch in every frame) cancel, new or deeper ones count. A pair the
    original has deeper than ``tol`` that the motion loses by more than ``tol`` (a real contact,
    e.g. hand on arm, gone) is a *lost touching pair* (``lost_contacts``: bones that touched, not a
    foot on the floor), counted separately rather than as an improvement.

    Args:
        checks, baseline: the motion's and the original's :class:`FrameChecks` (same frames, same
            point names).
    Returns:
        ``self_pen_excess_mm``: mean over frames of the largest pair excess [mm];
        ``self_pen_excess_n``: frames; ``self_pen_excess_max_mm``; ``self_pen_excess_pairs``:
        (frame, pair) samples with excess > ``tol``; ``lost_contacts``: (frame, pair) samples lost.
    """
    if len(checks.self_pairs) != len(baseline.self_pairs):
        raise UsageError("self-penetration excess needs both replays' pairs over the same frames")
    worst, n_exc, lost = [], 0, 0
    for rec, orig in zip(checks.self_pairs, baseline.self_pairs, strict=True):
        exc = [max(0.0, d - orig.get(k, 0.0)) for k, d in rec.items()]
        worst.append(max(exc, default=0.0))
        n_exc += sum(e > tol for e in exc)
        lost += sum(d > tol and d - rec.get(k, 0.0) > tol for k, d in orig.items())
    w = np.array(worst)
    return {
        "self_pen_excess_mm": 1e3 * float(w.mean()) if w.size else float("nan"),
        "self_pen_excess_n": int(w.size),
        "self_pen_excess_max_mm": 1e3 * float(w.max(initial=0.0)),
        "self_pen_excess_pairs": int(n_exc),
        "lost_contacts": int(lost),
    }


def _lengths(m: PointMotion) -> np.ndarray:
    """(P,) mean bone length [m] of each point (root 0)."""
    parent = np.where(m.parents < 0, np.arange(len(m.parents)), m.parents)
    return np.linalg.norm(m.positions - m.positions[:, parent], axis=-1).mean(axis=0)


# Figures that get worse as they grow; their excess over the original is reported.
PHYSICAL_KEYS = (
    "bone_drift_max_mm", "floor_depth_max_mm", "floor_frames", "self_pen_frames",
    "self_pen_pairs", "self_pen_depth_max_mm", "skate_mean_mm_s", "skate_max_mm_s",
    "joint_limit_max_deg", "joint_limit_frames",
)  # fmt: skip


def summarise(checks: FrameChecks, *, tol: float = 1e-3) -> dict[str, float]:
    """Per-clip figures of a :class:`FrameChecks` (plain floats, JSON-ready).

    Frames "affected" have a depth above ``tol`` [m]. ``self_pen_pairs`` sums penetrating pairs over
    frames; ``skate_*`` are over (frame, foot) samples in floor contact; ``joint_limit_*`` are NaN
    when the motion has no joint angles.
    """
    c = require_type(checks, FrameChecks, "checks")
    in_contact = c.foot_contact
    sk = c.foot_speed[in_contact]
    has_q = bool(np.all(c.joint_limit_count >= 0))
    return {
        "frames": int(len(c.mpjpe)),
        "bone_drift_max_mm": 1e3 * float(c.bone_drift.max(initial=0.0)),
        "floor_depth_max_mm": 1e3 * float(c.floor_depth.max(initial=0.0)),
        "floor_frames": int((c.floor_depth > tol).sum()),
        "self_pen_frames": int((c.self_depth > tol).sum()),
        "self_pen_pairs": int(c.self_count.sum()),
        "self_pen_depth_max_mm": 1e3 * float(c.self_depth.max(initial=0.0)),
        "contact_samples": int(in_contact.sum()),
        "skate_mean_mm_s": 1e3 * float(sk.mean()) if sk.size else 0.0,
        "skate_max_mm_s": 1e3 * float(sk.max()) if sk.size else 0.0,
        "joint_limit_max_deg": float(np.degrees(c.joint_limit.max())) if has_q else float("nan"),
        "joint_limit_frames": int((c.joint_limit_count > 0).sum()) if has_q else float("nan"),
        "mpjpe_mm": 1e3 * float(c.mpjpe.mean()),
        "mpjpe_max_mm": 1e3 * float(c.mpjpe.max(initial=0.0)),
        "velocity_error_mm_s": 1e3 * float(c.velocity_error.mean()),
    }


def excess(summary: dict[str, float], baseline: dict[str, float]) -> dict[str, float]:
    """``summary - baseline`` for every physical figure (:data:`PHYSICAL_KEYS`): how much worse a
    reconstruction is than the original clip it came from (NaN where either lacks the figure)."""
    return {k: float(summary[k]) - float(baseline[k]) for k in PHYSICAL_KEYS}
