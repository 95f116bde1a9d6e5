"""How hard the simulated body's friction cone is enforced (``sim_spec(friction=...)``).

MuJoCo's contacts are soft: a friction force is a constraint with the same impedance as the
normal force, so under a sustained tangential load a sole creeps (it slides slowly though the
force is inside the cone: the constraint needs a residual velocity to push back). MuJoCo's
remedies, none of which changes the friction coefficient (the floor's, MuJoCo's default 1:
shoe on floor is about 0.6-1.0): an elliptic cone with ``impratio`` > 1 (the friction rows
harder than the normal row: "preventing slip without increasing the actual friction
coefficient", MuJoCo's documentation), and ``noslip_iterations`` (a post-pass of the solver that
removes the residual slip of the frictional rows). ``condim`` of the soles' floor contacts: 3
(sliding only), 4 (and torsion, about the contact normal, with the floor's torsional
coefficient) or 6 (and rolling). docs/synthetic.md ("The simulated body") says what each gave.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from sim.errors import UsageError


@dataclass(frozen=True)
class Friction:
    """The friction cone's enforcement: ``elliptic`` (MuJoCo's elliptic cone, else its default
    pyramidal one), ``impratio`` (frictional over normal impedance, MuJoCo's default 1),
    ``noslip_iterations`` (MuJoCo's default 0: none) and ``sole_condim`` (3, 4 or 6: the
    sole and toe boxes' floor contacts' dimension; 3 is MuJoCo's default); ``torsion`` [m]: their
    torsional coefficient with ``sole_condim`` 4 or 6 (the torque about the contact normal a
    contact resists is this times its normal force; None: the floor's, MuJoCo's default 0.005,
    a 7 mm patch). A uniformly loaded round patch of radius ``a`` resists ``2/3 mu a`` times its
    load before it spins; a shod heel or forefoot on the floor is 3-4 cm across."""

    elliptic: bool = False
    impratio: float = 1.0
    noslip_iterations: int = 0
    sole_condim: int = 3
    torsion: float | None = None

    def __post_init__(self):
        if not self.impratio >= 1.0:
            raise UsageError(f"impratio must be at least 1; got {self.impratio}")
        if self.sole_condim not in (3, 4, 6):
            raise UsageError(f"sole_condim must be 3, 4 or 6; got {self.sole_condim}")
        if self.noslip_iterations < 0:
            raise UsageError(f"noslip_iterations must be >= 0; got {self.noslip_iterations}")
        if self.torsion is not None and (self.sole_condim == 3 or not self.torsion >= 0):
            raise UsageError(f"torsion needs sole_condim 4 or 6 and >= 0; got {self.torsion}")


#: MuJoCo's own contact model (the pyramidal cone, impratio 1, no noslip, condim 3)
SOFT_FRICTION = Friction()


def apply_friction(spec, friction: Friction, soles: tuple[str, ...]) -> None:
    """Set ``friction`` on ``spec`` in place: its options, and the ``condim`` of geoms ``soles``
    (names; where ``sole_condim`` is not 3 they take priority over the floor for their floor
    contacts, with the floor's friction coefficients and, unless compliant soles set their own,
    its ``solref`` and ``solimp``)."""
    spec.option.cone = (
        mujoco.mjtCone.mjCONE_ELLIPTIC if friction.elliptic else mujoco.mjtCone.mjCONE_PYRAMIDAL
    )
    spec.option.impratio = friction.impratio
    spec.option.noslip_iterations = friction.noslip_iterations
    if friction.sole_condim == 3:
        return
    floor = spec.geom("floor")
    for name in soles:
        g = spec.geom(name)
        if g is None:
            continue
        if g.priority <= floor.priority:  # the floor's contact parameters, now the sole's
            g.priority = floor.priority + 1
            g.solref, g.solimp = list(floor.solref), list(floor.solimp)
        g.condim = friction.sole_condim
        g.friction = floor.friction
        if friction.torsion is not None:  # the sliding coefficient stays the floor's
            g.friction = [floor.friction[0], friction.torsion, floor.friction[2]]
