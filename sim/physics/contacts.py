"""Foot-floor contact: which feet (and other body points) rest on the floor, labelled from the
sole's geometry against the trial's floor. (Not the touching of two bones: that is
:func:`sim.replay.checks.self_penetration_excess`'s.)

Labels (:func:`label_contacts`): a foot is in contact while the lowest of its sole spheres
(:mod:`sim.physics.feet`) is on the floor. "On the floor" is judged over the frame's own time
interval, not only at its instant: the sphere's gap is also read half a frame before and after
(linear between frames), so a foot landing or lifting between two frames is in contact in the
frame whose interval holds the touch. A foot *enters* contact when that gap is within
``enter = max(CONTACT_GAP, 2 x the floor's spread)`` and its lowest sphere moves slower than
:data:`~sim.physics.feet.ENTER_SPEED` horizontally (a swinging foot passes low and fast), and
*leaves* once the gap exceeds ``enter`` plus the floor's spread (hysteresis against marker noise,
none on a noise-free floor). A foot
rolling heel to toe stays in contact: its lowest point passes from the heel sphere to the ball and
the toes while each in turn rests on the floor, and a foot turning about a point on the floor
(:func:`rolling_contact`) is in contact while its sole is within
:data:`~sim.physics.feet.ROLL_GAP`. A foot standing still a little above the humanoid's sole
level (a dancer's forefoot) is planted (:func:`planted_feet`), and support does not vanish for
a frame between a push-off and a heel strike: when no foot would be in contact though one was,
the feet still low and slow hold the body (:func:`label_contacts`). The rest of the body rests
on the floor by the same geometry (:func:`body_contacts`: hands, knees, hips, back), where ground
forces may act too. The labels of a whole trial are made once
(:func:`trial_contacts`); a clip's are a slice of them, and a reconstruction's own labels start
from the original's state at its first frame (keyframe 0 is the original's frame).

Metrics of a motion against the original's contacts: :mod:`sim.physics.contact_metrics`;
what the renderer draws at the feet: :mod:`sim.physics.foot_state`.

Units: metres, seconds, metres per second.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sim.errors import UsageError
from sim.model.capsules import bones_of
from sim.model.kinematics import FOOT_POINTS
from sim.physics.feet import (
    CONTACT_GAP,
    ENTER_SPEED,
    HOLD_GAP,
    HOLD_SPEED,
    ROLL_BACK,
    ROLL_FRONT,
    ROLL_GAP,
    ROLL_RATE,
    ROLL_TOLERANCE,
    STILL_SPEED,
    STILL_TIME,
    SUPPORT_GAP,
    Sole,
    sole,
)
from sim.physics.ground import Ground, horizontal_speed, runs, speed


def point_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(T, ...) speed [m/s] of ``positions`` (T, ..., 3) [m] by central differences."""
    return speed(positions, fps)


#: How far into the neighbouring frames a frame's interval reaches, as a share of the frame
#: interval, when judging whether a foot touches the floor during it (1/2: the whole interval).
INTERVAL_REACH = 0.25


def interval_gap(gap: np.ndarray, reach: float | None = None) -> np.ndarray:
    """(T, ...) the least of ``gap`` (T, ...) at each frame and ``reach`` (default
    :data:`INTERVAL_REACH`) of a frame before and after it (linear between frames): how close to
    the floor a point comes during the frame's interval."""
    reach = INTERVAL_REACH if reach is None else reach
    g = np.asarray(gap, dtype=np.float64)
    if len(g) < 2:
        return g.copy()
    out = g.copy()
    out[1:] = np.minimum(out[1:], g[1:] + reach * (g[:-1] - g[1:]))
    out[:-1] = np.minimum(out[:-1], g[:-1] + reach * (g[1:] - g[:-1]))
    return out


def enter_gap(ground: Ground) -> float:
    """[m] the gap within which a foot enters contact on ``ground`` (:data:`CONTACT_GAP`, or
    twice the floor's spread where the planted feet scatter more)."""
    return max(CONTACT_GAP, 2.0 * ground.noise)


def rolling_contact(
    ankle: np.ndarray,
    ball: np.ndarray,
    ankle_velocity: np.ndarray,
    ball_velocity: np.ndarray,
    ground: Ground,
) -> tuple[np.ndarray, np.ndarray]:
    """Whether a foot rolls on the floor: its instantaneous centre of rotation on the floor.

    The foot is the rigid segment ankle -> ball (T, 3) [m] with velocities (T, 3) [m/s]; its
    angular velocity across the segment is ``w = u x (v_ball - v_ankle) / L`` and the point of the
    segment's plane of motion that stands still is ``c = ankle + w x v_ankle / |w|^2``. The foot
    rolls on the floor where it turns faster than :data:`~sim.physics.feet.ROLL_RATE` about a
    ``c`` within :data:`~sim.physics.feet.ROLL_TOLERANCE` of the floor and along the foot
    (:data:`~sim.physics.feet.ROLL_BACK` behind the ankle to
    :data:`~sim.physics.feet.ROLL_FRONT` beyond the ball).

    Returns:
        rolling (T,) bool and ``c`` (T, 3) [m].
    """
    d = ball - ankle
    L = np.linalg.norm(d, axis=-1, keepdims=True)
    u = d / np.maximum(L, 1e-9)
    w = np.cross(u, (ball_velocity - ankle_velocity) / np.maximum(L, 1e-9))
    w2 = np.sum(w * w, axis=-1, keepdims=True)
    c = ankle + np.cross(w, ankle_velocity) / np.maximum(w2, 1e-12)
    h = c[..., 2] - ground.level(c[..., :2])
    along = np.sum((c - ankle) * u, axis=-1)
    ok = (
        (np.sqrt(w2[..., 0]) >= ROLL_RATE)
        & (np.abs(h) <= ROLL_TOLERANCE)
        & (along >= -ROLL_BACK)
        & (along <= L[..., 0] + ROLL_FRONT)
    )
    return ok, c


def label_contacts(
    gap: np.ndarray,
    hspeed: np.ndarray,
    *,
    enter: float = CONTACT_GAP,
    release: float = 0.0,
    enter_speed: float = ENTER_SPEED,
    initial=None,
    rolling=None,
    vspeed=None,
    planted=None,
) -> np.ndarray:
    """(T, F) contact labels of F feet with hysteresis.

    Args:
        gap: (T, F) each foot's lowest sole gap over the frame's interval [m]
            (:func:`interval_gap` of the sphere gaps, least over the foot's spheres).
        hspeed: (T, F) horizontal speed of that lowest sphere [m/s].
        enter, release, enter_speed: a foot enters contact when ``gap <= enter`` and
            ``hspeed < enter_speed``, and leaves when ``gap > enter + release``.
        initial: (F,) bool state before frame 0 (e.g. the original's label at a reconstruction's
            first frame); default out of contact.
        rolling: (T, F) bool, the foot rolls on the floor (:func:`rolling_contact`): in contact
            while its sole is within :data:`~sim.physics.feet.ROLL_GAP` (the real heel lies
            below the humanoid's heel sphere).
        vspeed: (T, F) vertical speed of the lowest sole point [m/s] (default 0).
        planted: (T, F) bool, the foot stands still near the floor (:func:`planted_feet`): in
            contact whatever its gap within :data:`~sim.physics.feet.HOLD_GAP`.

    Support does not vanish between two frames by a centimetre: when no foot would be in
    contact though one was in the frame before, every foot within
    :data:`~sim.physics.feet.HOLD_GAP` of the floor and slower than
    :data:`~sim.physics.feet.HOLD_SPEED` (horizontally and vertically) holds the body (a
    forefoot pushing off while the other heel strikes, both a little above the humanoid's
    rigid sole).
    """
    gap, hspeed = np.asarray(gap, dtype=np.float64), np.asarray(hspeed, dtype=np.float64)
    if gap.shape != hspeed.shape or gap.ndim != 2:
        raise UsageError(f"gap and hspeed must both be (T, F); got {gap.shape}, {hspeed.shape}")
    if release < 0:
        raise UsageError("release must be >= 0")
    vs = np.zeros_like(gap) if vspeed is None else np.abs(np.asarray(vspeed, dtype=np.float64))
    enter_all = (gap <= enter) & (hspeed < enter_speed)
    stay_all = gap <= enter + release
    hold_all = (gap <= HOLD_GAP) & (hspeed < HOLD_SPEED) & (vs < HOLD_SPEED)
    for extra, within in ((rolling, ROLL_GAP), (planted, HOLD_GAP)):
        if extra is not None:
            on = np.asarray(extra, dtype=bool) & (gap <= within)
            enter_all |= on
            stay_all |= on
    out = np.zeros(gap.shape, dtype=bool)
    state = np.zeros(gap.shape[1], dtype=bool) if initial is None else np.array(initial, bool)
    supported = bool(state.any())
    for t in range(gap.shape[0]):
        new = np.where(state, stay_all[t], enter_all[t])
        if supported and not new.any():  # support would vanish: the feet low and still hold
            new = hold_all[t]
        state = new
        supported = state.any()
        out[t] = state
    return out


def planted_feet(speed3: np.ndarray, fps: float) -> np.ndarray:
    """(T, F) bool: the foot's lowest sole sphere moves slower than
    :data:`~sim.physics.feet.STILL_SPEED` (3D) [m/s] through a run of at least
    :data:`~sim.physics.feet.STILL_TIME` [s] (``speed3`` (T, F) [m/s])."""
    sp = np.asarray(speed3, dtype=np.float64)
    n = max(1, int(round(STILL_TIME * fps)))
    out = np.zeros(sp.shape, dtype=bool)
    for f in range(sp.shape[1]):
        for a, e in runs(sp[:, f] < STILL_SPEED, n):
            out[a:e, f] = True
    return out


@dataclass(frozen=True)
class BodyContacts:
    """Ground contacts of the body beyond the soles (T frames, K body points).

    Attributes:
        names: (K,) the points (a knee is ``lfemur``, the end of the thigh; the pelvis ``root``):
            each is the body that carries it, where a ground force on it acts.
        contact: (T, K) bool labels.
        gap: (T, K) height of the point's sphere's lowest surface above the floor [m].
        bottoms: (T, K, 3) that lowest surface point [m].
    """

    names: tuple[str, ...]
    contact: np.ndarray
    gap: np.ndarray
    bottoms: np.ndarray

    def slice(self, start: int, stop: int) -> BodyContacts:
        return BodyContacts(
            self.names, self.contact[start:stop], self.gap[start:stop], self.bottoms[start:stop]
        )

    def shares(self) -> dict[str, float]:
        """Share of frames in which each body point that ever touches the floor does."""
        share = self.contact.mean(axis=0) if len(self.contact) else np.zeros(len(self.names))
        return {n: float(x) for n, x in zip(self.names, share, strict=True) if x > 0}


@dataclass(frozen=True)
class Contacts:
    """A motion's ground contacts: its feet (T frames, F feet, S sole spheres) and, where known,
    the rest of its body.

    Attributes:
        sides: (F,) the feet (``"l"``, ``"r"``).
        contact: (T, F) bool labels.
        sole: the sole spheres (:class:`sim.physics.feet.Sole`).
        gap: (T, S) each sphere's gap above the floor [m] at the frame's instant.
        foot_gap: (T, F) each foot's lowest gap [m] at the frame's instant.
        foot_speed: (T, F) horizontal speed of each foot's lowest sphere [m/s].
        lowest: (T, F, 3) each foot's lowest sole surface point [m].
        body: hands, knees, hips, back ... on the floor (:func:`body_contacts`; None: feet only).
    """

    sides: tuple[str, ...]
    contact: np.ndarray
    sole: Sole
    gap: np.ndarray
    foot_gap: np.ndarray
    foot_speed: np.ndarray
    lowest: np.ndarray
    body: BodyContacts | None = None

    def slice(self, start: int, stop: int) -> Contacts:
        """Frames ``[start, stop)`` (a clip of a trial labelled once)."""
        s = self.sole
        part = Sole(s.centres[start:stop], s.radius, s.side, s.part, s.body)
        return Contacts(
            self.sides, self.contact[start:stop], part, self.gap[start:stop],
            self.foot_gap[start:stop], self.foot_speed[start:stop], self.lowest[start:stop],
            None if self.body is None else self.body.slice(start, stop),
        )  # fmt: skip

    @property
    def supported(self) -> np.ndarray:
        """(T,) bool: some foot or other body point is on the floor."""
        on = self.contact.any(axis=1)
        return on if self.body is None else on | self.body.contact.any(axis=1)

    def points(self, ground: Ground, t: int) -> list[tuple[str, np.ndarray]]:
        """Where ground forces may act in frame ``t``: ``(body name, point (3,))`` for every sole
        sphere of a foot in contact that is within :data:`~sim.physics.feet.SUPPORT_GAP` of the
        floor (the lowest always), and every other body point in contact, each lowest point
        dropped onto the floor plane."""
        out = []
        if self.body is not None:
            for k in np.flatnonzero(self.body.contact[t]):
                p = self.body.bottoms[t, k].copy()
                p[2] = float(ground.level(p[:2]))
                out.append((self.body.names[k], p))
        b = self.sole.bottoms[t]
        for f, x in enumerate(self.sides):
            if not self.contact[t, f]:
                continue
            ks = self.sole.of(x)
            low = ks[np.argmin(self.gap[t, ks])]
            for k in ks:
                if k == low or self.gap[t, k] <= SUPPORT_GAP:
                    p = b[k].copy()
                    p[2] = float(ground.level(p[:2]))
                    out.append((self.sole.body[k], p))
        return out


def contacts_of_sole(
    s: Sole, fps: float, ground: Ground, *, initial=None, enter: float | None = None, rolling=None
) -> Contacts:
    """The :class:`Contacts` of sole ``s`` at ``fps`` on ``ground`` (see the module docstring).

    ``initial``: (F,) contact state before frame 0; ``enter``: default :func:`enter_gap`;
    ``rolling``: (T, F) :func:`rolling_contact` of each foot (None: geometry only)."""
    gap = ground.gaps(s)  # (T, S)
    ig = interval_gap(gap)
    hs = horizontal_speed(s.centres, fps)  # (T, S)
    T = gap.shape[0]
    fg, fi, fs, lo = [], [], [], []
    b = s.bottoms
    for x in s.sides:
        ks = s.of(x)
        k_int = ks[np.argmin(ig[:, ks], axis=1)]
        k_now = ks[np.argmin(gap[:, ks], axis=1)]
        fi.append(ig[np.arange(T), k_int])
        fs.append(hs[np.arange(T), k_now])
        fg.append(gap[np.arange(T), k_now])
        lo.append(b[np.arange(T), k_now])
    fi, fs = np.stack(fi, axis=1), np.stack(fs, axis=1)
    vs = np.gradient(fi, 1.0 / fps, axis=0) if T > 1 else np.zeros_like(fi)
    labels = label_contacts(
        fi, fs, enter=enter_gap(ground) if enter is None else enter, release=ground.noise,
        initial=initial, rolling=rolling, vspeed=vs,
        planted=planted_feet(np.hypot(fs, vs), fps),
    )  # fmt: skip
    return Contacts(s.sides, labels, s, gap, np.stack(fg, 1), fs, np.stack(lo, axis=1))


def body_contacts(
    positions: np.ndarray,
    names,
    parents,
    fps: float,
    ground: Ground,
    *,
    radius=None,
    initial=None,
    enter: float | None = None,
    points=None,
) -> BodyContacts:
    """Which body points other than the feet rest on the floor (T frames).

    Every point but the feet's (ankle, ball, toe tip: the sole's) is a sphere as wide as the
    widest bone capsule meeting there (:func:`sim.model.capsules.bones_of`): knees, hips and
    pelvis, spine, shoulders, elbows, wrists, hands, head. A point enters contact as a foot does:
    when its sphere comes within ``enter`` (:func:`enter_gap`) of the floor during the frame while
    it moves slower than :data:`~sim.physics.feet.ENTER_SPEED` horizontally (a hand swept past
    the floor is not planted on it), and leaves once it is ``enter`` plus the floor's spread up.

    Args:
        positions: (T, P, 3) points [m]; names, parents: (P,) as in a clip.
        radius: (P - 1,) capsule radius of each bone (default: :func:`bones_of`'s).
        initial: (K,) bool state before frame 0.
        points: the names of the points that may rest on the floor (default: all but the
            feet's); e.g. the points a reconstruction has, so that the original's support is
            judged on the same body.
    """
    names = tuple(names)
    p = np.asarray(positions, dtype=np.float64)
    bones = bones_of(names, parents)
    r_bone = bones.radius if radius is None else np.asarray(radius, dtype=np.float64)
    r = np.zeros(len(names))
    for b, (a, c) in enumerate(zip(bones.parent, bones.child, strict=True)):
        r[a], r[c] = max(r[a], r_bone[b]), max(r[c], r_bone[b])
    allowed = set(names) if points is None else set(points)
    keep = [j for j, n in enumerate(names) if n in allowed and n not in FOOT_POINTS and r[j] > 0]
    bottoms = p[:, keep].copy()
    bottoms[..., 2] -= r[keep]
    gap = bottoms[..., 2] - ground.level(bottoms[..., :2])  # (T, K)
    ig = interval_gap(gap)
    fast = horizontal_speed(p[:, keep], fps) >= ENTER_SPEED
    e = enter_gap(ground) if enter is None else enter
    enter_all = (ig <= e) & ~fast
    stay_all = ig <= e + ground.noise
    out = np.zeros(gap.shape, dtype=bool)
    state = np.zeros(len(keep), dtype=bool) if initial is None else np.array(initial, bool)
    for t in range(len(gap)):
        state = np.where(state, stay_all[t], enter_all[t])
        out[t] = state
    return BodyContacts(tuple(names[j] for j in keep), out, gap, bottoms)


def motion_contacts(
    positions: np.ndarray, names, fps: float, ground: Ground, *, initial=None, velocities=None
) -> Contacts:
    """:func:`contacts_of_sole` of the sole of points ``positions`` (T, P, 3) [m] named
    ``names``, rolling contact included; ``velocities`` (T, P, 3) [m/s] where known (default:
    central differences)."""
    names = tuple(names)
    p = np.asarray(positions, dtype=np.float64)
    v = np.gradient(p, 1.0 / fps, axis=0) if velocities is None or len(p) < 2 else velocities
    if len(p) < 2:
        v = np.zeros_like(p)
    s = sole(p, names)
    roll = []
    for x in s.sides:
        a, b = names.index(x + "tibia"), names.index(x + "foot")
        roll.append(rolling_contact(p[:, a], p[:, b], v[:, a], v[:, b], ground)[0])
    return contacts_of_sole(s, fps, ground, initial=initial, rolling=np.stack(roll, axis=1))


def trial_contacts(
    positions: np.ndarray,
    names,
    fps: float,
    ground: Ground,
    velocities=None,
    parents=None,
    *,
    body_points=None,
) -> Contacts:
    """The contacts of a whole trial, labelled once (the hysteresis' memory runs through; a
    clip's labels are :meth:`Contacts.slice` of these).

    Args:
        positions: (T, J, 3) the trial's points [m]; names: (J,); fps [1/s]; velocities:
            (T, J, 3) [m/s] where known (a clip's chain velocities).
        parents: (J,) the points' parents: the rest of the body may rest on the floor too
            (:func:`body_contacts`, on ``body_points``: default all); None: the feet only.
    """
    c = motion_contacts(positions, names, fps, ground, velocities=velocities)
    if parents is None:
        return c
    body = body_contacts(positions, names, parents, fps, ground, points=body_points)
    return replace(c, body=body)
