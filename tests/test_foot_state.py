"""Foot states drawn by the renderer (sim.physics.foot_state.foot_states): the original's feet in
contact from the sole's geometry, and the reconstruction's float, sink and skate flags, against
motions built so the answer is known frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

from sim.motion.points import PointMotion
from sim.physics.feet import sole
from sim.physics.foot_state import FootState, foot_states
from sim.physics.ground import estimate_ground

NAMES = ("root", "ltibia", "lfoot", "rtibia", "rfoot")
PARENTS = np.array([-1, 0, 1, 0, 3])
T, FPS = 40, 30.0


def standing(ground=0.0):
    """Root 0.9 m up, ankles 8 cm and balls 2.5 cm above ``ground``, nothing moving."""
    p = np.zeros((T, 5, 3))
    p[:, 0] = [0, 0, 0.9]
    p[:, 1] = [0, 0.1, 0.08]
    p[:, 2] = [0.12, 0.1, 0.025]
    p[:, 3] = [0, -0.1, 0.08]
    p[:, 4] = [0.12, -0.1, 0.025]
    p[..., 2] += ground
    return p


def motion(p):
    return PointMotion(NAMES, PARENTS, p, FPS)


def ground_of(p):
    return estimate_ground(p, NAMES, FPS)


def test_the_ground_is_where_the_soles_rest():
    p = standing(0.07)
    g = ground_of(p)
    s = sole(p, NAMES)
    lowest = (s.centres[0, :, 2] - s.radius).min()
    assert g.z == pytest.approx(lowest) and g.sides == ("l", "r") and g.fits
    np.testing.assert_allclose(g.offset, 0.0, atol=1e-12)


def test_standing_still_is_contact_without_flags():
    p = standing(0.05)
    s = foot_states(motion(p), motion(p), ground_of(p))
    assert isinstance(s, FootState) and s.points == ("ltibia", "lfoot", "rtibia", "rfoot")
    balls = [1, 3]
    assert s.contact[:, balls].all() and s.rec_contact[:, balls].all()
    assert not (s.floating.any() or s.sinking.any() or s.skating.any())


def test_lifted_foot_leaves_contact_and_comes_back():
    p = standing()
    ground = ground_of(p)
    p[10:20, 1:3, 2] += 0.15  # left foot up for ten frames
    s = foot_states(motion(p), None, ground)
    assert not s.contact[10:20, :2].any() and s.contact[:10, 1].all() and s.contact[20:, 1].all()
    assert s.contact[:, 3].all()  # the right foot stays down
    assert not (s.floating.any() or s.sinking.any() or s.skating.any())


def test_float_sink_and_skate_flags_where_built():
    orig = standing()
    r = standing()
    r[5:10, 1:3, 2] += 0.06  # the left foot floats 6 cm
    r[20:25, 3:5, 2] -= 0.05  # the right foot sinks 5 cm below the floor
    r[30:, 3:5, 0] += np.arange(T - 30)[:, None] * 1.0 / FPS  # the right foot slides at 1 m/s
    s = foot_states(motion(orig), motion(r), ground_of(orig))
    f = {n: i for i, n in enumerate(s.points)}
    assert set(np.flatnonzero(s.floating[:, f["lfoot"]])) == set(range(5, 10))
    assert set(np.flatnonzero(s.sinking[:, f["rfoot"]])) == set(range(20, 25))
    skate = set(np.flatnonzero(s.skating[:, f["rfoot"]]))
    assert set(range(31, T)) <= skate <= set(range(29, T))  # central differences at the start
    assert not s.floating[:, [f["rtibia"], f["rfoot"]]].any()
    assert s.skating[:, [f["ltibia"], f["lfoot"]]].sum() == 0
    # the sliding foot stays in contact (contact may slide: skating is measured, not excluded)
    assert s.rec_contact[31:, f["rfoot"]].all()
