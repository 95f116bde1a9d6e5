"""The reconstruction that keeps contacts: run-length coded contact bits, two-bone IK, pinned feet."""

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.evaluation.cases import make_case
from sidql.evaluation.evaluate import evaluate
from sidql.keyframes import reconstructions
from sidql.keyframes.contact_pinning import (
    BLEND_S,
    LEGS,
    _rolled,
    _steps,
    blend_offsets,
    decode_floor,
    decode_runs,
    encode_floor,
    encode_runs,
    foot_offsets,
    pin_feet,
    two_bone_ik,
)
from sidql.keyframes.spherical import POINTS, protocol_parent_indices
from sim.errors import MotionDataError
from sim.physics.feet import sole
from sim.physics.ground import Ground

FPS = 30.0
PARENTS = protocol_parent_indices()


def test_contact_runs_round_trip_and_cost_one_byte_per_change():
    rng = np.random.default_rng(3)
    for N in (1, 2, 60, 300):
        bits = rng.random((N, 2)) < 0.5
        bits[: N // 3, 0] = True  # long runs too
        code = encode_runs(bits)
        assert np.array_equal(decode_runs(code, N), bits)
        changes = sum(int(np.sum(bits[1:, f] != bits[:-1, f])) for f in range(2))
        # one header byte per foot, one byte per run but the last (runs < 128 frames)
        if N < 128:
            assert len(code) == 2 + changes


def test_the_floor_travels_in_20_bytes():
    g = Ground(0.03, ("l", "r"), np.array([0.004, 0.0]), slope=(0.002, -0.001), origin=(1.0, 2.0))
    code = encode_floor(g)
    floor = decode_floor(code)
    assert len(code) == 20
    xy = np.array([[0.5, -3.0], [4.0, 7.0]])
    level = g.level(xy)  # the ground's own plane, at two points far apart
    assert np.allclose(floor[0] + xy @ floor[1:3], level, atol=1e-6)
    assert np.allclose(floor[3:], [0.004, 0.0], atol=1e-9)
    with pytest.raises(MotionDataError):
        decode_floor(code[:-1])


def test_contact_runs_reject_bytes_that_do_not_describe_the_clip():
    code = encode_runs(np.array([[1, 0]] * 10 + [[0, 1]] * 5, dtype=bool))
    with pytest.raises(MotionDataError):
        decode_runs(code, 10)  # the last run would be empty
    with pytest.raises(MotionDataError):
        decode_runs(code, 9)  # the runs overrun the frames
    with pytest.raises(MotionDataError):
        decode_runs(code[:-1], 15)
    with pytest.raises(MotionDataError):
        decode_runs(code + b"\x00", 15)


def _legs(T, rng):
    hip = rng.normal(size=(T, 3)) * 0.05 + [0, 0, 0.9]
    knee = hip + [0.1, 0.0, -0.4] + rng.normal(size=(T, 3)) * 0.02
    ankle = knee + [-0.1, 0.0, -0.4] + rng.normal(size=(T, 3)) * 0.02
    ball = ankle + [0.14, 0.0, -0.07]
    return np.stack([hip, knee, ankle, ball], axis=1)


def test_two_bone_ik_keeps_bone_lengths_and_reaches_reachable_targets():
    rng = np.random.default_rng(0)
    leg = _legs(200, rng)
    l1 = np.linalg.norm(leg[:, 1] - leg[:, 0], axis=-1)
    l2 = np.linalg.norm(leg[:, 2] - leg[:, 1], axis=-1)
    target = leg[:, 2] + rng.normal(size=(200, 3)) * 0.3
    knee, ankle = two_bone_ik(leg, target)
    assert np.allclose(np.linalg.norm(knee - leg[:, 0], axis=-1), l1, atol=1e-12)
    assert np.allclose(np.linalg.norm(ankle - knee, axis=-1), l2, atol=1e-12)
    reach = np.linalg.norm(target - leg[:, 0], axis=-1)
    ok = (reach < 0.999 * (l1 + l2)) & (reach > 1.001 * np.abs(l1 - l2))
    assert ok.sum() > 50
    assert np.allclose(ankle[ok], target[ok], atol=1e-9)
    far = reach > l1 + l2  # out of reach: as far as the leg goes, towards the target
    u = (target - leg[:, 0])[far] / reach[far, None]
    got = (ankle - leg[:, 0])[far]
    assert np.allclose(np.cross(got, u), 0, atol=1e-9)
    assert np.all(np.linalg.norm(got, axis=-1) <= (l1 + l2)[far] + 1e-12)


def test_two_bone_ik_bends_the_knee_in_its_own_plane():
    rng = np.random.default_rng(1)
    leg = _legs(50, rng)
    target = leg[:, 2] + [0.05, 0.0, 0.02]
    knee, ankle = two_bone_ik(leg, target)
    # the new knee lies in the plane of hip, old knee and the target line
    n = np.cross(leg[:, 1] - leg[:, 0], target - leg[:, 0])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert np.allclose(np.sum((knee - leg[:, 0]) * n, axis=-1), 0, atol=1e-9)
    # on the same side as before (no flipped knee)
    u = (target - leg[:, 0]) / np.linalg.norm(target - leg[:, 0], axis=-1, keepdims=True)
    side = lambda k: k - leg[:, 0] - np.sum((k - leg[:, 0]) * u, -1, keepdims=True) * u  # noqa: E731
    assert np.all(np.sum(side(knee) * side(leg[:, 1]), axis=-1) > 0)


def _walker(N=60, speed=0.3, raised=None):
    """(N, 23, 3) a standing body sliding forward at ``speed`` [m/s] and bobbing 1 cm: every foot
    skates, nothing rotates; the foot ``raised`` ("l" or "r") is held 3 cm higher (in the air,
    never under the floor the other shows)."""
    base = np.zeros((len(POINTS), 3))
    place = {
        "root": (0, 0, 0.95), "lhipjoint": (0, 0.09, 0.9), "lfemur": (0.1, 0.09, 0.5),
        "ltibia": (0.0, 0.09, 0.1), "lfoot": (0.14, 0.09, 0.03), "rhipjoint": (0, -0.09, 0.9),
        "rfemur": (0.1, -0.09, 0.5), "rtibia": (0.0, -0.09, 0.1), "rfoot": (0.14, -0.09, 0.03),
    }  # fmt: skip
    for k, n in enumerate(POINTS):
        base[k] = place.get(n, (0.0, 0.02 * k, 1.0 + 0.03 * k))
    if raised:
        base[[POINTS.index(raised + "tibia"), POINTS.index(raised + "foot")], 2] += 0.03
    t = np.arange(N) / FPS
    shift = np.stack([speed * t, 0 * t, 0.01 * np.sin(2 * np.pi * t)], axis=1)
    return base[None] + shift[:, None]


def _flat(P, t, foot=0):
    """(5,) a horizontal floor at the height of foot ``foot``'s lowest sole point in frame ``t``
    (the sole geometry of sim.physics.feet)."""
    s = sole(P[t : t + 1], POINTS)
    z = float(s.bottoms[0, s.of("lr"[foot]), 2].min())
    return np.array([z, 0.0, 0.0, 0.0, 0.0])


def _lengths(P):
    return np.linalg.norm(P[:, 1:] - P[:, PARENTS[1:]], axis=-1)


def test_pinned_foot_stays_where_it_was_at_its_keyframe_and_bones_keep_lengths():
    P = _walker(raised="r")
    c = np.zeros((60, 2), bool)
    c[10:31, 0] = True  # left foot down over frames 10-30, keyframe 20 inside
    keys = np.array([0, 20, 59])
    out = pin_feet(P, c, keys, FPS, floor=_flat(P, 20))
    assert np.allclose(_lengths(out), _lengths(P), atol=1e-12)
    _, knee, ankle, ball = LEGS[0]
    for j in (ankle, ball):
        assert np.allclose(out[10:31, j], P[20, j], atol=1e-9)  # stationary, at the keyframe's
    assert np.allclose(out[20], P[20], atol=1e-12)  # the anchor keyframe is exact
    moved = np.abs(out - P).max(axis=(0, 2)) > 0
    assert set(np.flatnonzero(moved)) == {knee, ankle, ball}  # only the pinned leg moves
    w = int(round(BLEND_S * FPS))
    far = np.r_[0 : 10 - w, 31 + w : 60]
    clear = [np.all(P[max(0, t - w) : t + w + 1, ankle, 2] > P[20, ankle, 2] + 1e-9) for t in far]
    far = far[clear]  # (nearer a dip under the floor, the foot is lifted onto it)
    assert len(far) > 5
    assert np.array_equal(out[far], P[far])  # unchanged away from the contact and its blends


def test_keyframes_stay_exact_and_the_pin_slides_linearly_between_two_of_them():
    P = _walker(raised="r")
    c = np.zeros((60, 2), bool)
    c[10:41, 0] = True
    keys = np.array([0, 15, 35, 59])
    out = pin_feet(P, c, keys, FPS, floor=_flat(P, 15))
    assert np.array_equal(out[[15, 35]], P[[15, 35]])  # the run's keyframes are exact
    ankle = LEGS[0][2]
    s = (np.arange(15, 36) - 15) / 20.0
    line = (1 - s)[:, None] * P[15, ankle] + s[:, None] * P[35, ankle]
    xy = (slice(None), ankle, slice(0, 2))
    assert np.allclose(out[15:36][xy], line[:, :2], atol=1e-9)  # the original's net slide only
    assert np.allclose(out[10:16][xy], P[15, ankle, :2], atol=1e-9)  # still before the first
    assert np.allclose(out[35:41][xy], P[35, ankle, :2], atol=1e-9)  # and after the last
    # the height goes linearly from one keyframe's to the next (the walker bobs: the floor is
    # frame 15's, the lower of the two, so nothing is lifted)
    floor = P[15, ankle, 2]  # the ankle's height when the lowest sole point is on the floor
    assert P[35, ankle, 2] > floor
    assert np.allclose(out[15:36, ankle, 2], line[:, 2], atol=1e-9)
    assert np.allclose(out[10:16, ankle, 2], floor, atol=1e-9)
    assert np.allclose(_lengths(out), _lengths(P), atol=1e-12)


def test_a_foot_under_the_floor_is_lifted_onto_it_smoothly():
    P = _walker()
    c = np.zeros((60, 2), bool)
    c[:, 0] = True  # the left foot stands; the right one bobs 1 cm under its floor half the time
    keys = np.array([0, 30, 59])
    out = pin_feet(P, c, keys, FPS, floor=_flat(P, 30))
    floor = P[30, LEGS[0][2], 2]  # both feet alike: the ankle's height on that floor
    r_ankle = LEGS[1][2]
    assert np.all(out[:, r_ankle, 2] >= floor - 1e-9)
    # lifted smoothly: the lift changes by at most 1.5 x the deepest dip / (w + 1) per frame
    w = int(round(BLEND_S * FPS))
    lift = out[:, r_ankle, 2] - P[:, r_ankle, 2]
    deepest = np.maximum(floor - P[:, r_ankle, 2], 0).max()
    assert deepest > 0.005 and lift.min() >= -1e-12
    assert np.abs(np.diff(lift)).max() <= 1.5 * deepest / (w + 1) + 1e-9
    far = [t for t in range(60) if np.all(P[max(0, t - w) : t + w + 1, r_ankle, 2] >= floor)]
    assert len(far) and np.array_equal(out[far, r_ankle], P[far, r_ankle])  # no dip near


def test_no_contact_changes_nothing():
    P = _walker()
    out = pin_feet(P, np.zeros((60, 2), bool), np.array([0, 30, 59]), FPS)
    assert np.array_equal(out, P)


def test_blends_in_and_out_smoothly():
    P = _walker(speed=0.6, raised="l")
    c = np.zeros((60, 2), bool)
    c[20:35, 1] = True
    out = pin_feet(P, c, np.array([0, 27, 59]), FPS)
    ankle = LEGS[1][2]
    off = out[:, ankle] - P[:, ankle]
    size = np.abs(off).max()
    assert size > 0.03
    w = int(round(BLEND_S * FPS))
    # a smoothstep over w + 1 frames moves at most 1.5 x its size / (w + 1) per frame, and its
    # rate changes by at most 6 x size / (w + 1)^2 per frame (plus the pin's own rate, speed/fps)
    step = np.linalg.norm(np.diff(off, axis=0), axis=-1)
    assert step.max() <= 1.5 * size / (w + 1) + 0.6 / FPS + 1e-9
    jerk = np.linalg.norm(np.diff(off, 2, axis=0), axis=-1)
    assert jerk.max() <= 6 * size / (w + 1) ** 2 + 2 * 0.6 / FPS + 1e-9
    # the fade is monotone: the offset shrinks away from the run
    before = np.linalg.norm(off[20 - w - 1 : 20], axis=-1)
    assert np.all(np.diff(before) >= -1e-12)


def test_rolled_offsets_hold_the_lowest_sole_sphere_still_and_vanish_at_the_anchor():
    rng = np.random.default_rng(7)
    bottoms = rng.normal(size=(40, 3, 3))
    low = rng.integers(0, 3, size=40)
    a, e = 5, 31
    fwd, back = _steps(bottoms, low, a, e)
    for k in (0, 9, e - a - 1):
        out = _rolled(fwd, back, k)
        assert out.shape == (e - a, 2) and np.array_equal(out[k], [0.0, 0.0])
        for t in range(a + 1, e):  # the sphere lowest at the later (after) / earlier frame
            s = low[t] if t > a + k else low[t - 1]
            moved = bottoms[t, s, :2] + out[t - a] - (bottoms[t - 1, s, :2] + out[t - 1 - a])
            assert np.allclose(moved, 0.0, atol=1e-12)


def test_blend_offsets_fade_each_run_by_a_smoothstep_and_normalise_overlaps():
    contact = np.zeros(30, bool)
    contact[5:9] = contact[14:16] = True
    offsets = np.arange(90.0).reshape(30, 3)
    width = 4
    out = blend_offsets(offsets, contact, width)
    assert np.array_equal(out[contact], offsets[contact])

    def fade(d):  # 1 - smoothstep(d / (width + 1))
        x = min(d / (width + 1), 1.0)
        return 1.0 - x * x * (3.0 - 2.0 * x)

    for t in np.flatnonzero(~contact):
        ends, starts = [e for e in (8, 15) if e < t], [s for s in (5, 14) if s > t]
        terms = [(fade(t - ends[-1]), offsets[ends[-1]])] if ends else []
        terms += [(fade(starts[0] - t), offsets[starts[0]])] if starts else []
        total = sum((w * o for w, o in terms), np.zeros(3))
        weight = sum(w for w, _ in terms)
        assert np.allclose(out[t], total / max(1.0, weight), rtol=1e-12, atol=1e-12)


def test_contacts_reconstruction_counts_its_bits_and_keeps_bone_lengths():
    clip = smooth_clip(60, 30.0, seed=5)
    keys = np.array([0, 17, 40, 59])
    rec = reconstructions.rebuild("contacts", clip, keys)
    base = reconstructions.rebuild("hermite", clip, keys)
    assert rec.side_bytes >= 2 and rec.reconstruction == "contacts"
    assert np.allclose(_lengths(rec.positions), _lengths(base.positions), atol=1e-9)
    assert np.isfinite(rec.accelerations).all() and np.isfinite(rec.velocities).all()
    legs = [j for leg in LEGS for j in leg[1:]]
    rest = np.setdiff1d(np.arange(len(POINTS)), legs)
    assert np.array_equal(rec.positions[:, rest], base.positions[:, rest])


def test_evaluate_rebuilds_any_method_with_the_named_reconstruction():
    cases = [make_case(smooth_clip(60, 30.0, seed=40 + i), i) for i in range(2)]
    own = evaluate(cases, ["uniform"], [5], progress=False)
    pinned = evaluate(cases, ["uniform"], [5], progress=False, reconstruction="contacts")
    for a, b in zip(own["per_clip"], pinned["per_clip"], strict=True):
        assert a["indices"] == b["indices"]  # the same choice, rebuilt two ways
        assert a["reconstruction"] == "hermite" and b["reconstruction"] == "contacts"
        assert a["side_bytes"] == 0 and b["side_bytes"] >= 2
        assert b["q_hermite"] == a["q"]
    with pytest.raises(ValueError, match="unknown reconstruction"):
        evaluate(cases, ["uniform"], [5], progress=False, reconstruction="nope")


def _offsets_by_anchor(bottoms, contact, keyframes):
    """The horizontal pin offsets as the docstring of ``foot_offsets`` words them, one anchor
    per keyframe of a run (the offsets that keep the lowest sphere still, 0 at the keyframe),
    each frame blending the anchors of the keyframes around it: written independently."""
    N = len(contact)
    low = bottoms[..., 2].argmin(axis=1)
    out = np.zeros((N, 2))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], contact.astype(int), [0]])))
    for a, e in zip(edges[::2], edges[1::2], strict=True):
        keys = [k for k in keyframes if a <= k < e] or [a]  # none: held where it touched down
        anchors = []
        for k in keys:
            A = np.zeros((e - a, 2))
            for t in range(k + 1, e):  # after the keyframe: less each step forwards
                A[t - a] = A[t - 1 - a] - (bottoms[t, low[t], :2] - bottoms[t - 1, low[t], :2])
            for t in range(k - 1, a - 1, -1):  # before it: plus each step backwards
                A[t - a] = A[t + 1 - a] + (bottoms[t + 1, low[t], :2] - bottoms[t, low[t], :2])
            anchors.append(A)
        for t in range(a, e):
            i = max(0, min(sum(k <= t for k in keys) - 1, len(keys) - 1))
            j = min(i + 1, len(keys) - 1)
            s = 0.0 if t < keys[0] else min(max((t - keys[i]) / max(keys[j] - keys[i], 1), 0), 1)
            out[t] = (1 - s) * anchors[i][t - a] + s * anchors[j][t - a]
    return out


@pytest.mark.parametrize("seed", range(6))
def test_pinned_horizontal_offsets_are_the_blend_of_each_keyframes_anchor(seed):
    rng = np.random.default_rng(seed)
    N = 120
    bottoms = np.cumsum(rng.normal(0, 0.01, (N, 3, 3)), axis=0)
    contact = np.repeat(rng.random(N // 8 + 1) < 0.7, 8)[:N]
    every = rng.random() < 0.3  # every frame a keyframe (dense rates), or some
    keys = np.arange(N) if every else np.flatnonzero(rng.random(N) < 0.15)
    got = foot_offsets(bottoms, contact, keys, None)[:, :2]
    want = _offsets_by_anchor(bottoms, contact, keys)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
