"""Offscreen rendering of an original motion and its reconstruction: mp4 videos and contact sheets.

The original is drawn as solid blue-grey capsules, the reconstruction as a translucent orange ghost
over it (``layout="overlay"``) or beside it (``layout="side"``); on keyframes the ghost turns green
and a badge says so. The camera follows the original's root from the side of its travel. A caption
gives method, W, frame number and running error; a timeline at the bottom marks every keyframe.

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

from sim.motion.clip import write_atomic
from sim.motion.points import PointMotion
from sim.replay.capsules import bone_poses, bones_of, scene_xml

ORIGINAL_RGBA = (0.35, 0.45, 0.65, 1.0)
GHOST_RGBA = (1.0, 0.55, 0.15, 0.45)
KEY_RGBA = (0.15, 0.8, 0.3, 0.7)
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

    def __post_init__(self):
        if self.layout not in ("overlay", "side"):
            raise ValueError(f"unknown layout {self.layout!r}; known: overlay, side")


DEFAULT_STYLE = RenderStyle()


class SkeletonRenderer:
    """Owns a MuJoCo model of two capsule skeletons (original, ghost) and an offscreen renderer.

    Use as a context manager (closes the GL context). ``draw(original (P, 3), ghost (P, 3) or None,
    lookat (3,), azimuth [deg], key)`` returns an (H, W, 3) uint8 image.
    """

    def __init__(self, names, parents, style: RenderStyle = DEFAULT_STYLE, lengths=None):
        self.style = style
        self.bones = bones_of(names, parents, lengths)
        xml = scene_xml(
            self.bones,
            skeletons=(("o_", ORIGINAL_RGBA), ("g_", GHOST_RGBA)),
            visual=True,
            quality=(style.multisample, style.slices, style.stacks, 4096 if style.shadows else 0),
        )
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        B = len(self.bones.child)
        self._geo = np.arange(1, 2 * B + 1)
        self._ghost = np.arange(B + 1, 2 * B + 1)
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

    def draw(self, original, ghost=None, *, lookat, azimuth: float, key: bool = False):
        m, d = self.model, self.data
        poses = [original, original if ghost is None else ghost]
        c, q, h = bone_poses(self.bones, np.stack(poses))
        if self.style.layout == "side" and ghost is not None:
            a = np.radians(azimuth)
            right = np.array([np.sin(a), -np.cos(a), 0.0])  # camera's right on screen
            c[0] -= 0.5 * self.style.side_offset * right
            c[1] += 0.5 * self.style.side_offset * right
        d.mocap_pos[:] = c.reshape(-1, 3)
        d.mocap_quat[:] = q.reshape(-1, 4)
        m.geom_size[self._geo, 1] = h.reshape(-1)
        m.geom_rgba[self._ghost] = KEY_RGBA if key else GHOST_RGBA
        if ghost is None:
            m.geom_rgba[self._ghost, 3] = 0.0
        mujoco.mj_kinematics(m, d)
        self.camera.lookat[:] = lookat
        self.camera.azimuth = azimuth
        self.renderer.update_scene(d, camera=self.camera)
        img = self.renderer.render()
        top = img[: self._sky_rows]
        empty = (top[..., 0] | top[..., 1] | top[..., 2]) == 0
        np.copyto(top, self._sky[: self._sky_rows], where=empty[..., None])
        return img


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
    bottom with a tick per keyframe and the playhead at frame ``t`` of ``n``. Returns a new image."""
    img = Image.fromarray(image)
    g = ImageDraw.Draw(img, "RGBA")
    W, H = img.size
    s = max(11, H // 32)
    font = _font(s)
    y = 6
    for line in lines:
        g.rectangle([4, y - 2, 8 + g.textlength(line, font=font), y + s + 2], fill=(0, 0, 0, 110))
        g.text((6, y), line, fill=(255, 255, 255, 255), font=font)
        y += s + 6
    if key:
        g.rectangle([W - 140, 6, W - 6, 6 + s + 8], fill=(30, 170, 70, 220))
        g.text((W - 132, 10), "KEYFRAME", fill=(255, 255, 255, 255), font=font)
        g.rectangle([0, 0, W - 1, H - 1], outline=(30, 170, 70, 255), width=4)
    y0, y1, x0, x1 = H - 22, H - 8, 12, W - 12
    g.rectangle([x0, y0, x1, y1], fill=(0, 0, 0, 90))

    def x_of(k):
        return x0 + (x1 - x0) * (k / max(n - 1, 1))

    for k in keyframes:
        g.rectangle([x_of(k) - 1, y0 - 3, x_of(k) + 1, y1 + 3], fill=(30, 170, 70, 255))
    g.rectangle([x0, y0 + 5, x_of(t), y1 - 5], fill=(255, 255, 255, 200))
    g.polygon([(x_of(t) - 5, y0 - 6), (x_of(t) + 5, y0 - 6), (x_of(t), y0)], fill=(255, 255, 255))
    return np.asarray(img)


def render_frames(
    original: PointMotion,
    reconstruction: PointMotion | None = None,
    *,
    keyframes=(),
    method: str = "",
    style: RenderStyle = DEFAULT_STYLE,
    frames=None,
    progress: bool = False,
    renderer: SkeletonRenderer | None = None,
):
    """Yield annotated (H, W, 3) uint8 frames of ``original`` with ``reconstruction`` as a ghost.

    Args:
        original: (T, P', 3) points; restricted to the reconstruction's points when one is given.
        reconstruction: (T, P, 3) points or ``None`` (original alone).
        keyframes: frame indices marked as they pass.
        method: name in the caption.
        frames: which frame indices to render (default all).
        renderer: the clip's :class:`SkeletonRenderer` (same points and style), reused and left
            open; one is made and closed here when None.
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
    if renderer is not None and (renderer.bones.names != orig.names or renderer.style != style):
        raise ValueError("the renderer was built for other points or another style")
    owned = renderer is None
    r = SkeletonRenderer(orig.names, orig.parents, style) if owned else renderer
    try:
        for t in it:
            img = r.draw(
                orig.positions[t], None if rec is None else rec.positions[t],
                lookat=lookat[t], azimuth=azimuth, key=t in keyset,
            )  # fmt: skip
            lines = [f"{method or 'original'}   W = {len(keys)}   frame {t + 1}/{T}"]
            if err is not None:
                lines.append(
                    f"MPJPE now {1e3 * err[t]:.1f} mm, running mean {1e3 * err[: t + 1].mean():.1f} mm"
                )
            yield annotate(img, lines, t=t, n=T, keyframes=keys, key=t in keyset)
    finally:
        if owned:
            r.close()


def write_video(frames, path: str | os.PathLike, fps: float) -> Path:
    """Encode (H, W, 3) uint8 frames as an H.264 mp4 (yuv420p, fast start) atomically."""
    import imageio.v2 as imageio  # lazy: heavy optional video dependency, only to write an mp4

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.mp4")
    try:
        w = imageio.get_writer(
            tmp, fps=fps, codec="libx264", quality=7, pixelformat="yuv420p", macro_block_size=16,
            ffmpeg_log_level="error", ffmpeg_params=["-movflags", "+faststart"],
        )  # fmt: skip
        with w:
            for f in frames:
                w.append_data(f)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
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


def keyframe_sheet(
    original: PointMotion,
    reconstruction: PointMotion | None,
    keyframes,
    path,
    *,
    method: str = "",
    style: RenderStyle = DEFAULT_STYLE,
    cols: int = 5,
    renderer: SkeletonRenderer | None = None,
) -> Path:
    """PNG contact sheet of the keyframes (original with the reconstruction's ghost);
    ``renderer`` as in :func:`render_frames`."""
    keys = sorted(int(k) for k in keyframes)
    imgs = list(
        render_frames(
            original,
            reconstruction,
            keyframes=keys,
            method=method,
            style=style,
            frames=keys,
            renderer=renderer,
        )  # fmt: skip
    )
    return contact_sheet(imgs, [f"keyframe {k}" for k in keys], path, cols=cols)
