"""A clip's scene in the renderer: static boxes drawn exactly where the camera projects their
corners, footprints on their tops, the figures unchanged, and nothing drawn without boxes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from matplotlib.path import Path as Polygon
from PIL import Image
from scipy.ndimage import binary_dilation, binary_erosion
from scipy.spatial import ConvexHull

from sim.motion.synthetic import synthetic_motion
from sim.replay.checks import from_clip
from sim.replay.render import RenderStyle, SkeletonRenderer, scene_boxes
from sim.replay.sheets import keyframe_sheet
from sim.replay.video import render_frames

STYLE = RenderStyle(width=192, height=144, blob_shadow=False)


@pytest.fixture(scope="module")
def motion():
    return from_clip(synthetic_motion(1.0, seed=1))


def _corners(centre, half, yaw, ground=0.0) -> np.ndarray:
    """(8, 3) [m] the corners of a box's part above ``ground`` (buried parts are hidden)."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = []
    for i in (-1, 1):
        for j in (-1, 1):
            x, y = i * half[0], j * half[1]
            xy = np.array(centre[:2]) + [c * x - s * y, s * x + c * y]
            for z in (max(centre[2] - half[2], ground), centre[2] + half[2]):
                out.append([*xy, z])
    return np.array(out)


def _inside(renderer, corners, shape) -> np.ndarray:
    """(H, W) bool: pixel centres inside the convex hull of the projected ``corners``."""
    uv = renderer.project(corners)
    hull = Polygon(uv[ConvexHull(uv).vertices])
    rows, cols = np.mgrid[: shape[0], : shape[1]]
    centres = np.column_stack([cols.ravel() + 0.5, rows.ravel() + 0.5])
    return hull.contains_points(centres).reshape(shape)


def _sand(img) -> np.ndarray:
    """The boxes' warm colour: red well above blue (the floor is grey, the sky blue)."""
    i = img.astype(int)
    return i[..., 0] - i[..., 2] > 25


def test_a_box_is_drawn_where_its_projected_corners_say(gl_context, motion):
    p = motion.positions[0]
    look = np.array([p[0, 0], p[0, 1], 0.9])
    far = p + [100.0, 0, 0]  # the figure out of view: only floor, sky and the box
    # in front of the root, half buried as the inferred steps are (top 0.2 m above the floor)
    box = ((p[0, 0] + 0.1, p[0, 1] - 0.5, 0.05), (0.25, 0.15, 0.15), 0.5)
    with SkeletonRenderer(motion.names, motion.parents, STYLE) as r:
        bare = r.draw(far, None, lookat=look, azimuth=90.0)
    with SkeletonRenderer(motion.names, motion.parents, STYLE, boxes=[box]) as r:
        img = r.draw(far, None, lookat=look, azimuth=90.0)
        inside = _inside(r, _corners(*box), img.shape[:2])
        top = r.project([[box[0][0], box[0][1], 0.2]])[0]  # the top face's centre
        floor = r.project([[box[0][0] + 0.8, box[0][1], 0.0]])[0]  # floor beside it
    changed = np.any(np.abs(img.astype(int) - bare.astype(int)) > 8, axis=-1)
    near = binary_dilation(inside, iterations=2)
    core = binary_erosion(inside, iterations=2)
    assert inside.sum() > 300  # a box of a few hundred pixels, in view
    assert not (changed & ~near).any()  # nothing drawn outside its outline
    assert changed[core].mean() > 0.98  # and all of it drawn (opaque)
    u, w = top.astype(int)
    assert _sand(img)[w, u] and not _sand(bare)[w, u]
    u, w = floor.astype(int)
    assert not changed[w, u]


def test_figures_are_drawn_as_before_beside_boxes(gl_context, motion):
    """Boxes are world geoms numbered before the capsules: the figures' colours, radii and
    poses still reach the capsules (a box out of view changes no pixel of them)."""
    p = motion.positions[5]
    look = [p[0, 0], p[0, 1], 0.9]
    ghost = p + [0.3, 0.0, 0.0]
    box = ((p[0, 0], p[0, 1] + 40.0, 0.1), (0.2, 0.2, 0.1), 0.0)  # far behind the figure
    frames = []
    for boxes in ((), [box]):
        with SkeletonRenderer(motion.names, motion.parents, STYLE, boxes=boxes) as r:
            frames.append(r.draw(p, ghost, lookat=look, azimuth=90.0, key=True))
    d = np.abs(frames[0].astype(int) - frames[1].astype(int))
    assert (d > 2).mean() < 5e-3  # GL rounding at most (the ghost alone is ~10 % of pixels)


def test_what_stands_on_a_box_lies_on_its_top():
    """:meth:`SkeletonRenderer.surface` against the box's own geometry: a turned box covers a
    point its unturned footprint would not, and misses one that footprint would cover."""
    box = ((1.0, 2.0, 0.05), (0.3, 0.05, 0.15), np.pi / 4)
    r = SkeletonRenderer.__new__(SkeletonRenderer)  # no GL: surface() reads boxes and ground
    r.ground_z, r.boxes = 0.03, scene_boxes([box])
    along = np.array([1.0, 2.0]) + 0.25 * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    assert r.surface(along) == pytest.approx(0.2)
    assert r.surface(np.array([1.25, 2.0])) == 0.03  # inside the unturned box only
    assert r.surface(np.array([5.0, 5.0])) == 0.03
    disc = r._disc(along, 0.06, (0, 1, 0, 1), 0.002)
    assert disc[2][2] == pytest.approx(0.202)  # a footprint on the top, not under it


def test_render_frames_refuses_a_renderer_of_another_scene(gl_context, motion):
    box = ((0.0, 0.0, 0.1), (0.2, 0.2, 0.1), 0.0)
    with SkeletonRenderer(motion.names, motion.parents, STYLE) as r:
        with pytest.raises(ValueError, match="ground or scene"):
            list(render_frames(motion, None, style=STYLE, renderer=r, boxes=[box], frames=[0]))
    with SkeletonRenderer(motion.names, motion.parents, STYLE, boxes=[box]) as r:
        shared = next(render_frames(motion, None, style=STYLE, renderer=r, boxes=[box]))
    own = next(render_frames(motion, None, style=STYLE, boxes=[box]))
    assert (np.abs(shared.astype(int) - own.astype(int)) > 2).mean() < 5e-3


def test_filmstrip_tiles_draw_the_scene(gl_context, tmp_path, motion):
    tile = RenderStyle(width=96, height=128, distance=2.5)
    p = motion.positions[0]
    box = ((p[0, 0], p[0, 1], 0.05), (0.3, 0.3, 0.15), 0.0)  # under the root at frame 0
    imgs = []
    for boxes in ((), [box]):
        path = keyframe_sheet(motion, None, [0], tmp_path / f"k{len(boxes)}.png", style=tile,
                              boxes=boxes)  # fmt: skip
        imgs.append(np.asarray(Image.open(path).convert("RGB")))
    assert _sand(imgs[0]).sum() == 0 and _sand(imgs[1]).sum() > 100


def test_boxes_normalise_from_terrain_boxes():
    from sim.simulate.terrain import Box

    b = Box(np.array([1.0, 2.0, 0.1]), np.array([0.2, 0.3, 0.15]), 0.25)
    assert scene_boxes([b]) == (((1.0, 2.0, 0.1), (0.2, 0.3, 0.15), 0.25),)
    assert scene_boxes([]) == () and replace(STYLE) == STYLE
