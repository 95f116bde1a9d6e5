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

Everything is in :func:`train`, top to bottom, cleanrl style; :class:`Args` documents each knob. The
paper's values are the defaults where it gives them (memory 10,000, minibatch 256, γ = 0.5 were
its choices; the defaults here are the tuned ones, see the README's tuning table).
A run writes ``OUT`` (the policy), ``OUT.ckpt`` (everything needed to resume, written atomically
at every evaluation), ``OUT.csv`` (the log) and ``OUT.png`` (the learning curve).
"""

from __future__ import annotations

import csv
import io
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from sidql.learning.env import KeyframeEnv, KeyframeTask, keyframe_error_sum

# torch is imported inside the functions that need it, so that building the command line
# (which reads Args) stays light.


@dataclass
class Args:
    data: str | None = None
    """directory of CMU trials (``sim.motion.dataset.find_trials``); None: synthetic tasks (for tests)"""
    keyframes: tuple[int, ...] = (5, 10, 15)
    """keyframe counts W the policy learns (one drawn per episode)"""
    steps: int = 16_000
    """environment steps (keyframes chosen) in total"""
    out: str = "policy.pt"
    """where the trained policy goes; OUT.ckpt, OUT.csv and OUT.png are written beside it"""
    resume: bool = False
    """continue from OUT.ckpt if it exists"""
    seed: int = 0
    """seeds numpy, torch, the environments and the subject split"""
    test_subjects: tuple[str, ...] | None = None
    """held-out subjects (never trained on); None: every 4th subject in sorted order, offset by seed"""
    stride: int = 2
    """training clips start every ``stride`` frames (30 fps) of each training trial"""
    cache_dir: str | None = None
    """cache of per-trial (features, costs); None: ``sidql.learning.tasks.default_cache_dir()``"""
    synthetic_tasks: int = 64
    """number of synthetic tasks when ``data`` is None (a quarter of them held out)"""
    train_also: str | None = None
    """a ``sidql synth`` / ``sidql dataset`` folder whose 60-frame clips join the training tasks
    only (the held-out tasks stay the real held-out subjects')"""
    # -- DQN -------------------------------------------------------------------------------------
    buffer_size: int = 10_000
    """replay memory of the agent's own transitions (paper: 10,000)"""
    batch_size: int = 128
    """minibatch (paper: 256)"""
    learning_rate: float = 1e-4
    """Adam step size (paper: 0.01; larger rates drift away from the prior quickly)"""
    gamma: float = 1.0
    """discount (paper: 0.5, best with the greedy prior; 1 with the rollout prior, whose value is
    undiscounted)"""
    n_step: int = 1
    """n-step returns"""
    double: bool = True
    """double DQN: the main network picks the next action, the target network values it"""
    train_frequency: int = 4
    """one gradient step every this many environment steps (paper: 100-200)"""
    target_update: int = 250
    """copy the main network into the target network every this many gradient steps"""
    learning_starts: int = 500
    """environment steps before the first gradient step"""
    eps_start: float = 0.2
    """ε of the ε-greedy exploration at the start"""
    eps_end: float = 0.02
    """ε at the end of the linear schedule"""
    eps_fraction: float = 0.4
    """fraction of ``steps`` over which ε falls linearly"""
    demo_episodes: int = 3_000
    """demonstration episodes from the exact optimum seeded into their own replay memory (0: none)"""
    demo_fraction: float = 0.25
    """share of every minibatch drawn from the demonstrations"""
    margin: float = 0.02
    """DQfD margin [normalised reward] by which optimal frames must beat others on demonstrations"""
    margin_weight: float = 0.0
    """weight of the margin loss (0: plain TD learning from demonstrations)"""
    prior: str = "rollout"
    """what the learned part starts from: "greedy" (Q ranks like greedy untrained) or "rollout"
    (Q starts at the exact value of finishing greedily, sidql.learning.rollout; use with gamma 1)"""
    hidden: int = 32
    """width of the Q-network"""
    n_envs: int = 16
    """episodes played in parallel"""
    grad_clip: float = 10.0
    """gradient-norm clip"""
    eval_every: int = 2_000
    """evaluate on the held-out clips and checkpoint every this many environment steps"""
    threads: int = 1
    """torch threads"""
    progress: bool = True
    """tqdm progress bar"""
    extra: dict = field(default_factory=dict)
    """free-form notes stored with the policy"""


# --- replay memory -------------------------------------------------------------------------------


class ReplayMemory:
    """Fixed-size ring of n-step transitions; states are (task index, keyframe mask, remaining)."""

    def __init__(self, size: int, n_frames: int):
        self.size, self.pos, self.full = size, 0, False
        self.task = np.zeros(size, np.int64)
        self.mask = np.zeros((size, n_frames), bool)
        self.rem = np.zeros(size, np.int64)
        self.action = np.zeros(size, np.int64)
        self.ret = np.zeros(size, np.float32)
        self.next_mask = np.zeros((size, n_frames), bool)
        self.next_rem = np.zeros(size, np.int64)
        self.done = np.zeros(size, np.float32)
        self.disc = np.zeros(size, np.float32)
        self.expert = np.zeros((size, n_frames), bool)  # demonstrations: optimal frames still free

    def __len__(self):
        return self.size if self.full else self.pos

    def add(self, task, mask, rem, action, ret, next_mask, next_rem, done, disc, expert=None):
        i = self.pos
        self.expert[i] = False if expert is None else expert
        self.task[i], self.mask[i], self.rem[i], self.action[i] = task, mask, rem, action
        self.ret[i], self.next_mask[i], self.next_rem[i] = ret, next_mask, next_rem
        self.done[i], self.disc[i] = done, disc
        self.pos = (i + 1) % self.size
        self.full = self.full or self.pos == 0

    def sample(self, rng: np.random.Generator, k: int) -> np.ndarray:
        return rng.integers(len(self), size=k)

    def state_dict(self) -> dict:
        return {k: v for k, v in vars(self).items()}

    def load_state_dict(self, d: dict) -> None:
        vars(self).update(d)


class NStep:
    """Turns one episode's steps into n-step transitions (returns discounted by γ)."""

    def __init__(self, n: int, gamma: float):
        self.n, self.gamma, self.steps = n, gamma, []

    def push(self, memory, task, mask, rem, action, reward, next_mask, next_rem, done, expert=None):
        self.steps.append((task, mask, rem, action, reward, expert))
        if done:
            while self.steps:
                self._emit(memory, next_mask, next_rem, True)
        elif len(self.steps) == self.n:
            self._emit(memory, next_mask, next_rem, False)

    def _emit(self, memory, next_mask, next_rem, done):
        task, mask, rem, action, _, expert = self.steps[0]
        ret = sum(self.gamma**k * s[4] for k, s in enumerate(self.steps))
        disc = self.gamma ** len(self.steps)
        memory.add(task, mask, rem, action, ret, next_mask, next_rem, done, disc, expert)
        self.steps.pop(0)

    def clear(self):
        self.steps = []


# --- data ----------------------------------------------------------------------------------------


def split_subjects(subjects, test_subjects=None, seed: int = 0) -> tuple[list[str], list[str]]:
    """(train, test) subject ids: ``test_subjects`` if given, else every 4th subject of the sorted
    list starting at ``seed % 4``. Raises ValueError if either side would be empty."""
    subjects = sorted(set(subjects))
    test = sorted(test_subjects) if test_subjects else subjects[seed % 4 :: 4]
    train = [s for s in subjects if s not in test]
    if not train or not test:
        raise ValueError(f"need training and held-out subjects; have {subjects}, test {test}")
    return train, test


def make_tasks(args: Args) -> tuple[list[KeyframeTask], list[KeyframeTask], dict]:
    """(training tasks, held-out tasks, split description). Held-out tasks are the evaluation
    protocol's clips (non-overlapping 60-frame clips from frame 0) of subjects never trained on."""
    if args.data is None:
        from sidql.learning.tasks import synthetic_tasks

        tasks = synthetic_tasks(args.synthetic_tasks, seed=args.seed)
        n_test = max(1, len(tasks) // 4)
        return tasks[n_test:], tasks[:n_test], {"train": "synthetic", "test": "synthetic"}
    from sidql.learning.tasks import default_cache_dir, load_tasks
    from sim.motion.dataset import find_trials

    cache = Path(args.cache_dir) if args.cache_dir else default_cache_dir()
    train_s, test_s = split_subjects(
        [t.subject for t in find_trials(args.data)], args.test_subjects, args.seed
    )
    kw = dict(cache_dir=cache, progress=args.progress)
    train = load_tasks(args.data, stride=args.stride, subjects=set(train_s), **kw)
    test = load_tasks(args.data, stride=60, subjects=set(test_s), **kw)
    train_tasks = [t for trial in train for t in trial.tasks()]
    test_tasks = [t for trial in test for t in trial.tasks()]
    if args.train_also:
        from sidql.learning.tasks import clip_task
        from sim.motion.dataset import load_dataset_clips

        clips, subjects = load_dataset_clips(args.train_also, 60)
        train_tasks += [clip_task(c, subject=s) for c, s in zip(clips, subjects, strict=True)]
    if not train_tasks or not test_tasks:
        raise ValueError(f"no usable clips under {args.data} for the split {train_s} / {test_s}")
    return train_tasks, test_tasks, {"train": train_s, "test": test_s}


# --- baselines on cost matrices (for logging) ----------------------------------------------------


def greedy_keyframes(cost: np.ndarray, w: int) -> np.ndarray:
    """The paper's greedy on a cost matrix (``sidql.keyframes.methods.greedy_from_costs``)."""
    from sidql.keyframes.methods import greedy_from_costs

    return greedy_from_costs(cost, w)


def optimal_keyframes(cost: np.ndarray, w: int) -> np.ndarray:
    """The exact optimum of ``sidql.keyframes.optimal`` for W = ``w`` (sorted indices)."""
    from sidql.keyframes.optimal import solve

    return solve(cost, 1, w_max=w).keyframes(w)


# --- acting --------------------------------------------------------------------------------------


def prior_values(net, costs_np, task, mask, rem):
    """The rollout prior (B, N) of states (task indices into ``costs_np`` (K, N, N) float64,
    masks (B, N), remaining (B,)) as a tensor, or None for a greedy-prior network."""
    if net.config["prior"] != "rollout":
        return None
    import torch

    from sidql.learning.rollout import rollout_values_batch

    vals = rollout_values_batch(
        costs_np, np.asarray(task, np.int64), np.asarray(mask, bool), np.asarray(rem, np.int64)
    )
    return torch.as_tensor(vals, dtype=torch.float32)


def act(net, features, costs, masks, remaining, prior=None) -> np.ndarray:
    """Masked argmax of the network for a batch: (B, N, C), (B, N, N), (B, N) bool, (B,), and the
    rollout prior (B, N) if the network uses one -> (B,) actions."""
    import torch

    from sidql.learning.qnet import masked_q

    t = torch.as_tensor
    with torch.no_grad():
        q = net(t(features), t(costs), t(masks), t(remaining), prior)
        return masked_q(q, t(masks)).argmax(1).numpy()


def evaluate(net, tasks, keyframes) -> dict[int, float]:
    """Mean Q (eq. 18) of the network's greedy decisions over ``tasks`` for each W."""
    from sidql.learning.policy import Policy

    policy = Policy(net, keyframes, {})
    feats = np.stack([t.features for t in tasks])
    costs = np.stack([t.cost for t in tasks])
    out = {}
    for w in keyframes:
        keys = policy.decide(feats, costs, w)
        out[w] = float(
            np.mean(
                [
                    keyframe_error_sum(t.cost, k) / (t.n_frames * t.n_bones)
                    for t, k in zip(tasks, keys, strict=True)
                ]
            )
        )
    return out


# --- the algorithm -------------------------------------------------------------------------------


def _demonstrations(env: KeyframeEnv, memory: ReplayMemory, args: Args, rng) -> None:
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
            gains = {a: _gain(cost, mask, a) for a in todo}
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


def _gain(cost, mask, a):
    from sidql.learning.env import insertion_gain

    return insertion_gain(cost, mask, a)


def _margin_loss(net, feats, costs, costs_np, batch, args):
    """DQfD's large-margin loss on demonstration states: the best frame of the optimum must beat
    every other free frame by ``args.margin`` (in units of the normalised reward)."""
    import torch

    from sidql.learning.qnet import masked_q

    task, mask, rem, *_, expert = batch
    prior = prior_values(net, costs_np, task.numpy(), mask.numpy(), rem.numpy())
    q = masked_q(net(feats[task], costs[task], mask, rem, prior), mask)
    best_expert = q.masked_fill(~expert, float("-inf")).amax(1)
    best_other = q.masked_fill(expert | mask, float("-inf")).amax(1)
    has_other = torch.isfinite(best_other)
    gap = torch.relu(best_other + args.margin - best_expert)
    return torch.where(has_other, gap, torch.zeros_like(gap)).mean()


def _td_loss(net, target, feats, costs, costs_np, batch, args):
    """Huber loss between Q(s, a) and the n-step double-DQN target."""
    import torch
    import torch.nn.functional as F

    from sidql.learning.qnet import masked_q

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


def _batch(memory: ReplayMemory, idx: np.ndarray):
    import torch

    m = memory
    t = torch.as_tensor
    return (
        t(m.task[idx]), t(m.mask[idx]), t(m.rem[idx]), t(m.action[idx]), t(m.ret[idx]),
        t(m.next_mask[idx]), t(m.next_rem[idx]), t(m.done[idx]), t(m.disc[idx]),
        t(m.expert[idx]),
    )  # fmt: skip


def _cat(a, b):
    import torch

    return tuple(torch.cat([x, y]) for x, y in zip(a, b, strict=True))


def train(args: Args) -> dict:
    """Train a keyframe policy; returns the final held-out evaluation and baselines.

    Writes ``args.out`` (policy), ``args.out + '.ckpt'`` (resumable state), ``.csv`` log and
    ``.png`` learning curve. Deterministic for a given seed and thread count.
    """
    import torch
    from tqdm import tqdm

    from sidql.learning.qnet import KeyframeQNet

    torch.set_num_threads(args.threads)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    ckpt_path = out.with_name(out.name + ".ckpt")
    log_path, png_path = out.with_suffix(".csv"), out.with_suffix(".png")
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)

    train_tasks, test_tasks, split = make_tasks(args)
    n, c = train_tasks[0].features.shape
    feats = torch.as_tensor(np.stack([t.features for t in train_tasks]))
    costs_np = np.ascontiguousarray(np.stack([t.cost for t in train_tasks]), dtype=np.float64)
    costs = torch.as_tensor(costs_np.astype(np.float32))
    baselines = {
        name: {
            w: float(np.mean([keyframe_error_sum(t.cost, fn(t.cost, w)) / (n * t.n_bones)
                              for t in test_tasks]))
            for w in args.keyframes
        }
        for name, fn in (("greedy", greedy_keyframes), ("optimal", optimal_keyframes))
    }  # fmt: skip

    net = KeyframeQNet(c, hidden=args.hidden, prior=args.prior)
    flat = feats.reshape(-1, c)
    net.set_normalisation(flat.mean(0), flat.std(0))
    target = KeyframeQNet(c, hidden=args.hidden, prior=args.prior)
    target.load_state_dict(net.state_dict())
    opt = torch.optim.Adam(net.parameters(), lr=args.learning_rate)

    envs = [KeyframeEnv(train_tasks, args.keyframes) for _ in range(args.n_envs)]
    memory = ReplayMemory(args.buffer_size, n)
    demos = ReplayMemory(max(1, args.demo_episodes * (max(args.keyframes) - 2)), n)
    step, updates, episodes, log_rows = 0, 0, 0, []
    if args.resume and ckpt_path.exists():
        ck = torch.load(ckpt_path, weights_only=False)
        net.load_state_dict(ck["net"])
        target.load_state_dict(ck["target"])
        opt.load_state_dict(ck["opt"])
        memory.load_state_dict(ck["memory"])
        demos.load_state_dict(ck["demos"])
        step, updates, episodes, log_rows = ck["step"], ck["updates"], ck["episodes"], ck["log"]
        rng.bit_generator.state = ck["rng"]
        torch.set_rng_state(ck["torch_rng"])
        obs = [e.reset(seed=args.seed + 1000 * (step + 1) + i)[0] for i, e in enumerate(envs)]
    else:
        if args.demo_episodes:
            _demonstrations(KeyframeEnv(train_tasks, args.keyframes), demos, args, rng)
        obs = [e.reset(seed=args.seed + i)[0] for i, e in enumerate(envs)]
    nsteps = [NStep(args.n_step, args.gamma) for _ in envs]
    elapsed0 = log_rows[-1]["seconds"] if log_rows else 0.0
    t0 = time.perf_counter()
    n_demo = int(round(args.batch_size * args.demo_fraction)) if len(demos) else 0
    loss_avg, qmean = math.nan, math.nan

    def checkpoint():
        def write(f):
            torch.save(
                {
                    "net": net.state_dict(), "target": target.state_dict(),
                    "opt": opt.state_dict(), "memory": memory.state_dict(),
                    "demos": demos.state_dict(), "step": step, "updates": updates,
                    "episodes": episodes, "log": log_rows, "rng": rng.bit_generator.state,
                    "torch_rng": torch.get_rng_state(), "args": asdict(args),
                },
                f,
            )  # fmt: skip

        from sim.motion.clip import write_atomic

        write_atomic(ckpt_path, write)

    def log_eval():
        ev = evaluate(net, test_tasks, args.keyframes)
        row = {
            "step": step, "updates": updates, "episodes": episodes,
            "seconds": round(elapsed0 + time.perf_counter() - t0, 1),
            "epsilon": round(epsilon(), 4), "loss": loss_avg, "q_mean": qmean,
        }  # fmt: skip
        for w in args.keyframes:
            row[f"dqn_W{w}"] = ev[w]
            row[f"greedy_W{w}"] = baselines["greedy"][w]
            row[f"optimal_W{w}"] = baselines["optimal"][w]
        log_rows.append(row)
        _write_log(log_rows, log_path)
        _plot(log_rows, args.keyframes, png_path)
        return ev

    def epsilon():
        frac = min(1.0, step / max(1.0, args.eps_fraction * args.steps))
        return args.eps_start + frac * (args.eps_end - args.eps_start)

    if not log_rows:
        log_eval()  # step 0: the untrained network = its prior (greedy, or the greedy rollout)
    bar = tqdm(total=args.steps, initial=step, desc="train", disable=not args.progress)
    losses = []
    while step < args.steps:
        # act in every environment: ε-greedy over valid frames, masked argmax otherwise
        masks = np.stack([o["keyframes"].astype(bool) for o in obs])
        rems = np.array([o["remaining"] for o in obs])
        tasks_now = [env._task_index for env in envs]
        greedy = act(
            net, np.stack([o["features"] for o in obs]), np.stack([o["cost"] for o in obs]),
            masks, rems, prior_values(net, costs_np, tasks_now, masks, rems),
        )  # fmt: skip
        for i, env in enumerate(envs):
            if rng.random() < epsilon():
                a = int(rng.choice(np.flatnonzero(~masks[i])))
            else:
                a = int(greedy[i])
            task_i = env._task_index
            nobs, r, done, trunc, info = env.step(a)
            nsteps[i].push(
                memory, task_i, masks[i], rems[i], a, r,
                nobs["keyframes"].astype(bool), nobs["remaining"], done,
            )  # fmt: skip
            if done or trunc:
                episodes += 1
                nobs, _ = env.reset()
            obs[i] = nobs
            step += 1
            bar.update(1)
            # learn
            if step >= args.learning_starts and step % args.train_frequency == 0 and len(memory):
                batch = _batch(memory, memory.sample(rng, args.batch_size - n_demo))
                if n_demo:
                    demo_batch = _batch(demos, demos.sample(rng, n_demo))
                    batch = _cat(batch, demo_batch)
                loss, qm = _td_loss(net, target, feats, costs, costs_np, batch, args)
                if n_demo and args.margin_weight > 0:
                    loss = loss + args.margin_weight * _margin_loss(
                        net, feats, costs, costs_np, demo_batch, args
                    )
                opt.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(net.parameters(), args.grad_clip)
                opt.step()
                updates += 1
                losses.append(float(loss.detach()))
                qmean = float(qm)
                if updates % args.target_update == 0:
                    target.load_state_dict(net.state_dict())
            if step % args.eval_every == 0 or step == args.steps:
                loss_avg = float(np.mean(losses)) if losses else math.nan
                losses = []
                ev = log_eval()
                bar.set_postfix({f"W{w}": f"{ev[w] / baselines['optimal'][w]:.3f}" for w in ev})
                checkpoint()
            if step >= args.steps:
                break
    bar.close()
    if not log_rows or log_rows[-1]["step"] != step:
        log_eval()
        checkpoint()
    final = {w: log_rows[-1][f"dqn_W{w}"] for w in args.keyframes}
    save_policy(net, out, args, split, final, baselines)
    return {"dqn": final, **baselines, "split": split, "steps": step}


# --- policy files, log, plot ---------------------------------------------------------------------


def save_policy(net, path, args, split, final, baselines) -> None:
    """Write the policy (weights, network config, training args, held-out figures) atomically."""
    import torch

    from sim.motion.clip import write_atomic

    payload = {
        "format": "sidql-dqn-policy/1",
        "config": dict(net.config),
        "state_dict": {k: v.clone() for k, v in net.state_dict().items()},
        "keyframes": list(args.keyframes),
        "args": {k: v for k, v in asdict(args).items() if k != "extra"},
        "split": split,
        "heldout": {"dqn": final, **baselines},
    }
    buf = io.BytesIO()
    torch.save(payload, buf)
    write_atomic(path, lambda f: f.write(buf.getvalue()))


def _write_log(rows: list[dict], path: Path) -> None:
    from sim.motion.clip import write_atomic

    def write(f):
        text = io.StringIO()
        w = csv.DictWriter(text, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
        f.write(text.getvalue().encode())

    write_atomic(path, write)


def _plot(rows: list[dict], keyframes, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.motion.clip import write_atomic

    fig, ax = plt.subplots(figsize=(6, 3.6))
    steps = [r["step"] for r in rows]
    for w, color in zip(keyframes, ("C0", "C1", "C2", "C3", "C4", "C5"), strict=False):
        opt = rows[-1][f"optimal_W{w}"]
        ax.plot(steps, [r[f"dqn_W{w}"] / opt for r in rows], color=color, label=f"dqn W={w}")
        ax.axhline(rows[-1][f"greedy_W{w}"] / opt, color=color, ls="--", lw=0.8)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("held-out mean Q / optimal")
    ax.set_title("DQN learning curve (dashed: greedy)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    write_atomic(path, lambda f: fig.savefig(f, format="png", dpi=110))
    plt.close(fig)
