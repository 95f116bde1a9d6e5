"""The trained policy's decisions in compiled code: the numba kernels that mirror
:class:`sidql.learning.qnet.KeyframeQNet`'s encoder (:func:`encode_clip`) and head
(:func:`decide_clip`) in float64, and the weights they read from the network's named modules
(:func:`encoder_weights`, :func:`head_weights`), which refuse a network the kernels do not mirror.
"""

from __future__ import annotations

import numba
import numpy as np
from torch import nn

from sidql.keyframes.segment_costs import _clip_stacked_chart
from sidql.keyframes.single_costs import single_cost_matrix, turn_rates
from sidql.learning.qnet import N_SCALARS, KeyframeQNet
from sidql.learning.rollout import best_splits, greedy_sequences_of, rollout_values_seq
from sidql.learning.tasks import _stacked_features
from sim.errors import ArgumentTypeError

#: The modules of :class:`KeyframeQNet` the decision kernels know: the encoder's layers (mirrored
#: in :func:`encode_clip`) and the head's linear layers (mirrored in :func:`decide_clip`). A
#: network with any other module set, or with these of another type or shape, is refused by
#: :func:`encoder_weights` / :func:`head_weights`.
ENCODER_MODULES = ("inp", "convs", "ctx")
HEAD_MODULES = ("proj", "glob", "scal", "adv_hidden", "adv_out", "value_hidden", "value_out")


def head_weights(net: KeyframeQNet) -> tuple:
    """The head's weights as float64 arrays, read from its NAMED modules, for :func:`decide_clip`.

    Checks that the network is the one the kernel mirrors: exactly the modules
    :data:`ENCODER_MODULES` + :data:`HEAD_MODULES`, the head's layers ``nn.Linear`` of the shapes
    the kernel's arithmetic assumes (K = H = ``config["hidden"]``).

    Returns:
        (scal W (K, 11), scal b (K,), adv_hidden W (H, K), b (H,), adv_out w (H,), b float,
        value_hidden W (H, K), b (H,), value_out w (H,), b float).
    Raises:
        ArgumentTypeError: a layer was added, removed, renamed or changed (the kernel would silently
            compute something else).
    """
    h = int(net.config["hidden"])
    children = {name for name, _ in net.named_children()}
    if children != set(ENCODER_MODULES + HEAD_MODULES):
        raise ArgumentTypeError(
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
            raise ArgumentTypeError(
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
    """The encoder's weights as float64 arrays laid out for :func:`encode_clip`.

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
        raise ArgumentTypeError(f"the compiled decision kernel needs net.inp = Conv1d({c + 1}, {h}, 1); "
                        f"got {inp}")  # fmt: skip
    for conv in net.convs:
        d = conv.dilation[0] if type(conv) is nn.Conv1d else None
        if (type(conv) is not nn.Conv1d or tuple(conv.weight.shape) != (h, h, 3)
                or conv.padding != (d,) or conv.stride != (1,) or conv.bias is None):  # fmt: skip
            raise ArgumentTypeError(f"the compiled decision kernel needs Conv1d({h}, {h}, 3, padding=d, "
                            f"dilation=d) in net.convs; got {conv}")  # fmt: skip
    for name, shape in {"ctx": (h, h), "proj": (4 * h, h), "glob": (h, h)}.items():
        m = getattr(net, name)
        if type(m) is not nn.Linear or tuple(m.weight.shape) != shape or m.bias is None:
            raise ArgumentTypeError(f"the compiled decision kernel needs net.{name} = "
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


@numba.njit(cache=True, fastmath=True)
def encode_clip(feats, mean, std, w_in, b_in, conv_w, conv_b, dil, w_ctx, b_ctx, w_proj,
                 b_proj, w_glob, b_glob):  # fmt: skip
    """:meth:`KeyframeQNet.encode` of one clip followed by the head's ``proj`` and ``glob``
    layers, in float64, as matrix products (BLAS through numba: one thread at these sizes);
    each temporal layer's three taps as one product of the shifted frames side by side.

    Args:
        feats: (N, C) float32 per-frame features; the weights as :func:`encoder_weights` lays them.
    Returns:
        proj (N, 4K): the head's per-frame projections; glob (K,): its clip-wide term.
    """
    n, c = feats.shape
    h = b_in.shape[0]
    xin = np.empty((n, c + 1))
    for t in range(n):
        for i in range(c):
            xin[t, i] = (feats[t, i] - mean[i]) / std[i]
        xin[t, c] = -1.0 + 2.0 * t / (n - 1) if n > 1 else -1.0
    x = np.maximum(np.dot(xin, w_in) + b_in, 0.0)
    taps = np.empty((n, 3 * h))  # [x(t - d) | x(t) | x(t + d)], zero padding outside
    for layer in range(conv_b.shape[0]):
        d = dil[layer]
        for t in range(n):
            for k in range(h):
                taps[t, k] = x[t - d, k] if t >= d else 0.0
                taps[t, h + k] = x[t, k]
                taps[t, 2 * h + k] = x[t + d, k] if t + d < n else 0.0
        y = np.dot(taps, conv_w[layer].reshape(3 * h, h))  # the three taps in one product
        for t in range(n):
            for k in range(h):
                v = y[t, k] + conv_b[layer, k]
                x[t, k] += v if v > 0.0 else 0.0
    m = x.sum(axis=0) / n
    ctx = np.maximum(np.dot(m, w_ctx) + b_ctx, 0.0)
    # enc = x + ctx; its clip mean is m + ctx
    proj = np.dot(x + ctx, w_proj) + b_proj
    glob = np.dot(m + ctx, w_glob) + b_glob
    return proj, glob


@numba.njit(cache=True)
def select_clip(positions, velocities, idx, parents, dt, sin_eps, H, W, use_prior, enc_w, head_w):
    """:meth:`sidql.learning.policy.Policy.select` in one compiled call, the same kernels in
    the same order: the chart of the points ``idx`` of (N, J, 3) ``positions`` [m] and
    ``velocities`` [m/s] (:func:`sidql.keyframes.segment_costs.clip_stacked`), its features,
    the encoder (:func:`encode_clip`), the single-precision segment costs
    (:func:`sidql.keyframes.single_costs.single_cost_matrix`, ``H`` its weight table of N) and
    the head (:func:`decide_clip`); ``enc_w``, ``head_w``: :func:`encoder_weights`,
    :func:`head_weights`. One call instead of six: a decision waits for no Python in between.
    The costs run in the processor's widest vectors (:mod:`sidql.keyframes.wide_vectors`), over
    the protocol's 48 channels as a compile-time width (the same bits; this
    kernel's disk cache does not notice a change in the kernels it calls: clear
    ``sidql/learning/__pycache__/*.nb*`` after one).

    Returns:
        ((W,) int64 keyframes, True), or (empty, False) if a point is not finite.
    """
    X, R, ok = _clip_stacked_chart(positions, velocities, idx, parents, dt, sin_eps)
    if not ok:
        return np.empty(0, np.int64), False
    proj, glob = encode_clip(_stacked_features(X, R), *enc_w)
    cost = single_cost_matrix(X, turn_rates(R), H)
    return decide_clip(proj, glob, cost, W, use_prior, *head_w), True


@numba.njit(cache=True, fastmath=True)
def decide_clip(proj, glob, cost, W, use_prior, ws, bs, w1, b1, w2, b2, wv1, bv1, wv2, bv2):
    """W sorted keyframes of one clip by the head of :class:`sidql.learning.qnet.KeyframeQNet`.

    The same arithmetic as the torch head, step by step, but incremental: a frame's segment
    features (and the part of the head's first layer that depends on them) are recomputed only
    when its segment was split by the last keyframe; each step then only adds the terms for
    ``remaining`` and the best reward elsewhere, and runs the small MLPs.

    Args:
        proj: (N, 4K) the head's per-frame projections of the encoder output (self, left, right,
            segment); glob: (K,) its clip-wide term; cost: (N, N) segment costs; W: keyframes;
            use_prior: add the greedy-rollout prior (:mod:`sidql.learning.rollout`) as the torch head does.
        ws, bs: the scalar-input layer (K, 11) (as torch holds it), (K,); w1, b1, w2, b2: the advantage MLP;
        wv1, bv1, wv2, bv2: the value MLP (weights as in torch, ``out x in``).
    """
    n = cost.shape[0]
    k = glob.shape[0]
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
    gain2, split = best_splits(cost)  # the segment features' second gains, the prior's tables
    seq, length = greedy_sequences_of(gain2, split, max(W - 3, 0) if use_prior else 0)
    zsum = np.zeros(k)
    zs = np.empty((n, k))
    rows = np.empty(n, np.int64)
    seg_best = np.zeros(n)
    w1t = np.ascontiguousarray(w1.T)
    wst = np.ascontiguousarray(ws.T)  # (11, K): rows along K
    for step in range(W - 2):
        rem = W - 2 - step
        e = _segments(mask, cost, s0, new_left, new_right)
        if use_prior:
            prior = rollout_values_seq(cost, mask, rem, seq, length)
        _segment_features(mask, cost, s0, proj, glob, csum, wst, bs, new_left, new_right, left,
                          right, g1, base, gain2)  # fmt: skip
        top1, top2 = _two_best(mask, new_right, g1, seg_best)
        adv_mean, value = _advantages(mask, left, seg_best, base, wst, rem, top1, top2, w1t, b1,
                                      w2, b2, wv1, bv1, wv2, bv2, zs, zsum, rows, adv)  # fmt: skip
        best_a = _best_action(mask, g1, adv, prior, value, adv_mean, e, rem, use_prior)
        mask[best_a] = True
    return np.flatnonzero(mask)


@numba.njit(cache=True, fastmath=True)
def _segments(mask, cost, s0, new_left, new_right):
    """Each frame's enclosing keyframes into ``new_left`` and ``new_right`` (N,); returns the
    current error ``e``: the keyframed segments' costs over ``s0``."""
    n = cost.shape[0]
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
    return e / s0


@numba.njit(cache=True, fastmath=True)
def _segment_features(mask, cost, s0, proj, glob, csum, ws, bs, new_left, new_right, left, right,
                      g1, base, gain2):  # fmt: skip
    """The segment features of the free frames whose segment changed: their reward ``g1`` (N,)
    and the part of the head's scalar layer that depends on the segment, ``base`` (N, K).
    ``gain2``: (N, N) each segment's best split gain (:func:`sidql.learning.rollout.best_splits`,
    -inf where none): the second-step gains left and right of a frame, floored at 0. ``ws``:
    the scalar layer's weights as (11, K) (input by output: rows read along K vectorise)."""
    n = cost.shape[0]
    k = glob.shape[0]
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
        g2l = max(0.0, gain2[l, a])  # max(0, C[l, a] - C[l, m] - C[m, a] over l < m < a)
        g2r = max(0.0, gain2[a, r])
        s_0 = (a - l) / n
        s_1 = (r - a) / n
        s_2 = (r - l) / n
        inv = 1.0 / (r - l + 1)
        for j in range(k):
            base[a, j] = (
                proj[a, j] + proj[l, k + j] + proj[r, 2 * k + j]
                + (csum[r + 1, j] - csum[l, j]) * inv + glob[j] + bs[j]
                + ws[0, j] * s_0 + ws[1, j] * s_1 + ws[2, j] * s_2 + ws[4, j] * g1[a]
                + ws[5, j] * g2l / s0 + ws[6, j] * g2r / s0 + ws[7, j] * c_lr / s0
                + ws[8, j] * c_la / s0 + ws[9, j] * c_ar / s0
            )  # fmt: skip


@numba.njit(cache=True, fastmath=True)
def _two_best(mask, new_right, g1, seg_best):
    """The best reward per segment into ``seg_best`` (N,), at the segment's first keyframe,
    and the two best segments' (-inf where none)."""
    n = mask.shape[0]
    top1 = -np.inf
    top2 = -np.inf
    for i in range(n):  # segment starts are keyframes; scan each segment's free frames
        if not mask[i] or i == n - 1:
            continue
        best = -np.inf
        for a in range(i + 1, new_right[i + 1]):
            best = max(best, g1[a])
        seg_best[i] = best
        if best > top1:
            top2 = top1
            top1 = best
        elif best > top2:
            top2 = best
    return top1, top2


@numba.njit(cache=True, fastmath=True)
def _advantages(mask, left, seg_best, base, ws, rem, top1, top2, w1t, b1, w2, b2, wv1, bv1,
                wv2, bv2, zs, zsum, rows, adv):  # fmt: skip
    """The advantage MLP of every free frame into ``adv`` (N,) and the value MLP over their
    mean hidden input; returns (mean advantage, value). ``seg_best``: each segment's best
    reward (:func:`_two_best`); ``ws``: the scalar layer as (11, K); ``w1t``: the advantage
    MLP's first layer as (in, out), applied to every free frame in one matrix product; ``zs``
    (N, K), ``zsum`` (K,), ``rows`` (N,): scratch."""
    n = mask.shape[0]
    k = base.shape[1]
    hdim = b1.shape[0]
    n_free = 0
    zsum[:] = 0.0
    for a in range(n):
        if mask[a]:
            continue
        own = seg_best[left[a]]
        other = top2 if own >= top1 else top1
        if not np.isfinite(other) or other < 0.0:
            other = 0.0
        for j in range(k):
            v = base[a, j] + ws[3, j] * rem / n + ws[10, j] * other
            zs[n_free, j] = v if v > 0.0 else 0.0
            zsum[j] += zs[n_free, j]
        rows[n_free] = a
        n_free += 1
    hid = np.dot(zs[:n_free], w1t)  # (free frames, H)
    adv_sum = 0.0
    for f in range(n_free):
        out = b2
        for i in range(hdim):
            h = hid[f, i] + b1[i]
            if h > 0.0:
                out += w2[i] * h
        adv[rows[f]] = out
        adv_sum += out
    value = bv2
    for i in range(hdim):
        acc = bv1[i]
        for j in range(k):
            acc += wv1[i, j] * zsum[j] / max(n_free, 1)
        if acc > 0.0:
            value += wv2[i] * acc
    return adv_sum / max(n_free, 1), value


@numba.njit(cache=True, fastmath=True)
def _best_action(mask, g1, adv, prior, value, adv_mean, e, rem, use_prior):
    """The masked argmax of the head's Q: reward plus the share of the remaining error the
    network (on the rollout prior, with ``use_prior``) expects the rest to remove."""
    n = mask.shape[0]
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
    return best_a
