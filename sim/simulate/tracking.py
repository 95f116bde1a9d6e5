"""What one tracking simulation produced (:class:`Tracking`), and the record a controller
keeps while it runs (:class:`TrackRecord`): states, controls, torques and the floor's forces on
the feet every ``record_every`` control ticks, the root wrench of every tick, the deepest
contact penetrations and the fall. Shared by ``sim.simulate.controller`` (the plain tracker)
and ``sim.simulate.wholebody``. "The floor" is the floor geom and the scene's terrain boxes
(:func:`floor_ids`, ``sim.simulate.terrain``): a foot on a step is on the floor.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import itemgetter

import mujoco
import numpy as np

from sim.model.kinematics import SOLE_POINTS
from sim.simulate.model import SOLE_GEOMS, TOE_GEOMS, G, total_mass
from sim.simulate.terrain import terrain_geoms


@dataclass
class Tracking:
    """What one simulation produced, sampled every ``record_every`` ticks.

    Attributes:
        qpos: (F, nq) and qvel: (F, nv) the simulator's state.
        assistance: (F,) root assistance force over body weight around each recorded tick: the
            norm of the mean force over the ``record_every`` ticks centred on it.
        assist_wrench: (F, 6) the applied root wrench (free-joint generalised force: force [N]
            in the world frame, torque [N m] in the root's frame), the same mean.
        actions: (F, nu) the actuator controls (target angles [rad], feed-forward included)
            set at each recorded tick.
        joint_torque: (F, nu) the torque [N m] each actuator applied at the recorded tick's
            first physics step (``data.actuator_force``, within the joint's limit).
        foot_force: (F, 2, 3) the floor's contact force [N, world frame] on the left and right
            foot (foot and toe geoms) at that step (``mj_contactForce``); a foot is in contact
            where its force is non-zero.
        fall_frame: the recorded frame where the fall was detected, -1 if none; from that tick
            on the assistance is off and the joints hold the pose of the fall at
            ``sim.simulate.controller.FALLEN_TONE`` of their stiffness and strength (no tracking, no feed-forward):
            the body stays down (no get-up is generated).
        fell: whether the body fell (``sim.simulate.falls``; see ``sim.simulate.controller.track``).
        fall_tick: the control tick whose state was found fallen first, -1 if none.
        ticks: control ticks simulated.
        mean_assistance_all: mean assistance over every tick.
        penetration: deepest floor contact penetration [m] seen at the control ticks (>= 0).
        self_penetration: deepest contact penetration [m] between two body geoms seen at the
            control ticks (self-collision keeps it small).
        contact_penetration: (F,) deepest floor contact penetration [m] at the recorded ticks, 0
            where nothing touches the floor (the steady figure: its median over contact frames).
        unstable: MuJoCo flagged a diverging position, velocity or acceleration
            (:func:`divergences`; it then resets the state, so the recorded motion jumps: such a
            simulation is not a motion).
    """

    qpos: np.ndarray
    qvel: np.ndarray
    assistance: np.ndarray
    assist_wrench: np.ndarray
    fell: bool
    ticks: int
    mean_assistance_all: float = 0.0
    penetration: float = 0.0
    unstable: bool = False
    contact_penetration: np.ndarray | None = None
    actions: np.ndarray | None = None
    joint_torque: np.ndarray | None = None
    foot_force: np.ndarray | None = None
    fall_frame: int = -1
    self_penetration: float = 0.0
    fall_tick: int = -1


def floor_ids(model) -> np.ndarray:
    """(K,) the geoms that are floor: the ``floor`` geom, then the scene's terrain boxes
    (``sim.simulate.terrain.terrain_geoms``; none on the empty floor)."""
    terrain = terrain_geoms(model)
    boxes = [] if terrain is None else terrain[0].tolist()
    return np.array([model.geom("floor").id, *boxes])


def foot_forces(model, data, floor, side: np.ndarray, out: np.ndarray) -> None:
    """Write into ``out`` (2, 3) the floor's contact force [N, world frame] on the left (row 0)
    and right (row 1) foot: ``floor`` the floor's geom id or ids (:func:`floor_ids`); ``side``
    (ngeom,) is 0/1 for a foot geom of that side, -1 else."""
    out[:] = 0.0
    f6 = np.zeros(6)
    floor = np.atleast_1d(floor)
    for c in range(data.ncon):
        con = data.contact[c]
        g1, g2 = con.geom
        if g1 in floor:
            s, sign = side[g2], 1.0  # the force acts from geom1 on geom2
        elif g2 in floor:
            s, sign = side[g1], -1.0
        else:
            continue
        if s < 0:
            continue
        mujoco.mj_contactForce(model, data, c, f6)
        out[s] += sign * (con.frame.reshape(3, 3).T @ f6[:3])


def foot_sides(model) -> np.ndarray:
    """(ngeom,) 0 for a left foot geom (sole point, sole or toe box), 1 for a right one, -1
    for every other geom (``foot_forces``' ``side``)."""
    side = np.full(model.ngeom, -1)
    for name in SOLE_POINTS + SOLE_GEOMS + TOE_GEOMS:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        if g >= 0:
            side[g] = 0 if name.startswith("l") else 1
    return side


def contact_depths(data, floor) -> tuple[float, float]:
    """The deepest penetration [m] (>= 0) of ``data``'s contacts with geom ``floor`` (an id or
    ids: :func:`floor_ids`) and of those between two other geoms (the body's self-contacts); 0
    where there is none."""
    n = data.ncon
    if not n:
        return 0.0, 0.0
    on_floor = np.isin(data.contact.geom[:n], floor).any(axis=1)
    depth = -data.contact.dist[:n]
    floor_depth = max(0.0, float(depth[on_floor].max())) if on_floor.any() else 0.0
    self_depth = max(0.0, float(depth[~on_floor].max())) if not on_floor.all() else 0.0
    return floor_depth, self_depth


class TrackRecord:
    """What ``track`` keeps: the states, controls, torques and foot forces every
    ``record_every`` ticks of ``T``, the root wrench of every tick, the deepest penetrations
    and the fall."""

    def __init__(self, model, T: int, record_every: int):
        F = (T + record_every - 1) // record_every
        self.T, self.F, self.every = T, F, record_every
        self.qpos = np.empty((F, model.nq))
        self.qvel = np.empty((F, model.nv))
        self.ctrl = np.empty((F, model.nu))
        self.torque = np.empty((F, model.nu))
        self.depth = np.zeros(F)
        self.foot = np.zeros((F, 2, 3))
        self.assist = np.empty(T)
        self.wrench = np.empty((T, 6))
        self.deepest = self.deepest_self = 0.0
        self.fall_frame = self.fall_tick = -1

    def state(self, i: int, data) -> None:
        """Record frame ``i``: ``data``'s state and controls."""
        self.qpos[i] = data.qpos
        self.qvel[i] = data.qvel
        self.ctrl[i] = data.ctrl

    def fall(self, k: int) -> None:
        """The fall was found at tick ``k``; its frame is the first recorded at or after it."""
        self.fall_tick = k
        self.fall_frame = min(self.F - 1, -(-k // self.every))

    def contacts(self, data, floor, i: int | None) -> None:
        """Deepest penetrations so far, with ``data``'s contacts (frame ``i``'s floor depth
        too where it is recorded, else None)."""
        if not data.ncon:
            return
        floor_depth, self_depth = contact_depths(data, floor)
        self.deepest = max(self.deepest, floor_depth)
        self.deepest_self = max(self.deepest_self, self_depth)
        if i is not None:
            self.depth[i] = floor_depth

    def result(self, model, data, fell: bool) -> Tracking:
        """The :class:`Tracking`: per recorded state, the mean wrench over the ticks centred
        on it (the impulse delivered around that frame over its duration: a sample of every
        4th tick would alias the 120 Hz variations of the feed-forward)."""
        T, F, every = self.T, self.F, self.every
        weight = total_mass(model) * G
        rec_w = np.empty((F, 6))
        rec_a = np.empty(F)
        half = every // 2
        for i in range(F):
            lo, hi = max(0, i * every - half), min(T, i * every - half + every)
            rec_w[i] = self.wrench[lo:hi].mean(axis=0)
            rec_a[i] = np.linalg.norm(rec_w[i, :3]) / weight
        return Tracking(
            qpos=self.qpos,
            qvel=self.qvel,
            assistance=rec_a,
            assist_wrench=rec_w,
            fell=fell,
            ticks=T,
            mean_assistance_all=float(self.assist.mean()) if T else 0.0,
            penetration=self.deepest,
            self_penetration=self.deepest_self,
            contact_penetration=self.depth,
            unstable=divergences(data) > 0,
            actions=self.ctrl,
            joint_torque=self.torque,
            foot_force=self.foot,
            fall_frame=self.fall_frame,
            fall_tick=self.fall_tick,
        )


#: MuJoCo's warnings of a diverging state: it resets ``data`` and counts the warning
_DIVERGED = tuple(
    int(w) for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
                     mujoco.mjtWarning.mjWARN_BADQPOS)
)  # fmt: skip
_PICK_DIVERGED = itemgetter(*_DIVERGED)


def divergences(data) -> int:
    """Whether MuJoCo found ``data``'s position, velocity or acceleration diverging (NaN, Inf
    or huge) and reset it to the model's initial state since ``data`` was made or
    :func:`clear_divergences` (> 0: it did; a reset clears the counts, so this is no tally).
    Read after every tick of every rollout: one read of the counts, not one per warning."""
    return sum(_PICK_DIVERGED(data.warning.number.tolist()))


def clear_divergences(data) -> None:
    """Zero ``data``'s counts of :func:`divergences` (before a rollout from a set state)."""
    for w in _DIVERGED:
        data.warning[w].number = 0
