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
    of the first keyframes greedy adds strictly inside (l, r), in order, at most ``kmax``
    (``seq`` is (N, N, kmax + 1): -inf follows the last gain).

    Segments evolve independently, so greedy over several segments takes, each time, the segment
    whose own next gain is largest: ``seq(l, r) = [g(l, r)] + merge(seq(l, m), seq(m, r))`` with m
    the best split; built bottom-up over segment lengths in O(N^2 (N + kmax)).
    """
    if kmax == 0:
        n = cost.shape[0]
        return np.full((n, n, 1), -np.inf), np.zeros((n, n), np.int64)
    G, M = best_splits(cost)
    return greedy_sequences_of(G, M, kmax)


@numba.njit(cache=True)
def greedy_sequences_of(G, M, kmax):
    """:func:`greedy_sequences` from the segments' best splits ``(G, M)`` of
    :func:`best_splits` (a caller that also needs them computes them once)."""
    n = G.shape[0]
    seq = np.empty((n, n, kmax + 1))  # one more: -inf after the last gain, so merges need no
    seq[:, :, 0] = -np.inf  # test of which run is exhausted (gains are finite)
    length = np.zeros((n, n), np.int64)
    if kmax == 0:
        return seq, length
    for span in range(2, n):
        for l in range(0, n - span):
            r = l + span
            best, m = G[l, r], M[l, r]
            out = seq[l, r]
            a = seq[l, m]
            b = seq[m, r]
            out[0] = best
            i1 = 0
            i2 = 0
            count = 1 + min(kmax - 1, length[l, m] + length[m, r])
            for cnt in range(1, count):  # branch-free: a wins ties, -inf ends a run
                va = a[i1]
                vb = b[i2]
                take_a = va >= vb
                out[cnt] = va if take_a else vb
                i1 += take_a
                i2 += 1 - take_a
            out[count] = -np.inf
            length[l, r] = count
    return seq, length


@numba.njit(cache=True)
def best_splits(cost):
    """(G, M) (N, N): ``G[l, r]`` the largest gain ``C[l, r] - C[l, j] - C[j, r]`` over
    l < j < r and ``M[l, r]`` the first j reaching it (-inf and -1 where r < l + 2 or no gain
    is finite).

    The splits j run in the outer loop, in increasing order, and the segment ends r in the
    inner one, along rows l and j of C: a gain replaces ``G[l, r]`` only if strictly larger, so
    the first j wins a tie, as in a scan over j per segment; the same arithmetic, written as
    selects on slices indexed from 0 so that the inner loop vectorises."""
    n = cost.shape[0]
    G = np.full((n, n), -np.inf)
    M = np.full((n, n), -1, np.int64)
    for l in range(n):
        for j in range(l + 1, n - 1):
            c_lj = cost[l, j]
            g_l, m_l = G[l, j + 1 :], M[l, j + 1 :]
            c_l, c_j = cost[l, j + 1 :], cost[j, j + 1 :]
            for t in range(n - j - 1):
                g = c_l[t] - c_lj - c_j[t]
                better = g > g_l[t]
                g_l[t] = g if better else g_l[t]
                m_l[t] = j if better else m_l[t]
    return G, M


@numba.njit(cache=True)
def _merge2(a, n1, b, n2, k, out):
    """The first ``k`` values (at most) of the head-merge of the descending sequences ``a[:n1]``
    and ``b[:n2]`` (the largest head each time, ties to ``a``) into ``out``, which must not be
    either of them; returns how many."""
    i1 = 0
    i2 = 0
    t = 0
    while t < k:
        best = -np.inf
        bi = -1
        if i1 < n1 and a[i1] > best:
            best = a[i1]
            bi = 0
        if i2 < n2 and b[i2] > best:
            best = b[i2]
            bi = 1
        if bi < 0:
            break
        out[t] = best
        if bi == 0:
            i1 += 1
        else:
            i2 += 1
        t += 1
    return t


@numba.njit(cache=True)
def rollout_values_seq(cost, mask, rem, seq, length):
    """As :func:`rollout_values`, from the tables of :func:`greedy_sequences` (``kmax >= rem``;
    its runs end with -inf)."""
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
    for j in range(nk - 1):
        l0, r0 = keys[j], keys[j + 1]
        before_len[j + 1] = _merge2(before[j], before_len[j], seq[l0, r0], length[l0, r0], k,
                                    before[j + 1])  # fmt: skip
    for j in range(nk - 2, -1, -1):
        l0, r0 = keys[j], keys[j + 1]
        after_len[j] = _merge2(seq[l0, r0], length[l0, r0], after[j + 1], after_len[j + 1], k,
                               after[j])  # fmt: skip
    others = np.empty((nk - 1, k + 1))  # each run ended by -inf, as greedy_sequences' are
    for j in range(nk - 1):
        used = _merge2(before[j], before_len[j], after[j + 1], after_len[j + 1], k, others[j])
        others[j, used] = -np.inf
    for j in range(nk - 1):
        l0 = keys[j]
        r0 = keys[j + 1]
        for a in range(l0 + 1, r0):
            out[a] = _merge3_sum(others[j], seq[l0, a], seq[a, r0], k) / s0
    return out


@numba.njit(cache=True)
def _merge3_sum(s0, s1, s2, k):
    """Sum of the first ``k`` values of the head-merge (the largest head each time, ties to the
    earlier sequence) of three descending runs, each ended by -inf (fewer when all three end),
    in the order picked, without copying them; branch-free picks."""
    i0 = 0
    i1 = 0
    i2 = 0
    total = 0.0
    for _ in range(k):
        v0 = s0[i0]
        v1 = s1[i1]
        v2 = s2[i2]
        take0 = v0 >= v1 and v0 >= v2
        take1 = not take0 and v1 >= v2
        best = v0 if take0 else (v1 if take1 else v2)
        if best == -np.inf:
            break
        total += best
        i0 += take0
        i1 += take1
        i2 += not (take0 or take1)
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
