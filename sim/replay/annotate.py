"""What is drawn over a rendered frame: caption lines, a KEYFRAME badge and border, a timeline of
the keyframes, and the foot flags' phrases (:class:`sim.physics.foot_state.FootState`).

Frames numbered from 0, as everywhere in the report; images (H, W, 3) uint8.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from sim.physics.foot_state import FootState


def default_font(size: int):
    """PIL's default font at ``size`` [px]."""
    return ImageFont.load_default(size=size)


def annotate(image: np.ndarray, lines, *, t: int, n: int, keyframes, key: bool) -> np.ndarray:
    """Caption lines at the top left, a KEYFRAME badge on keyframes, and a timeline strip at the
    bottom with a tick per keyframe and the playhead at frame ``t`` of ``n``. Returns a new image.

    Only the two bands that carry drawing go through PIL (converting a whole frame costs more
    than drawing on it); the keyframe border is set directly."""
    out = np.array(image, dtype=np.uint8, copy=True)
    H, W = out.shape[:2]
    s = max(11, H // 32)
    font = default_font(s)
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
