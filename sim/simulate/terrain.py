"""The scene inferred from the motion: steps and platforms under feet that stand on them.

A capture's floor is not always the only support: in CMU's playground climb 01_02 the subject
stands on equipment 0.28, 0.55 and 0.8 m high for seconds at a time. Tracked on an empty floor,
such a reference has nothing under its feet. This module finds where a foot of the original
motion stands still clearly above the ground, for long enough, while the body relies on it, and
puts a static box there (top at that sole height): contact with static geometry, no force on the
body but what a step gives.

Per foot (its sole and toe boxes, ``sim.simulate.model.add_soles``), per frame: the lowest
bottom corner's height and the bottom corners' horizontal positions. A **stance** is a run of at
least :data:`MIN_STANCE_S` in which the sole moves slower than :data:`STILL_SPEED`. The
**ground** is the lowest stance level (or a floor the feet touch briefly well below it:
:data:`GROUND_PERCENTILE`); a stance at least :data:`MIN_RAISE` above it is **raised**. A
raised stance becomes a support only if the body relies on it (:func:`relies`): for at least
:data:`RELY_S` the other foot is off the ground (not within :data:`GROUND_GAP` of it) while the
centre of mass is within :data:`COM_REACH` horizontally of this foot. A foot held still in the
air (an arabesque, a held kick) has the other foot on the ground, or the centre of mass away
from it: no box. Boxes of similar height that overlap are merged (:func:`merge_boxes`);
optionally (:data:`CARVE`, off) cut back from where the motion's feet passed (:func:`carve`).
The ground track is the running floor (:func:`running_floor`) of the ground-level frames only.

Units: metres, seconds, radians; z up. Boxes are given in the frame of the reference after the
ground shift (:func:`find_terrain`'s ground track at z = 0). Terrain geoms in a model are the
world geoms named ``terrain<k>`` (:func:`add_terrain`); :func:`surface_height` reads them back.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from sim.simulate.model import FLOOR_BITS, FLOOR_DAMPRATIO, FLOOR_SOLIMP, FLOOR_TIMECONST

#: [m/s] a sole moving slower than this (its bottom corners' mean, smoothed) stands still
STILL_SPEED = 0.2
#: [s] a stance lasts at least this long
MIN_STANCE_S = 0.25
#: [m] a stance this much or more above the ground is raised
MIN_RAISE = 0.12
#: the ground is the lowest stance level, unless this percentile of the lowest foot point is
#: :data:`MIN_RAISE` or more below it: a foot touching the floor briefly (stepping up or down)
#: shows where the floor is; a dip of a few centimetres (marker noise, a fit's foot) does not
GROUND_PERCENTILE = 5.0
#: [m] a foot within this of the ground (its stance level) is on it
GROUND_GAP = 0.06
#: [s] the body relies on a raised foot at least this long (:func:`relies`)
RELY_S = 0.2
#: [m] ... with the centre of mass within this horizontally of the foot
COM_REACH = 0.35
#: [m] a box reaches this far beyond the footprint of the sole that stood on it
MARGIN = 0.04
#: boxes are carved (:func:`carve`) unless told otherwise: off. On the 11 clips with terrain
#: (01_02, 03_01, 03_02) carved boxes kept 5 of them up against 6 uncarved, with higher errors
#: in most (docs/synthetic.md, "The scene inferred from the motion")
CARVE = False
#: [m] a box keeps this clear of where the motion's feet were lower than its top (:func:`carve`)
CLEAR = 0.03
#: [m] a foot point this far below a box's top is beside or under it, not on it (:func:`carve`)
DROP = 0.08
#: [m] boxes whose tops are within this and whose footprints overlap are merged
MERGE_HEIGHT = 0.06
#: [m] a box reaches this far below the ground (no gap where it meets the floor)
BURY = 0.1
#: [s] the sole's speed is taken after a Gaussian of this scale (marker noise)
SPEED_SMOOTH_S = 0.03
TERRAIN_PREFIX = "terrain"
_SIDES = (("lsole", "ltoesole"), ("rsole", "rtoesole"))


@dataclass(frozen=True)
class Box:
    """A static box: ``centre`` (3,) [m], half sizes ``half`` (3,) [m], ``yaw`` [rad] about z."""

    centre: np.ndarray
    half: np.ndarray
    yaw: float

    @property
    def top(self) -> float:
        """[m] the height of the box's top face."""
        return float(self.centre[2] + self.half[2])


def foot_tracks(model, qpos: np.ndarray) -> tuple:
    """Per frame of ``qpos`` (T, nq) and foot (left, right): the lowest bottom corner's height
    (T, 2) [m], the bottom corners' horizontal positions (T, 2, 8, 2) [m] (sole and toe box),
    the sole's heading (T, 2) [rad] (its box's local x axis), the centre of mass (T, 3) [m] and
    the bottom corners' heights (T, 2, 8) [m]. None where the model has no soles."""
    ids = []
    for names in _SIDES:
        side = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in names]
        if min(side) < 0:
            return None
        ids.append(side)
    ids = np.array(ids)  # (2 feet, 2 boxes)
    signs = np.array([[i, j, -1.0] for i in (-1, 1) for j in (-1, 1)])  # bottom corners
    data = mujoco.MjData(model)
    T = len(qpos)
    low, corners, heights = np.empty((T, 2)), np.empty((T, 2, 8, 2)), np.empty((T, 2, 8))
    heading, com = np.empty((T, 2)), np.empty((T, 3))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        com[t] = data.subtree_com[0]
        for f in range(2):
            pts = []
            for g in ids[f]:
                R = data.geom_xmat[g].reshape(3, 3)
                pts.append(data.geom_xpos[g] + (signs * model.geom_size[g]) @ R.T)
            pts = np.concatenate(pts)  # (8, 3)
            low[t, f] = pts[:, 2].min()
            corners[t, f], heights[t, f] = pts[:, :2], pts[:, 2]
            R = data.geom_xmat[ids[f, 0]].reshape(3, 3)
            heading[t, f] = np.arctan2(R[1, 0], R[0, 0])
    return low, corners, heading, com, heights


def stances(
    low: np.ndarray, corners: np.ndarray, rate: float, min_s: float = MIN_STANCE_S
) -> list[list[tuple[int, int]]]:
    """Per foot, the runs [a, b) of frames (at ``rate`` [Hz]) of at least ``min_s`` [s] in which
    the sole (``low`` (T, 2) [m] and ``corners`` (T, 2, 8, 2) [m] of :func:`foot_tracks`) moves
    slower than :data:`STILL_SPEED` (3-D speed of its bottom corners' mean at its lowest height,
    smoothed by :data:`SPEED_SMOOTH_S`)."""
    T = len(low)
    out: list[list[tuple[int, int]]] = [[], []]
    if T < 3:
        return out
    for f in range(2):
        p = np.concatenate([corners[:, f].mean(axis=1), low[:, f, None]], axis=1)  # (T, 3)
        p = gaussian_filter1d(p, SPEED_SMOOTH_S * rate, axis=0, mode="nearest")
        still = np.linalg.norm(np.gradient(p, 1.0 / rate, axis=0), axis=1) < STILL_SPEED
        edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if (b - a) / rate >= min_s:
                out[f].append((int(a), int(b)))
    return out


def relies(f: int, seg: tuple, low: np.ndarray, corners: np.ndarray, com: np.ndarray,
           ground: float, rate: float) -> bool:  # fmt: skip
    """Whether the body relies on foot ``f`` (0 left, 1 right) over frames ``seg`` = [a, b): at
    least :data:`RELY_S` of them with the other foot more than :data:`GROUND_GAP` above
    ``ground`` [m] (off the ground: in the air or on something else) and the centre of mass
    ``com`` (T, 3) within :data:`COM_REACH` horizontally of this foot's footprint centre."""
    a, b = seg
    other_up = low[a:b, 1 - f] > ground + GROUND_GAP
    reach = np.linalg.norm(com[a:b, :2] - corners[a:b, f].mean(axis=1), axis=1) < COM_REACH
    return float(np.sum(other_up & reach)) / rate >= RELY_S


def box_of(corners: np.ndarray, yaw: float, top: float) -> Box:
    """The box of yaw ``yaw`` [rad] whose footprint holds the horizontal points ``corners``
    (N, 2) [m] with :data:`MARGIN` to spare, from :data:`BURY` below z = 0 to ``top`` [m]."""
    c, s = np.cos(yaw), np.sin(yaw)
    local = corners @ np.array([[c, -s], [s, c]])  # rows: (x, y) in the box's frame
    lo, hi = local.min(axis=0) - MARGIN, local.max(axis=0) + MARGIN
    mid = 0.5 * (lo + hi)
    centre_xy = np.array([c * mid[0] - s * mid[1], s * mid[0] + c * mid[1]])
    half = np.array([*(0.5 * (hi - lo)), 0.5 * (top + BURY)])
    return Box(np.array([*centre_xy, 0.5 * (top - BURY)]), half, float(yaw))


def box_corners(box: Box) -> np.ndarray:
    """(4, 2) [m] the horizontal corners of ``box``'s footprint."""
    c, s = np.cos(box.yaw), np.sin(box.yaw)
    signs = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * box.half[:2]
    return box.centre[:2] + signs @ np.array([[c, s], [-s, c]])


def _overlap(a: Box, b: Box) -> bool:
    """Whether two footprints overlap (separating axes of both boxes)."""
    ca, cb = box_corners(a), box_corners(b)
    for yaw in (a.yaw, b.yaw):
        for axis in (np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])):
            pa, pb = ca @ axis, cb @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def merge_boxes(boxes: list[Box]) -> list[Box]:
    """``boxes`` with every pair whose tops are within :data:`MERGE_HEIGHT` and whose
    footprints overlap replaced by one box (the first's yaw, both footprints, the mean top),
    until none is left to merge."""
    boxes = list(boxes)
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if abs(a.top - b.top) <= MERGE_HEIGHT and _overlap(a, b):
                    pts = np.concatenate([box_corners(a), box_corners(b)])
                    one = box_of(pts, a.yaw, 0.5 * (a.top + b.top))
                    # box_of adds a margin again: take it off the merged footprint
                    one = Box(one.centre, one.half - np.array([MARGIN, MARGIN, 0.0]), one.yaw)
                    boxes[j:j + 1] = []  # fmt: skip
                    boxes[i] = one
                    merged = True
                    break
            if merged:
                break
    return boxes


def find_terrain(
    model, qpos: np.ndarray, rate: float, carved: bool = CARVE
) -> tuple[list[Box], np.ndarray | None]:
    """The supports a motion stands on above its ground, and its ground track.

    Args:
        model: a ``sim_model`` with soles (without: nothing is found).
        qpos: (T, nq) the original motion as captured (before any floor shift) at ``rate`` [Hz].
        carved: each box made to leave free where the motion's feet passed (:func:`carve`).

    Returns:
        the boxes (:class:`Box`, merged) in the frame of ``qpos`` shifted down by the ground
        track, and the ground track (T,) [m]: :func:`running_floor` of the
        lowest foot point with the frames off the ground (more than :data:`GROUND_GAP` above the
        ground level) filled from their neighbours, so the platforms do not pull it up; ``([],
        None)`` where no support is found (the caller keeps its own floor track).
    """
    tracks = foot_tracks(model, qpos)
    if tracks is None:
        return [], None
    low, corners, heading, com, heights = tracks
    segs = stances(low, corners, rate)
    levels = [(f, s, float(np.median(low[s[0] : s[1], f]))) for f in range(2) for s in segs[f]]
    if not levels:
        return [], None
    lowest = low.min(axis=1)
    ground = min(h for _, _, h in levels)
    touched = float(np.percentile(lowest, GROUND_PERCENTILE))
    ground = touched if touched <= ground - MIN_RAISE else ground
    raised = [
        (f, s, h)
        for f, s, h in levels
        if h >= ground + MIN_RAISE and relies(f, s, low, corners, com, ground, rate)
    ]
    if not raised:
        return [], None
    on = lowest <= ground + GROUND_GAP
    t = np.arange(len(lowest))
    track = running_floor(np.interp(t, t[on], lowest[on]), rate)
    boxes, cores = [], []
    for f, (a, b), h in raised:
        yaw = float(np.angle(np.exp(1j * heading[a:b, f]).mean()))
        top = h - float(track[a:b].mean())
        cores.append(corners[a:b, f].reshape(-1, 2))
        boxes.append(box_of(cores[-1], yaw, top))
    # the feet's corners, their heights above the ground track: where the feet were
    feet = (corners.reshape(-1, 2), (heights - track[:, None, None]).reshape(-1))
    boxes = merge_boxes(boxes)
    return [carve(b, cores, *feet) for b in boxes] if carved else boxes, track


def carve(box: Box, cores: list, xy: np.ndarray, z: np.ndarray) -> Box:
    """``box`` made to leave free the space the motion's feet passed through: the points ``xy``
    (M, 2) [m] at heights ``z`` (M,) [m] more than :data:`DROP` below its top (a foot beside or
    below the step; the foot on it sinks a few centimetres in a fit). Its sides are cut back, one at a time, to :data:`CLEAR` short of each
    such point within :data:`CLEAR` of its footprint, keeping the footprints ``cores`` ((N_i,
    2) [m] each: the stances on it) whose centre it holds; a point within those (a foot on a
    lower rung, its toes under this one) raises the box's bottom to :data:`CLEAR` above it
    instead (a rung)."""
    c, s = np.cos(box.yaw), np.sin(box.yaw)
    rot = np.array([[c, -s], [s, c]])  # world (x, y) rows @ rot: the box's frame
    lo, hi = -box.half[:2].copy(), box.half[:2].copy()
    mine = [k for k in cores if np.all(np.abs((k.mean(axis=0) - box.centre[:2]) @ rot) <= hi)]
    if not mine:
        return box
    core = (np.concatenate(mine) - box.centre[:2]) @ rot
    clo, chi = core.min(axis=0), core.max(axis=0)
    low = z < box.top - DROP
    local = np.column_stack([(xy[low] - box.centre[:2]) @ rot, z[low]])  # (x, y, z) rows
    local = local[np.argsort(np.abs(local[:, :2] - 0.5 * (clo + chi)).max(axis=1))]  # nearest first
    for p in local[:, :2]:
        if np.any(p <= lo - CLEAR) or np.any(p >= hi + CLEAR):
            continue  # clear of the box already
        best, area = None, -1.0
        for k in range(2):  # cut one side back to CLEAR short of the point, the largest left
            for side, ok in ((hi, p[k] - CLEAR >= chi[k]), (lo, p[k] + CLEAR <= clo[k])):
                if ok:
                    new_lo, new_hi = lo.copy(), hi.copy()
                    (new_hi if side is hi else new_lo)[k] = (
                        p[k] - CLEAR if side is hi else p[k] + CLEAR
                    )
                    a = float(np.prod(new_hi - new_lo))
                    if a > area:
                        best, area = (new_lo, new_hi), a
        if best is not None:
            lo, hi = best
    under = np.all((local[:, :2] > lo - CLEAR) & (local[:, :2] < hi + CLEAR), axis=1)
    bottom = box.centre[2] - box.half[2]
    if under.any():  # feet below it within its footprint: a rung above them
        bottom = max(bottom, float(local[under, 2].max()) + CLEAR)  # < top: DROP > CLEAR
    mid = 0.5 * (lo + hi)
    centre = np.array([*(box.centre[:2] + rot @ mid), 0.5 * (box.top + bottom)])
    return Box(centre, np.array([*(0.5 * (hi - lo)), 0.5 * (box.top - bottom)]), box.yaw)


def running_floor(
    low: np.ndarray, rate: float, window: float = 1.5, percentile: float = 10.0
) -> np.ndarray:
    """(T,) [m] the floor under each frame of a lowest foot point ``low`` (T,) [m] at ``rate``
    [Hz]: its ``percentile`` over a ``window``-second window centred on the frame, then averaged
    over the same window (``sim.simulate.reference.floor_track`` of a motion)."""
    half = max(1, int(round(window * rate / 2)))
    pad = np.pad(low, half, mode="edge")
    wins = np.lib.stride_tricks.sliding_window_view(pad, 2 * half + 1)
    floor = np.percentile(wins, percentile, axis=1)
    pad = np.pad(floor, half, mode="edge")
    return np.convolve(pad, np.ones(2 * half + 1) / (2 * half + 1), mode="valid")


def terrain_geoms(model) -> tuple | None:
    """The terrain boxes of a compiled ``model`` (world geoms named :data:`TERRAIN_PREFIX`
    ``<k>``, :func:`add_terrain`): their ids (K,), tops (K,) [m], centres (K, 2) [m], half
    sizes (K, 2) [m] and yaws (K,) [rad]; None where it has none."""
    ids = [
        g for g in range(model.ngeom)
        if model.geom_bodyid[g] == model.nbody - 1 and model.geom(g).name.startswith(TERRAIN_PREFIX)
    ]  # fmt: skip
    if not ids:
        return None
    ids = np.array(ids)
    pos, size, quat = model.geom_pos[ids], model.geom_size[ids], model.geom_quat[ids]
    yaw = 2.0 * np.arctan2(quat[:, 3], quat[:, 0])
    return ids, pos[:, 2] + size[:, 2], pos[:, :2].copy(), size[:, :2].copy(), yaw


def surface_height(terrain: tuple | None, xy: np.ndarray) -> np.ndarray:
    """(...,) [m] the height of the highest support under horizontal points ``xy`` (..., 2)
    [m]: the top of a ``terrain`` box (:func:`terrain_geoms`) whose footprint holds the point,
    else the floor (0)."""
    xy = np.asarray(xy, dtype=float)
    out = np.zeros(xy.shape[:-1])
    if terrain is None:
        return out
    _, tops, centres, halves, yaws = terrain
    for top, c, h, yaw in zip(tops, centres, halves, yaws, strict=True):
        d = xy - c
        lx = d[..., 0] * np.cos(yaw) + d[..., 1] * np.sin(yaw)
        ly = -d[..., 0] * np.sin(yaw) + d[..., 1] * np.cos(yaw)
        inside = (np.abs(lx) <= h[0]) & (np.abs(ly) <= h[1])
        out = np.where(inside, np.maximum(out, top), out)
    return out


def add_terrain(spec, boxes: list[Box]) -> None:
    """Add ``boxes`` to ``spec`` in place: static geoms ``terrain<k>`` of a body ``terrain``
    at the origin, added last (the body's geom ids do not move), with the floor's contact
    bits, parameters and friction (a part touching one touches the floor), and no mass: they
    are the world's, not the figure's (``total_mass``, which the balance feedback's gains
    scale with, stays the body's: the boxes of eval's 2 s clips of 01_02 weighed 20-70 kg)."""
    floor = spec.geom("floor")
    body = spec.worldbody.add_body()
    body.name = TERRAIN_PREFIX
    for k, b in enumerate(boxes):
        g = body.add_geom()
        g.name = f"{TERRAIN_PREFIX}{k}"
        g.type = mujoco.mjtGeom.mjGEOM_BOX
        g.size = b.half
        g.pos = b.centre
        g.quat = [np.cos(b.yaw / 2), 0.0, 0.0, np.sin(b.yaw / 2)]
        g.contype, g.conaffinity = FLOOR_BITS
        g.solref = [FLOOR_TIMECONST, FLOOR_DAMPRATIO]
        g.solimp = list(FLOOR_SOLIMP)
        g.priority = floor.priority
        g.friction = floor.friction
        g.condim = floor.condim
        g.density = 0.0  # static either way: only the figures of the body's mass see it
        g.rgba = [0.6, 0.5, 0.4, 1.0]


def scene_model(spec, boxes: list[Box]) -> mujoco.MjModel:
    """``spec`` (a body's ``MjSpec``, not changed) compiled with ``boxes`` added
    (:func:`add_terrain`)."""
    scene = spec.copy()
    add_terrain(scene, boxes)
    return scene.compile()
