"""The friction cone's enforcement (``sim_spec(friction=...)``, off by default): only MuJoCo's
solver options (and, for torsional friction, the soles' contact dimension) change; Coulomb's
law as the oracle: a loaded sole pushed below the friction limit stays (MuJoCo's soft default
creeps, the harder cone much less), pushed beyond it slides at (F / m - mu g) whatever the
setting (the friction coefficient is the floor's); the stored MJCF carries the setting."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.friction import Friction, apply_friction
from sim.simulate.model import SOLE_GEOMS, TOE_GEOMS, sim_model, sim_spec

HARD = Friction(elliptic=True, impratio=10.0)
#: a sole-sized 40 kg box resting on the floor, MuJoCo's default friction (mu = 1)
BOX = """<mujoco><option timestep="0.0020833" integrator="implicitfast"/><worldbody>
<geom name="floor" type="plane" size="0 0 1" priority="1" solref="0.005 1"/>
<body name="b" pos="0 0 0.0099"><freejoint/>
<geom name="box" type="box" size="0.12 0.045 0.01" mass="40"/></body></worldbody></mujoco>"""
MASS, G = 40.0, 9.81


def _array_fields(model) -> dict[str, np.ndarray]:
    return {
        k: getattr(model, k)
        for k in dir(model)
        if not k.startswith("_") and isinstance(getattr(model, k), np.ndarray)
    }


@pytest.mark.parametrize("condim", [3, 4])
def test_only_the_solver_options_and_the_soles_contact_dimension_change(condim):
    skeleton = canonical_skeleton()
    plain = sim_model(skeleton)
    f = Friction(elliptic=True, impratio=5.0, noslip_iterations=2, sole_condim=condim)
    hard = sim_model(skeleton, friction=f)
    a, b = _array_fields(plain), _array_fields(hard)
    changed = {k for k in a if a[k].shape != b[k].shape or not np.array_equal(a[k], b[k])}
    feet = sorted(plain.geom(n).id for n in SOLE_GEOMS + TOE_GEOMS)
    if condim == 3:
        assert changed == set()
    else:  # the soles take priority with the floor's parameters and friction
        assert changed == {"geom_priority", "geom_condim", "geom_solref"}
        for k in changed:
            rows = np.nonzero((a[k] != b[k]).reshape(len(a[k]), -1).any(axis=1))[0]
            assert rows.tolist() == feet
        floor = plain.geom("floor").id
        np.testing.assert_array_equal(hard.geom_solref[feet], hard.geom_solref[[floor] * 4])
        np.testing.assert_array_equal(hard.geom_friction[feet], hard.geom_friction[[floor] * 4])
    assert plain.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL and plain.opt.impratio == 1.0
    assert hard.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert (hard.opt.impratio, hard.opt.noslip_iterations) == (5.0, 2)


def test_the_stored_mjcf_carries_the_setting():
    xml = sim_spec(canonical_skeleton(), friction=HARD).to_xml()
    m = mujoco.MjModel.from_xml_string(xml)
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and m.opt.impratio == 10.0


def _pushed(friction: Friction, force: float, seconds: float = 1.0) -> float:
    """[m] how far the box moves in ``seconds`` under a horizontal ``force`` [N] after
    settling."""
    spec = mujoco.MjSpec.from_string(BOX)
    apply_friction(spec, friction, ("box",))
    m = spec.compile()
    d = mujoco.MjData(m)
    for _ in range(240):  # settle
        mujoco.mj_step(m, d)
    x0 = d.qpos[0]
    d.xfrc_applied[1, 0] = force
    for _ in range(int(round(seconds / m.opt.timestep))):
        mujoco.mj_step(m, d)
    return float(d.qpos[0] - x0)


def test_below_the_limit_the_harder_cone_creeps_far_less():
    """Coulomb: half the friction limit moves nothing. Measured: MuJoCo's default creeps
    0.66 mm in 1 s, the elliptic cone at impratio 10 0.03 mm, with noslip nothing."""
    soft = _pushed(Friction(), 0.5 * MASS * G)
    hard = _pushed(HARD, 0.5 * MASS * G)
    noslip = _pushed(Friction(elliptic=True, impratio=10.0, noslip_iterations=3), 0.5 * MASS * G)
    assert 2e-4 < soft < 2e-3  # the creep these settings remove
    assert hard < soft / 5
    assert abs(noslip) < 1e-5


@pytest.mark.parametrize("friction", [Friction(), HARD, Friction(noslip_iterations=3)])
def test_beyond_the_limit_it_slides_as_coulomb_says(friction):
    """1.2 mu m g pushes the box at 0.2 g: 0.98 m in 1 s, whatever the cone's hardness."""
    got = _pushed(friction, 1.2 * MASS * G)
    np.testing.assert_allclose(got, 0.5 * 0.2 * G, rtol=0.05)


def test_settings_out_of_range_are_refused():
    for bad in ({"impratio": 0.5}, {"sole_condim": 5}, {"noslip_iterations": -1}):
        with pytest.raises(UsageError):
            Friction(**bad)


#: a 40 kg ball 1 cm across: one contact point, where only torsional friction resists a spin
BALL = BOX.replace('type="box" size="0.12 0.045 0.01"', 'type="sphere" size="0.005"').replace(
    'pos="0 0 0.0099"', 'pos="0 0 0.0049"'
)


def _spun(friction: Friction, torque: float) -> float:
    """[rad/s] the ball's spin about the vertical after 1 s under ``torque`` [N m]."""
    spec = mujoco.MjSpec.from_string(BALL)
    apply_friction(spec, friction, ("box",))
    m = spec.compile()
    d = mujoco.MjData(m)
    for _ in range(240):
        mujoco.mj_step(m, d)
    d.xfrc_applied[1, 5] = torque
    for _ in range(480):
        mujoco.mj_step(m, d)
    return float(d.qvel[5])


def test_torsional_friction_holds_a_point_contact_up_to_its_coefficient_times_the_load():
    """Coulomb for torsion: a point contact resists up to ``torsion`` times its load; without
    torsion (condim 3) nothing resists, the ball spins up. Measured after 1 s at half the
    limit: condim 3 spinning, the pyramidal cone with torsion creeping 0.2 rad/s (the ball's
    tiny inertia), the elliptic cone at impratio 10 0.006 rad/s; at 1.5 times it, spinning."""
    tor = Friction(elliptic=True, impratio=10.0, sole_condim=4, torsion=0.02)
    limit = 0.02 * MASS * G
    assert abs(_spun(Friction(), 0.5 * limit)) > 10.0
    assert abs(_spun(tor, 0.5 * limit)) < 0.02
    assert abs(_spun(tor, 1.5 * limit)) > 10.0
