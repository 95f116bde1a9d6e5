"""Closed-loop prediction and quantisation of the position coding's keyframe values (coding 2),
one compiled kernel for both directions (:class:`sidql.codec.quantise.PositionQuantiser`).

Keyframe w of channel d is predicted from the decoded keyframes before it,
``t = x[w-1] + rho * (x[w-1] - x[w-2]) * gap_w / gap_{w-1}`` (the ratio capped at 2;
``x[w-1]`` alone for w = 1, 0 for w = 0), plus ``kappa_d`` times the innovation ``x - t`` its
partner channel (``partners[d]``, decoded before it: the parent bone's same angle) had at this
keyframe (a bone tends to turn with its parent); ``kappa_d`` starts at 0 and follows the channel
by normalised least mean squares (rate ``mu``, kept in [lo, hi]). The value is sent as
``r = round((x - p) / step)`` (or one nearer 0, :data:`RDO_BAND`); the decoder rebuilds
``p + r step``. ``step`` is ``scale[d]`` for theta and root channels and
``min(scale[d] / max(sin(theta_hat), SIN_FLOOR), MAX_PHI_STEP)`` for phi, theta_hat being the
same keyframe's decoded theta of that bone, each times the keyframe's factor (:func:`steps`,
version 5). In versions 5 and 6 there is no partner term (``partners`` all -1) and a channel's
first keyframe is predicted from its parent bone's same angle (``firsts``) instead of 0. In
version 6 a bone on cones (``cones`` (M, 3): alpha, r, beta; all -1 for none) is predicted on
them at every keyframe (:func:`sidql.codec.cones.predict_cone`), and a bone with a second cone
about a bone r of its depth is visited after the others of that depth (:func:`depth_order`).

Every value a channel's prediction, step or target needs is decoded before it: its own channel
at the keyframes before, its bone's theta (for phi) and its parent bone (partner innovation, the
parent point's error) at this keyframe. So the decoded values depend only on that partial order,
not on the order the channels are visited in, and the kernel visits them by depth in the tree:
the root's three channels, then every bone one step from the root (thetas, then phis), then
every bone two steps down, and so on. The bones of one depth are independent of each other,
which lets the processor work on several at once (the chain of one keyframe is as long as the
tree is deep, not as its bone count); the stream is the same as visiting them one bone at a time.
A parent list whose parents do not precede their children (never in a stream: the reader
refuses it) is visited bone by bone in index order. The encoder's usual case (aiming, no partner
channels, parents first) runs a copy of the loop without the branches the other cases need
(:func:`_aimed`): the same operations on the same values, so the same codes, bit for bit.

Units: radians (theta, phi), metres (root, lengths, point errors).
"""

from __future__ import annotations

import numba
import numpy as np

from sidql.codec.cones import predict_cone

#: phi of a bone is quantised with a step divided by ``max(sin(theta), SIN_FLOOR)`` (its effect on
#: positions), capped at :data:`MAX_PHI_STEP` [rad] so the azimuth stays continuous near a pole.
SIN_FLOOR = 0.05
MAX_PHI_STEP = 0.5
#: the partner predictor: its adaptation rate and the range of its weights.
PARTNER_RATE = 0.5
PARTNER_WEIGHTS = (-0.5, 1.5)
#: the encoder rounds a residual whose magnitude is a power of two one step towards zero (one
#: bit-length class down, a bit or more saved) when that moves the value by at most 0.5 + this
#: many steps; 0.1 measured best against 0, 0.2 and 0.3 on the CMU trials of ``../shared``.
RDO_BAND = 0.1


@numba.njit(cache=True, nogil=True)
def depth_order(parents, deferred):
    """(M,) bones (point index - 1) by depth in the tree, (L + 1,) start of each depth in it.

    ``parents``: (M + 1,) point parent indices, -1 for the root (point 0). When a parent does not
    precede its child, every bone is its own depth, in index order. ``deferred`` (M,) bool: a
    bone predicted from another bone of its depth (a second cone, :func:`sidql.codec.cones.predict_cone`) comes
    after the other bones of its depth, in a level of its own."""
    J = parents.shape[0]
    depth = np.zeros(J, dtype=np.int64)
    ordered = parents[0] < 0
    for j in range(1, J):
        p = parents[j]
        if p < 0 or p >= j:
            ordered = False
        else:
            depth[j] = depth[p] + 2  # even: a depth in the tree; odd: its deferred bones
    if not ordered:
        return np.arange(J - 1), np.arange(J)
    for j in range(1, J):
        if deferred[j - 1]:
            depth[j] += 1
    top = depth.max()
    bones = np.argsort(depth[1:], kind="mergesort")  # stable: index order within a depth
    starts = np.searchsorted(depth[1:][bones], np.arange(1, top + 2))
    return bones, starts


@numba.njit(cache=True, nogil=True)
def visit_order(parents, deferred):
    """(2 M + 3,) channels in the order the kernel visits them: the root's three, then for each
    depth in the tree the thetas of its bones, then their phis (see the module docstring; the
    deferred bones of a depth after the others, :func:`depth_order`).

    ``parents``: (M + 1,) point parent indices, -1 for the root (point 0)."""
    J = parents.shape[0]
    M = J - 1
    bones, starts = depth_order(parents, deferred)
    order = np.empty(2 * M + 3, dtype=np.int64)
    order[:3] = 2 * M + np.arange(3)
    i = 3
    for level in range(starts.shape[0] - 1):
        for angle in range(2):
            for k in range(starts[level], starts[level + 1]):
                order[i] = bones[k] + angle * M
                i += 1
    return order


# inline="always": compiled into dpcm's loop (measured 5-10 % faster than a call per keyframe;
# the same arithmetic, so the same codes and values)
@numba.njit(cache=True, inline="always")
def _keyframe(w, values, codes, out, keys, scale, M, rho, encode, partners, mu, lo, hi, basis,
              lengths, parents, innov, kappa, err, aim, root_rho, order, target_phi,
              v, kstep, firsts, cones, cone_phi, silent, reach):  # fmt: skip
    """Keyframe w of :func:`dpcm`: channels in ``order`` (:func:`visit_order`). With ``aim``,
    ``err`` (J, 3) holds the decoded points' errors [m] to first order, and a bone's targets
    are its true angles minus its parent point's error along the bone's theta and phi
    directions (``basis[v, b]``) over its length (and sin theta, floored at SIN_FLOOR, for
    phi), each change capped at 0.5 rad."""
    D = codes.shape[1]
    P = partners.shape[1]
    ratio = 0.0
    if w >= 2:
        ratio = min((keys[w] - keys[w - 1]) / (keys[w - 1] - keys[w - 2]), 2.0)
    for i in range(D):
        d = order[i]
        pred = 0.0
        if w == 0 and firsts[d] >= 0:  # the first keyframe: the parent bone's same angle
            pred = out[0, firsts[d]]
        elif w == 1:
            pred = out[0, d]
        elif w >= 2:
            slope = root_rho if d >= 2 * M else rho
            pred = out[w - 1, d] + slope * ratio * (out[w - 1, d] - out[w - 2, d])
        pred = _on_cone(w, d, pred, out, parents, cones, cone_phi, firsts, rho, root_rho, ratio,
                        M)  # fmt: skip
        temporal = pred
        turn = 0.0  # whole turns the target of a phi on a cone moved by
        norm = 1e-8
        for j in range(P):
            pc = partners[d, j]
            if w >= 1 and pc >= 0:
                pred += kappa[d, j] * innov[pc]
                norm += innov[pc] * innov[pc]
        step = scale[d] * kstep[w]
        if M <= d < 2 * M:
            step = min(step / max(np.sin(out[w, d - M]), SIN_FLOOR), MAX_PHI_STEP)
        if encode:
            target = values[v, d]
            if aim and d < M:  # theta; phi's target comes with it
                p = parents[d + 1]
                L = max(reach[d], 1e-6)
                e0, e1, e2 = err[p, 0], err[p, 1], err[p, 2]
                g0, g1, g2 = basis[v, d, 0], basis[v, d, 1], basis[v, d, 2]
                dt = -(e0 * g0 + e1 * g1 + e2 * g2) / L
                dp = -(e0 * basis[v, d, 3] + e1 * basis[v, d, 4]) / (L * max(-g2, SIN_FLOOR))
                target += min(max(dt, -0.5), 0.5)
                target_phi[d] = values[v, M + d] + min(max(dp, -0.5), 0.5)
            elif aim and d < 2 * M:
                target = target_phi[d - M]
            if M <= d < 2 * M and max(cones[d - M, 0], cones[d - M, 1]) >= 0.0:  # its branch
                turn = 2.0 * np.pi * np.rint((target - pred) / (2.0 * np.pi))
                target -= turn
            codes[w, d] = 0 if aim and d < 2 * M and silent[d % M] else _code(target, pred, step)
        out[w, d] = pred + codes[w, d] * step
        own = out[w, d] - temporal
        for j in range(P):  # normalised least mean squares towards this keyframe's miss
            pc = partners[d, j]
            if w >= 1 and pc >= 0:
                k = kappa[d, j] + mu * (own - (pred - temporal)) * innov[pc] / norm
                kappa[d, j] = min(max(k, lo), hi)
        innov[d] = own
        if aim and d >= 2 * M:
            err[0, d - 2 * M] = out[w, d] - values[v, d]
        elif aim and d >= M:  # the bone's point: its parent's error plus its own turn
            b = d - M
            g0, g1, g2 = basis[v, b, 0], basis[v, b, 1], basis[v, b, 2]
            a = lengths[b] * (out[w, b] - values[v, b])
            f = -lengths[b] * g2 * (out[w, d] + turn - values[v, d])
            p = parents[b + 1]
            err[b + 1, 0] = err[p, 0] + a * g0 + f * basis[v, b, 3]
            err[b + 1, 1] = err[p, 1] + a * g1 + f * basis[v, b, 4]
            err[b + 1, 2] = err[p, 2] + a * g2


@numba.njit(cache=True, nogil=True)
def dpcm(values, codes, keys, scale, n_bones, rho, encode, partners, mu, lo, hi, basis, lengths,
         parents, root_rho, quarters, firsts, rows, cones):  # fmt: skip
    """Closed-loop prediction and quantisation of keyframe values (see the module docstring).

    Args:
        values: (N, 2 M + 3) values [theta | phi | root] (encode) or unused; keyframe w's are
            row ``rows[w]`` (e.g. the whole chart's, ``rows`` the keyframes).
        codes: (W, 2 M + 3) int64 residuals: filled (encode) or read.
        keys: (W,) keyframe indices [frames]; scale: (2 M + 3,) channel steps before phi's
            sin theta division; partners: (2 M + 3, P) partner channels (-1: none).
        basis: (N, M, 5) (see :func:`sidql.codec.quantise.aim_basis`, rows as ``values``;
            (0, M, 5): none). With it
            (encode only) a bone's target is not its own angles but the direction from its
            *decoded* parent point to its true point, to first order: its true angles minus
            the parent point's error along the bone's theta and phi directions over its length
            (and sin theta, floored at SIN_FLOOR, for phi), each change capped at 0.5 rad; so
            each bone corrects the error its ancestors left.
        lengths: (M,) bone lengths [m]; parents: (M + 1,) point parents (-1: root).
        quarters: 4 g, each keyframe's step times :func:`steps` (version 5; 0: none).
        firsts: (2 M + 3,) the channel whose decoded first keyframe predicts each channel's
            (version 5: the parent bone's same angle; -1: predicted 0). Encoding, each bone's
            phi is first moved by whole turns onto its parent's branch (:func:`same_branch`).
        rows: (W,) int64 row of ``values`` and ``basis`` of each keyframe.
        cones: (M, 3) per bone its cones (alpha, r, beta) (version 6; all -1: none).

    Returns the decoded (W, 2 M + 3) values.
    """
    W, D = codes.shape
    M = n_bones
    kstep = steps(keys, quarters)
    if encode and basis.shape[0] > 0 and _tree_ordered(parents) and np.all(partners < 0):
        values = same_branch(values, firsts, M, rows)
        bones, starts = depth_order(parents, cones[:, 1] >= 0.0)
        return _aimed(values, codes, keys, scale, M, rho, basis, lengths, parents, root_rho,
                      kstep, firsts, rows, bones, starts, cones)  # fmt: skip
    out = np.zeros((W, D))
    innov = np.zeros(D)
    kappa = np.zeros((D, partners.shape[1]))
    aim = encode and basis.shape[0] > 0
    err = np.zeros((M + 1, 3))
    order = visit_order(parents, cones[:, 1] >= 0.0)
    target_phi = np.zeros(M)
    cone_phi = np.zeros(M)
    silent, reach = followers(cones, parents, lengths)
    if encode:
        values = same_branch(values, firsts, M, rows)
    for w in range(W):
        _keyframe(w, values, codes, out, keys, scale, M, rho, encode, partners, mu, lo, hi,
                  basis, lengths, parents, innov, kappa, err, aim, root_rho, order,
                  target_phi, rows[w], kstep, firsts, cones, cone_phi, silent, reach)  # fmt: skip
    return out


@numba.njit(cache=True, inline="always")
def _code(target, pred, step):
    """The residual code of ``target`` predicted by ``pred`` at ``step``: rounded, one class
    down where :data:`RDO_BAND` allows (as :func:`_keyframe` codes)."""
    q = (target - pred) / step
    r = np.int64(np.floor(q + 0.5))
    a = abs(r)
    down = (a > 0) & ((a & (a - 1)) == 0) & (a - abs(q) > 0.5 - RDO_BAND)
    return r - np.int64(down) * (np.int64(r > 0) - np.int64(r < 0))


@numba.njit(cache=True, nogil=True)
def _tree_ordered(parents):
    """Whether ``parents`` (M + 1,) has the root first and every parent before its child."""
    if parents[0] >= 0:
        return False
    for j in range(1, parents.shape[0]):
        if parents[j] < 0 or parents[j] >= j:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _aimed(values, codes, keys, scale, M, rho, basis, lengths, parents, root_rho, kstep, firsts,
           rows, bones, starts, cones):  # fmt: skip
    """:func:`dpcm` encoding with aiming, without partner channels (version 5), parents before
    children (``bones``, ``starts``: :func:`depth_order`'s): :func:`_keyframe`'s operations on
    each value, without its branches. Per keyframe the temporal predictions (the keyframes
    before), the root's channels, then per depth every bone's theta, then every bone's phi and
    its point's error: one depth's bones read only their parents' errors, so each pass is a run
    of independent chains the processor overlaps (about 15 % faster than one bone at a time).
    Returns the decoded (W, 2 M + 3) values; ``codes`` filled."""
    W, D = codes.shape
    out = np.zeros((W, D))
    err = np.zeros((M + 1, 3))
    pred = np.zeros(D)
    silent, reach = followers(cones, parents, lengths)
    for w in range(W):
        v, ks = rows[w], kstep[w]
        if w >= 2:
            ratio = min((keys[w] - keys[w - 1]) / (keys[w - 1] - keys[w - 2]), 2.0)
            for d in range(D):
                slope = root_rho if d >= 2 * M else rho
                pred[d] = out[w - 1, d] + slope * ratio * (out[w - 1, d] - out[w - 2, d])
        elif w == 1:
            pred[:] = out[0]
        for d in range(2 * M, D):
            if w == 0:
                pred[d] = out[0, firsts[d]] if firsts[d] >= 0 else 0.0
            codes[w, d] = _code(values[v, d], pred[d], scale[d] * ks)
            out[w, d] = pred[d] + codes[w, d] * (scale[d] * ks)
            err[0, d - 2 * M] = out[w, d] - values[v, d]
        for level in range(starts.shape[0] - 1):
            for i in range(starts[level], starts[level + 1]):
                b = bones[i]
                if w == 0:
                    pred[b] = out[0, firsts[b]] if firsts[b] >= 0 else 0.0
                    pred[M + b] = out[0, firsts[M + b]] if firsts[M + b] >= 0 else 0.0
                p = parents[b + 1]
                if max(cones[b, 0], cones[b, 1]) >= 0.0:  # on cones about decoded directions
                    pred[b], pred[M + b] = predict_cone(out[w], p - 1, cones[b], pred[b],
                                                         pred[M + b], M)  # fmt: skip
                dt = -(err[p, 0] * basis[v, b, 0] + err[p, 1] * basis[v, b, 1]
                       + err[p, 2] * basis[v, b, 2]) / max(reach[b], 1e-6)  # fmt: skip
                target = values[v, b]
                target += min(max(dt, -0.5), 0.5)
                codes[w, b] = 0 if silent[b] else _code(target, pred[b], scale[b] * ks)
                out[w, b] = pred[b] + codes[w, b] * (scale[b] * ks)
            for i in range(starts[level], starts[level + 1]):
                b = bones[i]
                d, p = M + b, parents[b + 1]
                g0, g1, g2, g3, g4 = basis[v, b, 0], basis[v, b, 1], basis[v, b, 2], \
                    basis[v, b, 3], basis[v, b, 4]  # fmt: skip
                dp = -(err[p, 0] * g3 + err[p, 1] * g4) / (
                    max(reach[b], 1e-6) * max(-g2, SIN_FLOOR)
                )
                target_phi = values[v, d] + min(max(dp, -0.5), 0.5)
                turn = 0.0
                if max(cones[b, 0], cones[b, 1]) >= 0.0:  # the branch of the prediction
                    turn = 2.0 * np.pi * np.rint((target_phi - pred[d]) / (2.0 * np.pi))
                    target_phi -= turn
                step = min(scale[d] * ks / max(np.sin(out[w, b]), SIN_FLOOR), MAX_PHI_STEP)
                codes[w, d] = 0 if silent[b] else _code(target_phi, pred[d], step)
                out[w, d] = pred[d] + codes[w, d] * step
                a = lengths[b] * (out[w, b] - values[v, b])
                f = -lengths[b] * g2 * (out[w, d] + turn - values[v, d])
                err[b + 1, 0] = err[p, 0] + a * g0 + f * g3
                err[b + 1, 1] = err[p, 1] + a * g1 + f * g4
                err[b + 1, 2] = err[p, 2] + a * g2
    return out


@numba.njit(cache=True, nogil=True)
def followers(cones, parents, lengths):
    """((M,) bool, (M,) float64): the bones on their parent's direction (cone angle 0, no
    second bone), which the encoder leaves at their prediction (code 0: aiming them costs more
    bytes than the error it takes off), and each bone's reach [m], its length plus its chain
    of such followers': a bone aims at its followers' far end, the point its direction moves
    most (on a forearm with its wrist: the wrist point's error 0, the forearm's a third of the
    elbow's, against a half at the wrist aiming at its own end)."""
    M = lengths.shape[0]
    silent = (cones[:, 0] == 0.0) & (cones[:, 1] < 0.0)
    reach = lengths.copy()
    for j in range(M, 0, -1):  # children after their parents
        if silent[j - 1] and parents[j] > 0:
            reach[parents[j] - 1] += reach[j - 1]
    return silent, reach


@numba.njit(cache=True, inline="always")
def _on_cone(w, d, pred, out, parents, cones, cone_phi, firsts, rho, root_rho, ratio, M):
    """Channel d's prediction at keyframe w: ``pred`` (temporal), or for a bone on cones its
    theta's and phi's (:func:`sidql.codec.cones.predict_cone`, phi's kept in ``cone_phi``)."""
    if d < M and max(cones[d, 0], cones[d, 1]) >= 0.0:
        pt = _temporal(w, M + d, out, firsts, rho, root_rho, ratio, M)
        pred, cone_phi[d] = predict_cone(out[w], parents[d + 1] - 1, cones[d], pred, pt, M)
    elif M <= d < 2 * M and max(cones[d - M, 0], cones[d - M, 1]) >= 0.0:
        pred = cone_phi[d - M]
    return pred


@numba.njit(cache=True, inline="always")
def _temporal(w, d, out, firsts, rho, root_rho, ratio, M):
    """Channel d's prediction at keyframe w from the keyframes before (as :func:`_keyframe`)."""
    if w == 0:
        return out[0, firsts[d]] if firsts[d] >= 0 else 0.0
    if w == 1:
        return out[0, d]
    slope = root_rho if d >= 2 * M else rho
    return out[w - 1, d] + slope * ratio * (out[w - 1, d] - out[w - 2, d])


@numba.njit(cache=True, nogil=True)
def steps(keys, quarters):
    """(W,) each keyframe's step factor ``(mean_w / w_w)^g`` with g = quarters / 4
    (:func:`sidql.codec.quantise.keyframe_steps`); ``keys``: (W,) int64 keyframes."""
    W = keys.shape[0]
    out = np.ones(W)
    if quarters == 0 or W < 2:
        return out
    frames = 2.0 * (keys[W - 1] - keys[0] + 1)
    for w in range(W):
        both = (keys[w] - keys[w - 1] if w > 0 else 1) + (keys[w + 1] - keys[w] if w < W - 1 else 1)
        ratio = frames / (W * np.float64(both))  # mean_w / w_w; 2 w_w = both, integers
        root = np.sqrt(ratio)
        if quarters == 1:
            out[w] = np.sqrt(root)
        elif quarters == 2:
            out[w] = root
        elif quarters == 3:
            out[w] = root * np.sqrt(root)
        else:
            out[w] = ratio
    return out


@numba.njit(cache=True, nogil=True)
def same_branch(values, firsts, M, rows):
    """(N, D) ``values``, each bone's phi moved by whole turns so that its first keyframe (row
    ``rows[0]``) lies within pi of its parent's (``firsts``; parents before children): the
    points do not move and the first keyframe's residual, predicted from the parent's phi,
    stays small. ``values`` itself when nothing moves."""
    if rows.shape[0] == 0:
        return values
    first = values[rows[0]].copy()
    turn = np.zeros(M)
    for b in range(M):
        pc = firsts[M + b]
        if pc >= 0:
            turn[b] = 2.0 * np.pi * np.rint((first[pc] - first[M + b]) / (2.0 * np.pi))
            first[M + b] += turn[b]
    if not np.any(turn != 0.0):
        return values
    out = values.copy()
    for n in range(values.shape[0]):
        for b in range(M):
            out[n, M + b] += turn[b]
    return out
