"""The trained keyframe policy: load it, decide keyframes, and the ``dqn`` selection method.

Importing this module imports torch; ``sidql.methods`` names it in ``LAZY_METHODS`` so that only
``--methods dqn`` pays for that. The shipped policy is ``sidql/data/policy.pt``; the environment
variable ``SIDQL_POLICY`` points the ``dqn`` method at another file.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from .methods import register
from .qnet import KeyframeQNet, masked_q

#: The policy shipped with the repository.
DEFAULT_POLICY = Path(__file__).resolve().parent / "data" / "policy.pt"


class Policy:
    """A trained Q-network and what it was trained for.

    Attributes:
        net: the :class:`sidql.qnet.KeyframeQNet` (eval mode).
        keyframes: the W it was trained on (it accepts any 3 <= W <= N).
        meta: training arguments, subject split and held-out figures stored with it.
    """

    def __init__(self, net: KeyframeQNet, keyframes, meta: dict):
        self.net, self.keyframes, self.meta = net.eval(), tuple(keyframes), meta

    @torch.no_grad()
    def decide(self, features: np.ndarray, costs: np.ndarray, W: int) -> np.ndarray:
        """Greedy (masked argmax) decisions for a batch of clips.

        Args:
            features: (B, N, C) float32 per-frame features (:func:`sidql.tasks.clip_features`).
            costs: (B, N, N) segment-cost matrices of the same clips (``sidql.segment_costs``).
            W: keyframe count including both ends, 2 <= W <= N.
        Returns:
            (B, W) int64 sorted keyframe indices; one encoder pass, then W - 2 masked argmaxes.
        """
        feats = torch.as_tensor(np.asarray(features, dtype=np.float32))
        if feats.ndim != 3 or feats.shape[-1] != self.net.config["n_features"]:
            raise ValueError(
                f"features must be (B, N, {self.net.config['n_features']}); got {tuple(feats.shape)}"
            )
        b, n, _ = feats.shape
        if not 2 <= W <= n:
            raise ValueError(f"W must be in [2, {n}]; got {W}")
        cost = torch.as_tensor(np.asarray(costs, dtype=np.float32))
        if cost.shape != (b, n, n):
            raise ValueError(f"costs must be ({b}, {n}, {n}); got {tuple(cost.shape)}")
        enc = self.net.encode(feats)
        mask = torch.zeros(b, n, dtype=torch.bool)
        mask[:, [0, n - 1]] = True
        rows = torch.arange(b)
        for k in range(W - 2):
            rem = torch.full((b,), W - 2 - k)
            mask[rows, masked_q(self.net.head(enc, cost, mask, rem), mask).argmax(1)] = True
        return np.nonzero(mask.numpy())[1].reshape(b, W).astype(np.int64)

    def select(self, clip, W: int) -> np.ndarray:
        """(W,) keyframes of a :class:`sim.clip.Clip` (chart, features, costs, :meth:`decide`)."""
        from .segment_costs import segment_cost_matrix
        from .spherical import chart
        from .tasks import clip_features

        series = chart(clip)
        cost = segment_cost_matrix(series, "hermite")
        return self.decide(clip_features(series)[None], cost[None], W)[0]


def load_policy(path: str | os.PathLike | None = None) -> Policy:
    """Load a policy file written by :func:`sidql.dqn.save_policy` (default: ``$SIDQL_POLICY`` or
    the shipped one). Raises FileNotFoundError with the path when it is missing."""
    path = Path(path or os.environ.get("SIDQL_POLICY") or DEFAULT_POLICY)
    return _load(str(path.resolve()), path.stat().st_mtime_ns if path.exists() else 0)


@lru_cache(maxsize=4)
def _load(path: str, _mtime: int) -> Policy:
    if not Path(path).exists():
        raise FileNotFoundError(f"no policy at {path}; train one with `sidql train`")
    payload = torch.load(path, map_location="cpu", weights_only=False)
    if payload.get("format") != "sidql-dqn-policy/1":
        raise ValueError(f"{path} is not a sidql DQN policy")
    cfg = payload["config"]
    net = KeyframeQNet(cfg["n_features"], hidden=cfg["hidden"], dilations=cfg["dilations"])
    net.load_state_dict(payload["state_dict"])
    meta = {k: v for k, v in payload.items() if k not in ("state_dict",)}
    return Policy(net, payload["keyframes"], meta)


@register("dqn")
def dqn(clip, W: int, *, seed: int = 0) -> np.ndarray:
    """SIDQL: the trained Deep Q-Network's greedy (masked argmax) keyframes; deterministic."""
    return load_policy().select(clip, W)
