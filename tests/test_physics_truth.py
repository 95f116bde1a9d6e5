"""Inverse dynamics at the analysis rate (30 fps) against an ``mj_step`` ground truth.

The humanoid is simulated at 1200 Hz with its limbs driven (PD towards 0.45-0.5 rad sinusoids at
1.5-3 Hz), known pushes on the thorax and a hand, in flight and standing, and a landing; the
analysis sees its 30 fps frames and, for derivatives, the 120 Hz samples around each frame (as the
original's 120 fps source frames or a reconstruction's curve supply them). Truth: the push MuJoCo
applied, and MuJoCo's own contacts.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest

from sim.model import quaternion as quat
from sim.model.humanoid import humanoid_model
from sim.model.rotations import Y_UP_TO_Z_UP
from sim.physics.dynamics import InverseDynamics, stencil_derivatives

SIM_HZ, DENSE_HZ, FPS = 1200, 120, 30
DRIVEN = {  # hinge: (amplitude [rad], frequency [Hz])
    "lfemur_rx": (0.45, 1.5), "rfemur_rx": (0.45, 2.0), "ltibia_rx": (0.5, 3.0),
    "lhumerus_rx": (0.45, 2.5), "rhumerus_rx": (0.45, 1.5), "rradius_rx": (0.5, 3.0),
}  # fmt: skip


@pytest.fixture(scope="module")
def model():
    return humanoid_model()[1]


def _pose(model, z):
    q = np.zeros(model.nq)
    q[3:7] = quat.from_matrix(Y_UP_TO_Z_UP)
    q[2] = z
    return q


def _simulate(model, *, seconds, z0, v0=(0, 0, 0), pushes=(), floor=False, kp=200.0, kd=5.0):
    """mj_step at :data:`SIM_HZ`; ``pushes``: (body name, force (3,) [N], start [s], stop [s],
    shape "box" or "sine" (half sine)). Returns dense qpos (N, nq) at :data:`DENSE_HZ`, the applied
    force on the body per sample (N, 3) [N], and MuJoCo's floor contacts per sample (body, point).
    """
    m = copy.deepcopy(model)
    m.opt.timestep = 1.0 / SIM_HZ
    if not floor:
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    d = mujoco.MjData(m)
    q0 = _pose(m, z0)
    if z0 is None:  # standing: the lowest capsule 1 mm into the floor
        d.qpos[:] = _pose(m, 1.0)
        mujoco.mj_kinematics(m, d)
        axis = d.geom_xmat.reshape(-1, 3, 3)[:, 2, 2]
        low = d.geom_xpos[:, 2] - np.abs(axis) * m.geom_size[:, 1] - m.geom_size[:, 0]
        q0 = _pose(m, 1.0 - low[1:].min() - 0.001)
    d.qpos[:] = q0
    d.qvel[:3] = v0
    adr = {n: m.jnt_qposadr[m.joint(n).id] for n in DRIVEN}
    bodies = [(m.body(b).id, np.asarray(f, float), a, z, s) for b, f, a, z, s in pushes]
    every = SIM_HZ // DENSE_HZ
    qs, applied, contacts = [], [], []
    for k in range(int(seconds * SIM_HZ) + 1):
        t = k / SIM_HZ
        target = q0[7:].copy()
        for n, (amp, f) in DRIVEN.items():
            target[adr[n] - 7] += amp * np.sin(2 * np.pi * f * t)
        d.qfrc_applied[6:] = kp * (target - d.qpos[7:]) - kd * d.qvel[6:]
        d.xfrc_applied[:] = 0.0
        total = np.zeros(3)
        for b, f, a, z, shape in bodies:
            if a <= t < z:
                g = f * (np.sin(np.pi * (t - a) / (z - a)) if shape == "sine" else 1.0)
                d.xfrc_applied[b, :3] += g
                total += g
        if k % every == 0:
            mujoco.mj_forward(m, d)
            qs.append(d.qpos.copy())
            applied.append(total)
            cs = [c for c in d.contact[: d.ncon] if 0 in c.geom] if d.ncon else []
            contacts.append([(int(m.geom_bodyid[c.geom.max()]), c.pos.copy()) for c in cs])
        mujoco.mj_step(m, d)
    return np.array(qs), np.array(applied), contacts


def _analyse(model, dense, contacts=None, mu=1.0):
    """The 30 fps analysis: frames every 4th dense sample, derivatives from the 120 Hz samples
    around each frame; ground forces at MuJoCo's contact points of the frame (none: flight)."""
    step, k = DENSE_HZ // FPS, 5  # exact differences of 5 samples: 4th order, one-sided at ends
    centre = np.arange(0, len(dense), step)
    lo = np.clip(centre - k // 2, 0, len(dense) - k)
    samples = np.stack([dense[lo + j] for j in range(k)], axis=1)
    inv = InverseDynamics(model, mu=mu)
    vel, acc = stencil_derivatives(inv.model, samples, 1.0 / DENSE_HZ, centre - lo)
    cons = [[]] * len(centre) if contacts is None else [contacts[i] for i in centre]
    return inv.run(dense[centre], FPS, cons, qvel=vel, qacc=acc), centre


def _limbs_move(model, dense):
    """Each driven hinge swings by at least 0.3 rad (half its peak to peak) (the motion is real)."""
    for n in DRIVEN:
        a = dense[:, model.jnt_qposadr[model.joint(n).id]]
        assert (a.max() - a.min()) / 2 >= 0.3, n


@pytest.mark.parametrize("body", ["thorax", "lhand"])
def test_a_push_in_flight_is_recovered_at_30_fps_with_limbs_moving(model, body):
    """A 266 N half-sine push for 200 ms on the thorax or a hand, during flight: its impulse
    within 5 %, its peak within 15 %; unpushed flight frames <= 3 % body weight on average."""
    push = np.array([200.0, -120.0, 120.0])  # |push| = 262 N
    dense, applied, _ = _simulate(
        model, seconds=1.0, z0=3.0, v0=(0.5, 0, 2.0), pushes=[(body, push, 0.4, 0.6, "sine")]
    )
    _limbs_move(model, dense)
    dyn, centre = _analyse(model, dense)
    rf = dyn.residual_force
    on = np.linalg.norm(applied[centre], axis=1) > 0
    # impulse: the frames' residual times the frame interval vs the applied impulse
    got = rf[on].sum(0) / FPS
    true = applied.sum(0) / DENSE_HZ
    assert np.linalg.norm(got - true) < 0.05 * np.linalg.norm(true)
    peak, true_peak = np.linalg.norm(rf[on], axis=1).max(), np.linalg.norm(push)
    assert abs(peak - true_peak) < 0.15 * true_peak
    quiet = ~on
    quiet[np.flatnonzero(on)[[0, -1]] + [-1, 1]] = False  # frames whose stencil touches the push
    assert np.linalg.norm(rf[quiet], axis=1).mean() / dyn.weight < 0.03
    # the 9-frame filter on the 30 fps frames alone misses this by far (the test can tell)
    sg = InverseDynamics(model).run(dense[centre], FPS, [[]] * len(centre))
    assert np.linalg.norm(sg.residual_force[quiet], axis=1).mean() / sg.weight > 0.1


def test_an_impact_does_not_leak_into_frames_two_away(model):
    """A 10 ms, 4 kN kick on a foot in flight (an impact): frames more than two frames from it
    show < 10 % body weight; the frame it straddles sees it."""
    kick = np.array([0.0, 1500.0, 3700.0])
    dense, applied, _ = _simulate(
        model, seconds=0.8, z0=3.0, pushes=[("rfoot", kick, 0.395, 0.405, "box")]
    )
    dyn, centre = _analyse(model, dense)
    rf = np.linalg.norm(dyn.residual_force, axis=1) / dyn.weight
    hit = int(round(0.4 * FPS))
    far = np.abs(np.arange(len(centre)) - hit) > 2
    assert rf[far].max() < 0.10
    assert rf[~far].max() > 1.0  # the kick is seen where it is


def test_a_landing_does_not_leak_into_the_fall_and_stance_needs_no_residual(model):
    """Dropped onto the floor with limbs moving: free-fall frames more than two frames before the
    first contact show < 10 % body weight; frames standing on MuJoCo's contacts afterwards need
    little residual (ground forces at the true contact points explain them)."""
    dense, _, contacts = _simulate(model, seconds=0.9, z0=1.05, floor=True, kp=300.0, kd=10.0)
    dyn, centre = _analyse(model, dense, contacts)
    rf = np.linalg.norm(dyn.residual_force, axis=1) / dyn.weight
    touch = np.array([len(contacts[i]) > 0 for i in centre])
    first = int(np.argmax(touch))
    assert first > 3  # some free fall first
    assert rf[: first - 2].max() < 0.10
    assert np.abs(rf[: first - 2] - 0).mean() < 0.03
    stance = touch.copy()
    stance[: first + 3] = False  # the landing itself
    assert stance.sum() > 5
    assert np.median(rf[stance]) < 0.05
