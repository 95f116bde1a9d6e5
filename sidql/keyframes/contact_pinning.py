"""The reconstruction that keeps contacts (``contacts``): foot-contact bits sent beside the
keyframes, and the receiver pinning each foot in contact where it touched down.

**The sender** labels every frame's foot contacts (:func:`sender_contacts`: the clip's own floor
(:func:`sim.physics.ground.estimate_ground`) and the one definition of contact,
:func:`sim.physics.contacts.motion_contacts`) and sends them run-length coded
(:func:`encode_runs`: per foot one varint holding the number of runs and the first state, then
one varint per run length but the last; a 60-frame clip costs 2 + the number of contact changes
bytes, typically 6-10), and the floor it labelled them on (:func:`encode_floor`: a plane and
each foot's stance offset, 5 float32, 20 bytes). Those bytes are the reconstruction's side
information (:attr:`Reconstruction.side_bytes <sidql.keyframes.reconstructions.Reconstruction>`),
counted with its keyframes in every byte figure.

**The receiver** rebuilds the clip with the paper's Hermite (:mod:`sidql.keyframes.reconstructions`)
and then, per foot and contact run (:func:`pin_feet`):

* *where it touched down*: the foot's lowest sole point (:func:`sim.physics.feet.sole`: heel and
  ball spheres of the ankle-ball capsule) at the keyframes inside the run (exact poses of the
  original), or at the run's first frame when no keyframe falls inside it;
* *pinned*: an offset ``d(t)`` (3,) [m] keeps the lowest sole sphere from moving horizontally
  (integrated frame to frame from the anchor, so a foot rolling heel to ball still rolls: the
  contact point moves from sphere to sphere, no sphere slides); between two keyframes of one
  run the pin slides linearly from one to the other (the original's own net displacement:
  every keyframe stays exact); its height goes linearly from one keyframe's to the next (the
  original's own: a heel lifting at push-off lifts); a run without keyframes rests on the floor;
* *kept above the floor*: in contact or in the air (a long cubic through a swing), a foot whose
  lowest sole point would pass under the floor is lifted onto it by smooth bumps (a smoothstep
  envelope over :data:`BLEND_S`), not clamped (a clamp's kink is an impulse in the
  acceleration the dynamics read);
* *blended*: outside a run the offset fades to 0 over :data:`BLEND_S` by a smoothstep (between
  two runs closer than twice that, the two fades are averaged), so the foot moves smoothly in
  and out of its pin;
* *by analytic two-bone IK* (:func:`two_bone_ik`): the hip stays, the ankle goes to its pinned
  place (clamped inside the leg's reach), the knee bends in the plane the Hermite knee bent in,
  and the foot bone (ankle to ball, the protocol's toe point) follows the ankle rigidly; thigh,
  shin and foot keep their lengths exactly.

Velocities and accelerations are the Hermite curve's plus the finite differences (central, 30
fps) of the pinning's correction. Keyframes inside a contact run are reproduced exactly (their
offset is 0); a keyframe within a fade or a lift is not: smoothness comes first, since a
correction cut short at a keyframe is an impulse in the acceleration (it raised the residual
force at W = 10 from 0.006 to 0.04 BW over the original's on ``../shared/cmu``).

Pure numpy over arrays. Units: metres, seconds; positions (N, 23, 3) in world axes (z up).
"""

from __future__ import annotations

import numba
import numpy as np

from sidql.keyframes.reconstructions import Reconstruction, hermite, points_reconstruction
from sidql.keyframes.spherical import POINTS, SphericalSeries
from sim.errors import MotionDataError, UsageError
from sim.motion.clip import Clip
from sim.physics.contacts import motion_contacts
from sim.physics.feet import SIDES, sole
from sim.physics.ground import estimate_ground

#: [s] how long a foot takes to blend into and out of its pin around a contact run.
BLEND_S = 0.15
#: Per foot (``l``, ``r``): indices into :data:`~sidql.keyframes.spherical.POINTS` of the hip,
#: knee, ankle and ball (the ends of ``hipjoint``, ``femur``, ``tibia``, ``foot``).
LEGS: tuple[tuple[int, int, int, int], ...] = tuple(
    tuple(POINTS.index(s + b) for b in ("hipjoint", "femur", "tibia", "foot")) for s in SIDES
)
#: Fraction of the leg's full reach (thigh + shin) the ankle is allowed (a straight knee has no
#: bending plane; the clamp keeps the knee's solution well defined).
MAX_REACH = 0.9999


def sender_ground(clip: Clip):
    """The clip's own floor as its sender estimates it (:func:`sim.physics.ground.estimate_ground`
    on all its points).

    Raises:
        MotionDataError: the clip has no foot (ankle and ball).
    """
    try:
        return estimate_ground(clip.positions, tuple(clip.names), clip.fps)
    except ValueError as e:
        raise MotionDataError(clip.source or None, None, f"no floor: {e}") from None


def sender_contacts(clip: Clip, ground=None) -> np.ndarray:
    """(N, 2) bool foot-contact labels (``l``, ``r``) of a clip as its sender labels them:
    :func:`sim.physics.contacts.motion_contacts` on all its points, on ``ground`` (a
    :class:`sim.physics.ground.Ground`; default the clip's own floor, :func:`estimate_ground`).

    Raises:
        MotionDataError: the clip has no foot (ankle and ball) to label.
    """
    names = tuple(clip.names)
    if ground is None:
        ground = sender_ground(clip)
    try:
        c = motion_contacts(clip.positions, names, clip.fps, ground, velocities=clip.velocities)
    except ValueError as e:
        raise MotionDataError(clip.source or None, None, f"no foot contacts: {e}") from None
    out = np.zeros((clip.n_frames, len(SIDES)), dtype=bool)
    for f, s in enumerate(SIDES):
        if s in c.sides:
            out[:, f] = c.contact[:, c.sides.index(s)]
    return out


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _read_varint(data: bytes, pos: int) -> tuple[int, int]:
    n = shift = 0
    while True:
        if pos >= len(data) or shift > 28:
            raise MotionDataError(None, None, "contact runs: truncated or oversized varint")
        b = data[pos]
        pos += 1
        n |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return n, pos


def encode_runs(bits: np.ndarray) -> bytes:
    """Run-length code (N, F) bool labels: per foot ``varint(2 * runs + first state)`` then the
    varint length of every run but the last (LEB128 varints)."""
    b = np.asarray(bits, dtype=bool)
    if b.ndim != 2 or b.shape[0] < 1:
        raise UsageError(f"bits must be (N, F) with N >= 1; got {b.shape}")
    out = bytearray()
    for f in range(b.shape[1]):
        change = np.flatnonzero(b[1:, f] != b[:-1, f]) + 1
        edges = np.concatenate([[0], change, [len(b)]])
        out += _varint(2 * (len(edges) - 1) + int(b[0, f]))
        for length in np.diff(edges)[:-1]:
            out += _varint(int(length))
    return bytes(out)


def decode_runs(data: bytes, n_frames: int, n_feet: int = len(SIDES)) -> np.ndarray:
    """(n_frames, n_feet) bool labels from :func:`encode_runs`'s bytes (MotionDataError when they
    do not describe exactly that many frames and feet)."""
    out = np.zeros((n_frames, n_feet), dtype=bool)
    pos = 0
    for f in range(n_feet):
        head, pos = _read_varint(data, pos)
        n_runs, state = head >> 1, bool(head & 1)
        if not 1 <= n_runs <= n_frames:
            raise MotionDataError(
                None, None, f"contact runs: foot {f} has {n_runs} runs in {n_frames} frames"
            )
        t = 0
        for r in range(n_runs):
            if r < n_runs - 1:
                length, pos = _read_varint(data, pos)
            else:
                length = n_frames - t
            if length < 1 or t + length > n_frames:
                raise MotionDataError(
                    None, None, f"contact runs: foot {f}'s runs overrun {n_frames} frames"
                )
            out[t : t + length, f] = state
            t += length
            state = not state
    if pos != len(data):
        raise MotionDataError(None, None, f"contact runs: {len(data) - pos} trailing bytes")
    return out


def runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the True runs of a (N,) bool array (stop exclusive)."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(d[::2].tolist(), d[1::2].tolist(), strict=True))


def two_bone_ik(leg: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic two-bone IK: the new knee and ankle (T, 3) [m] of legs ``leg`` (T, 4, 3) =
    ``[hip, knee, ankle, ball]`` [m] whose ankle goes to ``target`` (T, 3) [m].

    The hip stays; thigh and shin keep their lengths in ``leg`` exactly; the knee bends in the
    plane it bent in (towards the ball when the leg was straight). A target beyond
    :data:`MAX_REACH` of the leg (or nearer the hip than its fold allows) is replaced by the
    reachable point on the line from the hip towards it.
    """
    target = np.asarray(target, dtype=np.float64)
    h_hip, h_knee, h_ankle, h_ball = (leg[:, k] for k in range(4))
    l1 = np.linalg.norm(h_knee - h_hip, axis=-1)
    l2 = np.linalg.norm(h_ankle - h_knee, axis=-1)
    r = target - h_hip
    d = np.linalg.norm(r, axis=-1)
    u = r / np.maximum(d, 1e-12)[:, None]
    dc = np.clip(d, np.abs(l1 - l2) / MAX_REACH + 1e-9, MAX_REACH * (l1 + l2))
    a = (l1**2 - l2**2 + dc**2) / (2 * dc)
    h = np.sqrt(np.maximum(l1**2 - a**2, 0.0))
    pole = h_knee - h_hip
    v = pole - np.sum(pole * u, axis=-1, keepdims=True) * u
    fwd = h_ball - h_ankle
    fwd = fwd - np.sum(fwd * u, axis=-1, keepdims=True) * u
    small = np.linalg.norm(v, axis=-1) < 1e-6 * np.maximum(l1, 1e-9)
    v[small] = fwd[small]
    v /= np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
    return h_hip + a[:, None] * u + h[:, None] * v, h_hip + dc[:, None] * u


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def blend_offsets(offsets: np.ndarray, contact: np.ndarray, width: int) -> np.ndarray:
    """(N, 3) offsets [m] defined on the contact frames of ``contact`` (N,) bool, faded to 0
    outside over ``width`` frames by a smoothstep (weight ``1 - smoothstep(distance /
    (width + 1))``); where the fades of two runs overlap their weighted sum is normalised by
    ``max(1, w1 + w2)`` so the result stays continuous. A fade crosses keyframes: cut short
    there, it would be an impulse in the acceleration."""
    out = np.where(contact[:, None], offsets, 0.0)
    spans = runs_of(contact)
    if not spans or width < 1:
        return out
    starts = np.array([a for a, _ in spans])
    ends = np.array([e - 1 for _, e in spans])
    t = np.flatnonzero(~contact)
    total, weight = np.zeros((len(t), 3)), np.zeros(len(t))
    i = np.searchsorted(ends, t) - 1  # last run ending before t
    before = i >= 0
    x = 1.0 - _smoothstep((t[before] - ends[i[before]]) / (width + 1))
    total[before] += x[:, None] * offsets[ends[i[before]]]
    weight[before] += x
    j = np.searchsorted(starts, t)  # first run starting after t
    after = j < len(starts)
    x = 1.0 - _smoothstep((starts[j[after]] - t[after]) / (width + 1))
    total[after] += x[:, None] * offsets[starts[j[after]]]
    weight[after] += x
    out[t] = total / np.maximum(1.0, weight)[:, None]
    return out


def _steps(bottoms: np.ndarray, low: np.ndarray, a: int, e: int):
    """The horizontal steps [m] of a foot's lowest sole sphere over frames ``[a, e)``, (e - a - 1,
    2) each: ``fwd[k]``, the sphere lowest at frame a + k + 1 from frame a + k to it; ``back[k]``,
    the sphere lowest at frame a + k from it to frame a + k + 1."""
    t = np.arange(a + 1, e)
    fwd = bottoms[t, low[t], :2] - bottoms[t - 1, low[t], :2]
    back = bottoms[t, low[t - 1], :2] - bottoms[t - 1, low[t - 1], :2]
    return fwd, back


def _rolled(fwd: np.ndarray, back: np.ndarray, k: int) -> np.ndarray:
    """(L, 2) horizontal offsets [m] over the L frames of a run (its :func:`_steps` ``fwd``,
    ``back``) that keep the foot's lowest sole sphere from moving horizontally, 0 at the run's
    frame ``k``: after it each frame's offset is the one before less ``fwd``, before it the one
    after plus ``back`` (running sums from 0, added in that order)."""
    out = np.zeros((len(fwd) + 1, 2))
    zero = np.zeros((1, 2))
    if k < len(fwd):
        out[k + 1 :] = np.subtract.accumulate(np.concatenate([zero, fwd[k:]]), axis=0)[1:]
    if k > 0:
        out[:k][::-1] = np.add.accumulate(np.concatenate([zero, back[:k][::-1]]), axis=0)[1:]
    return out


def foot_offsets(
    bottoms: np.ndarray,
    contact: np.ndarray,
    keyframes: np.ndarray,
    floor: np.ndarray | None,
) -> np.ndarray:
    """(N, 3) pin offsets [m] of one foot on its contact frames (0 elsewhere).

    Horizontally, a run holding no keyframe is pinned where the foot touched down (its first
    frame); a run holding keyframes is pinned at each of them exactly: before the first and
    after the last the foot stays where it was at that keyframe, between two of them the pin
    slides linearly from one to the next (the original's net displacement); the rolling of the
    foot (which sphere is lowest) is kept. Vertically the lowest sole point goes linearly from
    one keyframe's height to the next (the original's own heights: a heel lifting at push-off
    lifts); a run without keyframes rests on ``floor`` (on the touch-down height when no floor
    is known). :func:`lift_above` keeps it off the floor's underside afterwards.

    Args:
        bottoms: (N, S, 3) the lowest surface points of the foot's sole spheres [m].
        contact: (N,) bool contact labels; keyframes: (W,) indices.
        floor: (N,) the floor's height under the foot [m] (None: unknown).
    """
    N = len(contact)
    low = bottoms[..., 2].argmin(axis=1)  # (N,) the lowest sphere per frame
    z = bottoms[np.arange(N), low, 2]
    out = np.zeros((N, 3))
    keys = np.asarray(keyframes, dtype=np.int64)
    for a, e in runs_of(contact):
        inside = keys[(keys >= a) & (keys < e)]
        t = np.arange(a, e)
        if not len(inside):
            out[a:e, :2] = _rolled(*_steps(bottoms, low, a, e), 0)
            out[a:e, 2] = (z[a] if floor is None else floor[a:e]) - z[a:e]
            continue
        out[a:e, 2] = np.interp(t, inside, z[inside]) - z[a:e]
        before, after = _anchors(*_steps(bottoms, low, a, e), inside - a)
        pos = np.clip(np.searchsorted(inside, t, side="right") - 1, 0, len(inside) - 1)
        nxt = np.minimum(pos + 1, len(inside) - 1)
        span = np.maximum(inside[nxt] - inside[pos], 1)
        s = np.clip((t - inside[pos]) / span, 0.0, 1.0)[:, None]
        s[t < inside[0]] = 0.0
        out[a:e, :2] = (1 - s) * before + s * after
    return out


@numba.njit(cache=True, nogil=True)
def _anchors(fwd, back, keys):
    """(L, 2), (L, 2) [m]: at each frame of a run (its :func:`_steps` ``fwd``, ``back``; L - 1
    rows) the offset :func:`_rolled` gives it from the run's keyframe before it and from the one
    after it, as :func:`foot_offsets` pairs them (``keys`` (K,): the run's keyframes, sorted,
    from 0; before the first: the first's and the second's, from the last on: the last's), each
    the same running sum in the same order, in O(L) where all the anchors would take O(K L)."""
    L, K = fwd.shape[0] + 1, keys.shape[0]
    before, after = np.zeros((L, 2)), np.zeros((L, 2))
    for i in range(K):
        k = keys[i]
        end = keys[i + 1] if i + 1 < K else L  # forwards: the frames this keyframe is before
        for c in range(2):
            acc = 0.0
            for t in range(k + 1, end):
                acc = acc - fwd[t - 1, c]
                before[t, c] = acc
            acc = 0.0  # backwards: the first keyframe's own frames before it, and the frames
            lo = 0 if i <= 1 else keys[i - 1]  # this keyframe is after
            for t in range(k - 1, lo - 1, -1):
                acc = acc + back[t, c]
                if i == 0:
                    before[t, c] = acc
                if i > 0 or K == 1:
                    after[t, c] = acc
    last = keys[K - 1]
    after[last:] = before[last:]
    return before, after


def lift_above(lowest: np.ndarray, floor: np.ndarray, width: int) -> np.ndarray:
    """(N,) how far [m] a foot whose lowest sole point is at ``lowest`` (N,) [m] is lifted to
    stay on or above ``floor`` (N,) [m], smoothly: the upper envelope of smoothstep bumps, one
    per frame under the floor, as high as its depth there and ``width`` frames wide either
    side. A pointwise clamp would put a kink in the foot's path, an impulse into its
    acceleration."""
    depth = np.maximum(floor - lowest, 0.0)
    N = len(depth)
    out = np.zeros(N)
    for s in np.flatnonzero(depth > 0):
        t = np.arange(max(0, s - width), min(N, s + width + 1))
        bump = depth[s] * (1.0 - _smoothstep(np.abs(t - s) / (width + 1)))
        out[t] = np.maximum(out[t], bump)
    return out


def pin_feet(
    positions: np.ndarray,
    contact: np.ndarray,
    keyframes,
    fps: float,
    *,
    floor: np.ndarray | None = None,
    blend_s: float = BLEND_S,
) -> np.ndarray:
    """(N, 23, 3) ``positions`` [m] (the protocol points, world axes z up) with each foot pinned
    on its contact frames (see the module docstring).

    Args:
        positions: (N, 23, 3) the receiver's reconstruction [m].
        contact: (N, 2) bool foot-contact bits (``l``, ``r``).
        keyframes: (W,) the keyframe indices (exact poses of the original).
        fps: frame rate [1/s]; blend_s: blend time [s].
        floor: (5,) the sender's floor (:func:`decode_floor`); None: unknown (runs keep their
            keyframes' or touch-down heights, nothing is lifted).
    """
    P = np.array(positions, dtype=np.float64)
    c = np.asarray(contact, dtype=bool)
    N = P.shape[0]
    if P.shape != (N, len(POINTS), 3) or c.shape != (N, len(SIDES)):
        raise UsageError(
            f"positions must be (N, 23, 3) and contact (N, 2); got {P.shape}, {c.shape}"
        )
    k = np.asarray(keyframes, dtype=np.int64)
    s = sole(P, POINTS)
    b = s.bottoms
    width = int(round(blend_s * fps))
    out = P.copy()
    for f, (hip, knee, ankle, ball) in enumerate(LEGS):
        foot = b[:, s.of(SIDES[f])]
        lowest = foot[np.arange(N), foot[..., 2].argmin(axis=1)]  # (N, 3)
        under = None if floor is None else floor_heights(floor, lowest[:, :2], f)
        off = foot_offsets(foot, c[:, f], k, under)
        off = blend_offsets(off, c[:, f], width)
        if under is not None:  # no foot under the floor, in contact or in the air
            off[:, 2] += lift_above(lowest[:, 2] + off[:, 2], under, width)
        moved = np.flatnonzero(np.abs(off).max(axis=1) > 0)
        if not len(moved):
            continue
        leg = P[moved][:, [hip, knee, ankle, ball]]
        new_knee, new_ankle = two_bone_ik(leg, leg[:, 2] + off[moved])
        out[moved, knee] = new_knee
        out[moved, ankle] = new_ankle
        out[moved, ball] = leg[:, 3] + (new_ankle - leg[:, 2])
    return out


def encode_floor(ground) -> bytes:
    """The sender's floor (a :class:`sim.physics.ground.Ground`) as 5 float32 (20 bytes): its
    height at the world origin [m], its slopes dz/dx, dz/dy, and each foot's stance offset [m]."""
    sx, sy = ground.slope
    z0 = ground.z - sx * ground.origin[0] - sy * ground.origin[1]
    values = [z0, sx, sy, *(ground.offset_of(x) for x in SIDES)]
    return np.asarray(values, dtype="<f4").tobytes()


def decode_floor(data: bytes) -> np.ndarray:
    """(5,) float64 floor parameters from :func:`encode_floor`'s 20 bytes."""
    if len(data) != 5 * 4:
        raise MotionDataError(None, None, f"floor: {len(data)} bytes, expected 20")
    v = np.frombuffer(data, dtype="<f4").astype(np.float64)
    if not np.all(np.isfinite(v)):
        raise MotionDataError(None, None, "floor: non-finite values")
    return v


def floor_heights(floor: np.ndarray, xy: np.ndarray, foot: int) -> np.ndarray:
    """(N,) height [m] of the floor ``floor`` (5,) under points ``xy`` (N, 2) [m], where foot
    ``foot`` (0: ``l``, 1: ``r``) stands (its stance offset included)."""
    return floor[0] + xy[:, 0] * floor[1] + xy[:, 1] * floor[2] + floor[3 + foot]


def correction_derivatives(delta: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second time derivatives [m/s, m/s^2] of a correction ``delta`` (N, ...) [m] by
    central differences (one-sided first difference at the ends, second difference copied from
    the neighbour; zeros for N < 3)."""
    d = np.asarray(delta, dtype=np.float64)
    if len(d) < 3:
        return np.zeros_like(d), np.zeros_like(d)
    v = np.gradient(d, 1.0 / fps, axis=0)
    a = np.zeros_like(d)
    a[1:-1] = (d[2:] - 2 * d[1:-1] + d[:-2]) * fps**2
    a[0], a[-1] = a[1], a[-2]
    return v, a


def rebuild(clip: Clip, keyframes, series: SphericalSeries | None = None) -> Reconstruction:
    """The ``contacts`` reconstruction of ``clip`` from ``keyframes`` (W,): ``hermite``, then the
    sender's side information (its contact bits, :func:`sender_contacts`, run-length coded, and
    its floor, :func:`encode_floor`: their bytes in ``side_bytes``) decoded as the receiver has
    it, and each foot pinned (:func:`pin_feet`); velocities [m/s] and accelerations [m/s^2] are
    the curve's plus the central differences of the pinning's correction
    (:func:`correction_derivatives`)."""
    base = hermite(clip, keyframes, series)
    ground = sender_ground(clip)
    runs, plane = encode_runs(sender_contacts(clip, ground)), encode_floor(ground)
    bits, floor = decode_runs(runs, clip.n_frames), decode_floor(plane)  # what the receiver has
    P = pin_feet(base.positions, bits, base.keyframes, clip.fps, floor=floor)
    dV, dA = correction_derivatives(P - base.positions, clip.fps)
    return points_reconstruction(
        P, base.velocities + dV, base.parents, base.keyframes, "contacts", clip.fps,
        base.accelerations + dA, side_bytes=len(runs) + len(plane),
    )  # fmt: skip
