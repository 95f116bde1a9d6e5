"""When the simulated body has fallen: the one definition every simulation room reads.

A simulated body **has fallen** at an instant when either

* it touches the floor with a part other than its feet (sole boxes, foot and toe capsules), and
  the reference does not have that same part on the floor at that moment (within
  :data:`REFERENCE_GAP`): hands and knees in a crawl, the seat of a sitting motion are support,
  a shoulder or a back that the reference holds up is a fall. For a capsule (a limb) the part
  is the cross-section of the limb where the body touches: a shin whose ankle end the
  reference holds a few centimetres above the floor does not excuse a knee on the floor; or
* its head is below :data:`HEAD_SHARE` of the reference's head height at that moment (a body
  upside down, or folded over with its root still high, has fallen too).

Root height alone does not decide it: a body lying on its side with the pelvis propped up, or
standing on its head, has fallen whatever the root does.

On a model with terrain (``sim.simulate.terrain.add_terrain``: steps and platforms inferred from
the motion) the terrain's boxes are floor: a knee on a step is on the floor, and a reference part
is on the floor within :data:`REFERENCE_GAP` of the support under it.

Units: metres, z up, the floor at z = 0 (a reference lifted by ``sim.simulate.reference``'s
``FLOOR_LIFT`` counts its parts within :data:`REFERENCE_GAP` of that).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.model.kinematics import SOLE_POINTS
from sim.simulate.model import SOLE_GEOMS, TOE_GEOMS
from sim.simulate.terrain import surface_height, terrain_geoms

#: geoms that may always touch the floor: the feet (capsules, sole and toe boxes)
FOOT_GEOMS = SOLE_POINTS + SOLE_GEOMS + TOE_GEOMS
#: [m] a reference part whose lowest surface point is at most this high is on the floor (a hand
#: planted on the floor in motion capture hovers 1-3 cm: marker offsets, floor drift)
REFERENCE_GAP = 0.05
#: the head below this share of the reference's head height is down
HEAD_SHARE = 0.5
HEAD_GEOM = "head"


def geom_bottoms(model, data) -> np.ndarray:
    """(ngeom,) the lowest surface point [m] of every geom of ``data`` (kinematics done): a
    capsule's lower end sphere, a box's lowest corner, a sphere's bottom; the floor plane gets
    +inf."""
    out = np.full(model.ngeom, np.inf)
    for g in range(model.ngeom):
        t, c, R = model.geom_type[g], data.geom_xpos[g, 2], data.geom_xmat[g, 6:9]
        size = model.geom_size[g]
        if t == mujoco.mjtGeom.mjGEOM_CAPSULE:
            out[g] = c - size[1] * abs(R[2]) - size[0]
        elif t == mujoco.mjtGeom.mjGEOM_BOX:
            out[g] = c - np.abs(R) @ size
        elif t == mujoco.mjtGeom.mjGEOM_SPHERE:
            out[g] = c - size[0]
        elif t == mujoco.mjtGeom.mjGEOM_CYLINDER:
            out[g] = c - size[1] * abs(R[2]) - size[0] * np.sqrt(max(0.0, 1 - R[2] ** 2))
    return out


@dataclass(frozen=True)
class FallReference:
    """What a fall is judged against, per control tick of a reference (T ticks).

    Attributes:
        head_z: (T,) height [m] of the reference's head (centre of its head geom).
        on_floor: (T, ngeom) the reference's geom is on the floor (:data:`REFERENCE_GAP`); the
            feet are always allowed.
        floor, head: the floor's and the head's geom ids (looked up once: a fall is looked for
            every control tick of every rollout).
        centre_z, axis_z: (T, ngeom) height [m] of each geom's centre and the vertical
            component of its local z axis (a capsule's axis) in the reference; None: a
            capsule's part is not told from the whole capsule.
        limbs: (ngeom,) the geom is a capsule that is not a foot (its part is looked at).
        floors: the ids of the floor and of the terrain's boxes (empty: ``floor`` alone).
        tops: (ngeom,) [m] the top of each of ``floors`` (0 for the floor; None: all 0).
    """

    head_z: np.ndarray
    on_floor: np.ndarray
    floor: int = -1
    head: int = -1
    centre_z: np.ndarray | None = None
    axis_z: np.ndarray | None = None
    limbs: np.ndarray | None = None
    floors: tuple = ()
    tops: np.ndarray | None = None


def fall_reference(model, ref_qpos: np.ndarray) -> FallReference:
    """The :class:`FallReference` of ``ref_qpos`` (T, nq) on ``model`` (a ``sim_model``)."""
    data = mujoco.MjData(model)
    head = model.geom(HEAD_GEOM).id
    allowed = _foot_mask(model)
    head_z = np.empty(len(ref_qpos))
    on_floor = np.empty((len(ref_qpos), model.ngeom), bool)
    centre_z = np.empty((len(ref_qpos), model.ngeom))
    axis_z = np.empty((len(ref_qpos), model.ngeom))
    terrain = terrain_geoms(model)
    for t, q in enumerate(ref_qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        head_z[t] = data.geom_xpos[head, 2]
        bottoms = geom_bottoms(model, data)
        if terrain is not None:  # above the support under each geom's centre
            bottoms = bottoms - surface_height(terrain, data.geom_xpos[:, :2])
        on_floor[t] = (bottoms <= REFERENCE_GAP) | allowed
        centre_z[t] = data.geom_xpos[:, 2]
        axis_z[t] = data.geom_xmat[:, 8]
    floor = model.geom("floor").id
    limbs = (model.geom_type == mujoco.mjtGeom.mjGEOM_CAPSULE) & ~allowed
    tops = np.zeros(model.ngeom)
    floors = (floor,)
    if terrain is not None:
        floors += tuple(int(g) for g in terrain[0])
        tops[terrain[0]] = terrain[1]
    return FallReference(head_z=head_z, on_floor=on_floor, floor=floor, head=head,
                         centre_z=centre_z, axis_z=axis_z, limbs=limbs, floors=floors,
                         tops=tops)  # fmt: skip


def section_bottom(model, data, ref: FallReference, k: int, g: int, point) -> float:
    """[m] the lowest surface point of capsule ``g``'s cross-section through ``point`` (3,)
    [m, world, e.g. a contact's position on ``data``'s body] in the reference at tick ``k``:
    the point's place along the capsule's axis (``data``'s pose, clipped to the axis
    segment) carried to the reference's capsule, less the radius."""
    axis = data.geom_xmat[g, 2::3]  # the capsule's local z axis, world frame
    d = point - data.geom_xpos[g]
    half = model.geom_size[g, 1]
    a = min(half, max(-half, d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]))
    return ref.centre_z[k, g] + a * ref.axis_z[k, g] - model.geom_size[g, 0]


def _foot_mask(model) -> np.ndarray:
    mask = np.zeros(model.ngeom, bool)
    for n in FOOT_GEOMS:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n)
        if g >= 0:
            mask[g] = True
    return mask


def fall_cause(model, data, ref: FallReference, k: int) -> str | None:
    """Why ``data``'s body has fallen at reference tick ``k``, None if it has not:
    ``"contact:<geom>"`` (a part the reference does not have on the floor touches it, among
    ``data``'s contacts of its last step) or ``"head"`` (head below :data:`HEAD_SHARE` of the
    reference's head height; ``data``'s kinematics must be current)."""
    floors = ref.floors or ((ref.floor if ref.floor >= 0 else model.geom("floor").id),)
    allowed = ref.on_floor[k]
    n = data.ncon
    if n:  # a loop over Python ints: a handful of contacts costs less than numpy's calls
        for i, (g1, g2) in enumerate(data.contact.geom[:n].tolist()):
            if g1 in floors or g2 in floors:
                f, g = (g1, g2) if g1 in floors else (g2, g1)
                top = 0.0 if ref.tops is None else ref.tops[f]  # the step's top, the floor's 0
                if not allowed[g] or (
                    ref.limbs is not None and ref.limbs[g]
                    and section_bottom(model, data, ref, k, g, data.contact.pos[i])
                    > REFERENCE_GAP + top
                ):  # fmt: skip
                    return f"contact:{model.geom(g).name}"
    head = ref.head if ref.head >= 0 else model.geom(HEAD_GEOM).id
    if data.geom_xpos[head, 2] < HEAD_SHARE * ref.head_z[k]:
        return "head"
    return None


def has_fallen(model, data, ref: FallReference, k: int) -> bool:
    """Whether ``data``'s body has fallen at reference tick ``k`` (:func:`fall_cause`)."""
    return fall_cause(model, data, ref, k) is not None


def first_fall(model, qpos: np.ndarray, ref_qpos: np.ndarray) -> int:
    """The first frame of a recorded motion ``qpos`` (F, nq) that has fallen against the
    reference ``ref_qpos`` (F, nq, same frames), -1 if none. Contacts are MuJoCo's collision
    detection at each frame's pose (``mj_forward``)."""
    ref = fall_reference(model, ref_qpos)
    data = mujoco.MjData(model)
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        if has_fallen(model, data, ref, t):
            return t
    return -1
