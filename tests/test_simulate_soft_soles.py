"""Compliant soles (``sim_spec(soft_soles=...)``, off by default): only the soles' contact
parameters change; a standing body on padded soles bears at heel and ball where the stiff
floor leaves it on a point or an edge; the sole sinks a few millimetres; deterministic."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.model import (
    FLOOR_SOLIMP,
    FLOOR_TIMECONST,
    PAD_SOLE,
    SOLE_GEOMS,
    TOE_GEOMS,
    SoftSole,
    sim_model,
)
from sim.simulate.reference import flat_soles, on_floor, trial_qpos
from sim.simulate.wholebody import track_wholebody
from sim.simulate.wholebody_reference import sole_corners

FEET = SOLE_GEOMS + TOE_GEOMS


@pytest.fixture(scope="module")
def bodies():
    """The torque-actuated body on the stiff floor's soles and on padded soles."""
    skeleton = canonical_skeleton()
    return {
        "rigid": sim_model(skeleton, actuators="motor"),
        "pad": sim_model(skeleton, actuators="motor", soft_soles=PAD_SOLE),
    }


@pytest.fixture(scope="module")
def still(cmu_dir, bodies):
    """1 s of 60_01 frame 108 (standing still on both feet), its soles laid flat on the
    floor."""
    model = bodies["rigid"]
    q = trial_qpos(cmu_dir / "60" / "60.asf", cmu_dir / "60" / "60_01.amc")[108:109]
    return on_floor(model, flat_soles(model, on_floor(model, np.repeat(q, 120, axis=0))))


def _array_fields(model) -> dict[str, np.ndarray]:
    return {
        k: getattr(model, k)
        for k in dir(model)
        if not k.startswith("_") and isinstance(getattr(model, k), np.ndarray)
    }


@pytest.mark.parametrize("actuators", ["position", "motor"])
def test_only_the_soles_contact_parameters_change(actuators):
    skeleton = canonical_skeleton()
    plain = sim_model(skeleton, actuators=actuators)
    soft = sim_model(skeleton, actuators=actuators, soft_soles=SoftSole(0.02, 1.0, FLOOR_SOLIMP))
    a, b = _array_fields(plain), _array_fields(soft)
    assert a.keys() == b.keys()
    changed = {k for k in a if a[k].shape != b[k].shape or not np.array_equal(a[k], b[k])}
    assert changed == {"geom_priority", "geom_solref"}  # solimp: the floor's here as there
    feet = sorted(plain.geom(n).id for n in FEET)
    for k in changed:
        rows = np.nonzero((a[k] != b[k]).reshape(len(a[k]), -1).any(axis=1))[0]
        assert rows.tolist() == feet


def test_the_soles_floor_contacts_take_their_parameters_and_the_floors_friction(bodies, still):
    data = {n: mujoco.MjData(m) for n, m in bodies.items()}
    for n, m in bodies.items():
        data[n].qpos[:] = still[0]
        mujoco.mj_kinematics(m, data[n])
        low = min(sole_corners(m, data[n], m.geom(g).id)[:, 2].min() for g in SOLE_GEOMS)
        data[n].qpos[2] -= low + 0.001  # the lowest sole corner 1 mm into the floor
        mujoco.mj_forward(m, data[n])
    rigid, pad = data["rigid"], data["pad"]
    assert rigid.ncon == pad.ncon > 0  # the same pose, the same contacts
    np.testing.assert_array_equal(rigid.contact.geom, pad.contact.geom)
    np.testing.assert_array_equal(rigid.contact.dist, pad.contact.dist)
    np.testing.assert_array_equal(rigid.contact.friction, pad.contact.friction)
    np.testing.assert_array_equal(rigid.contact.dim, pad.contact.dim)
    model = bodies["pad"]
    feet = {model.geom(n).id for n in FEET}
    on_sole = np.array([bool(set(g) & feet) for g in pad.contact.geom])
    assert on_sole.any()
    np.testing.assert_allclose(
        pad.contact.solref[on_sole], [[FLOOR_TIMECONST, 1.0]] * on_sole.sum()
    )
    np.testing.assert_allclose(pad.contact.solimp[on_sole], [PAD_SOLE.solimp] * on_sole.sum())
    np.testing.assert_allclose(rigid.contact.solimp[on_sole], [FLOOR_SOLIMP] * on_sole.sum())
    with pytest.raises(UsageError):
        sim_model(canonical_skeleton(), soles=False, soft_soles=PAD_SOLE)


def _bearing(model, qpos) -> tuple[float, float, float]:
    """Over the touching soles of ``qpos`` (T, nq): the share whose floor contacts reach both
    the heel's and the ball's half of the sole box, the mean count of contacts, and the
    deepest penetration [m]."""
    data = mujoco.MjData(model)
    floor = model.geom("floor").id
    both, count, deepest = [], [], 0.0
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_forward(model, data)
        for sole, toes in zip(SOLE_GEOMS, TOE_GEOMS, strict=True):
            g, t = model.geom(sole).id, model.geom(toes).id
            axis, centre = data.geom_xmat[g].reshape(3, 3)[:, 0], data.geom_xpos[g]
            along = []
            for i in range(data.ncon):
                pair = set(data.contact.geom[i])
                if floor in pair and pair & {g, t}:
                    along.append((data.contact.pos[i] - centre) @ axis)
                    deepest = max(deepest, -data.contact.dist[i])
            if along:
                half = model.geom_size[g, 0] / 2
                both.append(min(along) < -half and max(along) > half)
                count.append(len(along))
    return float(np.mean(both)), float(np.mean(count)), deepest


def test_a_standing_body_on_padded_soles_bears_at_heel_and_ball(bodies, still):
    """The QP holding a still standing pose: on the stiff floor's soles it stands on a point
    or an edge nearly all the time (measured: heel and ball in 4 % of the sole-ticks, 1.1
    contacts per sole); on padded soles in 28 %, 2.9 contacts, sinking 2-4 mm."""
    got = {}
    for n, model in bodies.items():
        r = track_wholebody(model, still, record_every=1)
        assert not r.fell
        got[n] = _bearing(model, r.qpos[30:])  # after the first quarter second
    (rigid_both, rigid_n, rigid_deep), (pad_both, pad_n, pad_deep) = got["rigid"], got["pad"]
    assert rigid_both < 0.1 and pad_both > 0.2
    assert pad_n > 2 * rigid_n
    assert rigid_deep < 0.002 and 0.002 < pad_deep < 0.006  # a pad, not a swamp


def test_padded_soles_are_deterministic(bodies, still):
    model = bodies["pad"]
    a = track_wholebody(model, still[:60], record_every=1)
    b = track_wholebody(model, still[:60], record_every=1)
    np.testing.assert_array_equal(a.qpos, b.qpos)
