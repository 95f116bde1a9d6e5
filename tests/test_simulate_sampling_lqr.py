"""The LQR's gain per window as the sampler's base policy (``sim.simulate.sampling_lqr``): off,
the gain-choosing sampler is what it was bit for bit; on, it is deterministic, its gains are
linearised once per window, the replay passes through the very states the rollouts reached, the
targets it applied (``data.ctrl``, what an episode stores) replayed through ``mj_step`` alone
give the same motion bit for bit, and the torques stay within the human limits."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.gainchoice import GainChoice, choice_search, choice_track, common_body
from sim.simulate.model import SUBSTEPS, Gains, sim_model
from sim.simulate.sampling import BALANCE
from sim.simulate.sampling_lqr import WindowLQR

STIFF = Gains(min_deflection=0.1, omega=2 * np.pi * 12.0)
KW = dict(samples=6, keep=2, seed=3, choice=GainChoice(share=0.5))


@pytest.fixture(scope="module")
def bodies():
    sk = canonical_skeleton()
    return common_body([sim_model(sk), sim_model(sk, gains=STIFF)])


@pytest.fixture(scope="module")
def walk(trial_on_floor, bodies):
    """0.5 s of the walk 07_01 on the canonical body, on the floor (120 Hz)."""
    return trial_on_floor(bodies[0], "07_01")[:60]


def test_off_is_the_sampler_bit_for_bit(bodies, walk):
    default, stiff = bodies
    before = choice_search(bodies, walk, **KW)
    off = choice_search(bodies, walk, lqr=None, **KW)
    for a, b in zip(before, off, strict=True):
        np.testing.assert_array_equal(a, b)
    plain = choice_track(default, walk, alternates=(stiff,), record_every=1, **KW)
    none = choice_track(default, walk, alternates=(stiff,), record_every=1, lqr_feedback=None,
                        **KW)  # fmt: skip
    np.testing.assert_array_equal(plain.qpos, none.qpos)
    # a zero scale runs every step of the hook (linearisations on the rollouts' scratch data,
    # the feedback added to every target) and must change nothing: x + (-0.0) is x
    lqr = WindowLQR(0.0)
    zero = choice_search(bodies, walk, lqr=lqr, **KW)
    assert len(lqr.gains) == 5
    for a, b in zip(before, zero, strict=True):
        np.testing.assert_array_equal(a, b)
    again = choice_track(default, walk, alternates=(stiff,), record_every=1, lqr_feedback=0.0,
                         **KW)  # fmt: skip
    np.testing.assert_array_equal(again.qpos, plain.qpos)


class _Log:
    """A recorder: each tick's state, applied control and model (as an episode records)."""

    def __init__(self, model, ticks: int):
        self.ticks = ticks
        self.spec = mujoco.mjtState.mjSTATE_INTEGRATION
        self.start = np.empty(mujoco.mj_stateSize(model, self.spec))
        self.ctrl, self.models, self.qpos = [], [], []

    def __call__(self, k, data, model):
        if k == 0:
            mujoco.mj_getState(model, data, self.start, self.spec)
        self.qpos.append(data.qpos.copy())  # the state before tick k's steps
        if k < self.ticks:
            self.ctrl.append(data.ctrl.copy())
            self.models.append(model)


def test_on_it_replays_the_rolled_out_states_and_its_actions_bit_for_bit(bodies, walk):
    default, stiff = bodies
    lqr = WindowLQR(1.0)
    off, sets, reached = choice_search(bodies, walk, lqr=lqr, **KW)
    assert sorted(lqr.gains) == list(range(5))  # one gain per window (5 of 12 ticks)
    assert any(np.abs(g).max() > 0 for g in lqr.gains.values())
    log = _Log(default, len(walk))
    r = track(default, walk, assist_limit=0.0, offsets=off, record_every=1, balance=BALANCE,
              switch=(bodies, sets), feedback=lqr.feedback, recorder=log)  # fmt: skip
    assert not r.fell
    np.testing.assert_array_equal(r.qpos[12::12], reached[:-1])  # the very states, bit for bit
    lim = default.actuator_forcerange[:, 1]
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-9))  # human strength
    # the stored targets alone, stepped through MuJoCo, give the same motion (no controller)
    data = mujoco.MjData(default)
    mujoco.mj_setState(default, data, log.start, log.spec)
    for k, (ctrl, m) in enumerate(zip(log.ctrl, log.models, strict=True)):
        np.testing.assert_array_equal(data.qpos, log.qpos[k])
        data.ctrl[:] = ctrl
        mujoco.mj_step(m, data, nstep=SUBSTEPS)
    np.testing.assert_array_equal(data.qpos, log.qpos[-1])
    # the feedback acted: the applied targets differ from the sampler's own on the same offsets
    plain = track(default, walk, assist_limit=0.0, offsets=off, record_every=1, balance=BALANCE,
                  switch=(bodies, sets))  # fmt: skip
    assert not np.array_equal(plain.qpos, r.qpos)
    # deterministic, any number of threads, through the tracker's entry point
    again = choice_track(default, walk, alternates=(stiff,), record_every=1, threads=2,
                         lqr_feedback=1.0, **KW)  # fmt: skip
    np.testing.assert_array_equal(again.qpos, r.qpos)


def test_the_feedback_is_the_gain_times_the_state_error_over_kp(bodies, walk):
    default, stiff = bodies
    lqr = WindowLQR(0.5)
    lqr.start(walk, np.zeros((len(walk), default.nv)), 12)
    data = mujoco.MjData(default)
    data.qpos[:] = walk[0]
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(default, spec))
    mujoco.mj_forward(default, data)
    mujoco.mj_getState(default, data, state, spec)
    K = lqr.set_window(0, default, mujoco.MjData(default), state, spec, np.zeros(default.nu))
    data.qpos[7] += 0.1  # one hinge off by 0.1 rad, at rest
    dx = np.zeros(2 * default.nv)
    dx[6] = 0.1
    for m in (default, stiff):  # the same torque on either gains
        got = lqr.feedback(m, data, 3)
        np.testing.assert_allclose(got * m.actuator_gainprm[:, 0], -K @ dx, rtol=1e-9,
                                   atol=1e-12)  # fmt: skip
