"""Settings of a DQN training run (:func:`sidql.learning.dqn.train`), light to import: the command
line builds its options from :class:`Args` without importing torch."""

from __future__ import annotations

import ast
import inspect
import math
from dataclasses import dataclass, field
from functools import lru_cache

from sidql.keyframes.counts import LEAST_LEARNED_W, check_counts
from sim.errors import UsageError

#: Args that may differ between a checkpoint and the run that resumes it (everything else must
#: match: the network, the replay memories and the data split are built from it).
RESUME_MAY_CHANGE = ("steps", "resume", "out", "cache_dir", "progress", "threads", "eval_every",
                     "extra", "data")  # fmt: skip
#: Settings added after checkpoints were first written, with the value every older run had (a
#: checkpoint that does not store one is read as having it).
LATER_DEFAULTS = {"reward": "q"}
#: The rewards a run may learn from (:attr:`Args.reward`).
REWARDS = ("q", "physics")


@dataclass
class Args:
    """Every knob of a training run, one documented field each (``sidql train`` has one option
    per field)."""

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
    reward: str = "q"
    """"q": the paper's reward (eq. 21-22, from Q); "physics": from Q plus the physics method's
    weight (its stated rule) times the physical cost of the segments (skating, floor, residual
    force; sidql.keyframes.physical_costs): every task's segment costs become the physics
    method's, so demonstrations, prior and held-out figures follow them (needs --data)"""
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


@lru_cache(maxsize=1)
def field_docs() -> dict[str, str]:
    """Field name -> the docstring written under it in :class:`Args`, on one line (reST markup
    removed): the help of ``sidql train``'s options."""
    out = {}
    body = ast.parse(inspect.getsource(Args)).body[0].body
    for field_node, doc in zip(body, body[1:], strict=False):
        if (
            isinstance(field_node, ast.AnnAssign)
            and isinstance(field_node.target, ast.Name)
            and isinstance(doc, ast.Expr)
            and isinstance(doc.value, ast.Constant)
            and isinstance(doc.value.value, str)
        ):
            out[field_node.target.id] = " ".join(doc.value.value.replace("``", "").split())
    return out


#: What each numeric setting must be (``sidql train`` refuses anything else in one line, before
#: reading any data): a description and the test. Upper bounds keep the replay memories and the
#: network within memory (``hidden`` as :data:`sidql.learning.policy.MAX_HIDDEN`).
LIMITS = {
    "steps": ("an integer >= 1", lambda v: v >= 1),
    "stride": ("an integer >= 1", lambda v: v >= 1),
    "synthetic_tasks": ("an integer in [4, 100000]", lambda v: 4 <= v <= 100_000),
    "buffer_size": ("an integer in [1, 2000000]", lambda v: 1 <= v <= 2_000_000),
    "batch_size": ("an integer in [1, 65536]", lambda v: 1 <= v <= 65_536),
    "learning_rate": ("a number in (0, 1]", lambda v: 0 < v <= 1),
    "gamma": ("a number in (0, 1]", lambda v: 0 < v <= 1),
    "n_step": ("an integer in [1, 64]", lambda v: 1 <= v <= 64),
    "train_frequency": ("an integer >= 1", lambda v: v >= 1),
    "target_update": ("an integer >= 1", lambda v: v >= 1),
    "learning_starts": ("an integer >= 0", lambda v: v >= 0),
    "eps_start": ("a number in [0, 1]", lambda v: 0 <= v <= 1),
    "eps_end": ("a number in [0, 1]", lambda v: 0 <= v <= 1),
    "eps_fraction": ("a number in [0, 1]", lambda v: 0 <= v <= 1),
    "demo_episodes": ("an integer in [0, 100000]", lambda v: 0 <= v <= 100_000),
    "demo_fraction": ("a number in [0, 1)", lambda v: 0 <= v < 1),
    "margin": ("a number >= 0", lambda v: v >= 0),
    "margin_weight": ("a number >= 0", lambda v: v >= 0),
    "hidden": ("an integer in [1, 1024]", lambda v: 1 <= v <= 1024),
    "n_envs": ("an integer in [1, 1024]", lambda v: 1 <= v <= 1024),
    "grad_clip": ("a number > 0", lambda v: v > 0),
    "eval_every": ("an integer >= 1", lambda v: v >= 1),
    "threads": ("an integer in [1, 256]", lambda v: 1 <= v <= 256),
}


def settings_problems(args: Args) -> list[str]:
    """What is wrong with ``args`` (see :data:`LIMITS`), one line each; empty when nothing is."""
    out = []
    for name, (what, ok) in LIMITS.items():
        v = getattr(args, name)
        finite = not isinstance(v, float) or math.isfinite(v)
        if isinstance(v, bool) or not isinstance(v, int | float) or not finite or not ok(v):
            out.append(f"--{name.replace('_', '-')} must be {what}; got {v}")
    if args.reward not in REWARDS:
        out.append(f"--reward must be one of {', '.join(REWARDS)}; got {args.reward}")
    elif args.reward == "physics" and args.data is None:
        out.append("--reward physics needs --data (synthetic tasks have no physics)")
    try:
        check_counts(args.keyframes, 60, least=LEAST_LEARNED_W, name="--keyframes")
    except UsageError as e:
        out.append(str(e))
    return out
