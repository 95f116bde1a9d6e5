"""The foot: its sole's geometry, and the thresholds of when it touches the floor.

Where the sole's geometry and the foot-floor contact thresholds are defined (which points stand
for the feet: :mod:`sim.model.kinematics`; the contact labels made with them:
:mod:`sim.physics.contacts`): :mod:`sim.physics.ground` (the floor), :mod:`sim.physics.contacts`
(labels), :mod:`sim.analysis.job` (where ground forces act), :mod:`sim.replay.checks` (the
kinematic replay's foot contacts) and the simulator's feet (:mod:`sim.simulate`) all read it.
Bones touching each other (self-penetration) are another idea: :mod:`sim.replay.checks`.

The sole is the humanoid's own foot geometry (:func:`sim.model.humanoid.build_mjcf`, the body the
dynamics and the simulator use): the foot bone's capsule from the ankle to the ball, shortened by
half its radius at both ends, and the toes' capsule (a sphere when the bone is shorter than its
diameter). Its surface reaches lowest at one of the spheres that end those capsules: the *heel*
(the foot capsule's ankle end), the *ball* (its other end) and the *toes*. A foot touches the
floor when the lowest of its spheres does; a foot rolling heel to toe moves its lowest point from
one sphere to the next while the sphere on the floor barely moves.

Units: metres, metres per second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.errors import UsageError
from sim.model.humanoid import capsule_radius
from sim.model.kinematics import SIDES

#: Foot point -> the part of the sole nearest it (what the renderer's foot balls stand for).
FOOT_PART = {
    "ltibia": "l_heel", "lfoot": "l_ball", "ltoes": "l_toes",
    "rtibia": "r_heel", "rfoot": "r_ball", "rtoes": "r_toes",
}  # fmt: skip
#: [m] a foot enters contact when its lowest sole point comes within ``max(CONTACT_GAP, 2 x the
#: floor's spread)`` of the floor during the frame, and leaves it once that point is a further
#: floor spread up (hysteresis against marker noise; none on a noise-free floor).
CONTACT_GAP = 0.005
#: [m/s] a foot enters contact only while its lowest sole sphere moves slower than this
#: horizontally (a swinging foot passes a centimetre over the floor at 3-5 m/s); once in contact
#: it may slide (skating is measured, not excluded).
ENTER_SPEED = 1.0
#: Rolling contact: a foot turning faster than ROLL_RATE [rad/s] about an axis across it, whose
#: instantaneous centre of rotation lies within ROLL_TOLERANCE [m] of the floor and along the foot
#: (from ROLL_BACK behind the ankle to ROLL_FRONT beyond the ball [m]), rolls on the floor there:
#: the heel rocker of a heel strike, the forefoot rocker of a push-off, whatever the sole's shape.
ROLL_RATE, ROLL_TOLERANCE, ROLL_BACK, ROLL_FRONT = 3.0, 0.015, 0.10, 0.10
#: Rolling counts only while the foot's lowest sole sphere is within ROLL_GAP [m] of the floor
#: (a foot swinging in, turning about a point near the floor, is not yet on it).
ROLL_GAP = 0.03
#: A foot in contact stays in contact while its lowest sole sphere stays within HOLD_GAP [m] of
#: the floor and moves slower than HOLD_SPEED [m/s] horizontally: a forefoot pushing off pivots
#: about toes that bend, where the humanoid's rigid toes capsule rises 1-2 cm.
HOLD_GAP, HOLD_SPEED = 0.035, 0.3
#: A foot whose lowest sole sphere moves slower than STILL_SPEED [m/s] for STILL_TIME [s] or
#: longer within HOLD_GAP of the floor is planted (a foot standing on its toes, a dancer's
#: forefoot) whatever its gap: a sole held still in the air stands higher (a one-leg balance).
STILL_SPEED, STILL_TIME = 0.1, 0.1
#: [m] the sole spheres of a foot in contact that are at most this far above the floor bear
#: ground forces (the heel of a foot standing on its toes does not).
SUPPORT_GAP = 0.03


@dataclass(frozen=True)
class Sole:
    """The sole spheres of a motion's feet (T frames, S spheres).

    Attributes:
        centres: (T, S, 3) sphere centres [m].
        radius: (S,) sphere radii [m].
        side: (S,) ``"l"`` or ``"r"``.
        part: (S,) ``"heel"``, ``"ball"`` or ``"toes"``.
        body: (S,) the bone whose body carries the sphere (``"lfoot"``, ``"ltoes"``): where a
            ground force on it acts in the humanoid.
    """

    centres: np.ndarray
    radius: np.ndarray
    side: tuple[str, ...]
    part: tuple[str, ...]
    body: tuple[str, ...]

    @property
    def sides(self) -> tuple[str, ...]:
        """The feet present, in :data:`SIDES` order."""
        return tuple(s for s in SIDES if s in self.side)

    def of(self, s: str) -> np.ndarray:
        """(k,) indices of the spheres of foot ``s``."""
        return np.array([k for k, x in enumerate(self.side) if x == s], dtype=int)

    @property
    def bottoms(self) -> np.ndarray:
        """(T, S, 3) the lowest surface point of each sphere (centre minus radius along z) [m]."""
        b = np.array(self.centres, dtype=np.float64)
        b[..., 2] -= self.radius
        return b


def _capsule_ends(a: np.ndarray, b: np.ndarray, r: float):
    """Centres of the end spheres of a capsule on the segment a->b (T, 3) shortened by r/2 at both
    ends (as :func:`sim.model.humanoid.build_mjcf` shapes bones); one sphere at the middle when
    the bone is no longer than its diameter."""
    d = b - a
    L = np.linalg.norm(d, axis=-1, keepdims=True)
    if float(np.mean(L)) <= 2 * r:
        return [(a + b) / 2]
    u = d / np.maximum(L, 1e-9)
    return [a + u * (r / 2), b - u * (r / 2)]


def sole(positions: np.ndarray, names) -> Sole:
    """The sole spheres of the feet whose ankle and ball are among ``names``.

    Args:
        positions: (T, P, 3) points [m] named ``names`` (P,): per foot the ankle (``ltibia``) and
            ball (``lfoot``), and the toe tip (``ltoes``) when present (without it the foot has no
            toes sphere).
    Returns:
        The :class:`Sole` (ValueError when no foot has both ankle and ball).
    """
    names = tuple(names)
    p = np.asarray(positions, dtype=np.float64)
    centres, radius, sides, parts, bodies = [], [], [], [], []
    for s in SIDES:
        if s + "tibia" not in names or s + "foot" not in names:
            continue
        ankle, ball = p[:, names.index(s + "tibia")], p[:, names.index(s + "foot")]
        r = capsule_radius(s + "foot", float(np.linalg.norm(ball - ankle, axis=-1).mean()))
        ends = _capsule_ends(ankle, ball, r)
        for c, part in zip(ends, ("heel", "ball") if len(ends) == 2 else ("ball",), strict=True):
            centres.append(c)
            radius.append(r)
            sides.append(s)
            parts.append(part)
            bodies.append(s + "foot")
        if s + "toes" in names:
            tip = p[:, names.index(s + "toes")]
            rt = capsule_radius(s + "toes", float(np.linalg.norm(tip - ball, axis=-1).mean()))
            for c in _capsule_ends(ball, tip, rt):
                centres.append(c)
                radius.append(rt)
                sides.append(s)
                parts.append("toes")
                bodies.append(s + "toes")
    if not centres:
        raise UsageError(f"no foot with both ankle and ball among {names}; need e.g. ltibia, lfoot")
    return Sole(
        np.stack(centres, axis=1), np.array(radius), tuple(sides), tuple(parts), tuple(bodies)
    )
