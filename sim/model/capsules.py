"""MJCF scenes of bone-aligned capsules on mocap bodies, for any point set.

A point set is ``names`` (P,) and ``parents`` (P,) (``-1`` for the root), as in :class:`sim.motion.clip.Clip`:
point ``j`` is the end of bone ``j``, which runs from point ``parents[j]`` to point ``j``. Every bone
becomes one mocap body carrying one capsule whose axis is the body's local z axis; a frame of motion
places each body at its bone's midpoint, turns its z axis along the bone and sets the capsule's
half-length to half the bone's current length (see :func:`bone_poses`). Nothing here simulates
dynamics: MuJoCo only does kinematics, collision detection and rendering.

Units: metres, world z up, quaternions ``wxyz``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.errors import UsageError
from sim.model.humanoid import capsule_radius

FLOOR = "floor"
_MIN_HALF = 1e-4  # [m] MuJoCo wants a positive half-length; a zero-length bone becomes a sphere
# Radii [m] that differ from the humanoid's (sim.model.humanoid.capsule_radius) because here a capsule spans
# its whole bone: the head's would reach into the thorax across the short neck, and the feet's must
# let the foot points (toe bases, a centimetre or two above the ground in stance) stand on the floor.
RADIUS_OVERRIDES = {"head": 0.07, "lfoot": 0.025, "rfoot": 0.025, "ltoes": 0.02, "rtoes": 0.02}


@dataclass(frozen=True)
class Bones:
    """The bones of a point set.

    Attributes:
        names: (P,) point names.
        parents: (P,) parent point index, -1 for the root.
        child: (B,) index of the point at the end of each bone (every non-root point).
        parent: (B,) index of the point at its start.
        radius: (B,) capsule radius [m].
    """

    names: tuple[str, ...]
    parents: np.ndarray
    child: np.ndarray
    parent: np.ndarray
    radius: np.ndarray

    @property
    def bone_names(self) -> tuple[str, ...]:
        return tuple(self.names[j] for j in self.child)


def bones_of(names, parents, lengths=None) -> Bones:
    """Bones of the point set ``names`` (P,), ``parents`` (P,); ``lengths`` (P,) [m] sizes unknown
    bones' radii (default 0.3 m)."""
    names = tuple(str(n) for n in names)
    parents = np.asarray(parents, dtype=np.int64)
    if parents.shape != (len(names),):
        raise UsageError(f"parents must have {len(names)} entries; got shape {parents.shape}")
    if len(set(names)) != len(names):
        raise UsageError(f"point names must be unique; got {names}")
    child = np.flatnonzero(parents >= 0)
    if np.any(parents[child] >= len(names)):
        raise UsageError(f"parent index out of range in {parents.tolist()}")
    L = np.full(len(names), 0.3) if lengths is None else np.asarray(lengths, dtype=np.float64)
    radius = np.array(
        [RADIUS_OVERRIDES.get(names[j], capsule_radius(names[j], float(L[j]))) for j in child]
    )
    return Bones(names, parents, child, parents[child], radius)


def adjacent_pairs(bones: Bones, hops: int = 1) -> set[tuple[int, int]]:
    """Pairs ``(a, b)``, ``a < b``, of bone indices within ``hops`` shared points of each other.

    ``hops=1``: bones that share a point (parent and child bone, siblings from the same joint);
    ``hops=2`` also excludes bones joined through one intermediate bone.
    """
    B = len(bones.child)
    # bone graph: bones are neighbours when they share an end point
    ends = [{int(bones.parent[b]), int(bones.child[b])} for b in range(B)]
    near = np.array([[bool(ends[a] & ends[b]) for b in range(B)] for a in range(B)])
    reach = near.copy()
    for _ in range(hops - 1):
        reach = reach | ((reach.astype(int) @ near.astype(int)) > 0)
    return {(a, b) for a in range(B) for b in range(a + 1, B) if reach[a, b]}


def _rgba(c) -> str:
    return " ".join(f"{x:.3g}" for x in c)


def _box_geoms(boxes, rgba) -> list[str]:
    """MJCF lines of static world boxes ``(centre, half sizes, yaw)`` (:func:`scene_xml`)."""
    return [
        f'    <geom name="scene{k}" type="box" pos="{_vec(centre)}" size="{_vec(half)}" '
        f'quat="{_vec(_yaw_quat(yaw))}" rgba="{_rgba(rgba)}" contype="0" conaffinity="0"/>'
        for k, (centre, half, yaw) in enumerate(boxes)
    ]


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    """``wxyz`` of a turn by ``yaw`` [rad] about z (MJCF's euler would read degrees)."""
    return (float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2)))


def _vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def scene_xml(
    bones: Bones,
    *,
    skeletons: tuple[tuple[str, tuple[float, float, float, float]], ...] = (
        ("", (0.8, 0.6, 0.4, 1)),
    ),
    collision_pairs: set[tuple[int, int]] | None = None,
    floor_z: float = 0.0,
    floor_margin: float = 0.0,
    visual: bool = False,
    quality: tuple[int, int, int, int] = (0, 16, 8, 0),
    boxes=(),
    box_rgba: tuple[float, float, float, float] = (0.7, 0.6, 0.47, 1.0),
) -> str:
    """MJCF text of ``len(skeletons)`` copies of ``bones`` as mocap capsules plus a floor.

    Args:
        bones: the point set's bones.
        skeletons: ``(prefix, rgba)`` per copy; body and geom names are ``prefix + bone name``.
            Mocap ids run copy by copy, bone by bone.
        collision_pairs: bone index pairs to test for self-penetration (only with one skeleton);
            ``None`` tests none. Every bone is also paired with the floor. Without pairs no collision
            is detected at all (rendering scenes).
        floor_z: floor height [m].
        floor_margin: contact margin [m] of bone/floor pairs: contacts closer than this are reported.
        visual: add a checker floor texture, a headlight and a light for rendering.
        quality: ``(offsamples, numslices, numstacks, shadowsize)`` of MuJoCo's ``<quality>``:
            multisampling, capsule tessellation and shadow-map size (MuJoCo's defaults: 4, 28, 16,
            4096; ours are cheap for software rendering).
        boxes: static world boxes ``(centre (3,), half sizes (3,), yaw [rad] about z)`` named
            ``scene<k>``, in ``box_rgba``, never collided with (a clip's steps, drawn); none: the
            text is as without the argument.
    """
    ms, slices, stacks, shadow = quality
    w: list[str] = ['<mujoco model="capsules">', '  <option gravity="0 0 0"/>']
    w.append(
        '  <visual><global offwidth="1920" offheight="1080"/>'
        f'<quality shadowsize="{shadow}" offsamples="{ms}" numslices="{slices}" numstacks="{stacks}"/>'
        '<headlight ambient="0.45 0.45 0.45" diffuse="0.5 0.5 0.5" specular="0.1 0.1 0.1"/></visual>'
    )
    if visual:
        w.append(
            '  <asset><texture name="grid" type="2d" builtin="checker" width="512" height="512" '
            'rgb1="0.82 0.84 0.86" rgb2="0.70 0.72 0.75" mark="edge" markrgb="0.5 0.5 0.55"/>'
            '<material name="grid" texture="grid" texrepeat="1 1" texuniform="true" '
            'reflectance="0"/></asset>'
        )
    w.append("  <worldbody>")
    mat = ' material="grid"' if visual else ' rgba="0.8 0.8 0.8 1"'
    w.append(
        f'    <geom name="{FLOOR}" type="plane" pos="0 0 {floor_z:.9g}" size="0 0 1"{mat} '
        'contype="0" conaffinity="0"/>'
    )
    w += _box_geoms(boxes, box_rgba)
    if visual:
        w.append('    <light directional="true" pos="0 0 5" dir="0.3 0.2 -1" castshadow="false"/>')
    for prefix, rgba in skeletons:
        for b, j in enumerate(bones.child):
            n = prefix + bones.names[j]
            w.append(
                f'    <body name="{n}" mocap="true"><geom name="{n}" type="capsule" '
                f'size="{bones.radius[b]:.6g} 0.1" rgba="{_rgba(rgba)}" contype="0" '
                'conaffinity="0" group="1"/></body>'
            )
    w.append("  </worldbody>")
    if collision_pairs is not None:
        if len(skeletons) != 1:
            raise UsageError("collision pairs need exactly one skeleton")
        prefix = skeletons[0][0]
        gname = [prefix + bones.names[j] for j in bones.child]
        w.append("  <contact>")
        for g in gname:
            w.append(f'    <pair geom1="{FLOOR}" geom2="{g}" margin="{floor_margin:.9g}"/>')
        for a, b in sorted(collision_pairs):
            w.append(f'    <pair geom1="{gname[a]}" geom2="{gname[b]}"/>')
        w.append("  </contact>")
    w.append("</mujoco>")
    return "\n".join(w)


def bone_poses(bones: Bones, positions: np.ndarray):
    """Mocap poses placing the capsules on a frame of points.

    Args:
        positions: (..., P, 3) point positions [m].
    Returns:
        centre (..., B, 3) bone midpoints [m], quat (..., B, 4) ``wxyz`` turning +z onto each bone's
        direction (identity for a zero-length bone), half (..., B) half-lengths [m].
    """
    p = np.asarray(positions, dtype=np.float64)
    a, c = p[..., bones.parent, :], p[..., bones.child, :]
    v = c - a
    length = np.linalg.norm(v, axis=-1)
    u = v / np.where(length > 1e-12, length, 1.0)[..., None]
    u = np.where((length > 1e-12)[..., None], u, np.array([0.0, 0.0, 1.0]))
    # shortest-arc rotation z -> u: q = (1 + z.u, z x u) normalised; z x u = (-u_y, u_x, 0)
    w = 1.0 + u[..., 2]
    q = np.stack([w, -u[..., 1], u[..., 0], np.zeros_like(w)], axis=-1)
    flip = w < 1e-9  # u = -z: half-turn about x
    q = np.where(flip[..., None], np.array([0.0, 1.0, 0.0, 0.0]), q)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return 0.5 * (a + c), q, np.maximum(0.5 * length, _MIN_HALF)
