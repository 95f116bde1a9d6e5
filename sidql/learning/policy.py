"""The trained keyframe policy: load it, decide keyframes, and the ``dqn`` selection function.

Importing this module imports torch; ``sidql.keyframes.methods`` names :func:`dqn` in
``LAZY_METHODS`` (``"sidql.learning.policy:dqn"``) so that only ``--methods dqn`` pays for that;
this module does not import the registry. The shipped policy is ``sidql/data/policy.pt``; the
environment variable ``SIDQL_POLICY`` points the ``dqn`` method at another file. Policy files are
loaded with ``torch.load(weights_only=True)`` and a format check (:mod:`sidql.learning.files`).
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numba
import numpy as np
import torch
from torch import nn

from sidql.keyframes.segment_costs import clip_stacked_costs
from sidql.learning.files import POLICY_FORMAT, load_payload
from sidql.learning.qnet import N_SCALARS, PRIORS, KeyframeQNet, masked_q
from sidql.learning.rollout import greedy_sequences, rollout_values_batch, rollout_values_seq
from sidql.learning.tasks import stacked_features
from sim.errors import ModelFileError
from sim.files import MAX_POLICY_BYTES
from sim.paths import package_file

#: The policy shipped inside the package.
DEFAULT_POLICY = package_file("sidql", "data/policy.pt")

#: The modules of :class:`KeyframeQNet` the decision kernels know: the encoder's layers (mirrored
#: in :func:`_encode_clip`) and the head's linear layers (mirrored in :func:`_decide_clip`). A
#: network with any other module set, or with these of another type or shape, is refused by
#: :func:`encoder_weights` / :func:`head_weights`.
ENCODER_MODULES = ("inp", "convs", "ctx")
HEAD_MODULES = ("proj", "glob", "scal", "adv_hidden", "adv_out", "value_hidden", "value_out")


def head_weights(net: KeyframeQNet) -> tuple:
    """The head's weights as float64 arrays, read from its NAMED modules, for :func:`_decide_clip`.

    Checks that the network is the one the kernel mirrors: exactly the modules
    :data:`ENCODER_MODULES` + :data:`HEAD_MODULES`, the head's layers ``nn.Linear`` of the shapes
    the kernel's arithmetic assumes (K = H = ``config["hidden"]``).

    Returns:
        (scal W (K, 11), scal b (K,), adv_hidden W (H, K), b (H,), adv_out w (H,), b float,
        value_hidden W (H, K), b (H,), value_out w (H,), b float).
    Raises:
        TypeError: a layer was added, removed, renamed or changed (the kernel would silently
            compute something else).
    """
    h = int(net.config["hidden"])
    children = {name for name, _ in net.named_children()}
    if children != set(ENCODER_MODULES + HEAD_MODULES):
        raise TypeError(
            "the compiled decision kernel mirrors KeyframeQNet's modules "
            f"{sorted(ENCODER_MODULES + HEAD_MODULES)}; this network has {sorted(children)}"
        )
    shapes = {
        "proj": (4 * h, h), "glob": (h, h), "scal": (h, N_SCALARS), "adv_hidden": (h, h),
        "adv_out": (1, h), "value_hidden": (h, h), "value_out": (1, h),
    }  # fmt: skip
    for name, shape in shapes.items():
        m = getattr(net, name)
        if type(m) is not nn.Linear or tuple(m.weight.shape) != shape or m.bias is None:
            raise TypeError(
                f"the compiled decision kernel needs net.{name} = Linear(in={shape[1]}, "
                f"out={shape[0]}); got {m}"
            )
    f = lambda t: t.detach().numpy().astype(np.float64)  # noqa: E731
    return (
        f(net.scal.weight), f(net.scal.bias),
        f(net.adv_hidden.weight), f(net.adv_hidden.bias),
        f(net.adv_out.weight)[0], float(net.adv_out.bias.detach()[0]),
        f(net.value_hidden.weight), f(net.value_hidden.bias),
        f(net.value_out.weight)[0], float(net.value_out.bias.detach()[0]),
    )  # fmt: skip


def encoder_weights(net: KeyframeQNet) -> tuple:
    """The encoder's weights as float64 arrays laid out for :func:`_encode_clip`.

    Checks that the encoder is the one the kernel mirrors: ``inp`` a kernel-1 ``Conv1d`` from
    C + 1 to H channels, every ``convs`` entry a kernel-3 ``Conv1d`` H -> H with padding equal to
    its dilation, ``ctx``, ``proj`` and ``glob`` ``nn.Linear`` with bias.

    Returns:
        (mean (C,), std (C,), inp W (C+1, H), b (H,), convs W (L, 3, H, H) as [layer, tap, in,
        out], b (L, H), dilations (L,) int64, ctx W (H, H) in x out, b (H,), proj W (H, 4K),
        b (4K,), glob W (H, K), b (K,)).
    Raises:
        TypeError: a layer of another type or shape (the kernel would silently compute
            something else).
    """
    h = int(net.config["hidden"])
    c = int(net.config["n_features"])
    f = lambda t: t.detach().numpy().astype(np.float64)  # noqa: E731
    inp = net.inp
    if type(inp) is not nn.Conv1d or tuple(inp.weight.shape) != (h, c + 1, 1) or inp.bias is None:
        raise TypeError(f"the compiled decision kernel needs net.inp = Conv1d({c + 1}, {h}, 1); "
                        f"got {inp}")  # fmt: skip
    for conv in net.convs:
        d = conv.dilation[0] if type(conv) is nn.Conv1d else None
        if (type(conv) is not nn.Conv1d or tuple(conv.weight.shape) != (h, h, 3)
                or conv.padding != (d,) or conv.stride != (1,) or conv.bias is None):  # fmt: skip
            raise TypeError(f"the compiled decision kernel needs Conv1d({h}, {h}, 3, padding=d, "
                            f"dilation=d) in net.convs; got {conv}")  # fmt: skip
    for name, shape in {"ctx": (h, h), "proj": (4 * h, h), "glob": (h, h)}.items():
        m = getattr(net, name)
        if type(m) is not nn.Linear or tuple(m.weight.shape) != shape or m.bias is None:
            raise TypeError(f"the compiled decision kernel needs net.{name} = "
                            f"Linear(in={shape[1]}, out={shape[0]}); got {m}")  # fmt: skip
    n_conv = len(net.convs)
    conv_w = np.zeros((n_conv, 3, h, h))
    conv_b = np.zeros((n_conv, h))
    dil = np.zeros(n_conv, np.int64)
    for i, conv in enumerate(net.convs):
        conv_w[i] = f(conv.weight).transpose(2, 1, 0)  # (out, in, tap) -> (tap, in, out)
        conv_b[i] = f(conv.bias)
        dil[i] = conv.dilation[0]
    return (
        f(net.feature_mean), f(net.feature_std),
        np.ascontiguousarray(f(inp.weight)[:, :, 0].T), f(inp.bias),
        conv_w, conv_b, dil,
        np.ascontiguousarray(f(net.ctx.weight).T), f(net.ctx.bias),
        np.ascontiguousarray(f(net.proj.weight).T), f(net.proj.bias),
        np.ascontiguousarray(f(net.glob.weight).T), f(net.glob.bias),
    )  # fmt: skip


def _weight_key(net: KeyframeQNet) -> tuple:
    """Identity and in-place version of every tensor of ``net``: changes whenever a weight is
    replaced or written (optimiser steps and ``load_state_dict`` write in place, bumping it)."""
    return tuple((id(t), t._version) for t in (*net.parameters(), *net.buffers())) + tuple(
        id(m) for m in net.children()
    )


@numba.njit(cache=True, fastmath=True)
def _encode_clip(feats, mean, std, w_in, b_in, conv_w, conv_b, dil, w_ctx, b_ctx, w_proj,
                 b_proj, w_glob, b_glob):  # fmt: skip
    """:meth:`KeyframeQNet.encode` of one clip followed by the head's ``proj`` and ``glob``
    layers, in float64.

    Args:
        feats: (N, C) float32 per-frame features; the weights as :func:`encoder_weights` lays them.
    Returns:
        proj (N, 4K): the head's per-frame projections; glob (K,): its clip-wide term.
    """
    n, c = feats.shape
    h = b_in.shape[0]
    x = np.empty((n, h))
    xin = np.empty(c + 1)
    for t in range(n):
        for i in range(c):
            xin[i] = (feats[t, i] - mean[i]) / std[i]
        xin[c] = -1.0 + 2.0 * t / (n - 1) if n > 1 else -1.0
        for o in range(h):
            x[t, o] = b_in[o]
        for i in range(c + 1):
            v = xin[i]
            for o in range(h):
                x[t, o] += w_in[i, o] * v
        for o in range(h):
            x[t, o] = max(x[t, o], 0.0)
    y = np.empty((n, h))
    for layer in range(conv_b.shape[0]):
        d = dil[layer]
        for t in range(n):
            for o in range(h):
                y[t, o] = conv_b[layer, o]
            for tap in range(3):
                s = t + (tap - 1) * d
                if s < 0 or s >= n:
                    continue
                for i in range(h):
                    v = x[s, i]
                    for o in range(h):
                        y[t, o] += conv_w[layer, tap, i, o] * v
        for t in range(n):
            for o in range(h):
                x[t, o] += max(y[t, o], 0.0)
    m = np.zeros(h)
    for t in range(n):
        for i in range(h):
            m[i] += x[t, i]
    m /= n
    ctx = b_ctx.copy()
    for i in range(h):
        for o in range(h):
            ctx[o] += w_ctx[i, o] * m[i]
    for o in range(h):
        ctx[o] = max(ctx[o], 0.0)
    # enc = x + ctx; its clip mean is m + ctx
    k4 = b_proj.shape[0]
    proj = np.empty((n, k4))
    for t in range(n):
        for o in range(k4):
            proj[t, o] = b_proj[o]
        for i in range(h):
            v = x[t, i] + ctx[i]
            for o in range(k4):
                proj[t, o] += w_proj[i, o] * v
    glob = b_glob.copy()
    for i in range(h):
        v = m[i] + ctx[i]
        for o in range(glob.shape[0]):
            glob[o] += w_glob[i, o] * v
    return proj, glob


class Policy:
    """A trained Q-network and what it was trained for.

    Attributes:
        net: the :class:`sidql.learning.qnet.KeyframeQNet` (eval mode).
        keyframes: the W it was trained on (it accepts any 3 <= W <= N).
        meta: training arguments, subject split and held-out figures stored with it.
    """

    def __init__(self, net: KeyframeQNet, keyframes, meta: dict):
        self.net, self.keyframes, self.meta = net.eval(), tuple(keyframes), meta
        self.uses_prior = net.config.get("prior", "greedy") == "rollout"

    def decide(self, features: np.ndarray, costs: np.ndarray, W: int) -> np.ndarray:
        """Greedy (masked argmax) decisions for a batch of clips, all in compiled code: per clip
        the encoder (:func:`_encode_clip`) and the head's W - 2 steps (:func:`_decide_clip`),
        the arithmetic of :meth:`KeyframeQNet.encode` and :meth:`KeyframeQNet.head` in float64.
        No torch call, so no torch threads: a decision costs one core however busy the machine.

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
            proj, glob = _encode_clip(feats[i], *enc_w)
            out[i] = _decide_clip(
                proj, glob, cost[i].astype(np.float64), W, self.uses_prior, *head_w
            )
        return out

    def _weights(self) -> tuple:
        """(encoder, head) weights for the kernels, read again whenever a tensor of the network
        was replaced or written (training changes the network between decisions)."""
        key = _weight_key(self.net)
        if getattr(self, "_weights_key", None) != key:
            self._cached_weights = (encoder_weights(self.net), head_weights(self.net))
            # the key holds ids: keep the objects alive so that no new tensor can reuse one
            self._weights_key, self._keyed = key, (*self.net.parameters(), *self.net.buffers(),
                                                   *self.net.children())  # fmt: skip
        return self._cached_weights

    def _check(self, features, costs, W):
        feats = np.ascontiguousarray(features, dtype=np.float32)
        c = self.net.config["n_features"]
        if feats.ndim != 3 or feats.shape[-1] != c:
            raise ValueError(f"features must be (B, N, {c}); got {feats.shape}")
        b, n, _ = feats.shape
        if not 2 <= W <= n:
            raise ValueError(f"W must be in [2, {n}]; got {W}")
        cost = np.ascontiguousarray(costs, dtype=np.float32)
        if cost.shape != (b, n, n):
            raise ValueError(f"costs must be ({b}, {n}, {n}); got {cost.shape}")
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
        """(W,) keyframes of a :class:`sim.motion.clip.Clip` (chart and costs in one compiled
        pass, features, :meth:`decide`)."""
        angles, rates, cost = clip_stacked_costs(clip, "hermite")
        features = stacked_features(angles, rates)
        c = int(self.net.config["n_features"])
        if features.shape[-1] != c:  # a policy trained on clips of another skeleton
            raise ModelFileError(
                self.meta.get("file"), None, f"the policy takes {c} features per frame; clips "
                f"of {angles.shape[1] // 2} bones give {features.shape[-1]}",
            )  # fmt: skip
        return self.decide(features[None], cost[None], W)[0]


@numba.njit(cache=True, fastmath=True)
def _decide_clip(proj, glob, cost, W, use_prior, ws, bs, w1, b1, w2, b2, wv1, bv1, wv2, bv2):
    """W sorted keyframes of one clip by the head of :class:`sidql.learning.qnet.KeyframeQNet`.

    The same arithmetic as the torch head, step by step, but incremental: a frame's segment
    features (and the part of the head's first layer that depends on them) are recomputed only
    when its segment was split by the last keyframe; each step then only adds the terms for
    ``remaining`` and the best reward elsewhere, and runs the small MLPs.

    Args:
        proj: (N, 4K) the head's per-frame projections of the encoder output (self, left, right,
            segment); glob: (K,) its clip-wide term; cost: (N, N) segment costs; W: keyframes;
            use_prior: add the greedy-rollout prior (:mod:`sidql.learning.rollout`) as the torch head does.
        ws, bs: the scalar-input layer (K, 11), (K,); w1, b1, w2, b2: the advantage MLP;
        wv1, bv1, wv2, bv2: the value MLP (weights as in torch, ``out x in``).
    """
    n = cost.shape[0]
    k = glob.shape[0]
    hdim = b1.shape[0]
    mask = np.zeros(n, np.bool_)
    mask[0] = True
    mask[n - 1] = True
    csum = np.zeros((n + 1, k))
    for i in range(n):
        for j in range(k):
            csum[i + 1, j] = csum[i, j] + proj[i, 3 * k + j]
    s0 = max(cost[0, n - 1], 1e-12)
    left = np.full(n, -1, np.int64)
    right = np.full(n, -1, np.int64)
    new_left = np.zeros(n, np.int64)
    new_right = np.zeros(n, np.int64)
    g1 = np.zeros(n)
    base = np.zeros((n, k))
    adv = np.zeros(n)
    prior = np.zeros(n)
    seq, length = greedy_sequences(cost, max(W - 3, 0) if use_prior else 0)
    z = np.zeros(k)
    zsum = np.zeros(k)
    for step in range(W - 2):
        rem = W - 2 - step
        last = 0
        for i in range(n):
            if mask[i]:
                last = i
            new_left[i] = last
        last = n - 1
        for i in range(n - 1, -1, -1):
            if mask[i]:
                last = i
            new_right[i] = last
        e = 0.0
        for i in range(n - 1):
            if mask[i]:
                e += cost[i, new_right[i + 1]]
        e /= s0
        if use_prior:
            prior = rollout_values_seq(cost, mask, rem, seq, length)
        # segment features of frames whose segment changed
        for a in range(n):
            if mask[a] or (new_left[a] == left[a] and new_right[a] == right[a]):
                continue
            l = new_left[a]
            r = new_right[a]
            left[a] = l
            right[a] = r
            c_lr = cost[l, r]
            c_la = cost[l, a]
            c_ar = cost[a, r]
            g1[a] = (c_lr - c_la - c_ar) / s0
            g2l = 0.0
            for m in range(l + 1, a):
                g2l = max(g2l, c_la - cost[l, m] - cost[m, a])
            g2r = 0.0
            for m in range(a + 1, r):
                g2r = max(g2r, c_ar - cost[a, m] - cost[m, r])
            s_0 = (a - l) / n
            s_1 = (r - a) / n
            s_2 = (r - l) / n
            inv = 1.0 / (r - l + 1)
            for j in range(k):
                base[a, j] = (
                    proj[a, j] + proj[l, k + j] + proj[r, 2 * k + j]
                    + (csum[r + 1, j] - csum[l, j]) * inv + glob[j] + bs[j]
                    + ws[j, 0] * s_0 + ws[j, 1] * s_1 + ws[j, 2] * s_2 + ws[j, 4] * g1[a]
                    + ws[j, 5] * g2l / s0 + ws[j, 6] * g2r / s0 + ws[j, 7] * c_lr / s0
                    + ws[j, 8] * c_la / s0 + ws[j, 9] * c_ar / s0
                )  # fmt: skip
        # best reward per segment, and the two best segments
        top1 = -np.inf
        top2 = -np.inf
        for i in range(n):  # segment starts are keyframes; scan each segment's free frames
            if not mask[i] or i == n - 1:
                continue
            best = -np.inf
            for a in range(i + 1, new_right[i + 1]):
                best = max(best, g1[a])
            if best > top1:
                top2 = top1
                top1 = best
            elif best > top2:
                top2 = best
        n_free = 0
        adv_sum = 0.0
        zsum[:] = 0.0
        for a in range(n):
            if mask[a]:
                continue
            n_free += 1
            own = -np.inf
            for m in range(left[a] + 1, right[a]):
                own = max(own, g1[m])
            other = top2 if own >= top1 else top1
            if not np.isfinite(other) or other < 0.0:
                other = 0.0
            for j in range(k):
                v = base[a, j] + ws[j, 3] * rem / n + ws[j, 10] * other
                z[j] = v if v > 0.0 else 0.0
                zsum[j] += z[j]
            out = b2
            for i in range(hdim):
                acc = b1[i]
                for j in range(k):
                    acc += w1[i, j] * z[j]
                if acc > 0.0:
                    out += w2[i] * acc
            adv[a] = out
            adv_sum += out
        value = bv2
        for i in range(hdim):
            acc = bv1[i]
            for j in range(k):
                acc += wv1[i, j] * zsum[j] / max(n_free, 1)
            if acc > 0.0:
                value += wv2[i] * acc
        adv_mean = adv_sum / max(n_free, 1)
        best_q = -np.inf
        best_a = -1
        for a in range(n):
            if mask[a]:
                continue
            q = g1[a]
            if rem > 1:
                logit = value + adv[a] - adv_mean
                e_after = e - g1[a]
                if use_prior:
                    share = min(max(prior[a] / max(e_after, 1e-9), 1e-4), 1.0 - 1e-4)
                    logit += np.log(share / (1.0 - share))
                q += e_after / (1.0 + np.exp(-logit))
            if q > best_q:
                best_q = q
                best_a = a
        mask[best_a] = True
    return np.flatnonzero(mask)


def load_policy(path: str | os.PathLike | None = None) -> Policy:
    """Load a policy file written by :func:`sidql.learning.dqn.save_policy` (default:
    ``$SIDQL_POLICY`` or the shipped one), tensors and plain values only.

    Raises:
        FileNotFoundError: no file there (the message says how to train one).
        ModelFileError: the file is refused (holds other objects, another format or version, or
            weights that do not fit the network it declares); one line naming the file.
    """
    path = Path(path or os.environ.get("SIDQL_POLICY") or DEFAULT_POLICY)
    if not path.exists():
        raise FileNotFoundError(f"no policy at {path}; train one with `sidql train`")
    return _load(str(path.resolve()), path.stat().st_mtime_ns)


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
        ValueError: a value out of its limits or of the wrong type, or weights that do not fit.
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
def _load(path: str, _mtime: int) -> Policy:
    payload = load_payload(path, POLICY_FORMAT, MAX_POLICY_BYTES)
    try:
        cfg = payload["config"]
        args = check_config(cfg, payload["state_dict"])  # before allocating any weight
        net = KeyframeQNet(*args[:3], prior=args[3])
        net.load_state_dict(payload["state_dict"])
        keyframes = tuple(int(w) for w in payload["keyframes"])
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ModelFileError(path, None, f"not a usable policy: {first}") from None
    meta = {k: v for k, v in payload.items() if k != "state_dict"}
    meta["file"] = path
    return Policy(net, keyframes, meta)


def dqn(clip, W: int, *, seed: int = 0) -> np.ndarray:
    """SIDQL: the trained Deep Q-Network's greedy (masked argmax) keyframes; deterministic.

    The ``dqn`` selection method (``sidql.keyframes.methods`` finds it by name, lazily)."""
    return load_policy().select(clip, W)
