"""Offscreen rendering: images show the figures, the camera follows the root, files read back."""

from __future__ import annotations

import imageio.v2 as imageio
import numpy as np
import pytest
from PIL import Image

from sim.motion.synthetic import synthetic_motion
from sim.replay.checks import PointMotion, from_clip
from sim.replay.render import (
    RenderStyle,
    SkeletonRenderer,
    annotate,
    camera_path,
    contact_sheet,
    render_frames,
    write_video,
)

SMALL = RenderStyle(width=192, height=144)  # multiples of 16: no resizing by the encoder


@pytest.fixture(scope="module")
def motion() -> PointMotion:
    return from_clip(synthetic_motion(1.0, seed=1))


@pytest.fixture(scope="module")
def renderer(gl_context, motion):
    # skips only when no GL context exists (conftest.gl_context); our scene's errors fail
    with SkeletonRenderer(motion.names, motion.parents, SMALL) as r:
        yield r


def test_frame_shows_the_figure_against_the_scene(renderer, motion):
    p = motion.positions[0]
    img = renderer.draw(p, None, lookat=[p[0, 0], p[0, 1], 0.9], azimuth=90.0)
    assert img.shape == (144, 192, 3) and img.dtype == np.uint8
    empty = renderer.draw(p + [50.0, 0, 0], None, lookat=[p[0, 0], p[0, 1], 0.9], azimuth=90.0)
    figure_pixels = np.any(np.abs(img.astype(int) - empty.astype(int)) > 30, axis=-1)
    assert 0.02 < figure_pixels.mean() < 0.5  # a figure, centred, neither missing nor filling all
    rows, cols = np.nonzero(figure_pixels)
    assert abs(cols.mean() - 96) < 30


def test_camera_follows_the_root(renderer, motion):
    p = motion.positions[0]
    look, az = camera_path(np.repeat(p[None, 0], 3, axis=0), 30.0)
    np.testing.assert_allclose(look[:, :2], p[None, 0, :2].repeat(3, 0))
    shift = np.array([7.3, -4.1, 0.0])
    masks = []
    for d in (0.0, shift):
        img = renderer.draw(p + d, None, lookat=look[0] + d, azimuth=az)
        empty = renderer.draw(p + 100.0, None, lookat=look[0] + d, azimuth=az)  # floor only
        masks.append(np.any(np.abs(img.astype(int) - empty.astype(int)) > 30, axis=-1))
    overlap = (masks[0] & masks[1]).sum() / (masks[0] | masks[1]).sum()
    assert masks[0].mean() > 0.02 and overlap > 0.9  # same figure, same place on screen


def test_camera_path_looks_across_the_travel_and_keeps_up():
    T = 90
    root = np.zeros((T, 3))
    root[:, 1] = np.linspace(0.0, 3.0, T)  # walking along +y
    look, az = camera_path(root, 30.0)
    assert az % 360 == pytest.approx(180.0)  # looking along -x: the travel crosses the screen
    assert np.abs(look[:, :2] - root[:, :2]).max() < 0.35  # the figure never leaves the middle
    # no lag mid-walk (one-way smoothing would trail by speed * 0.3 s = 0.1 m)
    assert np.abs(look[T // 2, :2] - root[T // 2, :2]).max() < 0.01


def test_ghost_and_keyframe_marks_change_the_picture(renderer, motion):
    p = motion.positions[0]
    look = [p[0, 0], p[0, 1], 0.9]
    alone = renderer.draw(p, None, lookat=look, azimuth=90.0)
    ghost = renderer.draw(p, p + [0, 0.4, 0], lookat=look, azimuth=90.0)
    keyed = renderer.draw(p, p + [0, 0.4, 0], lookat=look, azimuth=90.0, key=True)
    assert np.abs(alone.astype(int) - ghost.astype(int)).max() > 50
    green = keyed[..., 1].astype(int) - keyed[..., 0]
    assert (green > 60).sum() > (ghost[..., 1].astype(int) - ghost[..., 0] > 60).sum()
    marked = annotate(alone, ["method"], t=5, n=10, keyframes=[0, 5, 9], key=True)
    assert marked.shape == alone.shape and np.any(marked != alone)


def test_video_and_contact_sheet_read_back(tmp_path, renderer, motion):
    rec = PointMotion(motion.names, motion.parents, motion.positions + [0, 0.05, 0], motion.fps)
    frames = list(render_frames(motion, rec, keyframes=[0, 10, 29], method="m", style=SMALL))
    assert len(frames) == motion.n_frames
    path = write_video(frames, tmp_path / "v.mp4", motion.fps)
    with imageio.get_reader(path, format="FFMPEG") as reader:
        back = [f for f in reader]  # (list() asks len(), which is inf for ffmpeg streams)
    assert len(back) == motion.n_frames and back[0].shape == (144, 192, 3)
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind
    sheet = contact_sheet(frames[:5], [str(i) for i in range(5)], tmp_path / "s.png", cols=2)
    assert Image.open(sheet).size == (2 * 192, 3 * 144)


def same_picture(a, b) -> bool:
    """Equal up to the GL rasteriser's rounding: a few pixels may differ by one grey level."""
    d = np.abs(a.astype(int) - b.astype(int))
    return d.max() <= 1 and (d > 0).mean() < 1e-3


def test_a_reused_renderer_draws_what_a_fresh_one_draws(renderer, motion):
    rec = PointMotion(motion.names, motion.parents, motion.positions + [0, 0.1, 0], motion.fps)
    keys, frames = [0, 15, 29], [0, 7, 15]
    kw = dict(keyframes=keys, method="m", style=SMALL, frames=frames)
    fresh = list(render_frames(motion, rec, **kw))
    shared = list(render_frames(motion, rec, renderer=renderer, **kw))
    alone = list(render_frames(motion, None, renderer=renderer, **kw))  # ghost hidden, then back
    again = list(render_frames(motion, rec, renderer=renderer, **kw))
    for a, b, c in zip(fresh, shared, again, strict=True):
        assert same_picture(a, b) and same_picture(a, c)
    assert not any(same_picture(a, b) for a, b in zip(alone, fresh, strict=True))
    with pytest.raises(ValueError, match="other points or another style"):
        list(
            render_frames(motion, rec, keyframes=keys, style=RenderStyle(64, 48), renderer=renderer)
        )
