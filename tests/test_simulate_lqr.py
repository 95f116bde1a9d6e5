"""The time-varying LQR tracker (``sim.simulate.lqr``): its Riccati recursion against SciPy's
discrete algebraic Riccati solver and a hand-solved scalar case, its tick linearisation against
the simulator's own response, and its simulation: torques within the human limits, nothing
acting from outside, the same reference the same simulation bit for bit, a standing pose held."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from sim.model.humanoid import canonical_skeleton
from sim.simulate.lqr import (
    LQRWeights,
    lqr_reference,
    riccati_gains,
    tick_linearisation,
    track_lqr,
)
from sim.simulate.model import SUBSTEPS, sim_model
from sim.simulate.reference import contact_consistent, flat_soles, on_floor


def test_long_horizon_gains_are_the_dare_gains():
    """Far from the horizon's end the finite-horizon gain is the infinite-horizon one:
    ``K = (R + B'PB)^-1 B'PA`` with ``P`` from ``scipy.linalg.solve_discrete_are``."""
    rng = np.random.default_rng(3)
    n, m, T = 5, 2, 400
    A = np.eye(n) + 0.1 * rng.normal(size=(n, n))  # unstable, controllable
    B = rng.normal(size=(n, m))
    Q, R = np.diag(rng.uniform(0.5, 2.0, n)), np.diag(rng.uniform(0.5, 2.0, m))
    K = riccati_gains(np.repeat(A[None], T, 0), np.repeat(B[None], T, 0),
                      np.repeat(Q[None], T, 0), R, Q)  # fmt: skip
    P = solve_discrete_are(A, B, Q, R)
    K_dare = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    np.testing.assert_allclose(K[0], K_dare, rtol=1e-8, atol=1e-10)
    assert np.abs(np.linalg.eigvals(A - B @ K[0])).max() < 1.0


def test_scalar_riccati_by_hand():
    """x+ = x + u, cost x^2 + u^2: P = (1 + sqrt 5) / 2, K = P / (1 + P); one step from
    P_end = 1: K = 1/2."""
    one = np.ones((300, 1, 1))
    K = riccati_gains(one, one, one, np.eye(1), np.eye(1))
    golden = (1 + np.sqrt(5)) / 2
    assert K[0, 0, 0] == pytest.approx(golden / (1 + golden), rel=1e-12)
    assert K[-1, 0, 0] == pytest.approx(0.5, rel=1e-12)


PENDULUM = """<mujoco><option timestep="0.002"/><worldbody><body pos="0 0 1">
<joint name="j" type="hinge" axis="0 1 0" damping="0.1"/>
<geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05"/></body></worldbody>
<actuator><motor joint="j" ctrlrange="-5 5" ctrllimited="true"/></actuator></mujoco>"""


def test_tick_linearisation_predicts_the_simulators_tick():
    """A and B of one tick (``SUBSTEPS`` steps, control held) against the simulator itself:
    a small state or control change moves the state after the tick as A, B say."""
    model = mujoco.MjModel.from_xml_string(PENDULUM)
    data = mujoco.MjData(model)
    x0 = np.array([0.7, -0.3])

    def tick(x, u):
        data.qpos[:], data.qvel[:], data.ctrl[:] = x[:1], x[1:], u
        mujoco.mj_step(model, data, nstep=SUBSTEPS)
        return np.concatenate([data.qpos, data.qvel])

    data.qpos[:], data.qvel[:], data.ctrl[:] = x0[:1], x0[1:], 1.0
    mujoco.mj_forward(model, data)
    A, B = tick_linearisation(model, data, 1e-6)
    base = tick(x0, 1.0)
    dx, du = np.array([1e-4, -2e-4]), 1e-3
    np.testing.assert_allclose(tick(x0 + dx, 1.0) - base, A @ dx, rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(tick(x0, 1.0 + du) - base, B[:, 0] * du, rtol=1e-3, atol=1e-9)


@pytest.fixture(scope="module")
def bodies():
    skeleton = canonical_skeleton()
    return {a: sim_model(skeleton, actuators=a, lean=True) for a in ("position", "motor")}


@pytest.fixture(scope="module")
def walk_ref(trial_on_floor, bodies):
    model = bodies["position"]
    ref = on_floor(model, trial_on_floor(model, "02_01")[:48], lift=0.0)
    return contact_consistent(model, flat_soles(model, ref))


@pytest.mark.parametrize("actuators", ["position", "motor"])
def test_torques_within_limits_nothing_from_outside_same_simulation(
    bodies, walk_ref, actuators, monkeypatch
):
    """Every physics step: no applied force on any body or dof; torques within the human
    limits; the same reference gives the same simulation bit for bit."""
    model = bodies[actuators]
    step = mujoco.mj_step

    def checked_step(m, d, nstep=1):
        assert not d.qfrc_applied.any() and not d.xfrc_applied.any()
        step(m, d, nstep=nstep)

    monkeypatch.setattr(mujoco, "mj_step", checked_step)
    w = LQRWeights()
    a = track_lqr(model, walk_ref, weights=w)
    b = track_lqr(model, walk_ref, weights=w)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.joint_torque, b.joint_torque)
    lim = model.actuator_forcerange[:, 1]
    assert np.all(np.abs(a.joint_torque) <= lim * (1 + 1e-12))
    assert not a.assist_wrench.any() and a.assistance.max() == 0.0
    assert np.abs(a.joint_torque).max() > 10.0  # it did act


#: stiffer joints, dearer torque, four Riccati steps a tick: the weights that hold a still pose
#: (the default's weaker hinge weights let this mid-stride pose drift 9 cm in 1 s and fall
#: within 2 s; docs/synthetic.md, "The LQR tracker")
HOLDING = LQRWeights(hinge=0.1, hinge_vel=2.0, com_xy=0.1, torque=0.1, sweeps=4)


def test_a_standing_pose_is_held(bodies, walk_ref):
    """The walk's first pose (mid-stride, both feet down) held still for 1 s on the servo
    body: the body stays up, its root within a few centimetres of the pose."""
    model = bodies["position"]
    still = np.repeat(walk_ref[:1], 120, axis=0)
    r = track_lqr(model, still, weights=HOLDING)
    assert not r.fell
    assert np.abs(r.qpos[-1, :3] - still[0, :3]).max() < 0.03


def test_operating_controls_lie_in_the_actuators_range(bodies, walk_ref):
    for model in bodies.values():
        qvel, u = lqr_reference(model, walk_ref)
        assert qvel.shape == (len(walk_ref), model.nv) and u.shape == (len(walk_ref), model.nu)
        assert np.all(u >= model.actuator_ctrlrange[:, 0])
        assert np.all(u <= model.actuator_ctrlrange[:, 1])


def test_forward_validation_runs_it_on_either_body():
    """``controller="lqr"``: the servo body by default, the torque body accepted too; it
    tracks the contact-consistent reference unless told otherwise."""
    from sim.simulate.validate import ForwardValidation, forward_validation

    skeleton = canonical_skeleton()
    names = ("root", "lfoot", "head")
    fv = forward_validation(skeleton, names, controller="lqr")
    assert fv.model.actuator_biasprm[:, 1].any() and fv.contact
    motor = sim_model(skeleton, actuators="motor")
    assert ForwardValidation(motor, names, controller="lqr").contact
    assert not ForwardValidation(motor, names, controller="lqr", contact_reference=False).contact
