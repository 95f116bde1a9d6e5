"""The Hermite segment-cost matrix in single precision, for a caller that rounds the costs to
float32 anyway (the learned policy's decisions, :meth:`sidql.learning.policy.Policy.decide`).

The same sum as :mod:`sidql.keyframes.segment_costs`::

    C[i, j] = sum over frames i < n < j, channels d, of |wrap(x_i - x_n + h01 (x_j - x_i) + h10 r_i + h11 r_j)|

computed in turns (angles over 2 pi, so that the wrap is the distance to the nearest integer) and
in float32, eight channels a vector instruction (sixteen with AVX-512; twice float64's), four
frames a pass over the channels. The angle differences ``x_i - x_n`` are formed in float64 before they are rounded (per
segment start i, into an (N, D) float32 scratch that stays in the first-level cache), so a short
segment's small errors keep float32's relative precision (about 1e-7 of each term) rather than an
absolute 1e-7 rad from rounding the angles themselves. Each channel sums its terms over the
segment's frames in float32; the channels' sums are added and turned back into radians at the
end. The result is not the float64 matrix to the last bit: at most about 1.3e-6 of an entry on
real clips (tests/test_decision_oracle.py checks 2e-6, and that the policy's decisions on these
costs are those it takes on the float64 matrix; benchmarks/bench_dqn.py checks the decisions on
every clip and keyframe count).
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from sidql.keyframes.segment_costs import hermite_basis
from sidql.keyframes.wide_vectors import wide_vectors

#: The channel count is padded to a multiple of this (zero channels add |wrap(0)| = 0): whole
#: vectors, no scalar remainder loop.
LANES = 8

#: The arithmetic of :func:`single_cost_matrix`: fastmath but for "reassoc" (which would reorder
#: its sums as the vector width suits; the sums it needs reordered are written per channel).
_CONTRACT = {"contract", "nsz", "arcp", "afn"}

_TURN = 1.0 / (2.0 * np.pi)


@numba.njit(cache=True)
def turn_rates(R):
    """(N, Dp) float32 rates [turns/frame] from (N, D) float64 ``R`` [rad/frame], divided by
    2 pi in float64 before rounding, D padded with zeros to Dp, a multiple of :data:`LANES`."""
    N, D = R.shape
    R32 = np.zeros((N, (D + LANES - 1) // LANES * LANES), np.float32)
    for i in range(N):
        for d in range(D):
            R32[i, d] = R[i, d] * _TURN
    return R32


@numba.njit(cache=True)
def weight_table(N):
    """(N, N, 3) float32: row [L, t] the weights (h01, h10 L, h11 L) of the frame t after a
    segment's start, in a segment of L frames' span (0 < t < L < N)."""
    H = np.zeros((N, N, 3), np.float32)
    for L in range(2, N):
        for t in range(1, L):
            _, h01, h10, h11 = hermite_basis(t / L)
            H[L, t, 0] = h01
            H[L, t, 1] = h10 * L
            H[L, t, 2] = h11 * L
    return H


@numba.njit(cache=True, inline="always")
def _weights(H, n, i, L):
    """The weights of frame n in segment [i, i + L] from :func:`weight_table`'s ``H``."""
    return H[L, n - i, 0], H[L, n - i, 1], H[L, n - i, 2]


@numba.njit(cache=True, fastmath=_CONTRACT, inline="always")
def _turn_distance(v):
    """|wrap(v)| in turns: the distance of float32 ``v`` [turns] to the nearest integer (one
    rounding instruction, ``rint``: ties to even, the numbers that adding and subtracting
    1.5 * 2^23 gave, which this kernel did before, for every |v| < 2^22; about 0.93x the
    time: two of the four additions per term fewer)."""
    return abs(v - np.rint(v))


#: The padded channel count of the protocol's chart (22 bones: 44 angle channels): the one
#: :func:`single_cost_matrix` compiles with a constant width, whole vectors and no loop control.
PROTOCOL_LANES = 48


@numba.njit(cache=True, fastmath=_CONTRACT)
def single_cost_matrix(X, R, H):
    """(N, N) Hermite segment costs [rad], float32 values held in float64, from (N, D) float64
    angles X [rad], :func:`turn_rates` R and :func:`weight_table` H of N. Entries with
    j < i + 2 are 0.

    Per segment start i, the differences ``E[n] = (x_i - x_n) / 2 pi`` (n > i) are formed in
    float64 and rounded into one (N, Dp) float32 scratch (pad channels 0); the curve's error at
    frame n of segment (i, j) is then ``E[n] - h01 E[j] + h10 r_i + h11 r_j`` [turns]. Four
    frames share one pass over the channels; each channel's sum over the frames is kept in
    ``acc`` (Dp,) (elementwise, so the passes vectorise without reordering any sum), in the
    widest vectors the processor has (:mod:`sidql.keyframes.wide_vectors`: the same bits).
    The protocol's width (Dp = :data:`PROTOCOL_LANES`) is passed as a constant: the compiler
    then unrolls each pass into whole vectors (about 0.8x the time; the same operations in the
    same order, so the same bits)."""
    wide_vectors()
    if R.shape[1] == PROTOCOL_LANES:
        return _cost_passes(X, R, H, PROTOCOL_LANES)
    return _cost_passes(X, R, H, R.shape[1])


@numba.njit(cache=True, fastmath=_CONTRACT, inline="always")
def _cost_passes(X, R, H, Dp):
    """The loops of :func:`single_cost_matrix` over ``Dp`` (a multiple of :data:`LANES`)
    channels; inlined, so that a constant ``Dp`` reaches the compiler as one."""
    N, D = X.shape
    C = np.zeros((N, N))
    E = np.zeros((N, Dp), np.float32)
    acc = np.empty(Dp, np.float32)
    for i in range(N):
        for n in range(i + 1, N):
            for d in range(D):
                E[n, d] = (X[i, d] - X[n, d]) * _TURN
        for j in range(i + 2, N):
            L = j - i
            acc[:] = 0.0
            n = i + 1
            while n + 4 <= j:
                a0, b0, c0 = _weights(H, n, i, L)
                a1, b1, c1 = _weights(H, n + 1, i, L)
                a2, b2, c2 = _weights(H, n + 2, i, L)
                a3, b3, c3 = _weights(H, n + 3, i, L)
                for d in range(Dp):
                    e, ri, rj = E[j, d], R[i, d], R[j, d]
                    acc[d] += (_turn_distance(E[n, d] - a0 * e + b0 * ri + c0 * rj)
                               + _turn_distance(E[n + 1, d] - a1 * e + b1 * ri + c1 * rj)) + (
                               _turn_distance(E[n + 2, d] - a2 * e + b2 * ri + c2 * rj)
                               + _turn_distance(E[n + 3, d] - a3 * e + b3 * ri + c3 * rj))  # fmt: skip
                n += 4
            while n < j:
                a0, b0, c0 = _weights(H, n, i, L)
                for d in range(Dp):
                    acc[d] += _turn_distance(E[n, d] - a0 * E[j, d] + b0 * R[i, d] + c0 * R[j, d])
                n += 1
            C[i, j] = np.float32(_lanes_sum(acc) * (2.0 * np.pi))  # what the policy reads
    return C


@numba.njit(cache=True, fastmath=_CONTRACT, inline="always")
def _lanes_sum(acc):
    """The sum of ``acc`` (Dp,), Dp a multiple of :data:`LANES`: the blocks of LANES added
    elementwise into the first, then its lanes pairwise."""
    for b in range(LANES, acc.shape[0], LANES):
        for q in range(LANES):
            acc[q] += acc[b + q]
    return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))


def single_costs(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(N, N) Hermite segment costs [rad] of (N, D) angles X [rad] and rates times dt R
    [rad/frame] (:func:`sidql.keyframes.segment_costs.stacked`'s layout), computed in single
    precision (see the module docstring) and rounded to float32, held in a float64 array (what
    :meth:`sidql.learning.policy.Policy.decide` makes of any costs it is given)."""
    X = np.ascontiguousarray(X, np.float64)
    R32 = turn_rates(np.ascontiguousarray(R, np.float64))
    return single_cost_matrix(X, R32, weights_of(len(X)))


@lru_cache(maxsize=8)
def weights_of(N: int) -> np.ndarray:
    """:func:`weight_table` of N, made once per clip length (read only)."""
    H = weight_table(N)
    H.flags.writeable = False
    return H
