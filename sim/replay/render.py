"""Offscreen rendering of an original motion and its reconstruction, one frame at a time.

(Captions and timelines: :mod:`sim.replay.annotate`; videos: :mod:`sim.replay.video`;
keyframe sheets: :mod:`sim.replay.sheets`.)

The original is drawn as solid blue-grey capsules, the reconstruction as a translucent orange ghost
over it (``layout="overlay"``) or beside it (``layout="side"``); on keyframes a badge and a green
border say so. The ghost's capsules are thinner than the original's (:data:`GHOST_RADIUS_SCALE`), so
where the two coincide the ghost lies inside the original and the two surfaces never fight for the
same pixels (no stripes that look like error): only where the reconstruction departs does orange show.
Feet (:class:`sim.physics.foot_state.FootState`): the original's foot capsules turn teal and a teal
footprint lies on the ground while a foot point is in contact; the reconstruction's foot point is
marked by a blue ball when it floats, red when it sinks, magenta when it skates. A soft disc under
the body stands in for a shadow (real shadow maps cost most of a frame in software). A clip's
scene (``boxes``: the steps and platforms inferred under its feet, ``sim.simulate.terrain``) is
drawn as solid sand-coloured boxes, footprints and shadow on their tops; a clip without draws the
same frames as before. The camera
follows the original's root from the side of its travel. A caption gives method, W, frame number
(from 0, as everywhere in the report) and running error; a timeline at the bottom marks every
keyframe.

Defaults chosen for software rendering (Mesa llvmpipe under ``MUJOCO_GL=egl``): no shadows, no
reflections, no skybox, 640x480, no multisampling: these cost most of a frame without a GPU (see
``benchmarks/bench_render.py``).

Units: metres, z up; frames at the motion's fps.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from PIL import Image, ImageDraw

from sim.errors import UnknownNameError
from sim.model.capsules import bone_poses, bones_of, scene_xml

ORIGINAL_RGBA = (0.35, 0.45, 0.65, 1.0)
GHOST_RGBA = (1.0, 0.55, 0.15, 0.5)
KEY_RGBA = (0.15, 0.8, 0.3, 0.7)
CONTACT_RGBA = (0.0, 0.62, 0.56, 1.0)  # original's foot in contact: capsule and footprint
SHADOW_RGBA = (0.15, 0.17, 0.2, 0.22)
BOX_RGBA = (0.7, 0.6, 0.47, 1.0)  # a clip's steps: opaque, unlike the floor's greys
#: Reconstruction's foot point flags: ball colour per flag (float, sink, skate).
FLAG_RGBA = {
    "float": (0.15, 0.45, 1.0, 0.95),
    "sink": (0.9, 0.1, 0.1, 0.95),
    "skate": (0.85, 0.15, 0.85, 0.95),
}
#: Ghost capsule radius / original's: thinner, so coinciding surfaces never z-fight.
GHOST_RADIUS_SCALE = 0.78
SKY_TOP, SKY_BOTTOM = (150, 180, 215), (225, 232, 240)


@dataclass(frozen=True)
class RenderStyle:
    """How frames look.

    Attributes:
        width, height: image size [px].
        distance: camera distance from the root [m]; elevation: [deg] (negative looks down).
        layout: ``"overlay"`` (ghost over the original) or ``"side"`` (ghost beside it).
        side_offset: lateral gap between the two figures in ``"side"`` layout [m].
        shadows, reflections: MuJoCo's costly effects (off by default).
        multisample: MSAA samples of the offscreen buffer (MuJoCo's default 4; 0 here).
        slices, stacks: capsule tessellation (MuJoCo's defaults 28, 16).
        blob_shadow: a soft disc under the body (nearly free; a stand-in for shadow maps).
    """

    width: int = 640
    height: int = 480
    distance: float = 3.4
    elevation: float = -12.0
    layout: str = "overlay"
    side_offset: float = 1.0
    shadows: bool = False
    reflections: bool = False
    multisample: int = 0
    slices: int = 16
    stacks: int = 8
    blob_shadow: bool = True

    def __post_init__(self):
        if self.layout not in ("overlay", "side"):
            raise UnknownNameError("layout", self.layout, ("overlay", "side"))


DEFAULT_STYLE = RenderStyle()


class SkeletonRenderer:
    """Owns a MuJoCo model of two capsule skeletons (original, ghost) and an offscreen renderer.

    Use as a context manager (closes the GL context). ``draw(original (P, 3), ghost (P, 3) or None,
    lookat (3,), azimuth [deg], key)`` returns an (H, W, 3) uint8 image. ``boxes``: the clip's
    static scene (:func:`scene_boxes`), in the frame of the drawn points.
    """

    def __init__(
        self, names, parents, style: RenderStyle = DEFAULT_STYLE, lengths=None, *, ground_z=0.0,
        boxes=(),
    ):  # fmt: skip
        self.style = style
        self.ground_z = float(ground_z)
        self.boxes = scene_boxes(boxes)
        self.bones = bones_of(names, parents, lengths)
        self.model = self._compile(self.boxes)
        if self.boxes:  # MuJoCo scales its clipping planes by the model's extent: keep the view's
            self.model.stat.extent = self._compile(()).stat.extent  # (the horizon's) unchanged
        self.data = mujoco.MjData(self.model)
        B = len(self.bones.child)
        self._geo = np.flatnonzero(self.model.geom_bodyid > 0)  # the capsules (world: floor, boxes)
        self._orig, self._ghost = self._geo[:B], self._geo[B:]
        self.model.geom_size[self._ghost, 0] *= GHOST_RADIUS_SCALE
        # foot capsules of each foot point's side: the bones ending at that side's ball and toes
        self._foot_bones = {
            side: [b for b, j in enumerate(self.bones.child) if self.bones.names[j] in
                   (side + "foot", side + "toes")]
            for side in "lr"
        }  # fmt: skip
        self._index = {n: i for i, n in enumerate(self.bones.names)}
        self.renderer = mujoco.Renderer(self.model, style.height, style.width)
        flags = self.renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = int(style.shadows)
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = int(style.reflections)
        flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
        # MuJoCo clears to black without a skybox: paint the empty background as a sky gradient
        h = np.linspace(0.0, 1.0, style.height)[:, None, None]
        sky = np.array(SKY_TOP) * (1 - h) + np.array(SKY_BOTTOM) * h
        self._sky = np.broadcast_to(sky, (style.height, style.width, 3)).astype(np.uint8)
        # Looking down, the centre of the view hits the floor a few metres away, well inside the far
        # clipping distance, so only the upper half (plus a margin) can show the empty background.
        self._sky_rows = style.height // 2 + 8 if style.elevation <= -5 else style.height
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.distance = style.distance
        self.camera.elevation = style.elevation

    def _compile(self, boxes) -> mujoco.MjModel:
        """The model of the two skeletons, the floor and ``boxes``."""
        style = self.style
        xml = scene_xml(
            self.bones,
            skeletons=(("o_", ORIGINAL_RGBA), ("g_", GHOST_RGBA)),
            floor_z=self.ground_z,
            visual=True,
            quality=(style.multisample, style.slices, style.stacks, 4096 if style.shadows else 0),
            boxes=boxes,
            box_rgba=BOX_RGBA,
        )
        return mujoco.MjModel.from_xml_string(xml)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self.renderer.close()

    def draw(self, original, ghost=None, *, lookat, azimuth: float, key: bool = False, feet=None):
        """Render one frame.

        Args:
            original: (P, 3) points [m]; ghost: (P, 3) or ``None``.
            lookat: (3,) camera target [m]; azimuth [deg].
            key: a keyframe (the ghost is tinted green where it shows).
            feet: ``None`` or ``(points (F,), state)``: foot point names and a mapping of
                ``"contact"``, ``"float"``, ``"sink"``, ``"skate"`` to (F,) bools for this frame
                (one row of a :class:`~sim.physics.foot_state.FootState`).
        Returns:
            (H, W, 3) uint8 image.
        """
        m, d = self.model, self.data
        poses = [original, original if ghost is None else ghost]
        c, q, h = bone_poses(self.bones, np.stack(poses))
        shift = np.zeros((2, 3))
        if self.style.layout == "side" and ghost is not None:
            a = np.radians(azimuth)
            right = np.array([np.sin(a), -np.cos(a), 0.0])  # camera's right on screen
            shift[0] = -0.5 * self.style.side_offset * right
            shift[1] = 0.5 * self.style.side_offset * right
            c += shift[:, None, :]
        d.mocap_pos[:] = c.reshape(-1, 3)
        d.mocap_quat[:] = q.reshape(-1, 4)
        m.geom_size[self._geo, 1] = h.reshape(-1)
        m.geom_rgba[self._orig] = ORIGINAL_RGBA
        m.geom_rgba[self._ghost] = KEY_RGBA if key else GHOST_RGBA
        if ghost is None:
            m.geom_rgba[self._ghost, 3] = 0.0
        marks, rings = [], []
        if feet is not None:
            marks, rings = self._foot_marks(original, ghost, shift, *feet)
        mujoco.mj_kinematics(m, d)
        self.camera.lookat[:] = lookat
        self.camera.azimuth = azimuth
        self.renderer.update_scene(d, camera=self.camera)
        shadow = self._shadow(original + shift[0]) if self.style.blob_shadow else []
        self._add_geoms(marks + shadow)
        img = self.renderer.render()
        top = img[: self._sky_rows]
        empty = (top[..., 0] | top[..., 1] | top[..., 2]) == 0
        np.copyto(top, self._sky[: self._sky_rows], where=empty[..., None])
        if rings:
            img = self._rings(img, rings)
        return img

    def project(self, points) -> np.ndarray:
        """(N, 2) pixel coordinates (x right, y down) of world ``points`` (N, 3) [m] in the last
        rendered view (MuJoCo's OpenGL camera of the scene)."""
        # MuJoCo places two eye cameras ipd apart even in mono and renders from their mean
        cams = self.renderer.scene.camera
        pos, fwd, up = (
            np.mean([np.asarray(getattr(c, a), dtype=np.float64) for c in cams], axis=0)
            for a in ("pos", "forward", "up")
        )
        right = np.cross(fwd, up)
        v = np.asarray(points, dtype=np.float64) - pos
        z = np.maximum(v @ fwd, 1e-9)
        half = np.tan(np.radians(self.model.vis.global_.fovy) / 2)  # vertical half-extent / depth
        aspect = self.style.width / self.style.height
        u = (1 + (v @ right) / (z * half * aspect)) / 2 * self.style.width
        w = (1 - (v @ up) / (z * half)) / 2 * self.style.height
        return np.column_stack([u, w])

    def _rings(self, img, rings):
        """Circle each flagged foot point in its flag's colour, on top of everything (a ball can
        hide behind a leg)."""
        pil = Image.fromarray(img)
        g = ImageDraw.Draw(pil)
        xy = self.project([p for p, _ in rings])
        r = max(6, self.style.height // 40)
        for (u, w), (_, rgba) in zip(xy, rings, strict=True):
            colour = tuple(int(255 * c) for c in rgba[:3])
            g.ellipse([u - r, w - r, u + r, w + r], outline=colour, width=max(2, r // 4))
        return np.asarray(pil)

    def surface(self, xy) -> float:
        """[m] the height of what a point at ``xy`` (2,) [m] stands on: the highest top of the
        scene's boxes over it, else the ground."""
        z = self.ground_z
        for (cx, cy, cz), (hx, hy, hz), yaw in self.boxes:
            dx, dy = xy[0] - cx, xy[1] - cy
            c, s = np.cos(yaw), np.sin(yaw)
            if abs(c * dx + s * dy) <= hx and abs(c * dy - s * dx) <= hy:
                z = max(z, cz + hz)
        return z

    def _disc(self, xy, radius, rgba, lift):
        """A flat disc lying on what is under ``xy`` (:meth:`surface`), ``lift`` [m] above it
        (separate layers never fight)."""
        pos = np.array([xy[0], xy[1], self.surface(xy) + lift])
        return (mujoco.mjtGeom.mjGEOM_CYLINDER, [radius, 0.0005, 0.0], pos, rgba)

    def _shadow(self, points):
        """A soft blob under the body: a disc below the points' mean, fading with the height of
        the lowest point (a cheap stand-in for a shadow map)."""
        p = np.asarray(points)
        up = max(0.0, float(p[:, 2].min() - self.surface(p[:, :2].mean(axis=0))))
        rgba = (*SHADOW_RGBA[:3], SHADOW_RGBA[3] * max(0.3, 1.0 - up / 0.5))
        return [self._disc(p[:, :2].mean(axis=0), 0.32, rgba, 0.001)]

    def _foot_marks(self, original, ghost, shift, points, state):
        """Recolour the original's foot capsules in contact; footprints and flag balls. Returns the
        marks (for :meth:`_add_geoms`) and the rings ``(position, rgba)`` of flagged points."""
        marks, rings = [], []
        contact = np.asarray(state.get("contact", np.zeros(len(points), bool)))
        for f, name in enumerate(points):
            j = self._index.get(name)
            if j is None:
                continue
            if contact[f]:
                for b in self._foot_bones.get(name[0], []):
                    self.model.geom_rgba[self._orig[b]] = CONTACT_RGBA
                marks.append(self._disc(original[j, :2] + shift[0, :2], 0.06, CONTACT_RGBA, 0.002))
            if ghost is None:
                continue
            for flag, rgba in FLAG_RGBA.items():
                if np.asarray(state.get(flag, np.zeros(len(points), bool)))[f]:
                    pos = ghost[j] + shift[1]
                    marks.append((mujoco.mjtGeom.mjGEOM_SPHERE, [0.045, 0, 0], pos, rgba))
                    rings.append((pos, rgba))
                    break
        return marks, rings

    def _add_geoms(self, geoms):
        scn = self.renderer.scene
        eye = np.eye(3).reshape(-1)
        for kind, size, pos, rgba in geoms:
            if scn.ngeom >= scn.maxgeom:
                break
            mujoco.mjv_initGeom(
                scn.geoms[scn.ngeom], kind, np.asarray(size, np.float64),
                np.asarray(pos, np.float64), eye, np.asarray(rgba, np.float32),
            )  # fmt: skip
            scn.ngeom += 1


def scene_boxes(boxes) -> tuple:
    """A clip's static scene as the renderer keeps it: per box ``((cx, cy, cz), (hx, hy, hz),
    yaw)`` in floats (centre [m], half sizes [m], yaw [rad] about z), from objects with
    ``centre``, ``half`` and ``yaw`` (``sim.simulate.terrain.Box``) or such triples."""
    out = []
    for b in boxes:
        centre, half, yaw = (b.centre, b.half, b.yaw) if hasattr(b, "centre") else b
        out.append((tuple(map(float, centre)), tuple(map(float, half)), float(yaw)))
    return tuple(out)


def camera_path(root: np.ndarray, fps: float, *, height: float = 0.9, smooth_s: float = 0.3):
    """Where the camera looks, following the root, and from which side.

    Args:
        root: (T, 3) root positions [m].
    Returns:
        lookat (T, 3) [m]: the root's horizontal position, exponentially smoothed with time constant
        ``smooth_s`` [s] (both directions, so no lag), at ``height`` [m]; azimuth [deg]: looking
        across the clip's overall travel (from the side), or along -y when it barely moves.
    """
    root = np.asarray(root, dtype=np.float64)
    a = 1.0 - np.exp(-1.0 / (fps * smooth_s))
    fwd = root[:, :2].copy()
    for t in range(1, len(fwd)):
        fwd[t] = fwd[t - 1] + a * (root[t, :2] - fwd[t - 1])
    back = fwd.copy()
    for t in range(len(back) - 2, -1, -1):
        back[t] = back[t + 1] + a * (fwd[t] - back[t + 1])
    lookat = np.column_stack([back, np.full(len(root), height)])
    travel = root[-1, :2] - root[0, :2]
    if np.linalg.norm(travel) < 0.2:
        return lookat, 90.0
    heading = np.degrees(np.arctan2(travel[1], travel[0]))
    return lookat, float(heading + 90.0)  # MuJoCo's azimuth: camera looks along this direction
