"""Physics-aware keyframes (``physics``): the exact optimum of Q plus a physical cost per segment.

The segment cost is ``C[i, j] = C_Q[i, j] + weight * P[i, j]``: ``C_Q`` is Q's (eq. 18, the
Hermite kernel of :mod:`sidql.keyframes.segment_costs`) and ``P`` a physical cost of the segment
rebuilt between keyframes ``i < j``, summed over its inner frames ``n`` (keyframes are the
original's frames and cost nothing; their own acceleration, which depends on both neighbouring
segments, is not scored), each term divided by a stated scale so that one ``weight`` [rad per
unit] joins them to Q:

* **skating** [m/s] / :data:`SKATE_SCALE`: on each foot the original has in contact in frame
  ``n`` (the sender's contact bits, :func:`sidql.keyframes.contact_pinning.sender_contacts`),
  ``|v_h - v_h,orig|``, the horizontal velocity of the rebuilt foot's lowest sole sphere less the
  original's;
* **floor** [m] / :data:`HEIGHT_SCALE`: on a foot in contact ``|h - h_orig|`` (float or
  penetration of its lowest sole point against the original's), on a foot in the air the
  penetration beyond the original's ``max(0, pen - pen_orig)``;
* **residual** [BW] / :data:`RESIDUAL_SCALE`: the centre-of-mass acceleration the segment's
  contacts cannot supply, beyond the original's: with ``f = a_com - g``, its distance from the
  friction cone (mu = 0.8, circular) when a foot is in contact, ``|f|`` when none is, over ``g``;
  ``max(0, r - r_orig)`` with ``r_orig`` from the original's own (source-frame) accelerations.

**The proxy** (cheap, and what makes the decision fast): the rebuilt segment's centre of mass and
sole spheres move on the cubic Hermite through their keyframe positions and velocities (the
segment's end points), so every term is a closed form per frame. It is exact for a cartesian
reconstruction and close for the spherical one (both match positions and velocities at both ends);
the centre of mass is the de Leva 1996 segment masses (:mod:`sim.model.mass`) lumped at the 23
protocol points (each bone's mass half at each end), the body's other contacts (hands, knees)
are not counted. The measured figures of ``eval --physics`` judge the result, not this proxy.

The keyframes are rebuilt with ``contacts`` (:mod:`sidql.keyframes.contact_pinning`), whose
contact bits the cost already reads. The optimum of ``C`` for every W is the same dynamic
programme as Q's (:func:`sidql.keyframes.optimal.solve`): exact for this cost.

Pure numpy / numba. Units: metres, seconds; world axes (z up); BW = body weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from sidql.keyframes.contact_pinning import sender_contacts
from sidql.keyframes.methods import register
from sidql.keyframes.optimal import OptimalTable, solve
from sidql.keyframes.segment_costs import clip_cost_matrix
from sidql.keyframes.spherical import M_BONES, POINTS, protocol_indices, protocol_parent_indices
from sim.model.mass import CMU_SEGMENT, segment_fractions
from sim.motion.clip import Clip
from sim.physics.feet import SIDES, sole
from sim.physics.ground import estimate_ground

#: Scales dividing each term: skating [m/s], floor height [m], residual force [BW].
SKATE_SCALE, HEIGHT_SCALE, RESIDUAL_SCALE = 0.1, 0.01, 0.1
#: Friction coefficient of the cone (as :data:`sim.physics.dynamics.MU`) and gravity [m/s^2].
MU, GRAVITY = 0.8, 9.81
#: The one weight of the physical cost (rad of Q per unit of P): the rule that chose it and the
#: Q / physics curve it was read from are in docs/keyframes.md (``benchmarks/bench_physics_keyframes.py``).
PHYSICS_WEIGHT = 0.05


def point_masses() -> np.ndarray:
    """(23,) mass fractions of the protocol points (sum 1): each de Leva segment's fraction shared
    equally by its protocol bones (the root counts as one of the lower trunk's), each bone's half
    at its parent point and half at its own."""
    frac = segment_fractions()
    parents = protocol_parent_indices()
    members: dict[str, list[int]] = {}
    for k, name in enumerate(POINTS):
        members.setdefault(CMU_SEGMENT[name], []).append(k)
    w = np.zeros(len(POINTS))
    for seg, ks in members.items():
        for k in ks:
            m = frac[seg] / len(ks)
            if k == 0:
                w[0] += m
            else:
                w[k] += m / 2
                w[parents[k]] += m / 2
    return w / w.sum()


def cone_residual(f: np.ndarray, supported: np.ndarray, mu: float = MU) -> np.ndarray:
    """(T,) what a floor cannot supply of the specific force ``f = a_com - g`` (T, 3) [m/s^2]:
    its distance from the circular friction cone ``{f_z >= 0, |f_h| <= mu f_z}`` where
    ``supported`` (T,) bool, all of ``|f|`` where not."""
    fh = np.hypot(f[:, 0], f[:, 1])
    fz = f[:, 2]
    norm = np.linalg.norm(f, axis=1)
    outside = np.where(mu * fh + fz <= 0, norm, (fh - mu * fz) / np.sqrt(1 + mu * mu))
    cone = np.where(fh <= mu * fz, 0.0, outside)
    return np.where(supported, cone, norm)


@dataclass(frozen=True)
class SegmentInputs:
    """What the physical cost of a clip needs, per frame (N frames, F = 2 feet, K = 2 sole
    spheres per foot), world axes z up.

    Attributes:
        com, com_vel: (N, 3) centre of mass [m] and its velocity [m/s] (:func:`point_masses`).
        spheres, sphere_vel: (N, F, K, 3) sole sphere centres [m] and velocities [m/s].
        radius: (F,) sole sphere radius [m]; floor: (N, F) floor height under each foot [m].
        contact: (N, F) the sender's contact bits.
        height0: (N, F) the original's lowest sole point above the floor [m];
        vel0: (N, F, 2) its lowest sphere's horizontal velocity [m/s];
        residual0: (N,) the original's residual proxy [BW]; dt: frame interval [s].
    """

    com: np.ndarray
    com_vel: np.ndarray
    spheres: np.ndarray
    sphere_vel: np.ndarray
    radius: np.ndarray
    floor: np.ndarray
    contact: np.ndarray
    height0: np.ndarray
    vel0: np.ndarray
    residual0: np.ndarray
    dt: float


def segment_inputs(clip: Clip, contact: np.ndarray | None = None, ground=None) -> SegmentInputs:
    """:class:`SegmentInputs` of a clip (its 23 protocol points, its floor ``ground`` (a
    :class:`sim.physics.ground.Ground`; default the clip's own), the sender's contact bits on it
    unless given (N, 2) bool)."""
    idx = protocol_indices(clip)
    P, V = clip.positions[:, idx], clip.velocities[:, idx]
    if clip.accelerations is not None:
        A = clip.accelerations[:, idx]
    else:
        A = np.gradient(V, clip.dt, axis=0) if clip.n_frames > 1 else np.zeros_like(V)
    w = point_masses()
    com, com_vel, com_acc = (np.einsum("j,njk->nk", w, X) for X in (P, V, A))
    s = sole(P, POINTS)
    if ground is None:
        ground = estimate_ground(clip.positions, clip.names, clip.fps)
    c = sender_contacts(clip, ground) if contact is None else np.asarray(contact, dtype=bool)
    ankle, ball = (
        np.stack([P[:, POINTS.index(x + b)] for x in SIDES], 1) for b in ("tibia", "foot")
    )
    va, vb = (np.stack([V[:, POINTS.index(x + b)] for x in SIDES], 1) for b in ("tibia", "foot"))
    foot = [s.of(x) for x in SIDES]
    spheres = np.stack([s.centres[:, k] for k in foot], axis=1)  # (N, F, K, 3)
    radius = np.array([s.radius[k[0]] for k in foot])
    # each sphere centre is a fixed blend of ankle and ball: its velocity the same blend
    L = np.linalg.norm(ball - ankle, axis=-1, keepdims=True)
    frac = np.linalg.norm(spheres - ankle[:, :, None], axis=-1) / np.maximum(L, 1e-9)
    sphere_vel = va[:, :, None] + frac[..., None] * (vb - va)[:, :, None]
    bottom = spheres[..., 2] - radius[None, :, None]  # (N, F, K)
    low = bottom.argmin(axis=2)
    n, f = np.meshgrid(np.arange(clip.n_frames), np.arange(len(SIDES)), indexing="ij")
    low_xy = spheres[n, f, low, :2]
    floor = ground.level(low_xy) + np.array([ground.offset_of(x) for x in SIDES])[None]
    height0 = bottom[n, f, low] - floor
    vel0 = sphere_vel[n, f, low, :2]
    spec = com_acc + np.array([0.0, 0.0, GRAVITY])
    residual0 = cone_residual(spec, c.any(axis=1)) / GRAVITY
    return SegmentInputs(
        com, com_vel, spheres, sphere_vel, radius, floor, c, height0, vel0, residual0, clip.dt
    )


@numba.njit(cache=True)
def _physical_band(com, cv, S, SV, radius, floor, contact, h0, v0, r0, dt, mu, g, G):
    """(3, N, G + 1) summed skating [m/s], floor [m] and residual [BW] terms of every segment
    ``(i, i + L)``, 2 <= L <= G, at ``[:, i, L]`` (the module docstring), on the cubic Hermite
    through each quantity's keyframe values."""
    N = com.shape[0]
    F, K = S.shape[1], S.shape[2]
    out = np.zeros((3, N, G + 1))
    root = np.sqrt(1.0 + mu * mu)
    for i in range(N):
        for j in range(i + 2, min(N, i + G + 1)):
            L = j - i
            T = L * dt
            sk = 0.0
            ht = 0.0
            rs = 0.0
            for n in range(i + 1, j):
                s = (n - i) / L
                s2 = s * s
                s3 = s2 * s
                h00, h10 = 2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * T
                h01, h11 = -2 * s3 + 3 * s2, (s3 - s2) * T
                d00, d01 = (6 * s2 - 6 * s) / T, (-6 * s2 + 6 * s) / T
                d10, d11 = 3 * s2 - 4 * s + 1, 3 * s2 - 2 * s
                a00, a01 = (12 * s - 6) / (T * T), (-12 * s + 6) / (T * T)
                a10, a11 = (6 * s - 4) / T, (6 * s - 2) / T
                supported = False
                for f in range(F):
                    best = 1e300
                    bvx = 0.0
                    bvy = 0.0
                    for k in range(K):
                        z = h00 * S[i, f, k, 2] + h01 * S[j, f, k, 2]
                        z += h10 * SV[i, f, k, 2] + h11 * SV[j, f, k, 2]
                        if z < best:
                            best = z
                            bvx = d00 * S[i, f, k, 0] + d01 * S[j, f, k, 0]
                            bvx += d10 * SV[i, f, k, 0] + d11 * SV[j, f, k, 0]
                            bvy = d00 * S[i, f, k, 1] + d01 * S[j, f, k, 1]
                            bvy += d10 * SV[i, f, k, 1] + d11 * SV[j, f, k, 1]
                    h = best - radius[f] - floor[n, f]
                    if contact[n, f]:
                        supported = True
                        sk += np.hypot(bvx - v0[n, f, 0], bvy - v0[n, f, 1])
                        ht += abs(h - h0[n, f])
                    else:
                        ht += max(0.0, max(0.0, -h) - max(0.0, -h0[n, f]))
                fx = a00 * com[i, 0] + a01 * com[j, 0] + a10 * cv[i, 0] + a11 * cv[j, 0]
                fy = a00 * com[i, 1] + a01 * com[j, 1] + a10 * cv[i, 1] + a11 * cv[j, 1]
                fz = a00 * com[i, 2] + a01 * com[j, 2] + a10 * cv[i, 2] + a11 * cv[j, 2] + g
                norm = np.sqrt(fx * fx + fy * fy + fz * fz)
                r = norm
                if supported:
                    fh = np.hypot(fx, fy)
                    if fh <= mu * fz:
                        r = 0.0
                    elif mu * fh + fz > 0:
                        r = (fh - mu * fz) / root
                rs += max(0.0, r / g - r0[n])
            out[0, i, L] = sk
            out[1, i, L] = ht
            out[2, i, L] = rs
    return out


def physical_band(x: SegmentInputs, G: int) -> np.ndarray:
    """(3, N, G + 1) the physical terms of every segment ``(i, i + L)`` with ``L <= G`` at
    ``[:, i, L]``, summed over its inner frames: skating [m/s], floor [m], residual [BW] (the
    module docstring); 0 for ``L <= 1`` and past the last frame. O(N G^2) time, O(N G) memory:
    what a whole trial's banded programme (the codec's) reads."""
    return _physical_band(
        x.com, x.com_vel, np.ascontiguousarray(x.spheres), np.ascontiguousarray(x.sphere_vel),
        x.radius, x.floor, x.contact, x.height0, x.vel0, x.residual0, float(x.dt), MU, GRAVITY,
        int(G),
    )  # fmt: skip


def physical_costs(x: SegmentInputs) -> np.ndarray:
    """(3, N, N) the physical terms of every segment ``(i, j)``, summed over its inner frames:
    skating [m/s], floor [m], residual [BW] (the module docstring); 0 for ``j <= i + 1``."""
    N = x.com.shape[0]
    band = physical_band(x, max(N - 1, 0))
    out = np.zeros((3, N, N))
    i, L = np.nonzero(np.ones((N, N), dtype=bool))
    ok = i + L < N
    out[:, i[ok], i[ok] + L[ok]] = band[:, i[ok], L[ok]]
    return out


def scaled(terms: np.ndarray) -> np.ndarray:
    """(N, N) the physical cost P: the three terms (3, N, N) over their scales, summed."""
    scale = np.array([SKATE_SCALE, HEIGHT_SCALE, RESIDUAL_SCALE])[:, None, None]
    return (terms / scale).sum(axis=0)


def physics_table(
    clip: Clip, weight: float = PHYSICS_WEIGHT, w_max: int | None = None, terms=None
) -> OptimalTable:
    """Exact minima of ``sum C_Q + weight * P`` over keyframe sets for every W up to ``w_max``
    (``terms``: the clip's :func:`physical_costs`, when the caller has them). The table's ``q``
    is then that combined cost over N M, not Q."""
    if terms is None:
        terms = physical_costs(segment_inputs(clip))
    C = clip_cost_matrix(clip, "hermite") + weight * scaled(terms)
    return solve(C, M_BONES, w_max)


@register("physics", reconstruction="contacts")
def physics(clip: Clip, W: int, *, seed: int = 0, memo=None) -> np.ndarray:
    """Physics-aware keyframes: the exact minimiser of Q plus :data:`PHYSICS_WEIGHT` times the
    physical cost (:func:`physics_table`), meant for ``contacts``. With a ``memo`` one table
    serves every W up to ``memo["w_max"]``."""
    if memo is None:
        return physics_table(clip, w_max=W).keyframes(W)
    if "physics" not in memo or len(memo["physics"].cost) <= W:
        memo["physics"] = physics_table(clip, w_max=max(W, memo.get("w_max", W)))
    return memo["physics"].keyframes(W)
