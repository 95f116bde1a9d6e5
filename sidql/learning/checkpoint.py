"""Training checkpoints (OUT.ckpt): everything needed to resume a run, written and read here.

A checkpoint (:data:`CHECKPOINT_FORMAT`) is tensors and plain values
(:func:`training_state`), written atomically with the run's settings (:func:`save_checkpoint`)
and read with ``torch.load(weights_only=True)`` (:mod:`sidql.learning.files`); its settings are
compared with the run's by :func:`load_checkpoint`. A file whose settings match can still be
tampered with or damaged: :func:`checkpoint_problem` checks every entry against the objects of
the run that would take it (the networks' and optimiser's tensors by name, shape, type and
finiteness, the replay memories' arrays by shape and value range, counters, log rows and random
states), so that a bad file is refused in one line instead of failing deep inside torch or
numpy, or corrupting the run later; :func:`restore` then loads it into those objects.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from sidql.learning.files import load_payload, save_payload
from sidql.learning.settings import LATER_DEFAULTS, RESUME_MAY_CHANGE, Args
from sim.errors import ModelFileError
from sim.files import excerpt

#: Kind and version of a training checkpoint (OUT.ckpt); replay memories are stored as tensors.
CHECKPOINT_FORMAT = "sidql-dqn-checkpoint/2"

#: Largest counter (steps, updates, episodes) and log length a checkpoint may hold.
MAX_COUNT = 1 << 53
MAX_LOG_ROWS = 1 << 20
_COUNTERS = ("step", "updates", "episodes")


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
        old = stored.get(key, LATER_DEFAULTS.get(key))
        if isinstance(value, tuple) and isinstance(old, list | tuple):
            old = tuple(old)
        if old != value:
            flag = "--" + key.replace("_", "-")
            raise ModelFileError(
                str(path), None, f"written with {flag} {_show(old)}, this run has {flag} "
                f"{_show(value)}; resume with the same settings or choose another --out",
            )  # fmt: skip
    return ck


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


def checkpoint_problem(ck: dict, *, net, opt, memory, demos, keyframes, n_tasks: int) -> str | None:
    """Why ``ck`` cannot be loaded into this run's objects, or None when it can.

    Args:
        ck: the loaded checkpoint (settings already matched).
        net: the run's Q-network (the target network has the same layout); opt: its optimiser;
            memory, demos: its replay memories (:class:`sidql.learning.replay.ReplayMemory`);
        keyframes: the run's W values (the log's columns); n_tasks: its training tasks.
    """
    for key in _COUNTERS:
        v = ck.get(key)
        if type(v) is not int or not 0 <= v <= MAX_COUNT:
            return f"{key} {_show(v, 40)} is not a count"
    weights = net.state_dict()
    for key in ("net", "target"):
        problem = _tensors_problem(ck.get(key), weights, key)
        if problem:
            return problem
    problem = _optimiser_problem(ck.get("opt"), opt, net)
    if problem:
        return problem
    for key, mem in (("memory", memory), ("demos", demos)):
        problem = _memory_problem(ck.get(key), mem, key, max(keyframes), n_tasks)
        if problem:
            return problem
    problem = _log_problem(ck.get("log"), keyframes)
    if problem:
        return problem
    generator = np.random.default_rng()
    try:
        generator.bit_generator.state = ck.get("rng")
    except (TypeError, ValueError, KeyError, OverflowError, AttributeError):
        return "rng: not a numpy PCG64 state"
    state = ck.get("torch_rng")
    reference = torch.get_rng_state()
    if not (isinstance(state, torch.Tensor) and state.dtype == reference.dtype
            and state.shape == reference.shape):  # fmt: skip
        return "torch_rng: not a torch random state"
    try:
        torch.Generator().set_state(state)
    except (RuntimeError, ValueError, TypeError):
        return "torch_rng: not a torch random state"
    return None


def _show(value, limit: int = 80) -> str:
    """A setting as the command line spells it, cut short (a checkpoint may hold anything)."""
    text = " ".join(map(str, value)) if isinstance(value, list | tuple) else str(value)
    return excerpt(text, limit, quote=False)


def _tensors_problem(found, expected: dict, what: str) -> str | None:
    """Whether ``found`` holds exactly ``expected``'s tensors: names, shapes, dtypes, finite."""
    if not isinstance(found, dict) or set(found) != set(expected):
        return f"{what}: not the weights of this run's network"
    for k, ref in expected.items():
        v = found[k]
        if not isinstance(v, torch.Tensor) or v.shape != ref.shape or v.dtype != ref.dtype:
            return f"{what}.{k}: not a {ref.dtype} tensor of shape {tuple(ref.shape)}"
        if v.is_floating_point() and not torch.isfinite(v).all():
            return f"{what}.{k}: non-finite values"
    return None


def _optimiser_problem(found, opt, net) -> str | None:
    """Adam's state: the run's hyper-parameters, moments shaped like the parameters."""
    if not isinstance(found, dict) or set(found) != {"state", "param_groups"}:
        return "opt: not an optimiser state"
    if found["param_groups"] != opt.state_dict()["param_groups"]:
        return "opt: parameter groups or hyper-parameters differ from this run's"
    params = list(net.parameters())
    state = found["state"]
    if not isinstance(state, dict) or not set(state) <= set(range(len(params))):
        return "opt: state of parameters this network lacks"
    for i, entry in state.items():
        if not isinstance(entry, dict) or set(entry) != {"step", "exp_avg", "exp_avg_sq"}:
            return f"opt.state[{i}]: not an Adam state"
        step = entry["step"]
        if not (isinstance(step, torch.Tensor) and step.shape == () and step.is_floating_point()
                and math.isfinite(float(step)) and 0 <= float(step) <= MAX_COUNT):  # fmt: skip
            return f"opt.state[{i}].step: not a count"
        for k in ("exp_avg", "exp_avg_sq"):
            v = entry[k]
            if not (isinstance(v, torch.Tensor) and v.shape == params[i].shape
                    and v.dtype == params[i].dtype and torch.isfinite(v).all()):  # fmt: skip
                return f"opt.state[{i}].{k}: not finite and shaped like its parameter"
        if (entry["exp_avg_sq"] < 0).any():
            return f"opt.state[{i}].exp_avg_sq: negative values"
    return None


def _memory_problem(found, memory, what: str, max_w: int, n_tasks: int) -> str | None:
    """A replay memory's arrays: shapes and types of this run's, indices within range."""
    own = vars(memory)
    if not isinstance(found, dict) or set(found) != set(own):
        return f"{what}: not a replay memory of this run"
    if found["size"] != memory.size or type(found["size"]) is not int:
        return f"{what}: size {_show(found['size'], 40)}, this run's is {memory.size}"
    if type(found["pos"]) is not int or not 0 <= found["pos"] < memory.size:
        return f"{what}: position {_show(found['pos'], 40)} outside [0, {memory.size})"
    if type(found["full"]) is not bool:
        return f"{what}: 'full' is not true or false"
    n_frames = memory.mask.shape[1]
    ranges = {"task": n_tasks, "action": n_frames, "rem": max_w + 1, "next_rem": max_w + 1}
    for k, ref in own.items():
        if not isinstance(ref, np.ndarray):
            continue
        v = found[k]
        if not (isinstance(v, torch.Tensor) and tuple(v.shape) == ref.shape
                and v.numpy().dtype == ref.dtype):  # fmt: skip
            return f"{what}.{k}: not a {ref.dtype} array of shape {ref.shape}"
        a = v.numpy()
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            return f"{what}.{k}: non-finite values"
        if k in ranges and len(a) and not (a.min() >= 0 and a.max() < ranges[k]):
            return f"{what}.{k}: values outside [0, {ranges[k]})"
    return _transitions_problem(found, what, memory.size if found["full"] else found["pos"])


def _transitions_problem(found: dict, what: str, n: int) -> str | None:
    """The stored transitions (the first ``n``) are ones an episode can make: an action on a
    free frame with keyframes left to choose, a discount in [0, 1], and unless the episode
    ended, a next state with a free frame and keyframes left (else its value is undefined)."""
    t = {k: v.numpy()[:n] for k, v in found.items() if isinstance(v, torch.Tensor)}
    rows = np.arange(n)
    if np.any(t["mask"][rows, t["action"]]) or np.any(t["mask"].all(axis=1)):
        return f"{what}: a transition acts on a frame already chosen"
    if np.any(t["rem"] < 1):
        return f"{what}: a transition with no keyframe left to choose"
    if not (np.isin(t["done"], (0.0, 1.0)).all() and (t["disc"] >= 0).all()
            and (t["disc"] <= 1).all()):  # fmt: skip
        return f"{what}: 'done' not 0 or 1, or a discount outside [0, 1]"
    going = t["done"] == 0
    if np.any(t["next_mask"][going].all(axis=1)) or np.any(t["next_rem"][going] < 1):
        return f"{what}: an unfinished transition whose next state has nothing left to choose"
    return None


def _log_problem(log, keyframes) -> str | None:
    """The evaluation log: rows of the run's columns, numbers only."""
    columns = [*_COUNTERS, "seconds", "epsilon", "loss", "q_mean"]
    for w in keyframes:
        columns += [f"dqn_W{w}", f"greedy_W{w}", f"optimal_W{w}"]
    if not isinstance(log, list) or len(log) > MAX_LOG_ROWS:
        return "log: not a list of rows"
    for i, row in enumerate(log):
        if not isinstance(row, dict) or list(row) != columns:
            return f"log[{i}]: not a row of this run's columns"
        if any(type(v) not in (int, float) for v in row.values()):
            return f"log[{i}]: values other than numbers"
        if not (math.isfinite(row["seconds"]) and row["seconds"] >= 0):
            return f"log[{i}].seconds: not a duration"
    return None
