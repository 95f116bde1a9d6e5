"""The keyframe environment: Gymnasium contract, the paper's reward (eq. 21-22), determinism."""

import itertools
import shutil

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from sidql.learning.env import ENV_ID, InvalidActionError, KeyframeEnv
from sidql.learning.tasks import KeyframeTask, keyframe_q, linear_cost_matrix, synthetic_tasks


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
    env = KeyframeEnv(tasks, keyframe_counts=(7,))
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
    env = KeyframeEnv(tasks, keyframe_counts=(3,))
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
    np.testing.assert_array_equal(obs["features"], env.scaled(tasks[2])[0])
    assert env.unwrapped.tasks[info["task_index"]] is tasks[2]  # the raw arrays
    with pytest.raises(ValueError, match="keyframes"):
        env.reset(options={"keyframes": 2})


@pytest.mark.parametrize(
    "options, error, match",
    [
        ({"keyframe": 5}, ValueError, "unknown reset option.*'keyframe'.*known: task, keyframes"),
        ({"task": 1, "seed": 3}, ValueError, "unknown reset option.*'seed'"),
        ({"task": 1.7}, TypeError, "options\\['task'\\] must be an integer; got 1.7"),
        ({"keyframes": 5.0}, TypeError, "options\\['keyframes'\\] must be an integer"),
        ({"task": True}, TypeError, "must be an integer"),
    ],
)
def test_reset_refuses_unknown_option_keys_and_non_integer_values(tasks, options, error, match):
    env = KeyframeEnv(tasks)
    with pytest.raises(error, match=match):
        env.reset(seed=0, options=options)
    # integer types of every kind are accepted
    obs, info = env.reset(options={"task": np.int64(1), "keyframes": np.array(4)})
    assert info["task_index"] == 1 and obs["remaining"] == 2


def test_float_actions_are_refused_not_truncated(tasks):
    env = KeyframeEnv(tasks, keyframe_counts=(6,))
    env.reset(seed=0)
    for bad in (13.9, 13.0, np.float32(5.0), np.array(4.0), "4", True, None):
        with pytest.raises(InvalidActionError, match="must be an integer"):
            env.step(bad)
    assert env.action_masks().sum() == env.n_frames - 2  # nothing was chosen by the bad actions
    for good in (13, np.int64(5), np.array(7), np.array([9], dtype=np.int32)):
        _, _, _, _, info = env.step(good)
    assert np.flatnonzero(info["keyframe_mask"]).tolist() == [0, 5, 7, 9, 13, 19]


def test_zero_initial_error_gives_zero_rewards():
    task = KeyframeTask(np.zeros((6, 2), np.float32), np.zeros((6, 6)))
    env = KeyframeEnv([task], keyframe_counts=(4,))
    env.reset(seed=0)
    _, r, _, _, info = env.step(2)
    assert r == 0.0 and info["R"] == 0.0


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_env_runs_thousands_of_steps_with_episodes_out_of_step(mode):
    """Default settings (synthetic clips, W drawn from 5, 10, 15 per episode), so the two
    environments end their episodes at different steps; every info entry has a fixed shape."""
    envs = gym.make_vec("sidql.learning.env:sidql/Keyframe-v0", num_envs=2, vectorization_mode=mode)
    obs, infos = envs.reset(seed=0)
    assert obs["features"].shape == (2, 60, 12) and infos["action_mask"].shape == (2, 60)
    rng = np.random.default_rng(0)
    episodes, out_of_step = 0, 0
    for _ in range(2_000):
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in infos["action_mask"]])
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        assert infos["keyframe_mask"].shape == (2, 60) and infos["keyframe_mask"].dtype == bool
        np.testing.assert_array_equal(infos["keyframe_mask"], obs["keyframes"].astype(bool))
        np.testing.assert_array_equal(infos["action_mask"], ~infos["keyframe_mask"])
        assert envs.observation_space.contains(obs)
        episodes += int(terminated.sum())
        out_of_step += int(terminated[0] != terminated[1])
    envs.close()
    assert episodes > 2_000 / 15 and out_of_step > 50


def test_action_masks_through_wrappers_the_documented_way():
    env = gym.make(ENV_ID)  # wrapped (order enforcing, passive checker)
    _, info = env.reset(seed=0)
    with pytest.raises(AttributeError):
        env.action_masks()  # not forwarded by Gymnasium's wrappers
    np.testing.assert_array_equal(env.unwrapped.action_masks(), info["action_mask"])
    np.testing.assert_array_equal(env.get_wrapper_attr("action_masks")(), info["action_mask"])
    env.step(7)
    assert not env.get_wrapper_attr("action_masks")()[7] and not env.unwrapped.action_masks()[7]
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync")
    _, infos = envs.reset(seed=0)
    np.testing.assert_array_equal(np.stack(envs.call("action_masks")), infos["action_mask"])
    envs.close()


def test_observations_are_bounded_on_a_unit_scale_and_keep_the_rewards(tasks):
    env = KeyframeEnv(tasks, keyframe_counts=(8,))
    for space in ("features", "cost"):
        assert np.all(np.isfinite(env.observation_space[space].low))
        assert np.all(np.isfinite(env.observation_space[space].high))
    seen = []
    for i in range(len(tasks)):
        obs, info = env.reset(seed=i, options={"task": i})
        assert env.observation_space.contains(obs)
        assert obs["cost"].max() == 1.0 and obs["cost"].min() == 0.0
        seen.append(obs["features"])
        # rewards read off the observed costs: (c[l, r] - c[l, a] - c[a, r]) / c[0, N-1]
        c, n = obs["cost"].astype(np.float64), env.n_frames
        for a in (3, 11, 16):
            obs, r, *_ = env.step(a)
            left = max(k for k in range(a) if obs["keyframes"][k] and k != a)
            right = min(k for k in range(a + 1, n) if obs["keyframes"][k])
            assert r == pytest.approx((c[left, right] - c[left, a] - c[a, right]) / c[0, n - 1])
    seen = np.concatenate(seen)  # every frame of every task: standardised per channel
    assert np.abs(seen).max() < 5.0  # nothing clipped here, so exactly standardised
    np.testing.assert_allclose(seen.mean(0), 0.0, atol=1e-5)
    np.testing.assert_allclose(seen.std(0), 1.0, atol=1e-4)
    # an evaluation env can take the training env's standardisation
    other = KeyframeEnv(tasks[:2], feature_stats=(env.feature_mean, env.feature_std))
    obs, _ = other.reset(options={"task": 0})
    np.testing.assert_array_equal(obs["features"], env.scaled(tasks[0])[0])


def test_real_clip_observations_stay_in_bounds_and_env_q_is_q_error(walk_clip):
    """One Q: the environment's Q (and so its reward) equals sidql.keyframes.metrics.q_error of
    the reconstruction, on real clips."""
    from sidql.keyframes.metrics import q_error
    from sidql.keyframes.spherical import chart
    from sidql.learning.tasks import clip_task

    clips = [walk_clip.slice(s, s + 60) for s in (0, 13, 26)]
    env = KeyframeEnv([clip_task(c) for c in clips], keyframe_counts=(9,))
    rng = np.random.default_rng(1)
    for i, clip in enumerate(clips):
        obs, info = env.reset(options={"task": i})
        series = chart(clip)
        assert info["q0"] == pytest.approx(q_error(series, [0, 59]), rel=1e-9)
        done = False
        while not done:
            assert env.observation_space.contains(obs)
            obs, r, done, _, info = env.step(int(rng.choice(np.flatnonzero(info["action_mask"]))))
            q = q_error(series, np.flatnonzero(info["keyframe_mask"]))
            assert info["q"] == pytest.approx(q, rel=1e-9)
            assert r == pytest.approx((info["q_prev"] - q) / info["q0"], rel=1e-9, abs=1e-12)


def test_load_tasks_gives_env_tasks_and_a_repeated_load_reads_only_the_default_cache(
    tmp_path, monkeypatch, cmu_dir
):
    import sidql.learning.tasks as tasks_module

    data = tmp_path / "data" / "02"
    data.mkdir(parents=True)
    for name in ("02.asf", "02_02.amc"):
        shutil.copy(cmu_dir / "02" / name, data / name)
    monkeypatch.setenv("SIDQL_CACHE", str(tmp_path / "cache"))
    first = tasks_module.load_tasks(tmp_path / "data", progress=False)  # no cache_dir given
    tasks = first.tasks()  # the README's line
    assert len(tasks) == 1 and isinstance(tasks[0], KeyframeTask) and first.skipped == []
    assert len(list((tmp_path / "cache").glob("02_02-*.npz"))) == 1

    def no_motion_reading(*args, **kwargs):
        raise AssertionError("a repeated load read the motion files")

    monkeypatch.setattr(tasks_module, "load_motion", no_motion_reading)
    again = tasks_module.load_tasks(tmp_path / "data", progress=False).tasks()
    np.testing.assert_array_equal(again[0].cost, tasks[0].cost)
    np.testing.assert_array_equal(again[0].features, tasks[0].features)
    env = KeyframeEnv(again)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    with pytest.raises(AssertionError, match="read the motion files"):  # False: no cache at all
        tasks_module.load_tasks(tmp_path / "data", progress=False, cache_dir=False)


def test_the_old_keyword_for_the_keyframe_counts_still_works_and_warns(tasks):
    with pytest.warns(FutureWarning, match="KeyframeEnv\\(keyframes=...\\) is an old name"):
        env = KeyframeEnv(tasks, keyframes=(6,))
    assert env.keyframe_counts == (6,)
    obs, _ = env.reset(seed=0)
    assert obs["remaining"] == 4
