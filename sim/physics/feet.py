"""The foot: which points stand for it, and when one of them touches the floor.

The one definition of foot points and contact thresholds: :mod:`sim.physics.ground` (the floor),
:mod:`sim.physics.contacts` (labels and metrics) and :mod:`sim.replay.checks` (the kinematic
replay's foot contacts) all read it.

Units: metres, metres per second.
"""

from __future__ import annotations

#: Foot points, in the order metrics use them: (ankle ~ heel, ball, toes) per side. Each names the
#: bone whose *end* is the point: ``ltibia`` ends at the ankle, ``lfoot`` at the ball (toe base),
#: ``ltoes`` at the toe tip.
FOOT_POINTS: tuple[str, ...] = ("ltibia", "lfoot", "ltoes", "rtibia", "rfoot", "rtoes")
#: Foot point -> the part of the foot it stands for.
FOOT_PART = {
    "ltibia": "l_heel", "lfoot": "l_ball", "ltoes": "l_toes",
    "rtibia": "r_heel", "rfoot": "r_ball", "rtoes": "r_toes",
}  # fmt: skip
#: The sole's points (ball and toes), which rest on the floor in stance.
SOLE_POINTS: tuple[str, ...] = ("lfoot", "ltoes", "rfoot", "rtoes")
#: [m] radius of the sole's bone capsules in the replay scene (``sim.replay.capsules``): the floor
#: plane on which those capsules rest lies this far below the sole points' stance level.
SOLE_RADIUS = 0.02

#: [m] a point enters contact below H_ON above its stance level, leaves above H_OFF.
H_ON, H_OFF = 0.03, 0.05
#: [m/s] a point enters contact slower than V_ON, leaves faster than V_OFF ...
V_ON, V_OFF = 0.3, 0.5
#: [m/s] ... or, while another point of the same foot is slow enough to enter contact (the pivot
#: of a foot rolling heel to toe), slower than V_ROLL: the rolling points move at 0.5-2 m/s.
V_ROLL = 2.5


def side(point: str) -> str:
    """``"l"`` or ``"r"``: the foot a foot point belongs to."""
    return point[0]


def foot_points(names) -> tuple[str, ...]:
    """The foot points among ``names``, in :data:`FOOT_POINTS` order."""
    return tuple(n for n in FOOT_POINTS if n in names)
