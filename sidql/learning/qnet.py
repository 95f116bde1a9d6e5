"""The Q-network: one Q-value per frame of a clip, for the next keyframe to add.

Inputs per clip: the paper's per-frame features F, V (N, C), the clip's segment-cost matrix
(N, N) — a deterministic function of F and V (the Hermite segment costs of the chart the
features come from, :mod:`sidql.keyframes.segment_costs`) — the keyframe mask X (N,) and the number of keyframes still to choose.

Two parts, so that a decision of W keyframes costs one encoder pass and W - 2 cheap head passes:

- ``encode(features)``: mask-independent, sees the whole clip. Per-frame inputs (standardised with
  training statistics, plus the frame's position) go through a 1x1 convolution and residual
  dilated 1-D convolutions over time (dilations 1, 2, 4, 8: a 31-frame receptive field), then a
  clip-wide mean is added to every frame. Output (B, N, H).
- ``head(enc, cost, mask, remaining)``: for every frame a, the segment (l, r) of the current
  keyframes that contains it, and

  * ``g1(a) = (C[l, r] - C[l, a] - C[a, r]) / C[0, N-1]``: the exact reward of adding a (eq. 22);
  * ``g2(a)``: the best reward of one further keyframe inside (l, a) and inside (a, r), and the
    best reward in any other segment — a two-step look-ahead — and the normalised costs C[l, r],
    C[l, a], C[a, r];
  * the embeddings of a, l, r and the mean embedding over the segment, the positions
    (a - l) / N, (r - a) / N, (r - l) / N and remaining / N;

  and returns ``Q(s, a) = g1(a) + e_after(a) * sigmoid(V(s) + A(s, a) - mean A)``: the immediate
  reward is known exactly; what follows can remove at most the error ``e_after(a)`` left after
  adding a (normalised by C[0, N-1]), so the network predicts the *fraction* of it the remaining
  keyframes will remove (dueling: a state value plus centred advantages). This keeps the learned
  part on one scale across steps and clips. The advantage MLP's last layer starts at zero, so an
  untrained network ranks frames exactly as the paper's greedy method; TD learning then moves it
  towards the optimum. On the last step (one keyframe left) Q is the reward alone.

  With ``prior="rollout"`` the share's logit is offset by the exact share that finishing the
  episode greedily removes (:mod:`sidql.learning.rollout`, an input computed outside the network), and
  the value head also starts at zero: the untrained network is then Q^greedy (γ = 1), whose
  argmax is the rollout algorithm's improvement over greedy, and TD learning learns Q* - Q^greedy
  in logit space.

Q-values of frames that are already keyframes are set to -inf by :func:`masked_q`; the argmax over
the rest is the policy (both when acting and in the Bellman target).
"""

from __future__ import annotations

import torch
from torch import nn

from sim.errors import UnknownNameError, UsageError

#: What the learned part starts from: "greedy" (an untrained network ranks like greedy) or
#: "rollout" (it ranks by the exact value of finishing greedily, :mod:`sidql.learning.rollout`).
PRIORS = ("greedy", "rollout")

#: Number of scalar per-frame inputs of the head (see :meth:`KeyframeQNet.head`).
N_SCALARS = 11


class KeyframeQNet(nn.Module):
    """Q(s, a) for every frame a of a clip.

    Args:
        n_features: C, channels of the per-frame features.
        hidden: H, width of the per-frame embedding and of the head.
        dilations: dilations of the residual temporal convolutions (kernel 3).
    """

    def __init__(
        self, n_features: int, hidden: int = 32, dilations=(1, 2, 4, 8), prior: str = "greedy"
    ):
        super().__init__()
        if prior not in PRIORS:
            raise UnknownNameError("prior", prior, PRIORS)
        self.config = {
            "n_features": n_features, "hidden": hidden, "dilations": tuple(dilations),
            "prior": prior,
        }  # fmt: skip
        self.register_buffer("feature_mean", torch.zeros(n_features))
        self.register_buffer("feature_std", torch.ones(n_features))
        self.inp = nn.Conv1d(n_features + 1, hidden, 1)
        self.convs = nn.ModuleList(
            nn.Conv1d(hidden, hidden, 3, padding=d, dilation=d) for d in dilations
        )
        self.ctx = nn.Linear(hidden, hidden)
        k = hidden
        # first head layer, split by linearity into per-frame projections that are gathered
        self.proj = nn.Linear(hidden, 4 * k)  # self, left keyframe, right keyframe, segment mean
        self.glob = nn.Linear(hidden, k)
        self.scal = nn.Linear(N_SCALARS, k)
        # advantage MLP relu(z) -> adv_hidden -> relu -> adv_out, value MLP on the mean of relu(z)
        # over free frames: value_hidden -> relu -> value_out. Named one by one: the compiled
        # decision kernel (sidql.learning.policy) reads these modules by name.
        self.adv_hidden = nn.Linear(k, hidden)
        self.adv_out = nn.Linear(hidden, 1)
        self.value_hidden = nn.Linear(k, hidden)
        self.value_out = nn.Linear(hidden, 1)
        nn.init.zeros_(self.adv_out.weight)
        nn.init.zeros_(self.adv_out.bias)
        if prior == "rollout":  # start exactly at the prior: Q = g1 + greedy-completion value
            nn.init.zeros_(self.value_out.weight)
            nn.init.zeros_(self.value_out.bias)

    def set_normalisation(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Standardise inputs with per-channel ``mean``, ``std`` (C,) from the training clips."""
        self.feature_mean.copy_(mean)
        self.feature_std.copy_(torch.clamp(std, min=1e-6))

    def encode(self, features: torch.Tensor) -> torch.Tensor:
        """(B, N, C) features -> (B, N, H) per-frame embeddings (independent of the mask)."""
        b, n, _ = features.shape
        x = (features - self.feature_mean) / self.feature_std
        pos = torch.linspace(-1.0, 1.0, n, device=x.device).expand(b, n)[..., None]
        h = torch.relu(self.inp(torch.cat([x, pos], -1).transpose(1, 2)))  # (B, H, N)
        for conv in self.convs:
            h = h + torch.relu(conv(h))
        h = h.transpose(1, 2)  # (B, N, H)
        return h + torch.relu(self.ctx(h.mean(1, keepdim=True)))

    def head(
        self,
        enc: torch.Tensor,
        cost: torch.Tensor,
        mask: torch.Tensor,
        remaining: torch.Tensor,
        prior: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Q-values from embeddings (B, N, H), segment costs (B, N, N), keyframe mask (B, N) bool
        and keyframes still to choose (B,) -> (B, N). With ``config["prior"] == "rollout"``,
        ``prior`` (B, N) is :func:`sidql.learning.rollout.rollout_values` of the state. Entries of frames that are keyframes are meaningless (see :func:`masked_q`)."""
        b, n, _ = enc.shape
        idx = torch.arange(n, device=enc.device).expand(b, n)
        # nearest keyframe at or left of / at or right of each frame (0 and N-1 are keyframes)
        left = torch.cummax(torch.where(mask, idx, torch.zeros_like(idx)), 1).values
        right_rev = torch.where(mask, idx, torch.full_like(idx, n - 1)).flip(1)
        right = torch.cummin(right_rev, 1).values.flip(1)
        g1, g2l, g2r, c_lr, c_la, c_ar = gain_features(cost, idx, left, right)
        g_other = best_elsewhere(g1, mask, left)
        p_self, p_left, p_right, p_seg = self.proj(enc).chunk(4, -1)  # (B, N, K) each
        k = p_self.shape[-1]
        gather = lambda t, i: torch.gather(t, 1, i[..., None].expand(*i.shape, k))  # noqa: E731
        csum = torch.cat([enc.new_zeros(b, 1, k), p_seg.cumsum(1)], 1)  # (B, N+1, K)
        seg_len = right - left
        seg_mean = (gather(csum, right + 1) - gather(csum, left)) / (seg_len + 1)[..., None]
        scal = torch.stack(
            [
                (idx - left) / n, (right - idx) / n, seg_len / n, remaining[:, None] / n + 0 * idx,
                g1, g2l, g2r, c_lr, c_la, c_ar, g_other,
            ],
            -1,
        ).to(enc.dtype)  # fmt: skip
        z = (
            gather(p_self, idx) + gather(p_left, left) + gather(p_right, right) + seg_mean
            + self.glob(enc.mean(1, keepdim=True)) + self.scal(scal)
        )  # fmt: skip
        adv = self.adv_out(torch.relu(self.adv_hidden(torch.relu(z))))[..., 0]  # (B, N)
        # dueling: a state value (from the mean of z over the free frames) plus advantages centred
        # on their mean over the free frames; errors common to all actions leave the argmax alone
        free = (~mask).to(enc.dtype)
        cnt = free.sum(1, keepdim=True).clamp(min=1.0)
        z_mean = (torch.relu(z) * free[..., None]).sum(1) / cnt
        value = self.value_out(torch.relu(self.value_hidden(z_mean)))  # (B, 1)
        logit = value + adv - (adv * free).sum(1, keepdim=True) / cnt
        # the future can remove at most the error left after a: predict the fraction it removes
        e_after = current_error(cost, mask, right) - g1
        more = (remaining > 1).to(enc.dtype)[:, None]
        if self.config["prior"] == "rollout":
            if prior is None:
                raise UsageError("this network needs the rollout prior (sidql.learning.rollout)")
            share = (prior.to(enc.dtype) / e_after.clamp(min=1e-9)).clamp(1e-4, 1 - 1e-4)
            logit = logit + torch.log(share / (1 - share))
        return g1 + more * e_after * torch.sigmoid(logit)

    def forward(self, features, cost, mask, remaining, prior=None):
        """Q-values (B, N) of (B, N, C) features, (B, N, N) costs, (B, N) bool mask, (B,)
        remaining and, for a rollout-prior network, (B, N) prior."""
        return self.head(self.encode(features), cost, mask, remaining, prior)


def gain_features(cost, idx, left, right):
    """Exact reward features of adding frame ``idx`` inside segment (``left``, ``right``).

    Args:
        cost: (B, N, N) segment costs; idx, left, right: (B, K) frame indices.
    Returns:
        six (B, K) tensors, all divided by the clip's initial error C[0, N-1]:
        g1 = C[l, r] - C[l, a] - C[a, r] (the reward of adding a); g2l, g2r = the best reward
        of one more keyframe strictly inside (l, a), resp. (a, r), after a is added (0 if none);
        C[l, r]; C[l, a]; C[a, r].
    """
    b, n, _ = cost.shape
    s0 = cost[:, 0, n - 1].clamp(min=1e-12)[:, None]
    flat = cost.reshape(b, n * n)
    at = lambda i, j: torch.gather(flat, 1, i * n + j)  # noqa: E731
    c_lr, c_la, c_ar = at(left, right), at(left, idx), at(idx, right)
    g1 = c_lr - c_la - c_ar
    rows_l = torch.gather(cost, 1, left[..., None].expand(*left.shape, n))  # C[l, :]   (B, K, N)
    rows_a = torch.gather(cost, 1, idx[..., None].expand(*idx.shape, n))  # C[a, :]
    cols_a = torch.gather(cost.transpose(1, 2), 1, idx[..., None].expand(*idx.shape, n))  # C[:, a]
    cols_r = torch.gather(cost.transpose(1, 2), 1, right[..., None].expand(*right.shape, n))
    frames = torch.arange(n, device=cost.device)
    inside_l = (frames > left[..., None]) & (frames < idx[..., None])
    inside_r = (frames > idx[..., None]) & (frames < right[..., None])
    gl = c_la[..., None] - rows_l - cols_a  # adding m in (l, a): C[l,a] - C[l,m] - C[m,a]
    gr = c_ar[..., None] - rows_a - cols_r  # adding m in (a, r): C[a,r] - C[a,m] - C[m,r]
    g2l = torch.where(inside_l, gl, torch.zeros_like(gl)).amax(-1)
    g2r = torch.where(inside_r, gr, torch.zeros_like(gr)).amax(-1)
    return g1 / s0, g2l / s0, g2r / s0, c_lr / s0, c_la / s0, c_ar / s0


def best_elsewhere(g1, mask, left):
    """(B, N) for each frame, the largest reward ``g1`` of a free frame in *another* segment of
    the current keyframes (0 if there is none): what the next keyframe could gain elsewhere.

    Args: g1 (B, N) rewards; mask (B, N) bool keyframes; left (B, N) segment start of each frame.
    """
    b, n = g1.shape
    g = g1.masked_fill(mask, float("-inf"))
    seg_best = torch.full((b, n), float("-inf"), dtype=g1.dtype, device=g1.device)
    seg_best = seg_best.scatter_reduce(1, left, g, reduce="amax")  # best per segment start
    top2 = seg_best.topk(min(2, n), dim=1).values  # (B, 2)
    own = seg_best.gather(1, left)
    other = torch.where(own >= top2[:, :1], top2[:, 1:2], top2[:, :1])
    return torch.where(torch.isfinite(other), other, torch.zeros_like(other)).clamp(min=0.0)


def current_error(cost, mask, right):
    """(B, 1) error of the current keyframes, sum over segments of C[k, next k], / C[0, N-1].

    Args: cost (B, N, N); mask (B, N) bool; right (B, N) the keyframe at or right of each frame.
    """
    b, n, _ = cost.shape
    nxt = torch.cat([right[:, 1:], right[:, -1:]], 1)  # next keyframe after each keyframe
    seg = torch.gather(cost.reshape(b, n * n), 1, torch.arange(n, device=cost.device) * n + nxt)
    keep = mask.clone()
    keep[:, -1] = False
    e = torch.where(keep, seg, torch.zeros_like(seg)).sum(1, keepdim=True)
    return e / cost[:, 0, n - 1].clamp(min=1e-12)[:, None]


def masked_q(q: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Q-values with already-chosen frames (``mask`` True) set to -inf, (B, N)."""
    return q.masked_fill(mask, float("-inf"))
