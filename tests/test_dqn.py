"""The SIDQL DQN: network features, n-step returns, policy files, and a tiny training run."""

import dataclasses
import itertools
import os
import pickle
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from sidql.keyframes.methods import greedy_from_costs
from sidql.learning.checkpoint import CHECKPOINT_FORMAT, load_checkpoint, save_checkpoint
from sidql.learning.dqn import make_tasks, train
from sidql.learning.env import KeyframeEnv
from sidql.learning.files import POLICY_FORMAT
from sidql.learning.policy import DEFAULT_POLICY, Policy, load_policy
from sidql.learning.qnet import KeyframeQNet, current_error, gain_features
from sidql.learning.replay import NStep, ReplayMemory
from sidql.learning.run_files import save_policy
from sidql.learning.settings import Args
from sidql.learning.tasks import insertion_gain, keyframe_error_sum, synthetic_tasks
from sim.errors import ModelFileError, MotionDataError

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
        out=str(out), steps=240, synthetic_tasks=16, keyframe_counts=(4, 6), batch_size=32,
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
    save_policy(net, path, Args(keyframe_counts=(5,)), {"train": [], "test": []}, {}, {})
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
    env = KeyframeEnv(tasks, keyframe_counts=(6,))
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


# --- hostile files, refused settings, the kernel's named modules ------------------------------

REPO = Path(__file__).resolve().parent.parent


class Armed:
    """A pickled object whose reconstruction creates ``marker`` (stands in for any command)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def plant(path, marker, kind):
    """A malicious file at ``path``: a torch file whose dict of the right format holds an armed
    object, or a plain pickle of one."""
    if kind == "torch":
        fmt = CHECKPOINT_FORMAT if str(path).endswith(".ckpt") else POLICY_FORMAT
        torch.save({"format": fmt, "state_dict": {"x": Armed(marker)}}, path)
    else:
        path.write_bytes(pickle.dumps(Armed(marker)))


def pickled_payload(path) -> bytes:
    """The pickle inside ``path``: a torch file is a zip holding ``<name>/data.pkl``."""
    if not zipfile.is_zipfile(path):
        return Path(path).read_bytes()
    with zipfile.ZipFile(path) as z:
        return z.read(next(n for n in z.namelist() if n.endswith("/data.pkl")))


def cli(*argv, env=None):
    return subprocess.run(
        [sys.executable, "-m", "sidql.commands.main", *argv], capture_output=True, text=True,
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO), **(env or {})}, timeout=300,
    )  # fmt: skip


@pytest.mark.parametrize("kind", ["torch", "pickle"])
def test_a_malicious_policy_file_is_refused_and_runs_nothing(tmp_path, monkeypatch, kind):
    marker, path = tmp_path / "pwned", tmp_path / "evil.pt"
    plant(path, marker, kind)
    monkeypatch.setenv("SIDQL_POLICY", str(path))
    with pytest.raises(ModelFileError, match="evil.pt: refused: "):
        load_policy()
    assert not marker.exists()
    # the payload is armed: plain unpickling of the file's pickle (what an unsafe load does) runs it
    pickle.loads(pickled_payload(path))
    assert marker.exists()


def test_a_malicious_policy_through_the_cli_is_one_line_and_exit_2(tmp_path, cmu_dir):
    marker, path = tmp_path / "pwned", tmp_path / "evil.pt"
    plant(path, marker, "torch")
    out = cli("extract", str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_02.amc"),
              "--keyframes", "5", "--methods", "dqn", env={"SIDQL_POLICY": str(path)})  # fmt: skip
    assert out.returncode == 2, out.stderr
    assert out.stderr.count("\n") == 1 and "evil.pt: refused" in out.stderr
    assert not marker.exists()


@pytest.mark.parametrize("kind", ["torch", "pickle"])
def test_a_planted_checkpoint_is_refused_by_resume_and_runs_nothing(tmp_path, kind):
    marker, out = tmp_path / "pwned", tmp_path / "run" / "policy.pt"
    out.parent.mkdir()
    plant(out.with_name("policy.pt.ckpt"), marker, kind)
    res = cli("train", "--data", str(tmp_path), "--out", str(out), "--resume", "--quiet")
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1 and "policy.pt.ckpt: refused" in res.stderr
    assert not marker.exists() and not out.exists()


def test_policy_files_of_another_format_version_are_refused(tmp_path, tasks):
    net = KeyframeQNet(tasks[0].features.shape[1])
    path = tmp_path / "p.pt"
    save_policy(net, path, Args(keyframe_counts=(5,)), {"train": [], "test": []}, {}, {})
    payload = torch.load(path, weights_only=True)
    assert payload["format"] == POLICY_FORMAT
    for bad in ("sidql-dqn-policy/1", CHECKPOINT_FORMAT, None):
        payload["format"] = bad
        torch.save(payload, path)
        with pytest.raises(ModelFileError, match="format .*expected 'sidql-dqn-policy/2'"):
            load_policy(path)
    path.write_bytes(b"not a torch file at all")
    with pytest.raises(ModelFileError, match="p.pt: refused: not a file of tensors"):
        load_policy(path)
    path.write_bytes(b"PK\x03\x04 truncated zip")
    with pytest.raises(ModelFileError, match="p.pt: (refused|unreadable)"):
        load_policy(path)


def test_the_shipped_policy_loads_safely_with_its_format():
    policy = load_policy(DEFAULT_POLICY)
    assert policy.meta["format"] == POLICY_FORMAT and policy.net.config["hidden"] == 32


def test_resume_with_other_settings_is_one_line_and_exit_2(tmp_path):
    out = tmp_path / "policy.pt"
    save_checkpoint(out.with_name("policy.pt.ckpt"), {}, Args(data=str(tmp_path), hidden=32))
    res = cli("train", "--data", str(tmp_path), "--out", str(out), "--resume", "--hidden", "16")
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1
    assert "written with --hidden 32, this run has --hidden 16" in res.stderr
    with pytest.raises(ModelFileError, match="--keyframes 5 10 15, this run has --keyframes 5 10"):
        load_checkpoint(out.with_name("policy.pt.ckpt"), Args(keyframe_counts=(5, 10)))
    # what may change does not matter
    load_checkpoint(out.with_name("policy.pt.ckpt"), Args(steps=99, out="x", threads=2))


def test_train_without_clips_for_the_held_out_subjects_is_one_line_and_exit_2(tmp_path, cmu_dir):
    res = cli("train", "--data", str(cmu_dir), "--test-subjects", "99", "--out",
              str(tmp_path / "p.pt"), "--quiet")  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1 and "no trials of held-out subject(s) 99" in res.stderr
    # held-out trials that exist but give no usable clip: refused before training data is read
    data = tmp_path / "data"
    (data / "98").mkdir(parents=True)
    (data / "98" / "98.asf").write_text(":version 1.10\n")
    (data / "98" / "98_01.amc").write_text(":FULLY-SPECIFIED\n1\n")
    (data / "02").mkdir()
    for name in ("02.asf", "02_02.amc"):
        shutil.copy(cmu_dir / "02" / name, data / "02" / name)
    args = Args(
        data=str(data), test_subjects=("98",), cache_dir=str(tmp_path / "c"), progress=False
    )
    with pytest.raises(MotionDataError, match="no usable 60-frame clips of the held-out subjects"):
        make_tasks(args)
    assert not (tmp_path / "c").exists()  # subject 02 (training) was never read


def test_resume_of_a_real_run_refuses_another_width(tmp_path):
    args = Args(
        out=str(tmp_path / "p.pt"), steps=40, synthetic_tasks=8, keyframe_counts=(4,), batch_size=8,
        buffer_size=100, learning_starts=10, n_envs=2, demo_episodes=4, eval_every=40,
        progress=False, hidden=8,
    )  # fmt: skip
    train(args)
    with pytest.raises(ModelFileError, match="--hidden 8, this run has --hidden 16"):
        train(dataclasses.replace(args, resume=True, steps=80, hidden=16))
    assert train(dataclasses.replace(args, resume=True, steps=80))["steps"] == 80


def test_the_decision_kernel_reads_named_modules_and_refuses_a_changed_head(tasks):
    feats = np.stack([t.features for t in tasks])[:2]
    costs = np.stack([t.cost for t in tasks])[:2]
    c = feats.shape[-1]
    Policy(KeyframeQNet(c, hidden=16), (5,), {}).decide(feats, costs, 5)  # the real head works
    changes = {
        "a layer replaced by a block": lambda n: setattr(
            n, "adv_hidden", torch.nn.Sequential(torch.nn.Linear(16, 16), torch.nn.Tanh())
        ),
        "a wider layer": lambda n: (setattr(n, "value_hidden", torch.nn.Linear(16, 24)),
                                    setattr(n, "value_out", torch.nn.Linear(24, 1))),
        "a layer added": lambda n: setattr(n, "adv_extra", torch.nn.Linear(16, 16)),
        "a layer removed": lambda n: delattr(n, "value_hidden"),
        "a layer without bias": lambda n: setattr(n, "adv_out", torch.nn.Linear(16, 1, bias=False)),
    }  # fmt: skip
    for what, change in changes.items():
        net = KeyframeQNet(c, hidden=16)
        change(net)
        with pytest.raises(TypeError, match="decision kernel"):
            Policy(net, (5,), {}).decide(feats, costs, 5)
            pytest.fail(f"{what} was not caught")


def test_the_decision_reads_the_weights_the_network_holds_now(tasks):
    """The kernels' weights are cached per network and read again after any change: a weight
    written in place, a layer replaced (at the top or inside ``convs``), another network."""
    from sidql.learning.decide import encoder_weights, head_weights

    def same(got, net):
        want = (encoder_weights(net), head_weights(net))
        flat = lambda w: [np.asarray(x) for part in w for x in part]  # noqa: E731
        return all(np.array_equal(a, b) for a, b in zip(flat(got), flat(want), strict=True))

    c = tasks[0].features.shape[-1]
    net = KeyframeQNet(c, hidden=16)
    policy = Policy(net, (5,), {})
    first = policy._weights()
    assert policy._weights() is first and same(first, net)  # unchanged: the cached arrays
    changes = [
        lambda: net.adv_out.bias.add_(1.0),
        lambda: net.convs[2].weight.mul_(-1.0),
        lambda: setattr(net, "glob", torch.nn.Linear(16, 16)),
        lambda: net.convs.__setitem__(1, torch.nn.Conv1d(16, 16, 3, padding=2, dilation=2)),
        lambda: setattr(policy, "net", KeyframeQNet(c, hidden=16)),
    ]
    for change in changes:
        before = policy._weights()
        with torch.no_grad():
            change()
        got = policy._weights()
        assert got is not before and same(got, policy.net)
        assert policy._weights() is got


def test_import_of_the_method_registry_does_not_import_the_policy_or_torch():
    code = (
        "import sys, sidql.keyframes.methods as m; "
        "assert 'torch' not in sys.modules and 'sidql.learning.policy' not in sys.modules; "
        "f = m.get('dqn'); import sidql.learning.policy as p; assert f is p.dqn; print('ok')"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_train_also_never_trains_on_clips_made_from_held_out_subjects(tmp_path, cmu_dir, capsys):
    """The README's 'sidql synth --from ../shared/cmu' then 'train --train-also' tracked the
    held-out subjects' trials too, and their clips joined training (subject = the kind)."""
    import json

    from sim.motion.clip import save_npz
    from sim.motion.ingest import load_motion

    data = tmp_path / "data"
    for s, trial in (("02", "02_01"), ("07", "07_01")):
        (data / s).mkdir(parents=True)
        for name in (f"{s}.asf", f"{trial}.amc"):
            shutil.copy(cmu_dir / s / name, data / s / name)
    extra = tmp_path / "extra"
    clip = load_motion(data / "07" / "07.asf", data / "07" / "07_01.amc").slice(0, 60)
    entries = []
    for i, (subject, amc, task) in enumerate((
        ("track", str(data / "07" / "07_01.amc"), {"kind": "track"}),  # synth of held-out 07
        ("track", str(data / "02" / "02_01.amc"), {"kind": "track"}),  # synth of training 02
        ("procedural", None, {"kind": "procedural"}),
        ("07", str(data / "07" / "07_01.amc"), None),  # a 'sidql dataset' trial of 07
    )):  # fmt: skip
        save_npz(clip, extra / f"c{i}.npz")
        entries.append({"subject": subject, "amc": amc, "file": f"c{i}.npz", "task": task})
    (extra / "index.json").write_text(json.dumps({"trials": entries}))
    args = Args(data=str(data), test_subjects=("07",), cache_dir=str(tmp_path / "c"),
                progress=False, train_also=str(extra))  # fmt: skip
    train_tasks, _, split = make_tasks(args)
    assert split["test"] == ["07"]
    assert sorted(t.subject for t in train_tasks if t.subject != "02") == ["procedural", "track"]
    assert "left out 2 of 4 clips" in capsys.readouterr().err


def test_compiled_decisions_equal_the_torch_network_on_real_clips(cmu_dir):
    """The shipped policy decided in compiled code (encoder and head, no torch) takes exactly the
    torch network's decisions on real clips, and its encoder's projections match torch's."""
    from sidql.keyframes.segment_costs import segment_cost_matrix
    from sidql.keyframes.spherical import chart
    from sidql.learning.decide import encode_clip
    from sidql.learning.tasks import clip_features
    from sim.motion.ingest import load_clips

    policy = load_policy()
    clips = []
    for trial in ("02/02_01", "16/16_24", "35/35_01"):
        subject = trial.split("/")[0]
        amc = cmu_dir / f"{trial}.amc"
        if amc.exists():
            clips += load_clips(cmu_dir / subject / f"{subject}.asf", amc)[:3]
    assert len(clips) >= 3
    series = [chart(c) for c in clips]
    feats = np.stack([clip_features(s) for s in series]).astype(np.float32)
    costs = np.stack([segment_cost_matrix(s, "hermite") for s in series])
    for w in (3, 5, 15):
        np.testing.assert_array_equal(policy.decide(feats, costs, w),
                                      policy.decide_torch(feats, costs, w))  # fmt: skip
    enc_w, _ = policy._weights()
    with torch.no_grad():
        enc = policy.net.encode(torch.as_tensor(feats))
        proj, glob = policy.net.proj(enc).numpy(), policy.net.glob(enc.mean(1)).numpy()
    for i in range(len(feats)):
        p, g = encode_clip(feats[i], *enc_w)
        np.testing.assert_allclose(p, proj[i], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(g, glob[i], rtol=1e-4, atol=1e-5)


def test_the_compiled_encoder_equals_torch_on_clips_shorter_than_its_dilations():
    """The taps side by side (one product a layer) pad with zeros as torch does, also where a
    layer's dilation reaches past both ends of the clip (N <= d)."""
    from sidql.learning.decide import encode_clip

    policy = load_policy()
    enc_w, _ = policy._weights()
    c = policy.net.config["n_features"]
    rng = np.random.default_rng(3)
    for n in (2, 3, 8, 9):
        feats = rng.normal(size=(1, n, c)).astype(np.float32)
        with torch.no_grad():
            enc = policy.net.encode(torch.as_tensor(feats))
            proj, glob = policy.net.proj(enc).numpy(), policy.net.glob(enc.mean(1)).numpy()
        p, g = encode_clip(feats[0], *enc_w)
        np.testing.assert_allclose(p, proj[0], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(g, glob[0], rtol=1e-4, atol=1e-5)


def test_the_old_name_of_the_keyframe_counts_still_works_and_warns(tmp_path, tasks):
    """``keyframes`` was a count in Args and Policy (and their files); it is ``keyframe_counts``
    now, ``keyframes`` being an index array everywhere else."""
    import dataclasses
    import warnings

    with pytest.warns(FutureWarning, match="Args.keyframes is an old name"):
        args = Args(keyframes=(4, 6))
    assert args.keyframe_counts == (4, 6) and args == Args(keyframe_counts=(4, 6))
    with pytest.warns(FutureWarning, match="use Args.keyframe_counts"):
        assert args.keyframes == (4, 6)
    with pytest.warns(FutureWarning):
        assert dataclasses.replace(args, keyframes=(7,)).keyframe_counts == (7,)
    with pytest.raises(AttributeError, match="no attribute 'keyframez'"):
        args.keyframez  # noqa: B018
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new name does not warn
        assert Args(keyframe_counts=(5,)).keyframe_counts == (5,)
    # a policy file written before the rename (the shipped one is) still loads, counts and all
    net = KeyframeQNet(tasks[0].features.shape[1])
    path = tmp_path / "old.pt"
    save_policy(net, path, Args(keyframe_counts=(5, 9)), {"train": [], "test": []}, {}, {})
    payload = torch.load(path, weights_only=True)
    assert payload["keyframe_counts"] == [5, 9] and tuple(payload["args"]["keyframe_counts"]) == (
        5,
        9,
    )
    payload["keyframes"] = payload.pop("keyframe_counts")
    payload["args"]["keyframes"] = payload["args"].pop("keyframe_counts")
    torch.save(payload, path)
    old = load_policy(path)
    assert old.keyframe_counts == (5, 9) and tuple(old.meta["args"]["keyframe_counts"]) == (5, 9)
    with pytest.warns(FutureWarning, match="Policy.keyframes is an old name"):
        assert old.keyframes == (5, 9)
    assert load_policy(DEFAULT_POLICY).keyframe_counts == (5, 10, 15)
    # and so does a checkpoint: its settings match a run with the same counts
    ck = tmp_path / "old.ckpt"
    save_checkpoint(ck, {}, Args(keyframe_counts=(5, 9)))
    payload = torch.load(ck, weights_only=True)
    payload["args"]["keyframes"] = payload["args"].pop("keyframe_counts")
    torch.save(payload, ck)
    load_checkpoint(ck, Args(keyframe_counts=(5, 9)))
    with pytest.raises(ModelFileError, match="--keyframes 5 9, this run has --keyframes 5"):
        load_checkpoint(ck, Args(keyframe_counts=(5,)))


def plain_greedy_sequence(cost, l, r, k):
    """The first k gains greedy takes inside segment (l, r), simulated: each time, over every
    current segment, the split with the largest gain (ties: the leftmost segment, then the
    lowest frame)."""
    segments, gains = [(l, r)], []
    for _ in range(k):
        best = None
        for a, b in segments:
            for j in range(a + 1, b):
                g = cost[a, b] - cost[a, j] - cost[j, b]
                if best is None or g > best[0]:
                    best = (g, a, b, j)
        if best is None:
            break
        g, a, b, j = best
        gains.append(g)
        i = segments.index((a, b))
        segments[i : i + 1] = [(a, j), (j, b)]
    return gains


@pytest.mark.parametrize("ties", [False, True])
def test_greedy_sequences_are_greedy_simulated_segment_by_segment(ties):
    """The tabulated sequences equal a plain simulation, ties included (costs on a coarse grid
    make many splits equal: the first split reaching the best gain must be the one taken; their
    sums are exact). Elsewhere the gains may differ in the last bit: numba compiles a kernel
    first called from a fastmath kernel (the decision's) with its flags, and caches it so."""
    from sidql.learning.rollout import greedy_sequences

    rng = np.random.default_rng(7)
    n, k = 14, 6
    cost = np.triu(rng.uniform(0, 1, (n, n)), 1) * np.arange(n)[None, :]
    if ties:
        cost = np.round(cost * 2) / 2
    seq, length = greedy_sequences(cost, k)
    for l in range(n):
        for r in range(l + 2, n):
            want = plain_greedy_sequence(cost, l, r, k)
            got = seq[l, r, : length[l, r]].tolist()
            assert got == (want if ties else pytest.approx(want, rel=1e-12, abs=1e-12)), (l, r)
