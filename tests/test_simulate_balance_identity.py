"""The balance feedback's arithmetic, rearranged for speed, gives the torques of the feedback as
first written to the last bit: the first version (:func:`_oracle_torques`, kept here verbatim
as the oracle, with its drift lead) and ``sim.simulate.balance.balance_torques`` on perturbed
states of real CMU clips, in every stance (none, one foot, both), with and without the drift
term (at the root and at the feet, clipped and not, with a dead zone), with swing-foot
placement; and a whole search with either feedback finds the same offsets."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate import sampling
from sim.simulate.balance import Balance, balance_plan, balance_torques
from sim.simulate.drift import drift_lead
from sim.simulate.feedforward import reference_feedforward
from sim.simulate.model import sim_model

_DAMPED = 1e-3 * np.eye(3)

GAINS = {
    "plain": Balance(),
    "drift at the root, dead zone (eval's)": Balance(k_drift=2.0, drift_max=0.4, drift_dead=0.1),
    "drift at the feet": Balance(k_drift=2.0, drift_max=0.4, drift_dead=0.1, drift_feet=True),
    "drift clipped, no dead zone": Balance(k_drift=2.0, drift_max=0.05),
    "swing-foot placement": Balance(c_d=1.0, c_v=0.3),
    "all of them": Balance(c_d=1.0, c_v=0.3, k_drift=2.0, drift_dead=0.05, drift_feet=True),
}


def _oracle_drift_lead(ref_xy, sim_xy, rate, max_len, dead=0.0):
    if rate <= 0:
        return np.zeros(2)
    err = np.asarray(ref_xy, dtype=float) - np.asarray(sim_xy, dtype=float)
    n = float(np.hypot(err[0], err[1]))
    if dead <= 0:
        return rate * (err if n <= max_len else err * (max_len / n))
    return rate * err * (max(0.0, min(n, max_len) - dead) / n) if n > dead else np.zeros(2)


def _oracle_torques(model, data, plan, k: int, out: np.ndarray) -> np.ndarray:
    """``balance_torques`` as first written (array arithmetic throughout)."""
    out[:] = 0.0
    w = plan.share[k]
    if not w.any():
        return out
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    k_rot, d_rot, k_com, d_com = plan.gains
    e = np.zeros(3)
    mujoco.mju_subQuat(e, plan.quat[k], data.qpos[3:7])
    de = plan.angvel[k] - data.qvel[3:6]
    rot = data.xmat[1].reshape(3, 3) @ (k_rot * e + d_rot * de)
    mid = w @ data.xpos[plan.feet] / w.sum()
    f = k_com * ((data.subtree_com[1, :2] - mid[:2]) - plan.com_off[k])
    if plan.xy is not None:
        at = mid[:2] if plan.drift_feet else data.qpos[:2]
        f -= d_com * _oracle_drift_lead(plan.xy[k], at, *plan.drift)
    f += d_com * (data.qvel[:2] - plan.vel[k])
    M = np.empty((2, 2, 3))
    M[:, 0] = w[:, None] * rot
    M[:, 1] = w[:, None] * (f[1], -f[0], 0.0)
    X = data.xaxis[plan.jids] * plan.mask[..., None]
    XXt = X @ np.swapaxes(X, -1, -2) + _DAMPED
    tau = np.linalg.solve(XXt, X @ M[..., None])
    out[plan.aids[plan.valid]] = -tau.reshape(-1)[plan.valid.reshape(-1)]
    if plan.step is not None and w.sum() == 1.0 and w.max() == 1.0:
        swing = int(np.argmin(w))
        (c_d, c_v), kp, thighs = plan.step
        e_c = data.subtree_com[1, :2] - mid[:2] - plan.com_off[k]
        de_c = data.qvel[:2] - plan.vel[k]
        dp = c_d * e_c + c_v * de_c
        hip_to_ankle = data.xpos[plan.feet[swing]] - data.xpos[thighs[swing]]
        r = np.array([dp[1], -dp[0], 0.0]) / max(np.linalg.norm(hip_to_ankle), 1e-3)
        dq = np.linalg.solve(XXt[swing, 0], X[swing, 0] @ r)
        valid = plan.valid[swing, 0]
        out[plan.aids[swing, 0][valid]] += (kp[swing] * dq)[valid]
    return out


def _oracle_held(model, data, plan, k: int, out: np.ndarray) -> np.ndarray:
    return _oracle_torques(model, data, plan, k, out) if k % plan.every == 0 else out


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


@pytest.fixture(scope="module", params=["07_01", "17_10"])
def clip(request, trial_on_floor, model):
    """(ref_qpos, ref_qvel): 2 s of a walk (one and both feet) or of 17_10 (none, one, both)."""
    ref = trial_on_floor(model, request.param)[:240]
    qvel, _ = reference_feedforward(model, ref, mujoco.MjData(model))
    return ref, qvel


def _perturbed(model, ref, qvel, k: int, rng, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """A state near the reference's at tick ``k``: root moved (up to ``scale`` * 0.4 m, past
    the drift's clip and dead zone) and turned, hinges and velocities shaken."""
    q, v = ref[k].copy(), qvel[k].copy()
    q[:2] += scale * rng.uniform(-0.4, 0.4, 2)
    q[2] += scale * rng.uniform(-0.05, 0.05)
    turn = np.zeros(4)
    mujoco.mju_axisAngle2Quat(turn, rng.standard_normal(3), scale * rng.uniform(0, 0.4))
    mujoco.mju_mulQuat(q[3:7], turn, ref[k, 3:7].copy())
    q[7:] += scale * rng.normal(0, 0.15, model.nu)
    v += scale * rng.normal(0, 0.5, model.nv)
    return q, v


@pytest.mark.parametrize("name", list(GAINS))
def test_feedback_equals_the_first_version_bit_for_bit(model, clip, name):
    """Every tick of the clip, the reference's own state and three perturbed ones (the last
    with a tiny perturbation: errors near zero, where zeros' signs show): the same bytes,
    NaN written beforehand into ``out`` overwritten alike; all three stances met where the
    clip has them."""
    ref, qvel = clip
    plan = balance_plan(model, ref, qvel, GAINS[name])
    data = mujoco.MjData(model)
    rng = np.random.default_rng(7)
    new, old = np.full(model.nu, np.nan), np.full(model.nu, np.nan)
    nonzero = 0
    for k in range(len(ref)):
        for scale in (0.0, 1.0, 0.3, 1e-9):
            q, v = _perturbed(model, ref, qvel, k, rng, scale)
            data.qpos[:], data.qvel[:] = q, v
            a = balance_torques(model, data, plan, k, new).tobytes()
            data.qpos[:], data.qvel[:] = q, v  # the same state (the feedback leaves it)
            b = _oracle_torques(model, data, plan, k, old).tobytes()
            assert a == b, f"{name}, tick {k}, scale {scale}"
            nonzero += bool(np.any(new != 0.0))
    assert nonzero > len(ref)  # torques were made, not zeros compared
    counts = set(plan.stance.sum(axis=1).tolist())
    assert counts >= {1, 2}


def test_drift_lead_equals_the_first_version_bit_for_bit():
    """Errors inside the dead zone, between it and the clip, beyond the clip, at both edges
    exactly, and zero: the same bytes."""
    rng = np.random.default_rng(3)
    errs = np.concatenate([
        rng.normal(0, 0.3, (4000, 2)),
        [[0.0, 0.0], [-0.0, 0.0], [0.3, 0.4], [0.06, 0.08], [0.24, 0.32], [-0.3, 0.0]],
    ])  # fmt: skip
    for rate, max_len, dead in ((2.0, 0.4, 0.1), (2.0, 0.5, 0.0), (1.5, 0.1, 0.1), (0.0, 1, 0)):
        for err in errs:
            sim = rng.normal(0, 1, 2)
            ref = sim + err
            a = drift_lead(ref, sim, rate, max_len, dead).tobytes()
            assert a == _oracle_drift_lead(ref, sim, rate, max_len, dead).tobytes()


def test_a_search_with_either_feedback_finds_the_same_offsets(model, clip, monkeypatch):
    """The sampler's rollouts with the first version of the feedback in place of the present
    one: the same offsets and window-end states, exactly."""
    ref = clip[0][:72]
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=5, balance=GAINS["all of them"])
    new = sampling.search_offsets(model, ref, **kw)
    calls = []

    def oracle(model, data, plan, k, out):
        calls.append(k)
        return _oracle_held(model, data, plan, k, out)

    monkeypatch.setattr(sampling, "held_torques", oracle)
    old = sampling.search_offsets(model, ref, **kw)
    assert len(calls) > 6 * len(ref)  # the oracle ran every rollout tick
    for a, b in zip(new, old, strict=True):
        assert a.tobytes() == b.tobytes()
