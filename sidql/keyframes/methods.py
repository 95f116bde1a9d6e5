"""Keyframe selection methods behind one interface: ``(clip, W, *, seed) -> keyframe indices``.

Every method returns W sorted, unique int64 frame indices that include the first (0) and last
(N - 1) frame. Adding a method = one function plus one registration::

    from sidql.keyframes.methods import register

    @register("mine")  # or register("mine", reconstruction="slerp")
    def mine(clip, W, *, seed=0):
        ...

A method declares the reconstruction it is meant for (:data:`RECONSTRUCTION`, default
``"hermite"``; names from :mod:`sidql.keyframes.reconstructions`). A method whose choice depends on
the reconstruction (the optimum, greedy) also accepts ``reconstruction=`` and ``memo=`` (a dict
the caller keeps per clip, so that one table serves every W); :func:`select` passes them only to
methods whose signature names them.

A method living in a module that should only be imported on demand (e.g. one that needs torch
weights) is named in :data:`LAZY_METHODS` instead (``name -> "module:function"``, registered for
the Hermite reconstruction on first use; a bare ``"module"`` must call :func:`register` itself).
"""

from __future__ import annotations

import importlib
import inspect
import warnings
from collections.abc import Callable

import numpy as np

from sidql.keyframes import reconstructions
from sidql.keyframes.counts import check_counts
from sidql.keyframes.metrics import q_error
from sidql.keyframes.old_names import RENAMED
from sidql.keyframes.optimal import clip_optimal_keyframes
from sidql.keyframes.pitch import keyframes_for_count, pitch_distances, protocol_rotations
from sidql.keyframes.segment_costs import SEPARABLE, greedy_keyframes
from sidql.keyframes.spherical import chart
from sim.errors import UnknownNameError, UsageError, require_type
from sim.motion.clip import Clip

MethodFn = Callable[..., np.ndarray]

#: name -> function(clip, W, *, seed=0) -> (W,) indices.
METHODS: dict[str, MethodFn] = {}

#: name -> the reconstruction the method is meant for (see :mod:`sidql.keyframes.reconstructions`).
RECONSTRUCTION: dict[str, str] = {}

#: name -> module that registers it when imported (for methods with heavy dependencies).
#: ``"module:function"`` names the method's function; a bare ``"module"`` must register it on import.
LAZY_METHODS: dict[str, str] = {
    "dqn": "sidql.learning.policy:dqn",
    "physics": "sidql.keyframes.physical_costs",  # registers itself (rebuilt with contacts)
}

_OPTIONS = ("reconstruction", "memo")
_TAKES: dict[str, tuple[str, ...]] = {}


def register(name: str, reconstruction: str = "hermite") -> Callable[[MethodFn], MethodFn]:
    """Decorator registering ``fn(clip, W, *, seed=0) -> indices`` under ``name``, meant for
    ``reconstruction``.

    Raises:
        UsageError: an empty name. UnknownNameError: an unknown reconstruction.
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise UsageError(f"a method name must be a word (letters, digits, _); got {name!r}")
    reconstructions.get(reconstruction)

    def deco(fn: MethodFn) -> MethodFn:
        METHODS[name] = fn
        RECONSTRUCTION[name] = reconstruction
        params = inspect.signature(fn).parameters
        _TAKES[name] = tuple(p for p in _OPTIONS if p in params)
        return fn

    return deco


def current_name(name: str) -> str:
    """``name``, or its name now if it is an old one (:data:`RENAMED`; warns)."""
    if name in RENAMED:
        warnings.warn(
            f"method {name!r} is an old name; use {RENAMED[name]!r}", FutureWarning, stacklevel=3
        )
        return RENAMED[name]
    return name


def reconstruction_of(name: str) -> str:
    """The reconstruction method ``name`` is meant for (importing it if lazy)."""
    name = current_name(name)
    get(name)
    return RECONSTRUCTION.get(name, "hermite")


def available() -> list[str]:
    """Names of every method, registered or lazily importable."""
    return sorted(set(METHODS) | set(LAZY_METHODS))


def get(name: str) -> MethodFn:
    """The method registered as ``name`` (importing its module if lazy; an old name warns).

    Raises:
        UnknownNameError: (a KeyError) no such method; the message lists the known ones.
    """
    name = current_name(name)
    if name not in METHODS and name in LAZY_METHODS:
        module, _, function = LAZY_METHODS[name].partition(":")
        loaded = importlib.import_module(module)
        if function:
            register(name)(getattr(loaded, function))
    try:
        return METHODS[name]
    except KeyError:
        raise UnknownNameError("method", name, available()) from None


def select(
    name: str,
    clip: Clip,
    W: int,
    *,
    seed: int = 0,
    reconstruction: str | None = None,
    memo: dict | None = None,
) -> np.ndarray:
    """Choose W keyframes of ``clip`` with method ``name``.

    Args:
        name: a registered method (see :func:`available`).
        clip: the motion (N frames).
        W: keyframe count, both ends included, 2 <= W <= N (:mod:`sidql.keyframes.counts`).
        seed: seed of any randomness the method uses.
        reconstruction: the reconstruction the keyframes will be rebuilt with, for methods whose
            choice depends on it (default: the method's own, :func:`reconstruction_of`).
        memo: a dict kept by the caller for this clip only; methods cache per-clip work there
            (the chart, an optimum table for every W, pitch distances).

    Returns:
        (W,) sorted unique int64 indices with first 0 and last N - 1.

    Raises:
        UnknownNameError: an unknown method. UsageError: W out of range.
    """
    name = current_name(name)
    require_type(clip, Clip, "clip")
    N = clip.n_frames
    check_counts([W], N)
    fn = get(name)
    options = {"reconstruction": reconstruction or RECONSTRUCTION[name], "memo": memo}
    kw = {p: options[p] for p in _TAKES.get(name, ())}
    k = np.asarray(fn(clip, W, seed=seed, **kw), dtype=np.int64)
    got = k.tolist() if k.ndim == 1 else [None]  # plain ints: the check costs microseconds
    if len(got) != W or got[0] != 0 or got[-1] != N - 1 or any(map(int.__ge__, got, got[1:])):
        raise UsageError(f"method {name!r} returned bad keyframes {k.tolist()} for W={W}")
    return k


def _memo_chart(clip: Clip, memo: dict | None):
    if memo is None:
        return chart(clip)
    if "chart" not in memo:
        memo["chart"] = chart(clip)
    return memo["chart"]


@register("random")
def random_choice(clip: Clip, W: int, *, seed: int = 0) -> np.ndarray:
    """RC: both ends plus W - 2 distinct inner frames drawn uniformly (``default_rng(seed)``)."""
    N = clip.n_frames
    inner = np.random.default_rng(seed).choice(np.arange(1, N - 1), size=W - 2, replace=False)
    return np.concatenate([[0], np.sort(inner), [N - 1]]).astype(np.int64)


def uniform_indices(N: int, W: int) -> np.ndarray:
    """(W,) evenly spaced frame indices from 0 to N - 1 (rounded half up; unique for W <= N)."""
    return np.floor(np.linspace(0.0, N - 1.0, W) + 0.5).astype(np.int64)


@register("uniform")
def uniform_choice(clip: Clip, W: int, *, seed: int = 0) -> np.ndarray:
    """UC: W evenly spaced frames from first to last."""
    return uniform_indices(clip.n_frames, W)


@register("cartesian", reconstruction="cartesian")
def cartesian_uniform(clip: Clip, W: int, *, seed: int = 0) -> np.ndarray:
    """The Cartesian baseline many keyframe systems use (once named ``xyz``): W evenly spaced
    frames, every point interpolated in xyz between them (cubic Hermite with the keyframes' point velocities), so bone
    lengths are not kept - the motion the bone-length and IK checks exist for."""
    return uniform_indices(clip.n_frames, W)


def greedy_from_costs(C: np.ndarray, W: int) -> np.ndarray:
    """Greedy keyframes from a segment-cost matrix: start from both ends, then W - 2 times add
    the frame that lowers Q the most (ties: the lowest index).

    Adding frame f inside segment (a, b) changes the total cost by ``C[a,f] + C[f,b] - C[a,b]``.
    """
    N = C.shape[0]
    keys = np.array([0, N - 1], dtype=np.int64)
    frames = np.arange(N)
    for _ in range(W - 2):
        seg = np.clip(np.searchsorted(keys, frames, side="right") - 1, 0, len(keys) - 2)
        a, b = keys[seg], keys[seg + 1]
        delta = C[a, frames] + C[frames, b] - C[a, b]
        delta[keys] = np.inf
        keys = np.sort(np.append(keys, int(np.argmin(delta))))
    return keys


def naive_greedy(series, W: int) -> np.ndarray:
    """The paper's greedy taken literally: rebuild and score the whole clip for every candidate.

    O(W N) full reconstructions; the reference that :func:`greedy` must equal and the baseline its
    benchmark is measured against. ``series``: a :class:`~sidql.keyframes.spherical.SphericalSeries`.
    """
    keys = [0, series.n_frames - 1]
    for _ in range(W - 2):
        cands = [f for f in range(series.n_frames) if f not in keys]
        errs = [q_error(series, np.array(sorted(keys + [f]))) for f in cands]
        keys.append(cands[int(np.argmin(errs))])
    return np.array(sorted(keys))


@register("greedy")
def greedy(
    clip: Clip, W: int, *, seed: int = 0, reconstruction: str = "hermite", memo=None
) -> np.ndarray:
    """Greedy (paper): repeatedly add the frame whose addition lowers Q (eq. 18) the most, Q of
    ``reconstruction`` (one with a segment-cost kernel)."""
    if reconstructions.get(reconstruction).cost_matrix is None:
        raise UsageError(
            f"greedy needs a reconstruction with a segment-cost kernel; got {reconstruction!r}"
        )
    return greedy_keyframes(_memo_chart(clip, memo), W, reconstruction)


@register("optimal")
def optimal(
    clip: Clip, W: int, *, seed: int = 0, reconstruction: str = "hermite", memo=None
) -> np.ndarray:
    """The exact minimiser of Q (eq. 18) of ``reconstruction`` over all W-keyframe sets (its
    registered optimum). With a ``memo`` one table serves every W up to ``memo["w_max"]``."""
    optimum = reconstructions.get(reconstruction).optimum
    if optimum is None:
        raise UsageError(f"reconstruction {reconstruction!r} has no registered optimum")
    if memo is None and reconstruction in SEPARABLE:  # chart + the costs it can use, one pass
        return clip_optimal_keyframes(clip, W, reconstruction)
    series = _memo_chart(clip, memo)
    if memo is None:
        return optimum(series, w_max=W).keyframes(W)
    key = ("optimum", reconstruction)
    if key not in memo or len(memo[key].cost) <= W:
        memo[key] = optimum(series, w_max=max(W, memo.get("w_max", W)))
    return memo[key].keyframes(W)


@register("pitch", reconstruction="slerp")
def pitch(clip: Clip, W: int, *, seed: int = 0, memo=None) -> np.ndarray:
    """Li et al. 2015: inter-frame pitch threshold, searched to give exactly W keyframes."""
    if memo is None or "pitch_distances" not in memo:
        D = pitch_distances(protocol_rotations(clip)[1])
        if memo is not None:
            memo["pitch_distances"] = D
    else:
        D = memo["pitch_distances"]
    return keyframes_for_count(D, W)[0]
