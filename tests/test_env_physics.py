"""The keyframe environment's physical reward: each step's reward moves by the physical cost of
the segments it changes, its terms add up to it, the default reward is unchanged to the bit, and
a run's tasks carry the ``physics`` method's own segment costs."""

from dataclasses import replace

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from keyframe_synth import smooth_clip

from sidql.keyframes import methods
from sidql.keyframes.optimal import solve
from sidql.keyframes.physical_costs import PHYSICS_WEIGHT
from sidql.learning.env import KeyframeEnv
from sidql.learning.settings import Args, settings_problems
from sidql.learning.tasks import (
    KeyframeTask,
    clip_task,
    physics_task,
    reward_tasks,
    synthetic_tasks,
)
from sim.errors import UsageError

N = 20
LAMBDA = 0.3


@pytest.fixture(scope="module")
def tasks():
    rng = np.random.default_rng(7)
    out = []
    for t in synthetic_tasks(4, n_frames=N, n_channels=3, seed=2):
        P = np.triu(rng.random((N, N)) * 2.0, 2)  # any non-negative cost of the inner frames
        out.append(replace(t, physical=P))
    return out


def _episode(env, task, actions):
    obs, info = env.reset(options={"task": task, "keyframes": len(actions) + 2})
    steps = []
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        steps.append((r, info, obs))
    return steps


ACTIONS = [7, 3, 14, 10, 1]


def test_default_reward_is_unchanged_to_the_bit(tasks):
    bare = [replace(t, physical=None) for t in tasks]
    for i in range(len(tasks)):
        a = _episode(KeyframeEnv(tasks), i, ACTIONS)
        b = _episode(KeyframeEnv(bare), i, ACTIONS)
        for (ra, ia, oa), (rb, ib, ob) in zip(a, b, strict=True):
            assert ra == rb and ia["R"] == ib["R"] and ia["q"] == ib["q"]
            assert np.array_equal(oa["cost"], ob["cost"])
            assert ia["physical"] == 0.0 and ia["reward_physics"] == 0.0


def _phi(P, keys):
    """Phi: the physical cost of the segments between sorted keyframes over N M, by a loop."""
    return sum(P[a, b] for a, b in zip(keys[:-1], keys[1:], strict=False)) / (N * 3)


def test_the_reward_moves_by_the_physical_cost_of_the_segments(tasks):
    env = KeyframeEnv(tasks, physics_weight=LAMBDA)
    plain = KeyframeEnv(tasks)
    for i, t in enumerate(tasks):
        steps, base = _episode(env, i, ACTIONS), _episode(plain, i, ACTIONS)
        q0 = base[0][1]["q0"]
        e0 = q0 + LAMBDA * _phi(t.physical, [0, N - 1])
        keys = [0, N - 1]
        for (r, info, _), (_, binfo, _) in zip(steps, base, strict=True):
            before = _phi(t.physical, keys)
            keys = sorted([*keys, ACTIONS[len(keys) - 2]])
            after = _phi(t.physical, keys)
            q_part = (binfo["q_prev"] - binfo["q"]) / e0
            assert info["physical"] == pytest.approx(after, rel=1e-12)
            assert info["reward_q"] == pytest.approx(q_part, rel=1e-9, abs=1e-15)
            assert info["reward_physics"] == pytest.approx(LAMBDA * (before - after) / e0, rel=1e-9)
            assert r == pytest.approx(info["reward_q"] + info["reward_physics"], abs=1e-12)
            assert r == pytest.approx(info["R"] - info["R_prev"], abs=1e-15)
        assert any(s[1]["reward_physics"] != 0 for s in steps)


def test_a_first_step_changes_by_the_split_segments_physical_cost(tasks):
    t = tasks[0]
    a = 9
    (r, info, _), = _episode(KeyframeEnv(tasks, physics_weight=LAMBDA), 0, [a])  # fmt: skip
    (r0, info0, _), = _episode(KeyframeEnv(tasks), 0, [a])  # fmt: skip
    P = t.physical
    e0 = info0["q0"] + LAMBDA * P[0, N - 1] / (N * 3)
    gain = (P[0, N - 1] - P[0, a] - P[a, N - 1]) / (N * 3)
    assert r == pytest.approx(r0 * info0["q0"] / e0 + LAMBDA * gain / e0, rel=1e-9)


def test_folded_costs_give_the_same_rewards(tasks):
    env = KeyframeEnv(tasks, physics_weight=LAMBDA)
    folded = KeyframeEnv([physics_task(t, LAMBDA) for t in tasks])
    for i in range(len(tasks)):
        for (ra, _, oa), (rb, _, ob) in zip(
            _episode(env, i, ACTIONS), _episode(folded, i, ACTIONS), strict=True
        ):
            assert ra == pytest.approx(rb, abs=1e-12)
            assert np.allclose(oa["cost"], ob["cost"], atol=1e-6)


def test_the_physical_reward_passes_check_env_and_refuses_what_it_cannot_use(tasks):
    check_env(KeyframeEnv(tasks, physics_weight=LAMBDA), skip_render_check=True)
    with pytest.raises(UsageError, match="physical costs"):
        KeyframeEnv(synthetic_tasks(2, n_frames=N, seed=0), physics_weight=LAMBDA)
    with pytest.raises(UsageError, match=">= 0"):
        KeyframeEnv(tasks, physics_weight=-1.0)
    with pytest.raises(UsageError, match="physical must be"):
        replace(tasks[0], physical=np.zeros((3, 3)))
    with pytest.raises(UsageError, match="no physical costs"):
        physics_task(replace(tasks[0], physical=None))


def test_a_clip_tasks_physical_optimum_is_the_physics_methods_choice():
    clip = smooth_clip(N=60, fps=30.0, seed=4)
    task = physics_task(clip_task(clip, physics=True))
    assert isinstance(task, KeyframeTask) and task.physical.shape == (60, 60)
    table = solve(task.cost, task.n_bones, 10)
    for W in (5, 10):
        assert np.array_equal(table.keyframes(W), methods.select("physics", clip, W))
    assert reward_tasks([task], "q")[0] is task


def test_reward_settings_are_checked():
    assert settings_problems(Args(reward="physics", data="somewhere")) == []
    assert any("--reward must be" in p for p in settings_problems(Args(reward="force")))
    assert any("needs --data" in p for p in settings_problems(Args(reward="physics")))
    assert PHYSICS_WEIGHT > 0
