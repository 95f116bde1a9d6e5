"""The trained keyframe policy: load it, decide keyframes, and the ``dqn`` selection function.

Importing this module imports torch; ``sidql.keyframes.methods`` names :func:`dqn` in
``LAZY_METHODS`` (``"sidql.learning.policy:dqn"``) so that only ``--methods dqn`` pays for that;
this module does not import the registry. The shipped policy is ``sidql/data/policy.pt``; the
environment variable ``SIDQL_POLICY`` points the ``dqn`` method at another file. Policy files are
loaded with ``torch.load(weights_only=True)`` and a format check (:mod:`sidql.learning.files`).
"""

from __future__ import annotations

import os
import warnings
from functools import lru_cache

import numpy as np
import torch

from sidql.keyframes.single_costs import weights_of
from sidql.keyframes.spherical import SIN_EPS, protocol_maps
from sidql.learning.decide import (
    decide_clip,
    encode_clip,
    encoder_weights,
    head_weights,
    select_clip,
)
from sidql.learning.files import POLICY_FORMAT, load_payload
from sidql.learning.qnet import PRIORS, KeyframeQNet, masked_q
from sidql.learning.rollout import rollout_values_batch
from sidql.learning.settings import current_fields
from sim.errors import ModelFileError, MotionDataError, UsageError
from sim.files import MAX_POLICY_BYTES
from sim.paths import package_file

#: The policy shipped inside the package.
DEFAULT_POLICY = package_file("sidql", "data/policy.pt")


def _module_dicts(net: KeyframeQNet) -> tuple[list, list]:
    """Every module's parameter, buffer and child dicts in ``net``, and its tensors: what
    :func:`_weight_key` reads (one walk, made again only when the key changes)."""
    dicts, tensors, stack = [], [], [net]
    while stack:
        m = stack.pop()
        dicts += (m._parameters, m._buffers, m._modules)
        tensors += [t for g in (m._parameters, m._buffers) for t in g.values() if t is not None]
        stack += [c for c in m._modules.values() if c is not None]
    return dicts, tensors


def _weight_key(net: KeyframeQNet, dicts: list, tensors: list) -> tuple:
    """Identity of everything the module dicts of ``net`` hold and the in-place version of its
    tensors (``dicts`` and ``tensors`` from :func:`_module_dicts` of the same network): changes
    whenever a weight or module is replaced or added (a dict that was walked holds another
    object: its parent's) or written (optimiser steps and ``load_state_dict`` write in place,
    bumping the version). Two flat comprehensions: a few microseconds a decision."""
    ids = [id(v) for d in dicts for v in d.values()]
    return (id(net), *ids, *[t._version for t in tensors])


class Policy:
    """A trained Q-network and what it was trained for.

    Attributes:
        net: the :class:`sidql.learning.qnet.KeyframeQNet` (eval mode).
        keyframe_counts: the keyframe counts W it was trained on (it accepts any
            2 <= W <= N; ``keyframes``, the old name, still reads it and warns).
        meta: training arguments, subject split and held-out figures stored with it.
    """

    def __init__(self, net: KeyframeQNet, keyframe_counts, meta: dict):
        self.net, self.keyframe_counts, self.meta = net.eval(), tuple(keyframe_counts), meta
        self.uses_prior = net.config.get("prior", "greedy") == "rollout"

    @property
    def keyframes(self) -> tuple[int, ...]:
        """The old name of :attr:`keyframe_counts` (warns)."""
        warnings.warn("Policy.keyframes is an old name; use Policy.keyframe_counts",
                      FutureWarning, stacklevel=2)  # fmt: skip
        return self.keyframe_counts

    def decide(self, features: np.ndarray, costs: np.ndarray, W: int) -> np.ndarray:
        """Greedy (masked argmax) decisions for a batch of clips, all in compiled code: per clip
        the encoder (:func:`sidql.learning.decide.encode_clip`) and the head's W - 2 steps (:func:`sidql.learning.decide.decide_clip`),
        the arithmetic of :meth:`KeyframeQNet.encode` and :meth:`KeyframeQNet.head` in float64.
        No torch call, so no torch threads: a decision costs one core however busy the machine
        (the encoder's matrix products go to BLAS, which runs products this small on one thread).

        Args:
            features: (B, N, C) float32 per-frame features (:func:`sidql.learning.tasks.clip_features`).
            costs: (B, N, N) segment-cost matrices of the same clips (``sidql.keyframes.segment_costs``).
            W: keyframe count including both ends, 2 <= W <= N.
        Returns:
            (B, W) int64 sorted keyframe indices.
        """
        feats, cost = self._check(features, costs, W)
        enc_w, head_w = self._weights()
        out = np.empty((len(feats), W), np.int64)
        for i in range(len(feats)):
            proj, glob = encode_clip(feats[i], *enc_w)
            out[i] = decide_clip(
                proj, glob, cost[i].astype(np.float64), W, self.uses_prior, *head_w
            )
        return out

    def _weights(self) -> tuple:
        """(encoder, head) weights for the kernels, read again whenever a tensor of the network
        was replaced or written (training changes the network between decisions)."""
        net, walk = self.net, getattr(self, "_walk", None)
        if walk is None or walk[0] is not net or _weight_key(*walk) != self._weights_key:
            # the walk holds the dicts and so every object whose id is in the key: alive, no
            # new tensor or module can reuse one of their ids
            self._walk = walk = (net, *_module_dicts(net))
            self._weights_key = _weight_key(*walk)
            self._cached_weights = (encoder_weights(net), head_weights(net))
        return self._cached_weights

    def _check(self, features, costs, W):
        feats = np.ascontiguousarray(features, dtype=np.float32)
        c = self.net.config["n_features"]
        if feats.ndim != 3 or feats.shape[-1] != c:
            raise UsageError(f"features must be (B, N, {c}); got {feats.shape}")
        b, n, _ = feats.shape
        if not 2 <= W <= n:
            raise UsageError(f"W must be in [2, {n}]; got {W}")
        cost = np.ascontiguousarray(costs, dtype=np.float32)
        if cost.shape != (b, n, n):
            raise UsageError(f"costs must be ({b}, {n}, {n}); got {cost.shape}")
        return feats, cost

    @torch.no_grad()
    def decide_torch(self, features: np.ndarray, costs: np.ndarray, W: int) -> np.ndarray:
        """The same decisions as :meth:`decide`, all in torch (the reference implementation).

        Args:
            features: (B, N, C) float32 per-frame features (:func:`sidql.learning.tasks.clip_features`).
            costs: (B, N, N) segment-cost matrices of the same clips (``sidql.keyframes.segment_costs``).
            W: keyframe count including both ends, 2 <= W <= N.
        Returns:
            (B, W) int64 sorted keyframe indices; one encoder pass, then W - 2 masked argmaxes.
        """
        feats, cost = (torch.as_tensor(x) for x in self._check(features, costs, W))
        b, n, _ = feats.shape
        enc = self.net.encode(feats)
        mask = torch.zeros(b, n, dtype=torch.bool)
        mask[:, [0, n - 1]] = True
        rows = torch.arange(b)
        cost64 = np.ascontiguousarray(costs, dtype=np.float64)
        for k in range(W - 2):
            rem = torch.full((b,), W - 2 - k)
            prior = None
            if self.uses_prior:
                prior = torch.as_tensor(
                    rollout_values_batch(cost64, np.arange(b), mask.numpy(), rem.numpy()),
                    dtype=torch.float32,
                )
            q = self.net.head(enc, cost, mask, rem, prior)
            mask[rows, masked_q(q, mask).argmax(1)] = True
        return np.nonzero(mask.numpy())[1].reshape(b, W).astype(np.int64)

    def select(self, clip, W: int) -> np.ndarray:
        """(W,) keyframes of a :class:`sim.motion.clip.Clip`: the chart, its features, its Hermite
        segment costs in single precision (:mod:`sidql.keyframes.single_costs`, rounded to
        float32 as :meth:`decide` rounds any costs), then :meth:`decide`'s two kernels, all in
        one compiled call (:func:`sidql.learning.decide.select_clip`).

        Raises:
            UsageError: W out of [2, N]. ModelFileError: the policy takes other features.
            MotionDataError: as :func:`sidql.keyframes.spherical.chart`.
        """
        idx, parents = protocol_maps(clip)
        n, bones = clip.n_frames, len(idx) - 1
        c = int(self.net.config["n_features"])
        if 4 * bones != c:  # a policy trained on clips of another skeleton (features: angles
            raise ModelFileError(  # theta, phi and their rates per bone, stacked_features)
                self.meta.get("file"), None, f"the policy takes {c} features per frame; clips "
                f"of {bones} bones give {4 * bones}",
            )  # fmt: skip
        if not 2 <= W <= n:
            raise UsageError(f"W must be in [2, {n}]; got {W}")
        enc_w, head_w = self._weights()
        keys, ok = select_clip(clip.positions, clip.velocities, idx, parents, float(clip.dt),
                               SIN_EPS, weights_of(n), int(W), self.uses_prior, enc_w, head_w)  # fmt: skip
        if not ok:
            raise MotionDataError(clip.source or None, None, "non-finite positions or velocities")
        return keys


def load_policy(path: str | os.PathLike | None = None) -> Policy:
    """Load a policy file written by :func:`sidql.learning.run_files.save_policy` (default:
    ``$SIDQL_POLICY`` or the shipped one), tensors and plain values only.

    Raises:
        FileNotFoundError: no file there (the message says how to train one).
        ModelFileError: the file is refused (holds other objects, another format or version, or
            weights that do not fit the network it declares); one line naming the file.
    """
    path = os.fspath(path or os.environ.get("SIDQL_POLICY") or DEFAULT_POLICY)
    try:  # one system call per decision (the dqn method calls this every time); plain os
        st = os.stat(path)  # calls, not pathlib: a few microseconds, not tens, between kernels
    except OSError:
        raise FileNotFoundError(f"no policy at {path}; train one with `sidql train`") from None
    full = _normalised(path) if os.path.isabs(path) else os.path.abspath(path)
    return _load(full, st.st_mtime_ns, st.st_ino)


@lru_cache(maxsize=16)
def _normalised(path: str) -> str:
    """``os.path.abspath`` of an absolute path (no working folder in it), once per path."""
    return os.path.normpath(path)


#: Stated limits of a policy file's network config: width, input channels, temporal layers and
#: their dilation (the shipped policy: hidden 32, 14 features, dilations 1 2 4 8).
MAX_HIDDEN = 1024
MAX_FEATURES = 1024
MAX_LAYERS = 16
MAX_DILATION = 4096


def check_config(cfg, state_dict) -> tuple:
    """``(n_features, hidden, dilations, prior)`` of a policy file's ``config``, after checking
    it against :data:`MAX_HIDDEN` etc. and every stored tensor's shape against the network it
    declares (built on torch's ``meta`` device, which allocates no memory).

    Raises:
        ValueError: a value out of its limits or of the wrong type, or weights that do not fit
            (the loader turns it into a ModelFileError naming the file).
    """
    if not isinstance(cfg, dict) or not isinstance(state_dict, dict):
        raise ValueError("config and state_dict must be dicts")
    c, h, dil, prior = (
        cfg.get("n_features"),
        cfg.get("hidden"),
        cfg.get("dilations"),
        cfg.get("prior", "greedy"),
    )
    for name, v, hi in (("n_features", c, MAX_FEATURES), ("hidden", h, MAX_HIDDEN)):
        if type(v) is not int or not 1 <= v <= hi:
            raise ValueError(f"config {name} {str(v)[:40]!r} is not an integer in [1, {hi}]")
    if not isinstance(dil, list | tuple) or len(dil) > MAX_LAYERS:
        raise ValueError(f"config dilations: a list of at most {MAX_LAYERS} integers expected")
    if any(type(d) is not int or not 1 <= d <= MAX_DILATION for d in dil):
        raise ValueError(f"config dilations: each an integer in [1, {MAX_DILATION}]")
    if prior not in PRIORS:
        raise ValueError(f"config prior {str(prior)[:40]!r}; expected one of {', '.join(PRIORS)}")
    with torch.device("meta"):
        shapes = {k: tuple(v.shape) for k, v in KeyframeQNet(c, h, dil, prior).state_dict().items()}
    for k, shape in shapes.items():
        v = state_dict.get(k)
        if not isinstance(v, torch.Tensor) or tuple(v.shape) != shape:
            found = tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
            raise ValueError(f"weight {k}: {found}, the declared network needs {shape}")
    extra = sorted(set(state_dict) - set(shapes), key=str)
    if extra:
        raise ValueError(f"weights the declared network lacks: {str(extra[0])[:60]}")
    for k in shapes:
        v = state_dict[k]
        if not v.is_floating_point() or not torch.isfinite(v).all():
            raise ValueError(f"weight {k}: not all finite floating-point numbers")
    if not (state_dict["feature_std"] > 0).all():
        raise ValueError("weight feature_std: not all positive")
    return c, h, tuple(dil), prior


@lru_cache(maxsize=4)
def _load(path: str, _mtime: int, _inode: int = 0) -> Policy:
    payload = load_payload(path, POLICY_FORMAT, MAX_POLICY_BYTES)
    try:
        cfg = payload["config"]
        args = check_config(cfg, payload["state_dict"])  # before allocating any weight
        net = KeyframeQNet(*args[:3], prior=args[3])
        net.load_state_dict(payload["state_dict"])
        payload = current_fields(payload)  # a file written before the counts' rename
        counts = tuple(int(w) for w in payload["keyframe_counts"])
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ModelFileError(path, None, f"not a usable policy: {first}") from None
    meta = {k: v for k, v in payload.items() if k != "state_dict"}
    if isinstance(meta.get("args"), dict):
        meta["args"] = current_fields(meta["args"])
    meta["file"] = path
    return Policy(net, counts, meta)


def dqn(clip, W: int, *, seed: int = 0) -> np.ndarray:
    """SIDQL: the trained Deep Q-Network's greedy (masked argmax) keyframes; deterministic.

    The ``dqn`` selection method (``sidql.keyframes.methods`` finds it by name, lazily)."""
    return load_policy().select(clip, W)
