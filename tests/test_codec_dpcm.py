"""The position coding's closed-loop kernel (sidql.codec.dpcm) against a plain-Python oracle that
visits the channels one bone at a time in index order, as the stream format describes them:
the compiled kernel visits them by depth in the tree and must give the same codes and values,
bit for bit (the shipped streams' bytes depend on it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sidql.codec.dpcm import (
    MAX_PHI_STEP,
    PARTNER_RATE,
    PARTNER_WEIGHTS,
    RDO_BAND,
    SIN_FLOOR,
    depth_order,
    dpcm,
    same_branch,
    visit_order,
)
from sidql.codec.quantise import PositionQuantiser, aim_basis, keyframe_steps
from sidql.keyframes.spherical import protocol_parent_indices


def _clamp(x, lo, hi):
    return min(max(x, lo), hi)


def oracle(values, codes, keys, scale, M, rho, encode, partners, basis, lengths, parents,
           root_rho, gap_exponent, firsts, cones):  # fmt: skip
    """The kernel written out in Python, channels root first then bone by bone (index order,
    parents first), theta before phi. Returns (codes, decoded values)."""
    mu, lo, hi = PARTNER_RATE, *PARTNER_WEIGHTS
    kstep = keyframe_steps(keys, gap_exponent)
    if encode:
        values = same_branch(values, firsts, M, np.arange(len(keys)))
    W, D = codes.shape
    codes = codes.copy()
    out = np.zeros((W, D))
    innov, kappa = np.zeros(D), np.zeros(partners.shape)
    aim = encode and basis.shape[0] == W
    err = np.zeros((M + 1, 3))
    # a bone on its parent's direction is left at its prediction, and its parent aims at the far
    # end of the chain of such bones below it
    silent = [cones[b, 0] == 0 and cones[b, 1] < 0 for b in range(M)]
    reach = list(lengths)
    for b in reversed(range(M)):
        if silent[b] and parents[b + 1] > 0:
            reach[parents[b + 1] - 1] += reach[b]

    def predict(w, d):
        if w == 0:
            return out[0, firsts[d]] if firsts[d] >= 0 else 0.0
        if w == 1:
            return out[0, d]
        slope = root_rho if d >= 2 * M else rho
        return out[w - 1, d] + slope * ratio * (out[w - 1, d] - out[w - 2, d])

    for w in range(W):
        ratio = 0.0 if w < 2 else min((keys[w] - keys[w - 1]) / (keys[w - 1] - keys[w - 2]), 2.0)
        target_phi = 0.0
        for i in range(D):
            d = 2 * M + i if i < 3 else (i - 3) // 2 + M * ((i - 3) % 2)
            pred = predict(w, d)
            if d < M and max(cones[d, 0], cones[d, 1]) >= 0:  # both angles on the cones
                pred, cone_phi = _oracle_cone(out[w], d, parents, cones[d], pred,
                                              predict(w, M + d), M)  # fmt: skip
            elif M <= d < 2 * M and max(cones[d - M, 0], cones[d - M, 1]) >= 0:
                pred = cone_phi
            temporal, norm, turn = pred, 1e-8, 0.0
            for j, pc in enumerate(partners[d]):
                if w >= 1 and pc >= 0:
                    pred += kappa[d, j] * innov[pc]
                    norm += innov[pc] * innov[pc]
            step = scale[d] * kstep[w]
            if M <= d < 2 * M:
                step = min(step / max(math.sin(out[w, d - M]), SIN_FLOOR), MAX_PHI_STEP)
            if encode:
                target = values[w, d]
                if aim and d < M:
                    p, L, g = parents[d + 1], max(reach[d], 1e-6), basis[w, d]
                    e = err[p]
                    dt = -(e[0] * g[0] + e[1] * g[1] + e[2] * g[2]) / L
                    dp = -(e[0] * g[3] + e[1] * g[4]) / (L * max(-g[2], SIN_FLOOR))
                    target += _clamp(dt, -0.5, 0.5)
                    target_phi = values[w, M + d] + _clamp(dp, -0.5, 0.5)
                elif aim and d < 2 * M:
                    target = target_phi
                if M <= d < 2 * M and max(cones[d - M, 0], cones[d - M, 1]) >= 0:
                    turn = 2 * math.pi * round((target - pred) / (2 * math.pi))
                    target -= turn
                q = (target - pred) / step
                r = math.floor(q + 0.5)
                a = abs(r)
                if a > 0 and (a & (a - 1)) == 0 and a - abs(q) > 0.5 - RDO_BAND:
                    r -= 1 if r > 0 else -1
                codes[w, d] = 0 if aim and d < 2 * M and silent[d % M] else r
            out[w, d] = pred + float(codes[w, d]) * step
            own = out[w, d] - temporal
            for j, pc in enumerate(partners[d]):
                if w >= 1 and pc >= 0:
                    k = kappa[d, j] + mu * (own - (pred - temporal)) * innov[pc] / norm
                    kappa[d, j] = _clamp(k, lo, hi)
            innov[d] = own
            if aim and d >= 2 * M:
                err[0, d - 2 * M] = out[w, d] - values[w, d]
            elif aim and d >= M:
                b = d - M
                g = basis[w, b]
                a = lengths[b] * (out[w, b] - values[w, b])
                f = -lengths[b] * g[2] * (out[w, d] + turn - values[w, d])
                p = parents[b + 1]
                err[b + 1, 0] = err[p, 0] + a * g[0] + f * g[3]
                err[b + 1, 1] = err[p, 1] + a * g[1] + f * g[4]
                err[b + 1, 2] = err[p, 2] + a * g[2]
    return codes, out


def _vec(theta, phi):
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                     math.cos(theta)])  # fmt: skip


def _oracle_cone(x, b, parents, cone, tt, pt, M):
    """(theta, phi) of bone b on its cones (alpha about its parent bone, beta about bone r), by
    rotations: one cone, the parent's direction turned by alpha towards the temporal prediction
    (Rodrigues); two, the azimuth psi on the first cone where the angle to the second is beta
    (a cos psi + b sin psi = c), on the temporal prediction's side of the axes' plane."""
    alpha, r, beta = cone[0], int(cone[1]), cone[2]
    p = parents[b + 1] - 1
    t = _vec(tt, pt)
    if r >= 0 and alpha < 0:
        p, alpha, r = r, beta, -1
    u = _vec(x[p], x[M + p])
    if r < 0:
        n = np.cross(u, t)
        if np.linalg.norm(n) < 1e-9:
            return tt, pt
        n /= np.linalg.norm(n)
        v = u * math.cos(alpha) + np.cross(n, u) * math.sin(alpha)
    else:
        a = _vec(x[r], x[M + r])
        e1 = a - u * (a @ u)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        A, B = math.sin(alpha) * (e1 @ a), math.sin(alpha) * (e2 @ a)
        C = math.cos(beta) - math.cos(alpha) * (u @ a)
        R = math.hypot(A, B)
        base, half = math.atan2(B, A), math.acos(max(-1.0, min(1.0, C / R)))
        side = np.cross(u, a) @ t
        for psi in (base + half, base - half):
            v = u * math.cos(alpha) + math.sin(alpha) * (e1 * math.cos(psi) + e2 * math.sin(psi))
            if (np.cross(u, a) @ v >= 0) == (side >= 0):
                break
    theta = math.acos(max(-1.0, min(1.0, v[2])))
    phi = math.atan2(v[1], v[0])
    return theta, phi + 2 * math.pi * round((pt - phi) / (2 * math.pi))


def _case(seed: int, parents: np.ndarray, W: int = 40, v5: bool = True):
    rng = np.random.default_rng(seed)
    M = len(parents) - 1
    keys = np.cumsum(rng.integers(1, 6, W))
    t = np.cumsum(rng.normal(0.0, 0.15, (W, 2 * M + 3)), axis=0)
    values = np.concatenate([np.pi / 2 + 1.2 * np.sin(t[:, :M]), 3.0 * t[:, M:]], axis=1)
    lengths = rng.uniform(0.05, 0.5, M)
    q = PositionQuantiser(M, lengths, parents, float(np.float32(rng.uniform(2e-4, 3e-2))), 0.5,
                          exponent=0.125, root_rho=1.0, gap_exponent=0.25 * v5,
                          partner=not v5)  # fmt: skip
    return values, keys, q


def _run(kernel, values, keys, q, encode, codes=None, aim=True):
    M = q.n_bones
    codes = np.zeros(values.shape, dtype=np.int64) if codes is None else codes.copy()
    basis = aim_basis(values, M) if aim and encode else np.zeros((0, M, 5))
    lengths, parents = q._tree()
    args = (values, codes, keys, q.scales(), M, q.rho, encode, q.partners())
    rows = np.arange(len(keys))
    quarters, firsts = int(round(4 * q.gap_exponent)), q.firsts()
    if kernel is dpcm:
        out = dpcm(*args, PARTNER_RATE, *PARTNER_WEIGHTS, basis, lengths, parents, q.root_slope,
                   quarters, firsts, rows, q.cone_array())  # fmt: skip
        return codes, out
    return oracle(*args, basis, lengths, parents, q.root_slope, q.gap_exponent, firsts,
                  q.cone_array())  # fmt: skip


CHAIN = np.array([-1, 0, 1, 2, 3])
BUSHY = np.array([-1, 0, 0, 1, 1, 2, 0, 6, 3])


@pytest.mark.parametrize("parents", [protocol_parent_indices(), CHAIN, BUSHY])
@pytest.mark.parametrize("aim", [True, False])
@pytest.mark.parametrize("v5", [True, False])
def test_kernel_matches_bone_by_bone_oracle(parents, aim, v5):
    for seed in range(3):
        values, keys, q = _case(seed, np.asarray(parents, dtype=np.int64), v5=v5)
        codes, out = _run(dpcm, values, keys, q, True, aim=aim)
        ref_codes, ref_out = _run(oracle, values, keys, q, True, aim=aim)
        assert np.abs(codes).max() > 1  # the residuals are not all trivial
        assert np.array_equal(codes, ref_codes)
        assert np.array_equal(out, ref_out)
        decoded = _run(dpcm, values, keys, q, False, codes)[1]
        assert np.array_equal(decoded, ref_out)  # the decoder rebuilds the encoder's values
        assert np.array_equal(_run(oracle, values, keys, q, False, codes)[1], ref_out)


def test_visit_order_puts_parents_first_and_groups_depths():
    parents = protocol_parent_indices()
    M = len(parents) - 1
    order = visit_order(parents, np.zeros(len(parents) - 1, bool))
    assert sorted(order) == list(range(2 * M + 3))
    assert list(order[:3]) == [2 * M, 2 * M + 1, 2 * M + 2]
    seen = set(order[:3])
    for d in order[3:]:
        b = d % M
        if d >= M:
            assert b in seen  # phi after its bone's theta
        p = parents[b + 1] - 1
        if p >= 0:
            assert p + (d >= M) * M in seen  # the parent bone's same angle before it
        seen.add(d)
    bones, starts = depth_order(parents, np.zeros(M, bool))
    levels = [sorted(bones[a:b]) for a, b in zip(starts[:-1], starts[1:], strict=True) if b > a]
    assert starts[0] == 0 and starts[-1] == M and len(levels) == 7  # the protocol: 7 deep
    assert levels[0] == [0, 4, 8]  # lhipjoint, rhipjoint, lowerback
    deferred = np.zeros(M, bool)
    deferred[4] = True  # rhipjoint after the other bones of its depth, before their children
    bones, starts = depth_order(parents, deferred)
    levels = [sorted(bones[a:b]) for a, b in zip(starts[:-1], starts[1:], strict=True) if b > a]
    assert levels[:3] == [[0, 8], [4], [1, 5, 9]]


def test_unordered_parents_fall_back_to_index_order():
    bones, starts = depth_order(np.array([-1, 2, 0]), np.zeros(2, bool))  # 1's parent after it
    assert list(bones) == [0, 1] and list(starts) == [0, 1, 2]


def test_keyframes_read_in_place_by_rows_code_as_gathered_ones():
    values, _, q = _case(7, protocol_parent_indices(), W=60)
    keys = np.array([0, 3, 4, 9, 17, 18, 30, 41, 59])
    basis = aim_basis(values, q.n_bones)
    a = q.encode_keyframes(values[keys], keys, True, basis[keys])
    b = q.encode_keyframes(values, keys, True, basis, rows=keys)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.array_equal(q.decode_keyframes(b[0], keys), b[1])
