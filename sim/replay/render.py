"""Offscreen rendering of an original motion and its reconstruction: mp4 videos and contact sheets.

The original is drawn as solid blue-grey capsules, the reconstruction as a translucent orange ghost
over it (``layout="overlay"``) or beside it (``layout="side"``); on keyframes a badge and a green
border say so. The ghost's capsules are thinner than the original's (:data:`GHOST_RADIUS_SCALE`), so
where the two coincide the ghost lies inside the original and the two surfaces never fight for the
same pixels (no stripes that look like error): only where the reconstruction departs does orange show.
Feet (:class:`sim.replay.foot_state.FootState`): the original's foot capsules turn teal and a teal
footprint lies on the ground while a foot point is in contact; the reconstruction's foot point is
marked by a blue ball when it floats, red when it sinks, magenta when it skates. A soft disc under
the body stands in for a shadow (real shadow maps cost most of a frame in software). The camera
follows the original's root from the side of its travel. A caption gives method, W, frame number
(from 0, as everywhere in the report) and running error; a timeline at the bottom marks every
keyframe.

Defaults chosen for software rendering (Mesa llvmpipe under ``MUJOCO_GL=egl``): no shadows, no
reflections, no skybox, 640x480, no multisampling: these cost most of a frame without a GPU (see
``benchmarks/bench_render.py``).

Units: metres, z up; frames at the motion's fps.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont
from tqdm import tqdm

from sim.errors import UnknownNameError
from sim.files import write_atomic, written_by
from sim.motion.points import PointMotion
from sim.replay.capsules import bone_poses, bones_of, scene_xml
from sim.replay.foot_state import FootState

ORIGINAL_RGBA = (0.35, 0.45, 0.65, 1.0)
GHOST_RGBA = (1.0, 0.55, 0.15, 0.5)
KEY_RGBA = (0.15, 0.8, 0.3, 0.7)
CONTACT_RGBA = (0.0, 0.62, 0.56, 1.0)  # original's foot in contact: capsule and footprint
SHADOW_RGBA = (0.15, 0.17, 0.2, 0.22)
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
    lookat (3,), azimuth [deg], key)`` returns an (H, W, 3) uint8 image.
    """

    def __init__(
        self, names, parents, style: RenderStyle = DEFAULT_STYLE, lengths=None, *, ground_z=0.0
    ):
        self.style = style
        self.ground_z = float(ground_z)
        self.bones = bones_of(names, parents, lengths)
        xml = scene_xml(
            self.bones,
            skeletons=(("o_", ORIGINAL_RGBA), ("g_", GHOST_RGBA)),
            floor_z=self.ground_z,
            visual=True,
            quality=(style.multisample, style.slices, style.stacks, 4096 if style.shadows else 0),
        )
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        B = len(self.bones.child)
        self._geo = np.arange(1, 2 * B + 1)
        self._orig = np.arange(1, B + 1)
        self._ghost = np.arange(B + 1, 2 * B + 1)
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
                (one row of a :class:`~sim.replay.foot_state.FootState`).
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

    def _disc(self, xy, radius, rgba, lift):
        """A flat disc lying on the ground, ``lift`` [m] above it (separate layers never fight)."""
        pos = np.array([xy[0], xy[1], self.ground_z + lift])
        return (mujoco.mjtGeom.mjGEOM_CYLINDER, [radius, 0.0005, 0.0], pos, rgba)

    def _shadow(self, points):
        """A soft blob under the body: a disc below the points' mean, fading with the height of
        the lowest point (a cheap stand-in for a shadow map)."""
        p = np.asarray(points)
        up = max(0.0, float(p[:, 2].min() - self.ground_z))
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


def _font(size: int):
    return ImageFont.load_default(size=size)


def annotate(image: np.ndarray, lines, *, t: int, n: int, keyframes, key: bool) -> np.ndarray:
    """Caption lines at the top left, a KEYFRAME badge on keyframes, and a timeline strip at the
    bottom with a tick per keyframe and the playhead at frame ``t`` of ``n``. Returns a new image.

    Only the two bands that carry drawing go through PIL (converting a whole frame costs more
    than drawing on it); the keyframe border is set directly."""
    out = np.array(image, dtype=np.uint8, copy=True)
    H, W = out.shape[:2]
    s = max(11, H // 32)
    font = _font(s)
    top_h = min(H, max(6 + len(lines) * (s + 6) + 2, 6 + s + 8 + 2 if key else 0))
    if top_h > 0:
        band = Image.fromarray(out[:top_h])
        g = ImageDraw.Draw(band, "RGBA")
        y = 6
        for line in lines:
            g.rectangle(
                [4, y - 2, 8 + g.textlength(line, font=font), y + s + 2], fill=(0, 0, 0, 110)
            )
            g.text((6, y), line, fill=(255, 255, 255, 255), font=font)
            y += s + 6
        if key:
            g.rectangle([W - 140, 6, W - 6, 6 + s + 8], fill=(30, 170, 70, 220))
            g.text((W - 132, 10), "KEYFRAME", fill=(255, 255, 255, 255), font=font)
        out[:top_h] = np.asarray(band)
    b0 = max(H - 30, 0)  # the timeline band, drawn in its own coordinates
    band = Image.fromarray(out[b0:])
    g = ImageDraw.Draw(band, "RGBA")
    y0, y1, x0, x1 = H - 22 - b0, H - 8 - b0, 12, W - 12
    g.rectangle([x0, y0, x1, y1], fill=(0, 0, 0, 90))

    def x_of(k):
        return x0 + (x1 - x0) * (k / max(n - 1, 1))

    for k in keyframes:
        g.rectangle([x_of(k) - 1, y0 - 3, x_of(k) + 1, y1 + 3], fill=(30, 170, 70, 255))
    g.rectangle([x0, y0 + 5, x_of(t), y1 - 5], fill=(255, 255, 255, 200))
    g.polygon([(x_of(t) - 5, y0 - 6), (x_of(t) + 5, y0 - 6), (x_of(t), y0)], fill=(255, 255, 255))
    out[b0:] = np.asarray(band)
    if key:  # a 4-pixel green border
        green = np.array([30, 170, 70], dtype=np.uint8)
        out[:4], out[-4:], out[:, :4], out[:, -4:] = green, green, green, green
    return out


def caption(method: str, t: int, n: int, W: int, err=None, flags=()) -> list[str]:
    """Caption lines of frame ``t`` (numbered from 0, as in the report's tables and sheets) of
    ``n``: method, W, frame; running error when ``err`` (T,) [m] is given; foot flags
    (``"L ball sinks"``...) when any."""
    lines = [f"{method or 'original'}   W = {W}   frame {t} of 0-{n - 1}"]
    if err is not None:
        lines.append(
            f"MPJPE now {1e3 * err[t]:.1f} mm, running mean {1e3 * err[: t + 1].mean():.1f} mm"
        )
    if flags:
        lines.append("feet: " + ", ".join(flags))
    return lines


_FOOT_WORD = {"tibia": "heel", "foot": "ball", "toes": "toes"}
_FLAG_VERB = {"float": "floats", "sink": "sinks", "skate": "skates"}


def foot_frame(state: FootState | None, t: int):
    """``(points, {"contact", "float", "sink", "skate": (F,) bool})`` of frame ``t`` for
    :meth:`SkeletonRenderer.draw`, and the caption's flag phrases; ``(None, [])`` without state."""
    if state is None or not state.points:
        return None, []
    row = {
        "contact": state.contact[t], "float": state.floating[t], "sink": state.sinking[t],
        "skate": state.skating[t],
    }  # fmt: skip
    phrases = []
    for f, n in enumerate(state.points):
        for flag, verb in _FLAG_VERB.items():
            if row[flag][f]:
                phrases.append(f"{n[0].upper()} {_FOOT_WORD.get(n[1:], n[1:])} {verb}")
                break
    return (state.points, row), phrases


def render_frames(
    original: PointMotion,
    reconstruction: PointMotion | None = None,
    *,
    keyframes=(),
    method: str = "",
    style: RenderStyle = DEFAULT_STYLE,
    frames=None,
    progress: bool = False,
    feet: FootState | None = None,
    ground_z: float = 0.0,
    renderer: SkeletonRenderer | None = None,
):
    """Yield annotated (H, W, 3) uint8 frames of ``original`` with ``reconstruction`` as a ghost.

    Args:
        original: (T, P', 3) points; restricted to the reconstruction's points when one is given.
        reconstruction: (T, P, 3) points or ``None`` (original alone).
        keyframes: frame indices marked as they pass.
        method: name in the caption.
        frames: which frame indices to render (default all).
        feet: foot contact and flags per frame (e.g. :func:`sim.physics.contacts.foot_states`).
        ground_z: height of the drawn floor [m].
        renderer: the clip's :class:`SkeletonRenderer` (same points, style and ground), reused
            and left open; one is made and closed here when None.
    """
    rec = reconstruction
    orig = original if rec is None else original.restrict(rec.names)
    T = orig.n_frames
    keys = sorted(int(k) for k in keyframes)
    keyset = set(keys)
    err = None
    if rec is not None:
        err = np.linalg.norm(rec.positions - orig.positions, axis=-1).mean(axis=1)
    lookat, azimuth = camera_path(orig.positions[:, 0], orig.fps)
    frames = range(T) if frames is None else frames
    it = frames
    if progress:
        it = tqdm(frames, desc=f"render {method or 'original'}", unit="frame", leave=False)
    if renderer is not None and (
        renderer.bones.names != orig.names
        or renderer.style != style
        or renderer.ground_z != float(ground_z)
    ):
        raise ValueError("the renderer was built for other points, another style or ground")
    owned = renderer is None
    r = SkeletonRenderer(orig.names, orig.parents, style, ground_z=ground_z) if owned else renderer
    try:
        for t in it:
            marks, flags = foot_frame(feet, t)
            img = r.draw(
                orig.positions[t], None if rec is None else rec.positions[t],
                lookat=lookat[t], azimuth=azimuth, key=t in keyset, feet=marks,
            )  # fmt: skip
            lines = caption(method, t, T, len(keys), err, flags)
            yield annotate(img, lines, t=t, n=T, keyframes=keys, key=t in keyset)
    finally:
        if owned:
            r.close()


#: x264's speed preset for report videos: "veryfast" encodes a 640x480 frame several times faster
#: than the default "medium" (which costs as much as drawing the frame in software), for files a
#: little larger at the same quality.
X264_PRESET = "veryfast"


def write_video(frames, path: str | os.PathLike, fps: float, *, root=None) -> Path:
    """Encode (H, W, 3) uint8 frames as an H.264 mp4 (yuv420p, fast start) atomically: ffmpeg
    writes into a private folder beside ``path``, then the file is renamed into place
    (:func:`sim.files.written_by`; ``root``: the output folder, no link below it followed)."""
    import imageio.v2 as imageio  # lazy: heavy optional video dependency, only to write an mp4

    path = Path(path)
    with written_by(path, root=root, suffix=".mp4") as tmp:
        w = imageio.get_writer(
            tmp, fps=fps, codec="libx264", quality=7, pixelformat="yuv420p", macro_block_size=16,
            ffmpeg_log_level="error",
            ffmpeg_params=["-movflags", "+faststart", "-preset", X264_PRESET],
        )  # fmt: skip
        with w:
            for f in frames:
                w.append_data(f)
    return path


def contact_sheet(images, labels, path: str | os.PathLike, *, cols: int = 4) -> Path:
    """Tile (H, W, 3) uint8 ``images`` with ``labels`` into one PNG written atomically."""
    images = list(images)
    if not images:
        raise ValueError("a contact sheet needs at least one image")
    H, W = images[0].shape[:2]
    cols = min(cols, len(images))
    rows = -(-len(images) // cols)
    sheet = Image.new("RGB", (cols * W, rows * H), (255, 255, 255))
    g = ImageDraw.Draw(sheet)
    font = _font(max(12, H // 24))
    for i, (im, lab) in enumerate(zip(images, labels, strict=True)):
        x, y = (i % cols) * W, (i // cols) * H
        sheet.paste(Image.fromarray(im), (x, y))
        g.rectangle([x, y + H - 30, x + g.textlength(lab, font=font) + 12, y + H], fill=(0, 0, 0))
        g.text((x + 6, y + H - 27), lab, fill=(255, 255, 255), font=font)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda f: sheet.save(f, format="PNG", optimize=True))
    return path


def worst_frames(err: np.ndarray, keyframes) -> list[int]:
    """Per interval between consecutive keyframes, the frame of largest ``err`` (T,) strictly
    inside it (intervals without an inner frame are skipped)."""
    keys = sorted(int(k) for k in keyframes)
    out = []
    for a, b in zip(keys[:-1], keys[1:], strict=False):
        if b - a > 1:
            out.append(a + 1 + int(np.argmax(err[a + 1 : b])))
    return out


SHEET_TILE = RenderStyle(width=224, height=320, distance=2.5, elevation=-8.0)


def keyframe_sheet(
    original: PointMotion,
    reconstruction: PointMotion | None,
    keyframes,
    path,
    *,
    method: str = "",
    style: RenderStyle = SHEET_TILE,
    feet: FootState | None = None,
    ground_z: float = 0.0,
) -> Path:
    """PNG filmstrip of a method's keyframes and what happens between them.

    Top row: the original at each keyframe (the poses the method kept; the reconstruction equals
    them there). Bottom row, set between its two keyframes: the frame of largest MPJPE inside each
    interval, the reconstruction's ghost over the original, labelled with frame and error. Frames
    numbered from 0. Tiles are portrait crops (``style``, default 224x320) with the camera on the
    tile's own root, all from the clip's side, so poses read large and distinct.
    """
    keys = sorted(int(k) for k in keyframes)
    rec = reconstruction
    orig = original if rec is None else original.restrict(rec.names)
    err = np.zeros(orig.n_frames)
    if rec is not None:
        err = np.linalg.norm(rec.positions - orig.positions, axis=-1).mean(axis=1)
    worst = worst_frames(err, keys) if rec is not None else []
    _, azimuth = camera_path(orig.positions[:, 0], orig.fps)
    tw, th = style.width, style.height
    top = 34
    sheet = Image.new("RGB", (max(len(keys), 1) * tw, 2 * th + top if worst else th + top), "white")
    g = ImageDraw.Draw(sheet)
    font = _font(max(15, th // 18))
    head = f"{method or 'original'}: keyframes (top)" + (
        ", the worst frame between each pair (bottom, orange ghost: the reconstruction)"
        if worst
        else ""
    )
    g.text((6, 6), head, fill=(30, 30, 30), font=_font(22))
    with SkeletonRenderer(orig.names, orig.parents, style, ground_z=ground_z) as r:

        def tile(t, ghost, x, y, label, colour):
            look = np.array([*orig.positions[t, 0, :2], ground_z + 0.9])
            marks, _ = foot_frame(feet, t)
            img = r.draw(orig.positions[t], ghost, lookat=look, azimuth=azimuth, feet=marks)
            sheet.paste(Image.fromarray(img), (x, y))
            g.rectangle([x, y, x + tw - 1, y + th - 1], outline=(255, 255, 255), width=2)
            w = g.textlength(label, font=font)
            fs = font.size
            g.rectangle([x + 4, y + th - fs - 12, x + 12 + w, y + th - 4], fill=colour)
            g.text((x + 8, y + th - fs - 9), label, fill=(255, 255, 255), font=font)

        for i, k in enumerate(keys):
            tile(k, None, i * tw, top, f"key {k}", (30, 150, 70))
        for t in worst:
            i = next(i for i in range(len(keys) - 1) if keys[i] < t < keys[i + 1])
            label = f"frame {t}: {1e3 * err[t]:.0f} mm"
            tile(t, rec.positions[t], i * tw + tw // 2, top + th, label, (190, 90, 20))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda f: sheet.save(f, format="PNG", optimize=True))
    return path
