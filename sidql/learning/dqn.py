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
at every evaluation), ``OUT.csv`` (the log) and ``OUT.png`` (the learning curve). Policy and
checkpoint files hold tensors and plain values only and are read with ``weights_only=True``
(:mod:`sidql.learning.files`); ``--resume`` refuses a checkpoint whose settings differ.

The network reads the raw task arrays (``env.tasks[info["task_index"]]``: radians, its own input
standardisation), not the environment's unit-scale observations; the mask and the keyframes still
to choose come from the observation.
"""

from __future__ import annotations

import csv
import io
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from sidql.keyframes.methods import greedy_from_costs
from sidql.keyframes.optimal import solve
from sidql.learning.checkpoint import checkpoint_problem
from sidql.learning.env import KeyframeEnv
from sidql.learning.files import (
    CHECKPOINT_FORMAT,
    POLICY_FORMAT,
    load_payload,
    save_payload,
)
from sidql.learning.policy import Policy
from sidql.learning.qnet import KeyframeQNet, masked_q
from sidql.learning.rollout import rollout_values_batch
from sidql.learning.settings import RESUME_MAY_CHANGE, Args, settings_problems
from sidql.learning.tasks import (
    KeyframeTask,
    clip_task,
    insertion_gain,
    keyframe_q,
    load_tasks,
    synthetic_tasks,
)
from sim.errors import ModelFileError, MotionDataError
from sim.files import excerpt, write_atomic
from sim.motion.dataset import dataset_entries, find_trials, origin_subject

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
        """Tensors and plain values only (a checkpoint is loaded with ``weights_only=True``)."""
        return {k: torch.from_numpy(v.copy()) if isinstance(v, np.ndarray) else v
                for k, v in vars(self).items()}  # fmt: skip

    def load_state_dict(self, d: dict) -> None:
        arrays = {k: v for k, v in vars(self).items() if isinstance(v, np.ndarray)}
        for k, v in d.items():
            if k in arrays:
                v = np.asarray(v.numpy(), dtype=arrays[k].dtype)
                if v.shape != arrays[k].shape:
                    raise ValueError(f"replay memory {k}: shape {v.shape} != {arrays[k].shape}")
            setattr(self, k, v)


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
    kw = dict(cache_dir=args.cache_dir, progress=args.progress)  # None: the default task cache
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
        train_tasks += [_also_task(c, e, args.train_also) for c, e in kept]
    return train_tasks, test_tasks, {"train": train_s, "test": test_s}


def _also_task(clip, entry: dict, folder) -> KeyframeTask:
    """The task of a ``--train-also`` clip; one that cannot be a task is named by its index
    file and entry (never by the path its ``source`` claims)."""
    try:
        return clip_task(clip, subject=str(entry.get("subject", "")))
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


# --- files: checkpoint, policy, log, plot --------------------------------------------------------


def save_checkpoint(path: Path, state: dict, args: Args) -> None:
    """Write everything needed to resume (``state``: networks, optimiser, memories, counters,
    random states, log, split) with the run's settings, atomically."""
    save_payload(path, {"format": CHECKPOINT_FORMAT, "args": asdict(args), **state})


def load_checkpoint(path: Path, args: Args) -> dict:
    """The checkpoint at ``path`` (tensors and plain values only), after checking it was written
    with the same settings as ``args`` (all but :data:`RESUME_MAY_CHANGE`).

    Raises:
        ModelFileError: refused file, other format, or other settings (one line naming the file,
            the setting and both values).
    """
    ck = load_payload(path, CHECKPOINT_FORMAT)
    stored, now = ck.get("args"), asdict(args)
    if not isinstance(stored, dict):
        raise ModelFileError(str(path), None, "holds no training settings")
    for key, value in now.items():
        if key in RESUME_MAY_CHANGE:
            continue
        old = stored.get(key)
        if isinstance(value, tuple) and isinstance(old, list | tuple):
            old = tuple(old)
        if old != value:
            flag = "--" + key.replace("_", "-")
            raise ModelFileError(
                str(path), None, f"written with {flag} {_show(old)}, this run has {flag} "
                f"{_show(value)}; resume with the same settings or choose another --out",
            )  # fmt: skip
    return ck


def _show(value, limit: int = 80) -> str:
    """A setting as the command line spells it, cut short (a checkpoint may hold anything)."""
    text = " ".join(map(str, value)) if isinstance(value, list | tuple) else str(value)
    return excerpt(text, limit, quote=False)


def save_policy(net, path, args, split, final, baselines) -> None:
    """Write the policy (weights, network config, training args, held-out figures) atomically."""
    payload = {
        "format": POLICY_FORMAT,
        "config": dict(net.config),
        "state_dict": {k: v.clone() for k, v in net.state_dict().items()},
        "keyframes": list(args.keyframes),
        "args": {k: v for k, v in asdict(args).items() if k != "extra"},
        "split": split,
        "heldout": {"dqn": final, **baselines},
    }
    save_payload(path, payload)


def write_log(rows: list[dict], path: Path) -> None:
    """The evaluation log as CSV, atomically."""

    def write(f):
        text = io.StringIO()
        w = csv.DictWriter(text, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
        f.write(text.getvalue().encode())

    write_atomic(path, write)


def plot_curve(rows: list[dict], keyframes, path: Path) -> None:
    """Held-out mean Q / optimal per W over the run (dashed: greedy), as PNG."""
    import matplotlib  # lazy: heavy and only needed here

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy, after choosing the headless backend

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


def log_row(counters: dict, seconds: float, epsilon: float, loss: float, q_mean: float,
            heldout: dict[int, float], base: dict, keyframes) -> dict:  # fmt: skip
    """One line of the log: counters, time, ε, mean loss and Q since the last line, and the
    held-out mean Q of the network, greedy and the optimum for every W."""
    row = {**counters, "seconds": round(seconds, 1), "epsilon": round(epsilon, 4), "loss": loss,
           "q_mean": q_mean}  # fmt: skip
    for w in keyframes:
        row[f"dqn_W{w}"] = heldout[w]
        row[f"greedy_W{w}"] = base["greedy"][w]
        row[f"optimal_W{w}"] = base["optimal"][w]
    return row


@dataclass(frozen=True)
class RunFiles:
    """What a run writes: ``policy`` (OUT), ``checkpoint`` (OUT.ckpt), ``log`` (.csv), ``curve``
    (.png)."""

    policy: Path
    checkpoint: Path
    log: Path
    curve: Path

    @classmethod
    def beside(cls, out: str | Path) -> RunFiles:
        out = Path(out)
        return cls(out, out.with_name(out.name + ".ckpt"), out.with_suffix(".csv"),
                   out.with_suffix(".png"))  # fmt: skip


def record(files: RunFiles, log_rows: list[dict], row: dict, keyframes) -> None:
    """Append ``row`` to the log and rewrite the CSV and the learning curve."""
    log_rows.append(row)
    write_log(log_rows, files.log)
    plot_curve(log_rows, keyframes, files.curve)


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


def training_state(net, target, opt, memory, demos, counters, log_rows, rng, split, n_tasks):
    """Everything :func:`restore` needs, as tensors and plain values (for :func:`save_checkpoint`)."""
    return {
        **counters, "net": net.state_dict(), "target": target.state_dict(),
        "opt": opt.state_dict(), "memory": memory.state_dict(), "demos": demos.state_dict(),
        "log": list(log_rows), "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
        "split": split, "n_tasks": n_tasks,
    }  # fmt: skip


def restore(ck: dict, net, target, opt, memory, demos, rng, *, path: str = "",
            keyframes=(), n_tasks: int = 0) -> tuple[dict, list[dict]]:  # fmt: skip
    """Load a checkpoint's state into the run's objects; returns (counters, log rows).

    Every entry is checked against those objects first (:func:`checkpoint_problem`), so a file
    whose settings match but whose contents do not is refused before anything is loaded.

    Raises:
        ModelFileError: one line naming ``path`` and the entry that does not fit.
    """
    problem = checkpoint_problem(
        ck, net=net, opt=opt, memory=memory, demos=demos, keyframes=keyframes, n_tasks=n_tasks
    )
    if problem:
        raise ModelFileError(path or None, None, f"cannot resume from it: {problem}")
    try:
        net.load_state_dict(ck["net"])
        target.load_state_dict(ck["target"])
        opt.load_state_dict(ck["opt"])
        memory.load_state_dict(ck["memory"])
        demos.load_state_dict(ck["demos"])
        rng.bit_generator.state = ck["rng"]
        torch.set_rng_state(ck["torch_rng"])
    except (KeyError, TypeError, ValueError, RuntimeError) as e:  # a second line of defence
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ModelFileError(path or None, None, f"cannot resume from it: {first}") from None
    return {k: int(ck[k]) for k in ("step", "updates", "episodes")}, list(ck["log"])


# --- the algorithm -------------------------------------------------------------------------------


def train(args: Args) -> dict:
    """Train a keyframe policy; returns the final held-out evaluation and baselines.

    Writes ``args.out`` (policy), ``args.out + '.ckpt'`` (resumable state), ``.csv`` log and
    ``.png`` learning curve. Deterministic for a given seed and thread count.

    Raises:
        MotionDataError: no usable clips for the split.
        ModelFileError: a checkpoint that ``--resume`` refuses (unsafe file, other format or
            other settings).
    """
    # setup: files, checkpoint (checked before any data is read), data, networks, environments
    problems = settings_problems(args)
    if problems:
        raise ValueError(problems[0])
    torch.set_num_threads(args.threads)
    files = RunFiles.beside(args.out)
    resume = args.resume and files.checkpoint.exists()
    ck = load_checkpoint(files.checkpoint, args) if resume else None
    files.policy.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)

    train_tasks, test_tasks, split = make_tasks(args)
    if ck is not None and (ck.get("split") != split or ck.get("n_tasks") != len(train_tasks)):
        raise ModelFileError(
            str(files.checkpoint), None, f"written for another data split ({_show(ck.get('n_tasks'))} "
            f"training clips, {_show(ck.get('split'))}); this run has {len(train_tasks)}, "
            f"{_show(split)}",
        )  # fmt: skip
    n = train_tasks[0].n_frames
    feats = torch.as_tensor(np.stack([t.features for t in train_tasks]))
    costs_np = np.ascontiguousarray(np.stack([t.cost for t in train_tasks]), dtype=np.float64)
    costs = torch.as_tensor(costs_np.astype(np.float32))
    base = baselines(test_tasks, args.keyframes)

    net, target, opt = make_networks(args, feats)
    envs = [KeyframeEnv(train_tasks, args.keyframes) for _ in range(args.n_envs)]
    memory = ReplayMemory(args.buffer_size, n)
    demos = ReplayMemory(max(1, args.demo_episodes * (max(args.keyframes) - 2)), n)
    if ck is not None:
        counters, log_rows = restore(
            ck, net, target, opt, memory, demos, rng, path=str(files.checkpoint),
            keyframes=args.keyframes, n_tasks=len(train_tasks),
        )  # fmt: skip
        seeds = [args.seed + 1000 * (counters["step"] + 1) + i for i in range(len(envs))]
    else:
        counters, log_rows = {"step": 0, "updates": 0, "episodes": 0}, []
        if args.demo_episodes:
            play_demonstrations(KeyframeEnv(train_tasks, args.keyframes), demos, args, rng)
        seeds = [args.seed + i for i in range(len(envs))]
    step, updates, episodes = counters["step"], counters["updates"], counters["episodes"]
    started = [env.reset(seed=s) for env, s in zip(envs, seeds, strict=True)]
    obs, infos = [o for o, _ in started], [i for _, i in started]
    nsteps = [NStep(args.n_step, args.gamma) for _ in envs]
    elapsed0 = log_rows[-1]["seconds"] if log_rows else 0.0
    t0 = time.perf_counter()
    losses, q_mean = [], math.nan
    eps_steps = args.eps_fraction * args.steps
    if not log_rows:  # step 0: the untrained network = its prior (greedy, or the greedy rollout)
        heldout = evaluate(net, test_tasks, args.keyframes)
        row = log_row({"step": 0, "updates": 0, "episodes": 0}, 0.0, args.eps_start, math.nan,
                      math.nan, heldout, base, args.keyframes)  # fmt: skip
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
                updates += 1
                losses.append(float(loss.detach()))
                q_mean = float(qm)
                if updates % args.target_update == 0:
                    target.load_state_dict(net.state_dict())
            # evaluate on the held-out clips, log, checkpoint
            if step % args.eval_every == 0 or step == args.steps:
                heldout = evaluate(net, test_tasks, args.keyframes)
                counters = {"step": step, "updates": updates, "episodes": episodes}
                row = log_row(
                    counters, elapsed0 + time.perf_counter() - t0,
                    linear_schedule(args.eps_start, args.eps_end, eps_steps, step),
                    float(np.mean(losses)) if losses else math.nan, q_mean, heldout, base,
                    args.keyframes,
                )  # fmt: skip
                losses = []
                record(files, log_rows, row, args.keyframes)
                state = training_state(
                    net, target, opt, memory, demos, counters, log_rows, rng, split,
                    len(train_tasks),
                )  # fmt: skip
                save_checkpoint(files.checkpoint, state, args)
                bar.set_postfix(
                    {f"W{w}": f"{heldout[w] / base['optimal'][w]:.3f}" for w in heldout}
                )
            if step >= args.steps:
                break
    bar.close()
    final = {w: log_rows[-1][f"dqn_W{w}"] for w in args.keyframes}
    save_policy(net, files.policy, args, split, final, base)
    return {"dqn": final, **base, "split": split, "steps": step}
