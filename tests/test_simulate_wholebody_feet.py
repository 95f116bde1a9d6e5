"""The whole-body QP's foot options (``WholeBodyGains.land_depth``, ``hold_swing``): what each
plans, checked on the planned accelerations' effect on the sole (integrated by MuJoCo, not
through the QP's Jacobians), and that each leaves the controller bit for bit where it does not
apply."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.model import sim_model
from sim.simulate.reference import contact_consistent, flat_soles, on_floor
from sim.simulate.wholebody import WholeBodyGains, qp_tick, wholebody_reference
from sim.simulate.wholebody_reference import sole_corners

KNEE = "rtibia_rx"  # bending it lifts the right foot backwards and up


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton(), actuators="motor")


@pytest.fixture(scope="module")
def stand(trial_on_floor, model):
    """(nq,) a pose of a walk with both soles on the floor (the reference's stance)."""
    walk = on_floor(model, trial_on_floor(model, "02_01")[:90], lift=0.0)
    walk = contact_consistent(model, flat_soles(model, walk))
    both = np.flatnonzero(wholebody_reference(model, walk).stance.all(axis=1))
    assert len(both)
    q = walk[both[len(both) // 2]].copy()
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    low = [sole_corners(model, data, model.geom(f"{s}sole").id)[:, 2].min() for s in "lr"]
    q[2] -= max(low) + 5e-4  # both soles touch (the higher half a millimetre deep)
    return q


def _bent(model, q, deg):
    q = q.copy()
    q[model.joint(KNEE).qposadr[0]] += np.radians(deg)
    return q


def _plan(model, state, ref_qpos, gains):
    """The QP's plan at ``state`` (still) for a still reference of ``ref_qpos``; the planned
    vertical accelerations [m/s^2] of the right sole's centre and the mean of its floor contact
    points (0 if none), from the positions MuJoCo's kinematics gives after a short step at the
    planned ``qdd`` (not through the QP's Jacobians)."""
    ref = wholebody_reference(model, np.repeat(ref_qpos[None], 12, axis=0))
    data = mujoco.MjData(model)
    data.qpos[:] = state
    mujoco.mj_forward(model, data)
    res = qp_tick(model, data, ref, 6, gains, model.actuator_ctrlrange[:, 1], {})
    assert res.status == 1
    g, floor = model.geom("rsole").id, model.geom("floor").id
    foot = {g, model.geom("rtoesole").id}
    points = [(data.contact.pos[i].copy(), model.geom_bodyid[a + b - floor])
              for i, (a, b) in enumerate(data.contact.geom[: data.ncon])
              if floor in (a, b) and a + b - floor in foot]  # fmt: skip
    local = [(data.xmat[b].reshape(3, 3).T @ (p - data.xpos[b]), b) for p, b in points]
    z0 = np.array([data.geom_xpos[g, 2]] + [p[2] for p, _ in points])
    dt = 1e-3
    q = state.copy()
    mujoco.mj_integratePos(model, q, 0.5 * dt * res.qdd, dt)  # q + qdd dt^2 / 2
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    z1 = [data.geom_xpos[g, 2]] + [(data.xpos[b] + data.xmat[b].reshape(3, 3) @ p)[2]
                                   for p, b in local]  # fmt: skip
    acc = 2 * (np.array(z1) - z0) / dt**2
    return res, acc[0], float(acc[1:].mean()) if points else 0.0


def _touching(model, q) -> set[str]:
    """The soles (``"l"``, ``"r"``) touching the floor at ``q``."""
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    floor = model.geom("floor").id
    pairs = {tuple(sorted(p)) for p in data.contact.geom[: data.ncon].tolist()}
    return {s for s in "lr" if tuple(sorted((floor, model.geom(f"{s}sole").id))) in pairs}


def test_a_foot_the_reference_stands_on_seeks_the_floor(model, stand):
    """The right foot lifted off the floor (knee bent) where the reference stands on it: with
    ``land_depth`` its planned acceleration points down more than without (the PD's target
    ``land_depth`` lower: ``foot_omega^2 land_depth`` = 7.9 m/s^2 more at 5 cm, less what the
    other tasks take); where the foot touches, the option changes nothing."""
    lifted = _bent(model, stand, 25.0)
    assert _touching(model, lifted) == {"l"} and _touching(model, stand) == {"l", "r"}
    near = _plan(model, lifted, stand, WholeBodyGains(land_depth=1e-9, w_land=1e4))[1]
    deep = _plan(model, lifted, stand, WholeBodyGains(land_depth=0.05, w_land=1e4))[1]
    # the foot's task dominant (w_land): the PD's target 5 cm deeper, its acceleration
    # foot_omega^2 * 0.05 = 7.9 m/s^2 more downwards
    assert deep - near == pytest.approx(-(WholeBodyGains().foot_omega ** 2) * 0.05, rel=0.15)
    a_off = _plan(model, lifted, stand, WholeBodyGains())[1]
    a_on = _plan(model, lifted, stand, WholeBodyGains(land_depth=0.05, w_land=30.0))[1]
    assert a_on < a_off - 0.5  # at a weight the other tasks share
    same = [_plan(model, stand, stand, WholeBodyGains(land_depth=d))[0].tau for d in (0.0, 0.05)]
    assert np.array_equal(*same)


def test_a_swing_foot_that_scuffs_the_floor_is_not_pinned_without_hold_swing(model, stand):
    """The right sole on the floor where the reference lifts it (knee bent 60 deg): its
    contact points held still by default (a soft task: their planned upward acceleration small,
    2.3 m/s^2 measured), pulled up towards the reference with ``hold_swing=False`` (5.4); with the reference on both feet
    the option changes nothing."""
    swing = _bent(model, stand, 60.0)
    assert _touching(model, swing) == {"l"} and _touching(model, stand) == {"l", "r"}
    ref_swing = wholebody_reference(model, np.repeat(swing[None], 12, axis=0))
    assert not ref_swing.stance[6, 1] and ref_swing.stance[6, 0]
    held = _plan(model, stand, swing, WholeBodyGains())[2]
    free = _plan(model, stand, swing, WholeBodyGains(hold_swing=False))[2]
    assert free > 2 * held and free > held + 2.0
    same = [_plan(model, stand, stand, WholeBodyGains(hold_swing=h))[0].tau for h in (True, False)]
    assert np.array_equal(*same)


def _corners(model, data, name: str) -> np.ndarray:
    """(4, 3) the bottom corners of sole box ``name``, from its pose and half sizes."""
    g = model.geom(name).id
    R, half = data.geom_xmat[g].reshape(3, 3), model.geom_size[g]
    signs = np.array([[i, j, -1.0] for i in (-1, 1) for j in (-1, 1)])
    return data.geom_xpos[g] + (signs * half) @ R.T


def test_a_stance_sole_offers_its_corners_near_the_floor_as_support(model, stand):
    """With ``sole_gap`` a stance sole that touches plans forces at its bottom corners within
    the gap of the floor (the whole sole, not only the edge it rests on), none farther; the
    floating base's equations still hold with them; 0 (the default) leaves MuJoCo's points."""
    tilted = stand.copy()
    tilted[model.joint("rfoot_rx").qposadr[0]] += np.radians(1.5)  # the right sole tilts
    data = mujoco.MjData(model)
    data.qpos[:] = tilted
    mujoco.mj_forward(model, data)
    z = _corners(model, data, "rsole")[:, 2]
    tilted[2] -= z.min() + 5e-4  # its lowest corners half a millimetre deep, the others up
    data.qpos[:] = tilted
    mujoco.mj_forward(model, data)
    corners = _corners(model, data, "rsole")
    near = corners[corners[:, 2] < 0.004]
    assert 0 < len(near) < 4 and (corners[:, 2] > 0.001).any()
    ref = wholebody_reference(model, np.repeat(tilted[None], 12, axis=0))
    lim = model.actuator_ctrlrange[:, 1]
    plain = qp_tick(model, data, ref, 6, WholeBodyGains(), lim, {})
    res = qp_tick(model, data, ref, 6, WholeBodyGains(sole_gap=0.004), lim, {})
    assert res.status == 1
    extra = res.points[len(plain.points) :]
    assert np.array_equal(res.points[: len(plain.points)], plain.points)
    right = [p for p in extra if np.min(np.linalg.norm(corners - p, axis=1)) < 1e-9]
    assert len(right) == len(near)  # the right sole's corners within the gap, no other
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    jacp, gen = np.zeros((3, model.nv)), np.zeros(model.nv)
    for p, f in zip(res.points, res.forces, strict=True):
        body = model.body("rfoot").id if any(np.allclose(p, c) for c in corners) else None
        if body is None:  # a MuJoCo contact point: the nearest foot body's
            body = model.geom_bodyid[min(
                (model.geom(n).id for n in ("lsole", "ltoesole", "rsole", "rtoesole")),
                key=lambda g: np.linalg.norm(data.geom_xpos[g] - p))]  # fmt: skip
        mujoco.mj_jac(model, data, jacp, None, p, body)
        gen += jacp.T @ f
    root = M[:6] @ res.qdd + data.qfrc_bias[:6] - data.qfrc_passive[:6] - gen[:6]
    assert np.abs(root).max() < 1e-6 * max(1.0, np.abs(gen).max())
