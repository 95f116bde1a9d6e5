"""Supports under the hands: the scene inferred from the motion, where the hands hold it up.

In CMU's playground climb 01_02 the subject leans on and hangs from the equipment with its hands;
a scene of footholds (``sim.simulate.terrain``) does not give that. This module puts a static
box under a hand the way the terrain puts one under a foot: where a hand of the original motion
stands still clearly above the ground for long enough while **the feet alone cannot hold the
body**. Contact with static geometry only: a box pushes, it does not pull (no grip, no
adhesion, no force on the body but what a support gives).

Per hand (its geoms :data:`HANDS`), per frame: the lowest surface point and the geoms'
horizontal extent. A hand **stance** is ``terrain.stances`` of those (slower than
``STILL_SPEED`` for at least ``MIN_STANCE_S``), at least ``MIN_RAISE`` above the ground track.
It becomes a box only if for at least ``RELY_S`` of it the centre of mass lies
:data:`SUPPORT_MARGIN` or more outside the footprint of the soles that are on a support (the
ground or a foot's box; :func:`outside_soles`; no sole on one: anywhere): a hand held still in
the air while the feet hold the body (arms held out, a dancer's pose) gets none. No box either
where the reference's own body (any geom but the hands and wrists; the feet's sole corners)
passes below its top within its footprint: a static box may not stand where the motion's body
was (a thigh beside the hand would catch on it). Boxes are pillars down to ``BURY`` below the
floor, like the feet's (everything that reads a support under a point, ``surface_height``,
takes a box as solid down to the floor).

Units: metres, seconds; z up; boxes in the frame of the motion less its ground track.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from sim.simulate.terrain import (
    CARVE,
    CLEAR,
    DROP,
    GROUND_GAP,
    HANDS,
    MIN_RAISE,
    RELY_S,
    Box,
    box_of,
    boxes_terrain,
    feet_scene,
    merge_boxes,
    stances,
    surface_height,
)

#: geoms that may lie as low as the hand on its support (the wrist's capsule joins it)
NEXT_TO_HAND = ("lwrist", "rwrist")
#: [m] the body relies on a still hand where its centre of mass is this far or more outside the
#: footprint of the soles on a support
SUPPORT_MARGIN = 0.03


def find_handholds(
    model, qpos: np.ndarray, rate: float, carved: bool = CARVE
) -> tuple[list[Box], np.ndarray | None]:
    """``terrain.find_terrain``'s boxes and ground track with the boxes under the hands that
    hold the body up (:func:`hand_supports`) after them; where no hand box is found, exactly
    ``find_terrain``'s result."""
    boxes, track, tracks = feet_scene(model, qpos, rate, carved)
    if track is not None:
        boxes = boxes + hand_supports(model, qpos, rate, boxes, track, tracks)
    return (boxes, track) if boxes else ([], None)


def hand_tracks(model, qpos: np.ndarray) -> tuple | None:
    """Per frame of ``qpos`` (T, nq) and hand (left, right; :data:`HANDS`): the lowest surface
    point's height (T, 2) [m] and the geoms' horizontal extent (T, 2, 4K, 2) [m] (each geom's
    centre plus and minus its radius along x and y); the sample points (T, M, 3) [m] and radii
    (M,) [m] of the body's other round geoms (capsule ends and centres, spheres; not
    :data:`NEXT_TO_HAND`). None where the model has no hands."""
    find = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n)  # noqa: E731
    ids = np.array([[find(n) for n in side] for side in HANDS])  # (2 hands, K geoms)
    if ids.min() < 0:
        return None
    capsule, sphere = int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE)
    skip = set(ids.ravel().tolist()) | {find(n) for n in NEXT_TO_HAND}
    others = [g for g in range(model.ngeom) if model.geom_bodyid[g] > 0 and g not in skip
              and int(model.geom_type[g]) in (capsule, sphere)]  # fmt: skip
    radius = model.geom_size[ids, 0]
    half = model.geom_size[ids, 1] * (model.geom_type[ids] == capsule)
    ohalf = model.geom_size[others, 1] * (model.geom_type[others] == capsule)  # (G,)
    signs = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]])
    data = mujoco.MjData(model)
    T, K = len(qpos), ids.shape[1]
    low, pts = np.empty((T, 2)), np.empty((T, 2, 4 * K, 2))
    body = np.empty((T, 3, len(others), 3))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        c = data.geom_xpos[ids]  # (2, K, 3)
        axis_z = data.geom_xmat[ids][..., 8]  # a capsule's axis, its vertical component
        low[t] = (c[..., 2] - half * np.abs(axis_z) - radius).min(axis=1)
        pts[t] = (c[..., None, :2] + signs * radius[..., None, None]).reshape(2, 4 * K, 2)
        oc, axis = data.geom_xpos[others], data.geom_xmat[others][:, 2::3]  # (G, 3) each
        body[t] = oc + np.array([-1.0, 0.0, 1.0])[:, None, None] * (ohalf[:, None] * axis)
    return low, pts, body.reshape(T, -1, 3), np.tile(model.geom_size[others, 0], 3)


def outside_soles(com: np.ndarray, corners: np.ndarray, on: np.ndarray) -> np.ndarray:
    """(T,) [m] how far the centre of mass ``com`` (T, 2+) lies horizontally outside the
    footprint of the soles on a support: the convex hull of the bottom corners ``corners``
    (T, 2, 8, 2) of the soles ``on`` (T, 2) (its farthest edge line: at most the distance to
    the hull, exact where the nearest point is on an edge; negative inside); inf where no sole
    is on a support."""
    out = np.full(len(com), np.inf)
    for t in range(len(com)):
        pts = corners[t][on[t]].reshape(-1, 2)
        if len(pts):
            eq = ConvexHull(pts).equations  # rows (normal x, normal y, offset): <= 0 inside
            out[t] = float((eq[:, :2] @ com[t, :2] + eq[:, 2]).max())
    return out


def hand_supports(model, qpos, rate, boxes: list[Box], track, tracks) -> list[Box]:
    """Boxes under the hands of ``qpos`` (T, nq, at ``rate`` [Hz]) that hold the body up (the
    module's rules): a hand still at least ``MIN_RAISE`` above the ground ``track`` (T,) [m]
    while for at least ``RELY_S`` of that stance the centre of mass is :data:`SUPPORT_MARGIN`
    or more outside the footprint of the soles within ``GROUND_GAP`` of the ground or of the
    top of one of the feet's ``boxes`` under them (:func:`outside_soles`). Its top is the
    hand's lowest point (median over the stance), its footprint the hand's plus ``MARGIN``, yaw
    0; none where the motion's body passed below its top within it (sole corners more than
    ``DROP``, other geoms more than ``CLEAR`` below); merged (``merge_boxes``: one hand's
    stances a few centimetres apart at one place). ``tracks``: ``foot_tracks`` of ``qpos``."""
    hands = hand_tracks(model, qpos)
    if hands is None:
        return []
    hlow, hpts, body, radii = hands
    low, corners, _, com, heights = tracks
    up = low - track[:, None]  # (T, 2) above the ground, on it, or on a step under the sole
    under = surface_height(boxes_terrain(boxes), corners.mean(axis=2))
    on = (np.abs(up) < GROUND_GAP) | (np.abs(up - under) < GROUND_GAP)
    free = outside_soles(com, corners, on) >= SUPPORT_MARGIN  # (T,) the feet cannot hold it
    feet = (corners.reshape(-1, 2), (heights - track[:, None, None]).reshape(-1))
    body = (body[..., :2], body[..., 2] - radii - track[:, None])  # (T, M, 2), (T, M) bottoms
    out = []
    for h, segs in enumerate(stances(hlow, hpts, rate)):
        for a, b in segs:
            top = float(np.median(hlow[a:b, h])) - float(track[a:b].mean())
            if top < MIN_RAISE or np.sum(free[a:b]) / rate < RELY_S:
                continue
            box = box_of(hpts[a:b, h].reshape(-1, 2), 0.0, top)
            if clear_of(box, *feet, DROP) and clear_of(box, *body, CLEAR, grow=radii + CLEAR):
                out.append(box)
    return [Box(b.centre, b.half, b.yaw, hand=True) for b in merge_boxes(out)]


def clear_of(box: Box, xy: np.ndarray, z: np.ndarray, depth: float, grow=0.0) -> bool:
    """Whether no point ``xy`` (..., 2) [m] of bottom height ``z`` (...) [m] lies more than
    ``depth`` [m] below ``box``'s top within its footprint grown by ``grow`` [m] (a scalar, or
    one per point along the last axis: a geom's radius and a clearance)."""
    c, s = np.cos(box.yaw), np.sin(box.yaw)
    d = xy - box.centre[:2]
    lx, ly = d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c
    inside = (np.abs(lx) <= box.half[0] + grow) & (np.abs(ly) <= box.half[1] + grow)
    return not np.any(inside & (z < box.top - depth))
