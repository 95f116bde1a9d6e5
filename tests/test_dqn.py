"""The SIDQL DQN: network features, n-step returns, policy files, and a tiny training run."""

import itertools
import subprocess
import sys

import numpy as np
import pytest
import torch

from sidql.keyframes.methods import greedy_from_costs
from sidql.learning.dqn import Args, NStep, ReplayMemory, save_policy, train
from sidql.learning.env import KeyframeEnv, insertion_gain, keyframe_error_sum
from sidql.learning.policy import Policy, load_policy
from sidql.learning.qnet import KeyframeQNet, current_error, gain_features
from sidql.learning.tasks import synthetic_tasks

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def tasks():
    return synthetic_tasks(12, n_frames=24, n_channels=4, seed=3)


def mean_q(tasks, keys):
    return np.mean(
        [
            keyframe_error_sum(t.cost, k) / (t.n_frames * t.n_bones)
            for t, k in zip(tasks, keys, strict=True)
        ]
    )


def test_gain_features_match_brute_force():
    rng = np.random.default_rng(0)
    n = 9
    cost = np.triu(rng.uniform(0, 1, (n, n)), 1)
    mask = np.zeros(n, bool)
    mask[[0, 4, n - 1]] = True
    c = torch.as_tensor(cost)[None]
    for a in [1, 2, 3, 5, 6, 7]:
        left = max(k for k in range(a) if mask[k])
        right = min(k for k in range(a + 1, n) if mask[k])
        t = lambda i: torch.tensor([[i]])  # noqa: E731
        g1, g2l, g2r, c_lr, c_la, c_ar = (
            float(x) for x in gain_features(c, t(a), t(left), t(right))
        )
        s0 = cost[0, n - 1]

        def err(keys):
            return keyframe_error_sum(cost, sorted(keys))

        base = set(np.flatnonzero(mask))
        with_a = base | {a}
        assert g1 == pytest.approx((err(base) - err(with_a)) / s0)
        best_l = max([err(with_a) - err(with_a | {m}) for m in range(left + 1, a)] + [0.0])
        best_r = max([err(with_a) - err(with_a | {m}) for m in range(a + 1, right)] + [0.0])
        assert g2l == pytest.approx(best_l / s0) and g2r == pytest.approx(best_r / s0)
        assert (c_lr, c_la, c_ar) == pytest.approx(
            (cost[left, right] / s0, cost[left, a] / s0, cost[a, right] / s0)
        )


def test_current_error_is_the_error_sum_of_the_keyframes():
    rng = np.random.default_rng(2)
    n = 10
    cost = np.triu(rng.uniform(0, 1, (n, n)), 1)
    for keys in ([0, n - 1], [0, 3, 7, n - 1], [0, 1, 2, 8, n - 1]):
        mask = np.zeros(n, bool)
        mask[keys] = True
        right = np.array([min(k for k in range(i, n) if mask[k]) for i in range(n)])
        t = torch.as_tensor
        e = current_error(t(cost)[None], t(mask)[None], t(right)[None])
        assert float(e) == pytest.approx(keyframe_error_sum(cost, keys) / cost[0, n - 1])


def test_untrained_network_is_exactly_the_greedy_method(tasks):
    """The head is Q = exact reward + a learned term that starts at zero."""
    net = KeyframeQNet(tasks[0].features.shape[1])
    policy = Policy(net, (5,), {})
    feats = np.stack([t.features for t in tasks])
    costs = np.stack([t.cost for t in tasks])
    for w in (3, 6, 10):
        keys = policy.decide(feats, costs, w)
        for t, k in zip(tasks, keys, strict=True):
            np.testing.assert_array_equal(k, greedy_from_costs(t.cost, w))


def test_nstep_transitions_discount_rewards_and_bootstrap():
    mem = ReplayMemory(10, 4)
    ns = NStep(2, 0.5)
    m = np.zeros(4, bool)
    rewards = [1.0, 2.0, 4.0]
    for i, r in enumerate(rewards):
        ns.push(mem, 0, m, 3 - i, i, r, m, 2 - i, done=i == 2)
    assert len(mem) == 3
    np.testing.assert_allclose(mem.ret[:3], [1 + 0.5 * 2, 2 + 0.5 * 4, 4])
    np.testing.assert_allclose(mem.disc[:3], [0.25, 0.25, 0.5])
    np.testing.assert_array_equal(mem.done[:3], [0, 1, 1])
    np.testing.assert_array_equal(mem.action[:3], [0, 1, 2])


def test_tiny_training_beats_random_resumes_and_ships_a_loadable_policy(tmp_path, tasks):
    out = tmp_path / "p.pt"
    args = Args(
        out=str(out), steps=240, synthetic_tasks=16, keyframes=(4, 6), batch_size=32,
        buffer_size=500, learning_starts=60, train_frequency=4, target_update=20, n_envs=4,
        demo_episodes=40, eval_every=120, progress=False, seed=1,
    )  # fmt: skip
    result = train(args)
    assert out.exists() and out.with_suffix(".csv").exists() and out.with_suffix(".png").exists()
    test = synthetic_tasks(16, seed=1)[:4]
    rng = np.random.default_rng(0)
    for w in (4, 6):
        rand = [np.sort(np.r_[0, rng.choice(np.arange(1, 59), w - 2, replace=False), 59])
                for _ in test]  # fmt: skip
        assert result["dqn"][w] < mean_q(test, rand)
        assert result["dqn"][w] >= result["optimal"][w] - 1e-12
    policy = load_policy(out)
    feats = np.stack([t.features for t in test])
    keys = policy.decide(feats, np.stack([t.cost for t in test]), 6)
    assert mean_q(test, keys) == pytest.approx(result["dqn"][6])
    # resume: the run continues from its checkpoint's step, the log grows, nothing restarts
    args.steps, args.resume = 360, True
    train(args)
    steps = [int(line.split(",")[0]) for line in out.with_suffix(".csv").read_text().split()[1:]]
    assert steps == [0, 120, 240, 360]


def test_policy_round_trip_and_bad_inputs(tmp_path, tasks):
    net = KeyframeQNet(tasks[0].features.shape[1])
    torch.nn.init.normal_(net.adv_out.weight, std=0.5)
    torch.nn.init.normal_(net.value_out.weight, std=0.5)
    path = tmp_path / "p.pt"
    save_policy(net, path, Args(keyframes=(5,)), {"train": [], "test": []}, {}, {})
    loaded = load_policy(path)
    feats = np.stack([t.features for t in tasks])
    costs = np.stack([t.cost for t in tasks])
    np.testing.assert_array_equal(
        loaded.decide(feats, costs, 7), Policy(net, (5,), {}).decide(feats, costs, 7)
    )
    # the compiled decision kernel takes the same decisions as the torch head
    for w in (3, 8, 15):
        np.testing.assert_array_equal(
            loaded.decide(feats, costs, w), loaded.decide_torch(feats, costs, w)
        )
    with pytest.raises(ValueError, match="features"):
        loaded.decide(feats[..., :2], costs, 5)
    with pytest.raises(ValueError, match="W must"):
        loaded.decide(feats, costs, 1)
    with pytest.raises(FileNotFoundError, match="sidql train"):
        load_policy(tmp_path / "missing.pt")


def test_dqn_method_is_lazy_and_the_env_accepts_its_actions(tasks):
    code = (
        "import sys, sidql.keyframes.methods as m; assert 'torch' not in sys.modules; "
        "assert 'dqn' in m.available(); print('ok')"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    env = KeyframeEnv(tasks, keyframes=(6,))
    net = KeyframeQNet(tasks[0].features.shape[1])
    obs, info = env.reset(seed=0)
    done = False
    while not done:
        task = env.tasks[info["task_index"]]  # the network reads the raw arrays
        q = net(torch.as_tensor(task.features)[None], torch.as_tensor(task.cost)[None].float(),
                torch.as_tensor(obs["keyframes"].astype(bool))[None], torch.tensor([obs["remaining"]]))  # fmt: skip
        a = int(q.masked_fill(~torch.as_tensor(info["action_mask"])[None], -np.inf).argmax())
        obs, r, done, _, info = env.step(a)
    assert obs["keyframes"].sum() == 6


def test_subject_split_never_overlaps():
    from sidql.learning.dqn import split_subjects

    subjects = [f"{i:02d}" for i in range(10)]
    for seed in range(4):
        train_s, test_s = split_subjects(subjects, seed=seed)
        assert not set(train_s) & set(test_s) and sorted(train_s + test_s) == subjects
    assert split_subjects(subjects, ("03",))[1] == ["03"]
    with pytest.raises(ValueError):
        split_subjects(["01"], seed=0)


def test_every_pair_of_tiny_costs_has_the_brute_force_optimum_in_the_logged_baseline():
    from sidql.learning.dqn import optimal_keyframes

    rng = np.random.default_rng(1)
    cost = np.triu(rng.uniform(0, 1, (8, 8)), 1)
    best = min(
        (keyframe_error_sum(cost, [0, *k, 7]), [0, *k, 7])
        for k in itertools.combinations(range(1, 7), 3)
    )
    assert keyframe_error_sum(cost, optimal_keyframes(cost, 5)) == pytest.approx(best[0])


def brute_greedy_completion(cost, keys, k):
    """Total gain of adding k keyframes greedily to sorted ``keys`` (full recomputation)."""
    keys = sorted(keys)
    total = 0.0
    for _ in range(k):
        err = keyframe_error_sum(cost, keys)
        free = [a for a in range(cost.shape[0]) if a not in keys]
        gains = [err - keyframe_error_sum(cost, sorted(keys + [a])) for a in free]
        j = int(np.argmax(gains))
        total += gains[j]
        keys = sorted(keys + [free[j]])
    return total


def test_rollout_values_equal_a_brute_force_greedy_completion():

    rng = np.random.default_rng(4)
    n = 12
    cost = np.triu(rng.uniform(0, 1, (n, n)), 1) * np.arange(n)[None, :] ** 0.5
    for keys in ([0, 5, n - 1], [0, 2, 6, 8, n - 1]):
        mask = np.zeros(n, bool)
        mask[keys] = True
        check_rollout(cost, mask, n)


def check_rollout(cost, mask, n):
    from sidql.learning.rollout import greedy_sequences, rollout_values, rollout_values_seq

    for rem in (1, 2, 4):
        vals = rollout_values(cost, mask, rem)
        seq, length = greedy_sequences(cost, 5)
        np.testing.assert_allclose(
            rollout_values_seq(cost, mask, rem, seq, length), vals, atol=1e-12
        )
        for a in np.flatnonzero(~mask):
            keys = [*np.flatnonzero(mask).tolist(), int(a)]
            expect = brute_greedy_completion(cost, keys, rem - 1) / cost[0, n - 1]
            assert vals[a] == pytest.approx(expect, abs=1e-12)
        assert np.all(vals[mask] == 0)


def test_untrained_rollout_prior_network_is_the_rollout_algorithm(tasks):
    """With the rollout prior, Q starts at Q^greedy (γ = 1): argmax = reward + greedy completion;
    the compiled kernel and the torch head agree, also once the learned part is not zero."""
    from sidql.learning.rollout import rollout_values

    net = KeyframeQNet(tasks[0].features.shape[1], prior="rollout")
    policy = Policy(net, (5,), {})
    feats = np.stack([t.features for t in tasks])
    costs = np.stack([t.cost for t in tasks])
    w = 6
    keys = policy.decide(feats, costs, w)
    for t, k in zip(tasks, keys, strict=True):
        mask = np.zeros(t.n_frames, bool)
        mask[[0, -1]] = True
        for step in range(w - 2):
            s0 = t.cost[0, -1]
            g1 = np.full(t.n_frames, -np.inf)
            for a in np.flatnonzero(~mask):
                g1[a] = insertion_gain(t.cost, mask, a) / s0
            mask[int(np.argmax(g1 + rollout_values(t.cost, mask, w - 2 - step)))] = True
        np.testing.assert_array_equal(k, np.flatnonzero(mask))
    torch.nn.init.normal_(net.adv_out.weight, std=0.5)
    torch.nn.init.normal_(net.value_out.weight, std=0.5)
    np.testing.assert_array_equal(
        policy.decide(feats, costs, 9), policy.decide_torch(feats, costs, 9)
    )
