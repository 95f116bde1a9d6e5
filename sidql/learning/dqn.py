"""SIDQL's Deep Q-Network (Zhang et al. 2024, section 4.2, Algorithm 1), trained through
:class:`sidql.learning.env.KeyframeEnv`, with what is known to work added on top of the paper:

- double DQN targets with a masked argmax (already-chosen frames are never the max), n-step returns;
- the replay memory is seeded with demonstrations: episodes that add the keyframes of the exact
  optimum (``sidql.keyframes.optimal``) through the same environment; a fixed share of every minibatch comes
  from them, so it stays a Q-learner (the same Huber TD loss) that also learns from its own play;
- a network that sees the whole clip (``sidql.learning.qnet``) and one policy for several W (the number of
  keyframes still to choose is part of the state); its learned part sits on an exact prior: the
  reward of the action plus, with ``prior="rollout"``, the value of finishing greedily
  (``sidql.learning.rollout``), so an untrained network is already the rollout improvement of greedy;
- parallel episodes (one batched forward pass per step) and hard target updates.

:func:`train` reads top to bottom, cleanrl style (setup, then one loop: act, step, store, learn,
evaluate and checkpoint), with every piece it calls defined above it; :class:`Args` documents each
knob. The paper's values are the defaults where it gives them (memory 10,000, minibatch 256,
γ = 0.5 were its choices; the defaults here are the tuned ones: docs/policy.md lists what was
kept and what changed, and why).
A run writes ``OUT`` (the policy), ``OUT.ckpt`` (everything needed to resume, written atomically
at every evaluation: :mod:`sidql.learning.checkpoint`), ``OUT.csv`` (the log) and ``OUT.png``
(the learning curve: :mod:`sidql.learning.run_files`). Policy and checkpoint files hold tensors
and plain values only and are read with ``weights_only=True`` (:mod:`sidql.learning.files`);
``--resume`` refuses a checkpoint whose settings differ. The replay memory:
:mod:`sidql.learning.replay`.

The network reads the raw task arrays (``env.tasks[info["task_index"]]``: radians, its own input
standardisation), not the environment's unit-scale observations; the mask and the keyframes still
to choose come from the observation.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from sidql.keyframes.methods import greedy_from_costs
from sidql.keyframes.optimal import solve
from sidql.learning.checkpoint import (
    _show,
    load_checkpoint,
    restore,
    save_checkpoint,
    training_state,
)
from sidql.learning.env import KeyframeEnv
from sidql.learning.policy import Policy
from sidql.learning.qnet import KeyframeQNet, masked_q
from sidql.learning.replay import NStep, ReplayMemory
from sidql.learning.rollout import rollout_values_batch
from sidql.learning.run_files import RunFiles, log_row, record, save_policy
from sidql.learning.settings import Args, settings_problems
from sidql.learning.tasks import (
    KeyframeTask,
    clip_task,
    insertion_gain,
    keyframe_q,
    load_tasks,
    reward_tasks,
    synthetic_tasks,
)
from sim.errors import ModelFileError, MotionDataError, UsageError
from sim.files import excerpt
from sim.motion.dataset import dataset_entries, find_trials, origin_subject

# --- data ----------------------------------------------------------------------------------------


def split_subjects(subjects, test_subjects=None, seed: int = 0) -> tuple[list[str], list[str]]:
    """(train, test) subject ids: ``test_subjects`` if given, else every 4th subject of the sorted
    list starting at ``seed % 4``. Raises ValueError if either side would be empty."""
    subjects = sorted(set(subjects))
    test = sorted(test_subjects) if test_subjects else subjects[seed % 4 :: 4]
    train = [s for s in subjects if s not in test]
    if not train or not test:
        raise UsageError(f"need training and held-out subjects; have {subjects}, test {test}")
    return train, test


def make_tasks(args: Args) -> tuple[list[KeyframeTask], list[KeyframeTask], dict]:
    """(training tasks, held-out tasks, split description). Held-out tasks are the evaluation
    protocol's clips (non-overlapping 60-frame clips from frame 0) of subjects never trained on.

    Raises:
        MotionDataError: no trials, a held-out subject without trials, or no usable clips on
            either side of the split (one line naming the folder).
    """
    if args.data is None:
        tasks = synthetic_tasks(args.synthetic_tasks, seed=args.seed)
        n_test = max(1, len(tasks) // 4)
        return tasks[n_test:], tasks[:n_test], {"train": "synthetic", "test": "synthetic"}
    found = sorted({t.subject for t in find_trials(args.data, [])})  # names only
    missing = sorted(set(args.test_subjects or ()) - set(found))
    if missing:
        raise MotionDataError(
            args.data, None, f"no trials of held-out subject(s) {', '.join(missing)} "
            f"(subjects here: {', '.join(found) or 'none'})",
        )  # fmt: skip
    try:
        train_s, test_s = split_subjects(found, args.test_subjects, args.seed)
    except ValueError as e:
        raise MotionDataError(args.data, None, str(e)) from None
    physics = args.reward == "physics"  # then every task also carries its physical costs
    kw = dict(cache_dir=args.cache_dir, progress=args.progress, physics=physics)
    test_tasks = load_tasks(args.data, stride=60, subjects=set(test_s), **kw).tasks()
    if not test_tasks:
        raise MotionDataError(
            args.data, None, f"no usable 60-frame clips of the held-out subjects {test_s}"
        )
    train_tasks = load_tasks(args.data, stride=args.stride, subjects=set(train_s), **kw).tasks()
    if not train_tasks:
        raise MotionDataError(
            args.data, None, f"no usable 60-frame clips of the training subjects {train_s}"
        )
    if args.train_also:  # dataset/synth clips join the training tasks only, and never clips made
        # from a held-out subject's recordings (a synth folder tracks every trial it was given)
        entries = dataset_entries(args.train_also, 60)
        kept = [(c, e) for c, e in entries if origin_subject(e) not in set(test_s)]
        if len(kept) < len(entries):
            print(
                f"--train-also: left out {len(entries) - len(kept)} of {len(entries)} clips made "
                f"from held-out subjects' trials ({', '.join(test_s)})", file=sys.stderr,
            )  # fmt: skip
        train_tasks += [_also_task(c, e, args.train_also, physics) for c, e in kept]
    split = {"train": train_s, "test": test_s}
    return reward_tasks(train_tasks, args.reward), reward_tasks(test_tasks, args.reward), split


def _also_task(clip, entry: dict, folder, physics: bool = False) -> KeyframeTask:
    """The task of a ``--train-also`` clip; one that cannot be a task is named by its index
    file and entry (never by the path its ``source`` claims)."""
    try:
        return clip_task(clip, subject=str(entry.get("subject", "")), physics=physics)
    except MotionDataError as e:
        name = excerpt(str(entry.get("file")), 100, quote=False)
        raise MotionDataError(
            str(Path(folder) / "index.json"), None, f"{name}: {e.problem}"
        ) from None


# --- baselines on cost matrices (for logging) ----------------------------------------------------


def greedy_keyframes(cost: np.ndarray, w: int) -> np.ndarray:
    """The paper's greedy on a cost matrix (``sidql.keyframes.methods.greedy_from_costs``)."""
    return greedy_from_costs(cost, w)


def optimal_keyframes(cost: np.ndarray, w: int) -> np.ndarray:
    """The exact optimum of ``sidql.keyframes.optimal`` for W = ``w`` (sorted indices)."""
    return solve(cost, 1, w_max=w).keyframes(w)


def mean_q(tasks: list[KeyframeTask], keyframes) -> float:
    """Mean Q (eq. 18, :func:`sidql.learning.tasks.keyframe_q`) of one keyframe set per task."""
    return float(np.mean([keyframe_q(t, k) for t, k in zip(tasks, keyframes, strict=True)]))


def baselines(tasks: list[KeyframeTask], keyframes) -> dict[str, dict[int, float]]:
    """{"greedy": {W: mean Q}, "optimal": {W: mean Q}} on ``tasks``."""
    return {
        name: {w: mean_q(tasks, [fn(t.cost, w) for t in tasks]) for w in keyframes}
        for name, fn in (("greedy", greedy_keyframes), ("optimal", optimal_keyframes))
    }


# --- acting --------------------------------------------------------------------------------------


def linear_schedule(start: float, end: float, duration: float, t: int) -> float:
    """ε of the ε-greedy exploration: ``start`` falling linearly to ``end`` over ``duration``
    steps, then ``end``."""
    frac = min(1.0, t / max(1.0, duration))
    return start + frac * (end - start)


def prior_values(net, costs_np, task, mask, rem):
    """The rollout prior (B, N) of states (task indices into ``costs_np`` (K, N, N) float64,
    masks (B, N), remaining (B,)) as a tensor, or None for a greedy-prior network."""
    if net.config["prior"] != "rollout":
        return None
    vals = rollout_values_batch(
        costs_np, np.asarray(task, np.int64), np.asarray(mask, bool), np.asarray(rem, np.int64)
    )
    return torch.as_tensor(vals, dtype=torch.float32)


def act(net, features, costs, masks, remaining, prior=None) -> np.ndarray:
    """Masked argmax of the network for a batch: (B, N, C), (B, N, N), (B, N) bool, (B,), and the
    rollout prior (B, N) if the network uses one -> (B,) actions."""
    t = torch.as_tensor
    with torch.no_grad():
        q = net(t(features), t(costs), t(masks), t(remaining), prior)
        return masked_q(q, t(masks)).argmax(1).numpy()


def evaluate(net, tasks, keyframes) -> dict[int, float]:
    """Mean Q (eq. 18) of the network's greedy decisions over ``tasks`` for each W."""
    policy = Policy(net, keyframes, {})
    feats = np.stack([t.features for t in tasks])
    costs = np.stack([t.cost for t in tasks])
    return {w: mean_q(tasks, policy.decide(feats, costs, w)) for w in keyframes}


def play_demonstrations(env: KeyframeEnv, memory: ReplayMemory, args: Args, rng) -> None:
    """Play ``args.demo_episodes`` episodes through ``env`` that add the optimum's keyframes
    (largest immediate reward first) and store their n-step transitions in ``memory``."""
    cache: dict[tuple[int, int], np.ndarray] = {}
    nstep = NStep(args.n_step, args.gamma)
    for _ in range(args.demo_episodes):
        i = int(rng.integers(len(env.tasks)))
        w = int(rng.choice(args.keyframes))
        if (i, w) not in cache:
            cache[i, w] = optimal_keyframes(env.tasks[i].cost, w)
        todo = set(int(k) for k in cache[i, w][1:-1])
        obs, info = env.reset(options={"task": i, "keyframes": w})
        done = False
        while not done:
            mask = obs["keyframes"].astype(bool)
            cost = env.tasks[i].cost
            gains = {a: insertion_gain(cost, mask, a) for a in todo}
            a = max(gains, key=gains.get)
            expert = np.zeros_like(mask)
            expert[list(todo)] = True
            todo.remove(a)
            nobs, r, done, _, info = env.step(a)
            nstep.push(
                memory, i, mask, obs["remaining"], a, r,
                nobs["keyframes"].astype(bool), nobs["remaining"], done, expert,
            )  # fmt: skip
            obs = nobs


# --- learning ------------------------------------------------------------------------------------


def margin_loss(net, feats, costs, costs_np, batch, args):
    """DQfD's large-margin loss on demonstration states: the best frame of the optimum must beat
    every other free frame by ``args.margin`` (in units of the normalised reward)."""
    task, mask, rem, *_, expert = batch
    prior = prior_values(net, costs_np, task.numpy(), mask.numpy(), rem.numpy())
    q = masked_q(net(feats[task], costs[task], mask, rem, prior), mask)
    best_expert = q.masked_fill(~expert, float("-inf")).amax(1)
    best_other = q.masked_fill(expert | mask, float("-inf")).amax(1)
    has_other = torch.isfinite(best_other)
    gap = torch.relu(best_other + args.margin - best_expert)
    return torch.where(has_other, gap, torch.zeros_like(gap)).mean()


def td_loss(net, target, feats, costs, costs_np, batch, args):
    """Huber loss between Q(s, a) and the n-step (double) DQN target; and the mean Q(s, a)."""
    task, mask, rem, action, ret, nmask, nrem, done, disc, _ = batch
    f, c = feats[task], costs[task]
    prior = prior_values(net, costs_np, task.numpy(), mask.numpy(), rem.numpy())
    nprior = prior_values(net, costs_np, task.numpy(), nmask.numpy(), nrem.numpy())
    enc = net.encode(f)
    q = net.head(enc, c, mask, rem, prior).gather(1, action[:, None])[:, 0]
    with torch.no_grad():
        tenc = target.encode(f)
        q_next_t = masked_q(target.head(tenc, c, nmask, nrem, nprior), nmask)
        if args.double:
            a_next = masked_q(net.head(enc.detach(), c, nmask, nrem, nprior), nmask).argmax(1)
        else:
            a_next = q_next_t.argmax(1)
        v_next = q_next_t.gather(1, a_next[:, None])[:, 0]
        v_next = torch.where(done > 0, torch.zeros_like(v_next), v_next)
        y = ret + disc * v_next
    return F.smooth_l1_loss(q, y), q.detach().mean()


def sample_batch(memory: ReplayMemory, demos: ReplayMemory, rng, args: Args):
    """A minibatch of tensors: ``batch_size - n_demo`` transitions of the agent's own play and
    ``n_demo`` (= ``demo_fraction`` of the batch, 0 without demonstrations) demonstrations.
    Returns (batch, demonstration part or None)."""

    def take(m: ReplayMemory, k: int):
        idx = m.sample(rng, k)
        return tuple(
            torch.as_tensor(x[idx])
            for x in (m.task, m.mask, m.rem, m.action, m.ret, m.next_mask, m.next_rem, m.done,
                      m.disc, m.expert)
        )  # fmt: skip

    n_demo = int(round(args.batch_size * args.demo_fraction)) if len(demos) else 0
    batch = take(memory, args.batch_size - n_demo)
    if not n_demo:
        return batch, None
    demo = take(demos, n_demo)
    return tuple(torch.cat([x, y]) for x, y in zip(batch, demo, strict=True)), demo


def make_networks(args: Args, feats: torch.Tensor):
    """(Q-network, target network, Adam optimiser) for (K, N, C) training features: the network
    standardises its inputs with their per-channel mean and standard deviation."""
    c = feats.shape[-1]
    net = KeyframeQNet(c, hidden=args.hidden, prior=args.prior)
    flat = feats.reshape(-1, c)
    net.set_normalisation(flat.mean(0), flat.std(0))
    target = KeyframeQNet(c, hidden=args.hidden, prior=args.prior)
    target.load_state_dict(net.state_dict())
    return net, target, torch.optim.Adam(net.parameters(), lr=args.learning_rate)


# --- the algorithm -------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrainingData:
    """The run's tasks and what the networks read of them.

    Attributes:
        train, test: the training and held-out tasks; split: their subjects.
        feats: (K, N, C) training features; costs_np: (K, N, N) float64 segment costs, and
            costs: the same as a float32 tensor; base: held-out mean Q of greedy and the optimum
            per W (:func:`baselines`).
    """

    train: list
    test: list
    split: dict
    feats: torch.Tensor
    costs_np: np.ndarray
    costs: torch.Tensor
    base: dict


def training_data(args: Args, ck: dict | None, checkpoint: Path) -> TrainingData:
    """The run's tasks (:func:`make_tasks`) as arrays; a checkpoint ``ck`` written for another
    split is refused (:class:`sim.errors.ModelFileError` naming ``checkpoint``)."""
    train_tasks, test_tasks, split = make_tasks(args)
    if ck is not None and (ck.get("split") != split or ck.get("n_tasks") != len(train_tasks)):
        raise ModelFileError(
            str(checkpoint), None, f"written for another data split ({_show(ck.get('n_tasks'))} "
            f"training clips, {_show(ck.get('split'))}); this run has {len(train_tasks)}, "
            f"{_show(split)}",
        )  # fmt: skip
    feats = torch.as_tensor(np.stack([t.features for t in train_tasks]))
    costs_np = np.ascontiguousarray(np.stack([t.cost for t in train_tasks]), dtype=np.float64)
    costs = torch.as_tensor(costs_np.astype(np.float32))
    base = baselines(test_tasks, args.keyframes)
    return TrainingData(train_tasks, test_tasks, split, feats, costs_np, costs, base)


def gradient_step(net, target, opt, memory, demos, data: TrainingData, rng, args: Args):
    """One minibatch (:func:`sample_batch`), its TD loss plus the demonstrations' margin loss,
    and one clipped Adam step; returns (loss, mean Q(s, a)) as floats."""
    feats, costs, costs_np = data.feats, data.costs, data.costs_np
    batch, demo_batch = sample_batch(memory, demos, rng, args)
    loss, qm = td_loss(net, target, feats, costs, costs_np, batch, args)
    if demo_batch is not None and args.margin_weight > 0:
        loss = loss + args.margin_weight * margin_loss(
            net, feats, costs, costs_np, demo_batch, args
        )
    opt.zero_grad()
    loss.backward()
    torch.nn.utils.clip_grad_norm_(net.parameters(), args.grad_clip)
    opt.step()
    return float(loss.detach()), float(qm)


def train(args: Args) -> dict:
    """Train a keyframe policy; returns the final held-out evaluation and baselines.

    Writes ``args.out`` (policy), ``args.out + '.ckpt'`` (resumable state), ``.csv`` log and
    ``.png`` learning curve. Deterministic for a given seed and thread count.

    Raises:
        MotionDataError: no usable clips for the split.
        ModelFileError: a checkpoint that ``--resume`` refuses (unsafe file, other format or
            other settings).
    """
    # setup: files, checkpoint (checked before any data is read), data, networks, memories
    problems = settings_problems(args)
    if problems:
        raise UsageError(problems[0])
    torch.set_num_threads(args.threads)
    files = RunFiles.beside(args.out)
    resume = args.resume and files.checkpoint.exists()
    ck = load_checkpoint(files.checkpoint, args) if resume else None
    files.policy.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)
    data = training_data(args, ck, files.checkpoint)
    n = data.train[0].n_frames
    net, target, opt = make_networks(args, data.feats)
    envs = [KeyframeEnv(data.train, args.keyframes) for _ in range(args.n_envs)]
    memory = ReplayMemory(args.buffer_size, n)
    demos = ReplayMemory(max(1, args.demo_episodes * (max(args.keyframes) - 2)), n)
    if ck is not None:
        counters, log_rows = restore(
            ck, net, target, opt, memory, demos, rng, path=str(files.checkpoint),
            keyframes=args.keyframes, n_tasks=len(data.train),
        )  # fmt: skip
        seeds = [args.seed + 1000 * (counters["step"] + 1) + i for i in range(len(envs))]
    else:
        counters, log_rows = {"step": 0, "updates": 0, "episodes": 0}, []
        if args.demo_episodes:
            play_demonstrations(KeyframeEnv(data.train, args.keyframes), demos, args, rng)
        seeds = [args.seed + i for i in range(len(envs))]
    step = run_loop(args, data, files, (net, target, opt), (memory, demos), envs, seeds,
                    counters, log_rows, rng)  # fmt: skip
    final = {w: log_rows[-1][f"dqn_W{w}"] for w in args.keyframes}
    save_policy(net, files.policy, args, data.split, final, data.base)
    return {"dqn": final, **data.base, "split": data.split, "steps": step}


def run_loop(args, data, files, nets, memories, envs, seeds, counters, log_rows, rng) -> int:
    """The training loop from ``counters`` to ``args.steps``: act in every environment
    (ε-greedy), store n-step transitions, learn every ``train_frequency`` steps, evaluate, log
    and checkpoint every ``eval_every``; returns the last step."""
    net, target, opt = nets
    memory, demos = memories
    feats, costs, costs_np = data.feats, data.costs, data.costs_np
    step, updates, episodes = counters["step"], counters["updates"], counters["episodes"]
    started = [env.reset(seed=s) for env, s in zip(envs, seeds, strict=True)]
    obs, infos = [o for o, _ in started], [i for _, i in started]
    nsteps = [NStep(args.n_step, args.gamma) for _ in envs]
    elapsed0 = log_rows[-1]["seconds"] if log_rows else 0.0
    t0 = time.perf_counter()
    losses, q_mean = [], math.nan
    eps_steps = args.eps_fraction * args.steps
    if not log_rows:  # step 0: the untrained network = its prior (greedy, or the greedy rollout)
        heldout = evaluate(net, data.test, args.keyframes)
        row = log_row({"step": 0, "updates": 0, "episodes": 0}, 0.0, args.eps_start, math.nan,
                      math.nan, heldout, data.base, args.keyframes)  # fmt: skip
        record(files, log_rows, row, args.keyframes)

    bar = tqdm(total=args.steps, initial=step, desc="train", disable=not args.progress)
    while step < args.steps:
        # act in every environment: ε-greedy over valid frames, masked argmax otherwise
        tasks_now = np.array([info["task_index"] for info in infos])
        masks = np.stack([o["keyframes"].astype(bool) for o in obs])
        rems = np.array([o["remaining"] for o in obs])
        prior = prior_values(net, costs_np, tasks_now, masks, rems)
        greedy = act(net, feats[tasks_now], costs[tasks_now], masks, rems, prior)
        for i, env in enumerate(envs):
            epsilon = linear_schedule(args.eps_start, args.eps_end, eps_steps, step)
            explore = rng.random() < epsilon
            a = int(rng.choice(np.flatnonzero(~masks[i]))) if explore else int(greedy[i])
            # step; store the n-step transition (state = task, mask, remaining); reset when done
            nobs, r, done, trunc, ninfo = env.step(a)
            nsteps[i].push(
                memory, tasks_now[i], masks[i], rems[i], a, r,
                nobs["keyframes"].astype(bool), nobs["remaining"], done,
            )  # fmt: skip
            if done or trunc:
                episodes += 1
                nobs, ninfo = env.reset()
            obs[i], infos[i] = nobs, ninfo
            step += 1
            bar.update(1)
            # learn: one gradient step every train_frequency steps; hard target updates
            if step >= args.learning_starts and step % args.train_frequency == 0 and len(memory):
                loss, q_mean = gradient_step(net, target, opt, memory, demos, data, rng, args)
                updates += 1
                losses.append(loss)
                if updates % args.target_update == 0:
                    target.load_state_dict(net.state_dict())
            # evaluate on the held-out clips, log, checkpoint
            if step % args.eval_every == 0 or step == args.steps:
                heldout = evaluate(net, data.test, args.keyframes)
                counters = {"step": step, "updates": updates, "episodes": episodes}
                row = log_row(
                    counters, elapsed0 + time.perf_counter() - t0,
                    linear_schedule(args.eps_start, args.eps_end, eps_steps, step),
                    float(np.mean(losses)) if losses else math.nan, q_mean, heldout, data.base,
                    args.keyframes,
                )  # fmt: skip
                losses = []
                record(files, log_rows, row, args.keyframes)
                state = training_state(net, target, opt, memory, demos, counters, log_rows, rng,
                                       data.split, len(data.train))  # fmt: skip
                save_checkpoint(files.checkpoint, state, args)
                bar.set_postfix(
                    {f"W{w}": f"{heldout[w] / data.base['optimal'][w]:.3f}" for w in heldout}
                )
            if step >= args.steps:
                break
    bar.close()
    return step
