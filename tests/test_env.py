"""The keyframe environment: Gymnasium contract, the paper's reward (eq. 21-22), determinism."""

import itertools

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from sidql.learning.env import ENV_ID, InvalidActionError, KeyframeEnv, KeyframeTask, keyframe_q
from sidql.learning.tasks import linear_cost_matrix, synthetic_tasks


@pytest.fixture(scope="module")
def tasks():
    return synthetic_tasks(5, n_frames=20, n_channels=3, seed=1)


def brute_linear_q(x, keyframes):
    """Q of linear interpolation through the keyframes, by rebuilding the whole signal."""
    n = np.arange(len(x))
    rebuilt = np.stack([np.interp(n, keyframes, x[keyframes, c]) for c in range(x.shape[1])], 1)
    return np.abs(rebuilt - x).sum() / (x.shape[0] * x.shape[1])


def test_check_env_passes(tasks):
    check_env(KeyframeEnv(tasks), skip_render_check=True)


def test_registered_id_makes_a_working_env_and_wrappers_work():
    env = gym.make(ENV_ID)
    obs, info = env.reset(seed=3)
    assert obs["keyframes"][[0, -1]].tolist() == [1, 1]
    flat = gym.wrappers.FlattenObservation(gym.make(ENV_ID))
    fobs, info = flat.reset(seed=3)
    assert fobs.shape == flat.observation_space.shape
    check_env(gym.make(ENV_ID).unwrapped, skip_render_check=True)


def test_linear_cost_matrix_matches_rebuilding_the_signal():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(9, 2)), axis=0)
    cost = linear_cost_matrix(x)
    task = KeyframeTask(np.zeros((9, 1), np.float32), cost, n_bones=2)
    for k in itertools.combinations(range(1, 8), 2):
        keys = [0, *k, 8]
        assert keyframe_q(task, keys) == pytest.approx(brute_linear_q(x, keys), rel=1e-12)


def test_rewards_sum_to_final_minus_initial_R_and_info_holds_the_terms(tasks):
    env = KeyframeEnv(tasks, keyframes=(7,))
    obs, info = env.reset(seed=0)
    task = tasks[info["task_index"]]
    q0 = keyframe_q(task, [0, task.n_frames - 1])
    assert info["q0"] == pytest.approx(q0, rel=1e-12) and info["R"] == 0.0
    rng = np.random.default_rng(0)
    rewards, terminated = [], False
    while not terminated:
        a = rng.choice(np.flatnonzero(info["action_mask"]))
        obs, r, terminated, truncated, info = env.step(a)
        assert not truncated
        assert r == info["R"] - info["R_prev"]
        # R recomputed independently from the keyframe set.
        q = keyframe_q(task, np.flatnonzero(obs["keyframes"]))
        assert info["q"] == pytest.approx(q, rel=1e-12)
        assert info["R"] == pytest.approx(1 - q / q0, rel=1e-12, abs=1e-15)
        rewards.append(r)
    assert len(rewards) == 5 and obs["keyframes"].sum() == 7 and obs["remaining"] == 0
    assert sum(rewards) == pytest.approx(info["R"] - 0.0, rel=1e-12, abs=1e-15)


def test_same_seed_same_episode(tasks):
    def episode(seed):
        env = KeyframeEnv(tasks)
        env.action_space.seed(seed)
        obs, info = env.reset(seed=seed)
        trace = [info["task_index"], obs["remaining"]]
        done = False
        while not done:
            a = env.action_space.sample(mask=info["action_mask"].astype(np.int8))
            obs, r, done, _, info = env.step(a)
            trace += [int(a), r]
        return trace

    assert episode(5) == episode(5)
    assert any(episode(5) != episode(s) for s in range(6, 10))


def test_invalid_actions_raise_clear_errors(tasks):
    env = KeyframeEnv(tasks, keyframes=(3,))
    env.reset(seed=0)
    with pytest.raises(InvalidActionError, match="already a keyframe"):
        env.step(0)
    with pytest.raises(InvalidActionError, match="outside"):
        env.step(env.n_frames)
    assert env.action_masks()[[0, -1]].tolist() == [False, False]
    _, _, done, _, _ = env.step(4)
    assert done
    with pytest.raises(InvalidActionError, match="ended"):
        env.step(5)


def test_reset_options_pick_the_clip_and_the_keyframe_count(tasks):
    env = KeyframeEnv(tasks)
    obs, info = env.reset(seed=0, options={"task": 2, "keyframes": 4})
    assert info["task_index"] == 2 and obs["remaining"] == 2
    np.testing.assert_array_equal(obs["features"], tasks[2].features)
    with pytest.raises(ValueError, match="keyframes"):
        env.reset(options={"keyframes": 2})


def test_zero_initial_error_gives_zero_rewards():
    task = KeyframeTask(np.zeros((6, 2), np.float32), np.zeros((6, 6)))
    env = KeyframeEnv([task], keyframes=(4,))
    env.reset(seed=0)
    _, r, _, _, info = env.step(2)
    assert r == 0.0 and info["R"] == 0.0


def test_vector_env_runs_episodes_with_masks_from_infos():
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync")
    obs, infos = envs.reset(seed=0)
    assert obs["features"].shape[0] == 2 and infos["action_mask"].shape == (2, 60)
    rng = np.random.default_rng(0)
    finished = 0
    for _ in range(30):
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in infos["action_mask"]])
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        finished += int(terminated.sum())
        if finished >= 2:
            break
    assert finished >= 2
    envs.close()
