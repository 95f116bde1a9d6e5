"""Foot states drawn by the renderer: contact from height and speed, and the reconstruction's
float, sink and skate flags, against motions built so the answer is known frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

from sim.replay.checks import PointMotion
from sim.replay.foot_state import FootState, foot_points, simple_foot_states, simple_ground

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


def test_foot_points_and_ground():
    assert foot_points(("root", "ltibia", "lfoot", "ltoes", "tibia", "lhand")) == (
        "ltibia", "lfoot", "ltoes",
    )  # fmt: skip
    assert simple_ground(motion(standing(0.07))) == pytest.approx(0.07)  # ball one radius up


def test_standing_still_is_contact_without_flags():
    orig = motion(standing(0.05))
    s = simple_foot_states(orig, orig, ground_z=0.05)
    assert isinstance(s, FootState) and s.points == ("ltibia", "lfoot", "rtibia", "rfoot")
    assert s.contact.all() and s.rec_contact.all()
    assert not (s.floating.any() or s.sinking.any() or s.skating.any())


def test_lifted_foot_is_not_in_contact():
    p = standing()
    p[10:20, 1:3, 2] += 0.15  # left foot up for ten frames
    s = simple_foot_states(motion(p), ground_z=0.0)
    lifted = np.zeros(T, bool)
    lifted[10:20] = True
    np.testing.assert_array_equal(s.contact[:, 1], ~lifted)
    assert s.contact[:, 2:].all()  # the right foot stays down


def test_float_sink_and_skate_flags_where_built():
    orig = motion(standing())
    r = standing()
    r[5:10, 2, 2] += 0.06  # left ball floats 6 cm
    r[20:25, 4, 2] -= 0.05  # right ball sinks 5 cm below its rest height
    r[30:, 3, 0] += np.arange(T - 30) * 1.0 / FPS  # right ankle slides at 1 m/s
    s = simple_foot_states(orig, motion(r), ground_z=0.0)
    f = {n: i for i, n in enumerate(s.points)}
    assert set(np.flatnonzero(s.floating[:, f["lfoot"]])) == set(range(5, 10))
    assert set(np.flatnonzero(s.sinking[:, f["rfoot"]])) == set(range(20, 25))
    skate = set(np.flatnonzero(s.skating[:, f["rtibia"]]))
    assert set(range(31, T)) <= skate <= set(range(29, T))  # central differences at the start
    others = np.ones_like(s.floating)
    others[5:10, f["lfoot"]] = False
    assert not (s.floating & others).any()
    assert s.sinking.sum() == 5 and s.skating[:, [f["ltibia"], f["lfoot"], f["rfoot"]]].sum() == 0
