"""Videos of an original motion and its reconstruction: annotated frames
(:func:`render_frames`) and the mp4 writer (:func:`write_video`).

Units: metres, z up; frames at the motion's fps.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sim.errors import UsageError, require_positive, require_type
from sim.files import written_by
from sim.motion.points import PointMotion
from sim.physics.foot_state import FootState
from sim.replay.annotate import annotate, caption, foot_frame
from sim.replay.render import (
    DEFAULT_STYLE,
    RenderStyle,
    SkeletonRenderer,
    camera_path,
    scene_boxes,
)


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
    boxes=(),
):
    """Yield annotated (H, W, 3) uint8 frames of ``original`` with ``reconstruction`` as a ghost.

    Args:
        original: (T, P', 3) points; restricted to the reconstruction's points when one is given.
        reconstruction: (T, P, 3) points or ``None`` (original alone).
        keyframes: frame indices marked as they pass.
        method: name in the caption.
        frames: which frame indices to render (default all).
        feet: foot contact and flags per frame (e.g. :func:`sim.physics.foot_state.foot_states`).
        ground_z: height of the drawn floor [m].
        boxes: the clip's static scene in the points' frame (``sim.simulate.terrain.Box``
            or :func:`~sim.replay.render.scene_boxes` triples; default none).
        renderer: the clip's :class:`SkeletonRenderer` (same points, style and ground), reused
            and left open (same boxes too); one is made and closed here when None.

    Raises (when called, before any frame):
        ArgumentTypeError: ``original`` or ``reconstruction`` not a :class:`PointMotion`.
    """
    require_type(original, PointMotion, "original")
    if reconstruction is not None:
        require_type(reconstruction, PointMotion, "reconstruction")
    return _frames(original, reconstruction, keyframes, method, style, frames, progress, feet,
                   ground_z, renderer, scene_boxes(boxes))  # fmt: skip


def _frames(original, reconstruction, keyframes, method, style, frames, progress, feet, ground_z,
            renderer, boxes):  # fmt: skip
    """The generator behind :func:`render_frames` (arguments checked)."""
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
        or renderer.boxes != boxes
    ):
        raise UsageError("the renderer was built for other points, another style, ground or scene")
    owned = renderer is None
    r = renderer
    if owned:
        r = SkeletonRenderer(orig.names, orig.parents, style, ground_z=ground_z, boxes=boxes)
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

    require_positive(fps, "fps")
    path = Path(path)
    with written_by(path, root=root, suffix=".mp4") as tmp:
        w = imageio.get_writer(
            tmp, fps=fps, codec="libx264", quality=7, pixelformat="yuv420p", macro_block_size=16,
            ffmpeg_log_level="error",
            ffmpeg_params=["-movflags", "+faststart", "-preset", X264_PRESET],
        )  # fmt: skip
        with w:
            for f in frames:
                if np.ndim(f) != 3 or np.shape(f)[2] != 3:
                    raise UsageError(f"video frames must be (H, W, 3); got {np.shape(f)}")
                w.append_data(f)
    return path
