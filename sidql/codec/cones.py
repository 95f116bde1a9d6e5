"""Bones held at a fixed angle to bones decoded before them (the position coding, version 6).

Many skeletons tie some bones' directions together: in the CMU skeletons a wrist bone lies
along its forearm (angle 0), a clavicle keeps its angle to the thorax, and the two clavicles and
the two hip joints keep theirs to each other (rigid parts of the torso and the pelvis). The
encoder finds such *cones* in a stream's frames (:func:`rigid_cones`: an angle that varies by
less than :data:`CONE_TOLERANCE` over every frame) and sends them (:func:`cone_bytes`); encoder
and decoder then predict such a bone at every keyframe not from its own past alone but on its
cones about the directions already decoded at that keyframe (:func:`predict_cone`): a bone on
one cone keeps only the azimuth of its temporal prediction about the cone's axis, a bone on two
is fixed up to a mirror choice (the side of its temporal prediction), and a bone at angle 0 is
its parent's direction. The residual is then little more than the aiming correction.

A cone is (alpha, r, beta): the angle alpha [rad] to the bone's parent bone (-1: none; a child
of the root has no parent bone) and, where r >= 0, the angle beta to bone r, a bone of the same
depth in the tree that has no second cone itself, visited before it (:func:`sidql.codec.dpcm.
depth_order`). Angles are multiples of :data:`CONE_UNIT`.

Units: radians; directions ``(sin theta cos phi, sin theta sin phi, cos theta)`` (CMU axes).
"""

from __future__ import annotations

import struct

import numba
import numpy as np

from sim.errors import MotionDataError

#: a bone whose angle to another varies by less than this over every frame [rad] is on a cone
CONE_TOLERANCE = 1e-4
#: the grid of the cone angles: uint16 codes 0..65534 (65535: none)
CONE_UNIT = np.pi / 65534.0
_NONE16, _NONE8 = 0xFFFF, 0xFF
#: two cone axes closer to parallel than this |cosine| over the frames do not fix a direction
_PARALLEL = 0.99


def depths(parents) -> np.ndarray:
    """(M,) each bone's depth in the tree (the root's children: 1); parents before children."""
    p = np.asarray(parents, dtype=np.int64)
    depth = np.zeros(len(p), dtype=np.int64)
    for j in range(1, len(p)):
        depth[j] = depth[p[j]] + 1
    return depth[1:]


def rigid_cones(values: np.ndarray, n_bones: int, parents) -> tuple | None:
    """The cones of a stream: (M,) per bone ``(alpha, r, beta)`` or None (see the module
    docstring), its angles on the grid, from the chart ``values`` (N, 2 M + 3) of every frame
    [theta | phi | root]; None when no bone has one."""
    M = n_bones
    depth = depths(parents)
    th, ph = values[:, :M], values[:, M : 2 * M]
    u = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)

    def rigid(b, p):  # the angle on the grid, or None
        a = np.arccos(np.clip(np.einsum("nk,nk->n", u[:, b], u[:, p]), -1.0, 1.0))
        if a.max() - a.min() > CONE_TOLERANCE:
            return None
        return float(np.rint(a.mean() / CONE_UNIT) * CONE_UNIT)

    out: list = [None] * M
    for b in range(M):
        p = int(parents[b + 1]) - 1
        alpha = rigid(b, p) if p >= 0 else None
        if alpha is not None:
            out[b] = (alpha, -1, 0.0)
        if alpha == 0.0:  # its parent's direction: nothing to add
            continue
        for r in range(b):  # a second cone: a bone before it at its depth, not deferred
            if depth[r] != depth[b] or (out[r] is not None and out[r][1] >= 0):
                continue
            beta = rigid(b, r)
            para = np.abs(np.einsum("nk,nk->n", u[:, p], u[:, r])).max() if p >= 0 else 0.0
            if beta is not None and para < _PARALLEL:
                out[b] = (-1.0 if alpha is None else alpha, r, beta)
                break
    return tuple(out) if any(c is not None for c in out) else None


def cone_array(cones: tuple | None, n_bones: int) -> np.ndarray:
    """(M, 3) float64 per bone (alpha, r, beta), all -1 for a bone without a cone."""
    out = np.full((n_bones, 3), -1.0)
    for b, c in enumerate(cones or ()):
        if c is not None:
            out[b] = c
    return out


def cone_bytes(cones: tuple | None) -> bytes:
    """Version 6's cone section: K (uint8), then per bone on a cone, in bone order: its index
    (uint8), r (uint8, 255: none), alpha (uint16 in :data:`CONE_UNIT`, 65535: none), and where
    r is sent beta (uint16)."""
    entries = [(b, c) for b, c in enumerate(cones or ()) if c is not None]
    out = bytes([len(entries)])
    for b, (alpha, r, beta) in entries:
        a = _NONE16 if alpha < 0 else int(round(alpha / CONE_UNIT))
        out += struct.pack("<BBH", b, _NONE8 if r < 0 else int(r), a)
        if r >= 0:
            out += struct.pack("<H", int(round(beta / CONE_UNIT)))
    return out


def read_cones(take, where: str, n_bones: int, parents) -> tuple | None:
    """The cones of a version-6 stream (``take(n, what)``: the next n bytes); a section that
    breaks the rules (bones in increasing order; alpha only for a bone with a parent bone; r a
    bone of the same depth without a second cone, or none, with alpha or r given; angles on the
    grid) is refused."""
    M = n_bones
    (K,) = take(1, "cone count")
    depth = depths(parents)
    out: list = [None] * M
    last = -1
    for _ in range(K):
        b, r, a = struct.unpack("<BBH", take(4, "cone"))
        beta = struct.unpack("<H", take(2, "cone"))[0] if r != _NONE8 else 0
        ok = last < b < M and a <= _NONE16 and beta < _NONE16
        ok = ok and (a == _NONE16 or parents[b + 1] > 0) and (a != _NONE16 or r != _NONE8)
        if ok and r != _NONE8:
            ok = r < M and r != b and depth[r] == depth[b] and (out[r] is None or out[r][1] < 0)
        if not ok:
            raise MotionDataError(where, None, f"bad cone of bone {b}: {r}, {a}, {beta}")
        out[b] = (
            -1.0 if a == _NONE16 else a * CONE_UNIT,
            -1 if r == _NONE8 else int(r),
            beta * CONE_UNIT,
        )
        last = b
    for b, c in enumerate(out):  # a second cone's bone read before it may not be deferred
        if c is not None and c[1] >= 0 and out[c[1]] is not None and out[c[1]][1] >= 0:
            raise MotionDataError(where, None, f"bad cone of bone {b}: its bone {c[1]} is deferred")
    return tuple(out) if K else None


@numba.njit(cache=True, inline="always")
def predict_cone(x, p, cone, tt, pt, M):
    """(theta, phi) predicted for a bone with ``cone`` = (alpha, r, beta): at angle alpha from
    its parent bone p's decoded direction and (r >= 0) beta from bone r's, nearest the temporal
    prediction (tt, pt); ``x`` (2 M + 3,) this keyframe's decoded values so far."""
    r = np.int64(cone[1])
    if r < 0:
        return _cone(x[p], x[M + p], tt, pt, cone[0])
    if cone[0] < 0.0:  # no parent bone's cone: about bone r alone
        return _cone(x[r], x[M + r], tt, pt, cone[2])
    return _two_cones(x[p], x[M + p], cone[0], x[r], x[M + r], cone[2], tt, pt)


@numba.njit(cache=True, inline="always")
def _unit(t, p):
    s = np.sin(t)
    return s * np.cos(p), s * np.sin(p), np.cos(t)


@numba.njit(cache=True, inline="always")
def _angles(x, y, z, pt):
    """(theta, phi) of the unit vector (x, y, z), phi on the branch nearest pt."""
    theta = np.arccos(min(max(z, -1.0), 1.0))
    phi = np.arctan2(y, x)
    return theta, phi + 2.0 * np.pi * np.rint((pt - phi) / (2.0 * np.pi))


@numba.njit(cache=True, inline="always")
def _two_cones(ta, pa, alpha, tb, pb, beta, tt, pt):
    """(theta, phi) of the direction at angle alpha from (ta, pa) and beta from (tb, pb), of the
    two on the side of the temporal prediction (tt, pt) [rad] (:func:`_cone` about the first
    when the two axes are parallel; the nearest point when the cones do not meet)."""
    a0, a1, a2 = _unit(ta, pa)
    b0, b1, b2 = _unit(tb, pb)
    g = a0 * b0 + a1 * b1 + a2 * b2
    det = 1.0 - g * g
    if det < 1e-9:
        return _cone(ta, pa, tt, pt, alpha)
    ca, cb = np.cos(alpha), np.cos(beta)
    x, y = (ca - g * cb) / det, (cb - g * ca) / det
    w0, w1, w2 = x * a0 + y * b0, x * a1 + y * b1, x * a2 + y * b2
    c0, c1, c2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0  # |c|^2 = det
    z = np.sqrt(max(1.0 - (w0 * w0 + w1 * w1 + w2 * w2), 0.0) / det)
    t0, t1, t2 = _unit(tt, pt)
    if t0 * c0 + t1 * c1 + t2 * c2 < 0.0:
        z = -z
    u0, u1, u2 = w0 + z * c0, w1 + z * c1, w2 + z * c2
    n = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    return _angles(u0 / n, u1 / n, u2 / n, pt)


@numba.njit(cache=True, inline="always")
def _cone(tp, pp, tt, pt, alpha):
    """(theta, phi) of the direction at angle ``alpha`` from the parent's (tp, pp) nearest the
    temporal prediction (tt, pt) [rad]: the prediction turned about the parent's direction's
    normal until it makes ``alpha`` with it; alpha 0: the parent's own direction. phi on the
    branch nearest pt."""
    if alpha == 0.0:
        return tp, pp + 2.0 * np.pi * np.rint((pt - pp) / (2.0 * np.pi))
    u0, u1, u2 = _unit(tp, pp)
    t0, t1, t2 = _unit(tt, pt)
    c = t0 * u0 + t1 * u1 + t2 * u2
    v0, v1, v2 = t0 - c * u0, t1 - c * u1, t2 - c * u2
    n = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if n < 1e-9:
        return tt, pt
    ca, sa = np.cos(alpha), np.sin(alpha) / n
    return _angles(ca * u0 + sa * v0, ca * u1 + sa * v1, ca * u2 + sa * v2, pt)
