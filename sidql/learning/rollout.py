"""The value of finishing an episode greedily: an exact, cheap prior for the Q-network.

For a state (keyframe mask X, r keyframes still to choose) and a free frame a, the *greedy
rollout value* is the total reward (eq. 22, normalised by the initial error) of adding a and then
r - 1 keyframes by the paper's greedy rule (each time the frame that lowers Q most). With γ = 1 it
is exactly Q^greedy(s, a), the action value of the greedy policy, so ``argmax_a`` of it is one step
of policy improvement over greedy (the classical rollout algorithm). The DQN learns Q* on top of
it (see :mod:`sidql.learning.qnet`).

Pure numba over a (N, N) segment-cost matrix, two ways with the same values: for one state,
simulate the greedy completion of every candidate with memoised best splits
(:func:`rollout_values`, used in training batches); for a whole decision, tabulate every segment's
own greedy gains once per clip (:func:`greedy_sequences`) and merge them per state
(:func:`rollout_values_seq`, used by the decision kernel).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def greedy_sequences(cost, kmax):
    """Every segment's own greedy gains: ``seq[l, r, :length[l, r]]`` are the rewards (unnormalised)
    of the first keyframes greedy adds strictly inside (l, r), in order, at most ``kmax``.

    Segments evolve independently, so greedy over several segments takes, each time, the segment
    whose own next gain is largest: ``seq(l, r) = [g(l, r)] + merge(seq(l, m), seq(m, r))`` with m
    the best split; built bottom-up over segment lengths in O(N^2 (N + kmax)).
    """
    n = cost.shape[0]
    seq = np.zeros((n, n, kmax))
    length = np.zeros((n, n), np.int64)
    for span in range(2, n):
        for l in range(0, n - span):
            r = l + span
            best = -np.inf
            m = -1
            for j in range(l + 1, r):
                g = cost[l, r] - cost[l, j] - cost[j, r]
                if g > best:
                    best = g
                    m = j
            if kmax == 0:
                continue
            seq[l, r, 0] = best
            cnt = 1
            i1 = 0
            i2 = 0
            n1 = length[l, m]
            n2 = length[m, r]
            while cnt < kmax and (i1 < n1 or i2 < n2):
                if i2 >= n2 or (i1 < n1 and seq[l, m, i1] >= seq[m, r, i2]):
                    seq[l, r, cnt] = seq[l, m, i1]
                    i1 += 1
                else:
                    seq[l, r, cnt] = seq[m, r, i2]
                    i2 += 1
                cnt += 1
            length[l, r] = cnt
    return seq, length


@numba.njit(cache=True)
def _merge(seqs, lens, count, k, out):
    """The first ``k`` values (at most) of the head-merge of ``count`` descending sequences
    ``seqs`` (rows, ``lens`` long) into ``out``; returns how many."""
    pos = np.zeros(count, np.int64)
    t = 0
    while t < k:
        best = -np.inf
        bi = -1
        for i in range(count):
            if pos[i] < lens[i] and seqs[i, pos[i]] > best:
                best = seqs[i, pos[i]]
                bi = i
        if bi < 0:
            break
        out[t] = best
        pos[bi] += 1
        t += 1
    return t


@numba.njit(cache=True)
def _pair(a, a_len, b, b_len, two, lens2):
    """Rows ``a[:a_len]`` and ``b[:b_len]`` into ``two`` (2, width) and their lengths into
    ``lens2``, for :func:`_merge` (the first row wins ties)."""
    two[0, :a_len] = a[:a_len]
    two[1, :b_len] = b[:b_len]
    lens2[0] = a_len
    lens2[1] = b_len


@numba.njit(cache=True)
def rollout_values_seq(cost, mask, rem, seq, length):
    """As :func:`rollout_values`, from the tables of :func:`greedy_sequences` (``kmax >= rem``)."""
    n = cost.shape[0]
    keys = np.flatnonzero(mask)
    nk = len(keys)
    out = np.zeros(n)
    k = rem - 1
    if k <= 0:
        return out
    s0 = max(cost[0, n - 1], 1e-12)
    kmax = seq.shape[2]
    # others[j]: the merged greedy sequence of every current segment except segment j, as the
    # merge of the segments before j with those after it: a head-merge of merges picks what the
    # merge of all picks (the next of a merge is the largest of its heads, ties to the earlier
    # segment), so two sweeps of k-long merges replace one merge of nk - 2 segments per j
    width = max(k, kmax)
    before = np.zeros((nk, width))  # before[j]: segments 0..j-1; after[j]: segments j..nk-2
    after = np.zeros((nk, width))
    before_len = np.zeros(nk, np.int64)
    after_len = np.zeros(nk, np.int64)
    two = np.zeros((2, width))
    lens2 = np.zeros(2, np.int64)
    for j in range(nk - 1):
        _pair(before[j], before_len[j], seq[keys[j], keys[j + 1]], length[keys[j], keys[j + 1]],
              two, lens2)  # fmt: skip
        before_len[j + 1] = _merge(two, lens2, 2, k, before[j + 1])
    for j in range(nk - 2, -1, -1):
        _pair(seq[keys[j], keys[j + 1]], length[keys[j], keys[j + 1]], after[j + 1],
              after_len[j + 1], two, lens2)  # fmt: skip
        after_len[j] = _merge(two, lens2, 2, k, after[j])
    others = np.zeros((nk - 1, k))
    others_len = np.zeros(nk - 1, np.int64)
    for j in range(nk - 1):
        _pair(before[j], before_len[j], after[j + 1], after_len[j + 1], two, lens2)
        others_len[j] = _merge(two, lens2, 2, k, others[j])
    for j in range(nk - 1):
        l0 = keys[j]
        r0 = keys[j + 1]
        for a in range(l0 + 1, r0):
            total = _merge3_sum(others[j], others_len[j], seq[l0, a], length[l0, a], seq[a, r0],
                                length[a, r0], k)  # fmt: skip
            out[a] = total / s0
    return out


@numba.njit(cache=True)
def _merge3_sum(s0, n0, s1, n1, s2, n2, k):
    """Sum of the first ``k`` values of the head-merge (:func:`_merge`'s picks: the largest head,
    ties to the earlier sequence) of ``s0[:n0]``, ``s1[:n1]``, ``s2[:n2]``, in the order picked,
    without copying them."""
    i0 = 0
    i1 = 0
    i2 = 0
    total = 0.0
    for _ in range(k):
        best = -np.inf
        bi = -1
        if i0 < n0 and s0[i0] > best:
            best = s0[i0]
            bi = 0
        if i1 < n1 and s1[i1] > best:
            best = s1[i1]
            bi = 1
        if i2 < n2 and s2[i2] > best:
            best = s2[i2]
            bi = 2
        if bi < 0:
            break
        total += best
        if bi == 0:
            i0 += 1
        elif bi == 1:
            i1 += 1
        else:
            i2 += 1
    return total


@numba.njit(cache=True)
def _best_split(cost, l, r, memo_g, memo_m):
    if memo_m[l, r] == -2:
        best = -np.inf
        arg = -1
        for m in range(l + 1, r):
            g = cost[l, r] - cost[l, m] - cost[m, r]
            if g > best:
                best = g
                arg = m
        memo_g[l, r] = best
        memo_m[l, r] = arg
    return memo_g[l, r], memo_m[l, r]


@numba.njit(cache=True)
def rollout_values_memo(cost, mask, rem, memo_g, memo_m):
    """As :func:`rollout_values`, with caller-owned memo tables (N, N) float64 and int64 (the
    latter filled with -2 for "not computed"), reusable across the states of one clip."""
    n = cost.shape[0]
    keys = np.flatnonzero(mask)
    nk = len(keys)
    out = np.zeros(n)
    segl = np.zeros(n + 2, np.int64)
    segr = np.zeros(n + 2, np.int64)
    sg = np.zeros(n + 2)
    sm = np.zeros(n + 2, np.int64)
    s0 = max(cost[0, n - 1], 1e-12)
    for i in range(nk - 1):
        l0 = keys[i]
        r0 = keys[i + 1]
        for a in range(l0 + 1, r0):
            ns = 0
            for j in range(nk - 1):
                if j == i:
                    segl[ns], segr[ns] = l0, a
                    segl[ns + 1], segr[ns + 1] = a, r0
                    ns += 2
                else:
                    segl[ns], segr[ns] = keys[j], keys[j + 1]
                    ns += 1
            for s in range(ns):
                sg[s], sm[s] = _best_split(cost, segl[s], segr[s], memo_g, memo_m)
            total = 0.0
            for _ in range(rem - 1):
                bs = -1
                bg = -np.inf
                for s in range(ns):
                    if sm[s] >= 0 and (sg[s] > bg or (sg[s] == bg and sm[s] < sm[bs])):
                        bg = sg[s]
                        bs = s
                if bs < 0:
                    break
                total += bg
                m, l, r = sm[bs], segl[bs], segr[bs]
                segr[bs] = m
                sg[bs], sm[bs] = _best_split(cost, l, m, memo_g, memo_m)
                segl[ns], segr[ns] = m, r
                sg[ns], sm[ns] = _best_split(cost, m, r, memo_g, memo_m)
                ns += 1
            out[a] = total / s0
    return out


@numba.njit(cache=True)
def rollout_values(cost, mask, rem):
    """Greedy-completion value of every frame.

    Args:
        cost: (N, N) float64 segment costs; mask: (N,) bool keyframes (0 and N-1 included);
        rem: keyframes still to choose *including* the one being valued (>= 1).
    Returns:
        (N,) float64: for a free frame a, the summed rewards of the ``rem - 1`` greedy keyframes
        that follow adding a, divided by C[0, N-1] (the future part of Q^greedy(s, a) with γ = 1);
        0 for keyframes.
    """
    n = cost.shape[0]
    memo_g = np.zeros((n, n))
    memo_m = np.full((n, n), -2, np.int64)
    return rollout_values_memo(cost, mask, rem, memo_g, memo_m)


@numba.njit(cache=True)
def rollout_values_batch(costs, task, masks, rems):
    """(B, N) :func:`rollout_values` for states (task index into ``costs`` (K, N, N), mask, rem)."""
    b, n = masks.shape
    out = np.zeros((b, n))
    for i in range(b):
        out[i] = rollout_values(costs[task[i]], masks[i], rems[i])
    return out
