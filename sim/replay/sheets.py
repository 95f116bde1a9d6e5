"""Still images of a motion: a contact sheet of frames, and a method's keyframe filmstrip (the
keyframes and the worst frame between each pair). PNGs written atomically.

Units: metres, z up; frames numbered from 0.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from sim.errors import UsageError
from sim.files import write_atomic
from sim.motion.points import PointMotion
from sim.physics.foot_state import FootState
from sim.replay.annotate import default_font, foot_frame
from sim.replay.render import RenderStyle, SkeletonRenderer, camera_path


def contact_sheet(images, labels, path: str | os.PathLike, *, cols: int = 4) -> Path:
    """Tile (H, W, 3) uint8 ``images`` with ``labels`` into one PNG written atomically."""
    images = list(images)
    if not images:
        raise UsageError("a contact sheet needs at least one image")
    H, W = images[0].shape[:2]
    cols = min(cols, len(images))
    rows = -(-len(images) // cols)
    sheet = Image.new("RGB", (cols * W, rows * H), (255, 255, 255))
    g = ImageDraw.Draw(sheet)
    font = default_font(max(12, H // 24))
    for i, (im, lab) in enumerate(zip(images, labels, strict=True)):
        x, y = (i % cols) * W, (i // cols) * H
        sheet.paste(Image.fromarray(im), (x, y))
        g.rectangle([x, y + H - 30, x + g.textlength(lab, font=font) + 12, y + H], fill=(0, 0, 0))
        g.text((x + 6, y + H - 27), lab, fill=(255, 255, 255), font=font)
    path = Path(path)
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
    boxes=(),
) -> Path:
    """PNG filmstrip of a method's keyframes and what happens between them.

    Top row: the original at each keyframe (the poses the method kept; the reconstruction equals
    them there). Bottom row, set between its two keyframes: the frame of largest MPJPE inside each
    interval, the reconstruction's ghost over the original, labelled with frame and error. Frames
    numbered from 0. Tiles are portrait crops (``style``, default 224x320) with the camera on the
    tile's own root, all from the clip's side, so poses read large and distinct. ``boxes``: the
    clip's static scene (:class:`~sim.replay.render.SkeletonRenderer`), drawn in every tile.
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
    font = default_font(max(15, th // 18))
    head = f"{method or 'original'}: keyframes (top)" + (
        ", the worst frame between each pair (bottom, orange ghost: the reconstruction)"
        if worst
        else ""
    )
    g.text((6, 6), head, fill=(30, 30, 30), font=default_font(22))
    with SkeletonRenderer(orig.names, orig.parents, style, ground_z=ground_z, boxes=boxes) as r:

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
    write_atomic(path, lambda f: sheet.save(f, format="PNG", optimize=True))
    return path
