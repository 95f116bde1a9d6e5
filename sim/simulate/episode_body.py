"""The simulated body of a synthetic episode, and the gain sets its controller may switch
between.

An episode's body is compiled from its MJCF (the model simulated is the one the stored text
rebuilds). Where the sampler chooses its feedback gains per window (``sim.simulate.
gainchoice``), the gain sets are one body: the hinges' armature is the largest of the sets'
(``sim_spec`` raises it with ``kp`` for stability), written into the MJCF; the actuators' control
range is the union of the sets' (the default set's: a stiffer set's lies within it); and the
model of each further set is the MJCF's model with only its position actuators' ``kp`` and
``kv`` set (``sim.simulate.episode.set_gains``), exactly what a replay does with the gains an
episode records per tick. The torque limits (``forcerange``) are the human ones in every set.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.model.mass import DEFAULT_BODY_MASS_KG
from sim.simulate.episode import pd_gains, set_gains
from sim.simulate.model import Gains, sim_spec
from sim.simulate.terrain import add_terrain


def episode_model(
    skeleton, scale: float, gain: float, actuators: str = "position", lean: bool = False
) -> tuple[mujoco.MjModel, str, Gains]:
    """The simulated body of an episode: ``skeleton`` (already scaled by ``scale``) with mass
    scaling as its cube, the hinges' stiffness times ``gain`` (bandwidth times its square root;
    the torque limits are the human ones, never scaled, rounded down to the 6 digits an MJCF
    keeps), ``actuators`` ``"position"`` or ``"motor"`` and ``lean`` (``sim_spec``'s, in the
    MJCF's options); the model compiled from its MJCF (the model simulated, so the MJCF
    rebuilds it exactly), the MJCF itself and the gains."""
    models, mjcf, gains = episode_bodies(skeleton, scale, gain, actuators, lean)
    return models[0], mjcf, gains


def episode_bodies(
    skeleton,
    scale: float,
    gain: float,
    actuators: str = "position",
    lean: bool = False,
    alternates: tuple[Gains, ...] = (),
    terrain: list = (),
) -> tuple[tuple, str, Gains]:
    """:func:`episode_model`'s body with further gain sets: ``alternates`` (each scaled by
    ``gain`` like the default ``Gains()``), position actuators only; in the scene of the boxes
    ``terrain`` (``sim.simulate.terrain.Box``, added by ``add_terrain`` after the body: its
    ids do not move; none: the empty floor).

    Returns:
        the models (the MJCF's, then one per alternate: the MJCF's with that set's ``kp``,
        ``kv``), the MJCF (armature and control ranges common to all sets: module docstring;
        the boxes in it) and the default set's gains.
    """
    gains = Gains().scaled(gain)
    sets = [gains, *(g.scaled(gain) for g in alternates)]
    if alternates and actuators != "position":
        raise ValueError("gain sets are the position actuators'")
    specs = [_spec(skeleton, scale, g, actuators, lean) for g in sets]
    own = [mujoco.MjModel.from_xml_string(s.to_xml()) for s in specs] if alternates else []
    if alternates:  # each set's own body (``own``) made one
        armature = np.max([m.dof_armature for m in own], axis=0)
        base = own[0]
        for j in range(1, base.njnt):  # the hinges (the free joint's armature is 0 in all)
            specs[0].joint(base.joint(j).name).armature = float(armature[base.jnt_dofadr[j]])
        lo = np.min([m.actuator_ctrlrange[:, 0] for m in own], axis=0)
        hi = np.max([m.actuator_ctrlrange[:, 1] for m in own], axis=0)
        for i, a in enumerate(specs[0].actuators):
            a.ctrlrange = [lo[i], hi[i]]
    if len(terrain):  # a fresh spec of this episode's: no cached body is changed
        add_terrain(specs[0], list(terrain))
    mjcf = specs[0].to_xml()
    models = [mujoco.MjModel.from_xml_string(mjcf)]
    for m in own[1:]:
        models.append(mujoco.MjModel.from_xml_string(mjcf))
        set_gains(models[-1], pd_gains(m))
    return tuple(models), mjcf, gains


def _spec(skeleton, scale: float, gains: Gains, actuators: str, lean: bool) -> mujoco.MjSpec:
    """``sim_spec`` of the episode's body with its torque limits rounded down to the 6 digits
    an MJCF keeps (never up), a torque actuator's control range its limit."""
    spec = sim_spec(skeleton, body_mass_kg=DEFAULT_BODY_MASS_KG * scale**3, gains=gains,
                    actuators=actuators, lean=lean)  # fmt: skip
    for a in spec.actuators:
        a.forcerange = [-_down6(a.forcerange[1]), _down6(a.forcerange[1])]
        if actuators == "motor":  # a torque's control range is its limit
            a.ctrlrange = a.forcerange
    return spec


def _down6(x: float) -> float:
    """``x`` > 0 rounded down to 6 significant digits (what an MJCF writes)."""
    step = 10.0 ** (np.floor(np.log10(x)) - 5)
    return float(np.floor(x / step) * step)
