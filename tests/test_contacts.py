"""The floor and the foot contacts (sim.physics.ground, sim.physics.contacts): hand-made feet whose
answer is known, and MuJoCo's own contacts in motion simulated by sim.simulate."""

from __future__ import annotations

import numpy as np
import pytest

from sim.physics.contact_metrics import contact_metrics
from sim.physics.contacts import (
    body_contacts,
    interval_gap,
    label_contacts,
    motion_contacts,
    planted_feet,
    rolling_contact,
    trial_contacts,
)
from sim.physics.feet import HOLD_GAP, HOLD_SPEED, ROLL_GAP, STILL_SPEED, sole
from sim.physics.ground import MAX_OFFSET, Ground, estimate_ground

NAMES = ("ltibia", "lfoot", "ltoes", "rtibia", "rfoot", "rtoes")
FPS = 30.0


def _foot(ankle, ball, toe=(0.05, 0.0, -0.01)):
    """(3, 3) ankle, ball and toe tip of a flat foot whose ankle is at ``ankle``."""
    a = np.asarray(ankle, float)
    b = a + np.asarray(ball, float)
    return np.stack([a, b, b + np.asarray(toe, float)])


def _standing(T, z=0.0, slope=(0.0, 0.0), noise=0.0, seed=0):
    """Two feet taking turns on a (tilted) floor: each foot stands, lifts 10 cm and steps 40 cm
    forward, the other standing meanwhile; the soles' lowest points rest on the plane."""
    rng = np.random.default_rng(seed)
    p = np.zeros((T, 6, 3))
    x = {"l": 0.0, "r": 0.2}
    for t in range(T):
        phase = (t // 15) % 2  # 0.5 s per step
        moving = "l" if phase == 0 else "r"
        frac = (t % 15) / 15
        for k, s in enumerate("lr"):
            y = 0.1 if s == "l" else -0.1
            base = x[s] + (0.4 * frac if s == moving else 0.0)
            lift = 0.1 * np.sin(np.pi * frac) if s == moving else 0.0
            p[t, 3 * k : 3 * k + 3] = _foot((base, y, 0.08 + lift), (0.14, 0.0, -0.055))
        if t % 15 == 14:
            x[moving] += 0.4
    s = sole(p, NAMES)
    low = (s.centres[..., 2] - s.radius).min(axis=(0, 1))
    p[..., 2] += z - low + slope[0] * p[..., 0] + slope[1] * p[..., 1]
    return p + rng.normal(0, noise, p.shape)


def test_the_floor_is_fitted_through_the_footprints_tilted_and_noisy():
    p = _standing(240, z=0.07, slope=(0.02, 0.0), noise=0.001)
    g = estimate_ground(p, NAMES, FPS)
    assert g.slope[0] == pytest.approx(0.02, abs=0.003) and abs(g.slope[1]) < 0.01
    assert g.footprints >= 10 and g.fits and g.spread < 0.003
    s = sole(p, NAMES)
    gaps = g.gaps(s).min(axis=1)
    assert np.percentile(gaps, 5) == pytest.approx(0.0, abs=0.003)  # soles rest on it
    with pytest.raises(ValueError):
        estimate_ground(p[:, :, :2], NAMES, FPS)
    with pytest.raises(ValueError):
        estimate_ground(p, ("a", "b", "c", "d", "e", "f"), FPS)


def test_a_foot_held_still_in_the_air_is_not_a_floor():
    """One-leg balance: the right foot stands, the left is held still 6 cm up for 3 s: the floor
    is the right foot's, the left is never in contact."""
    T = 90
    p = np.zeros((T, 6, 3))
    p[:, 3:] = _foot((0.0, -0.1, 0.08), (0.14, 0.0, -0.055))
    p[:, :3] = _foot((0.0, 0.1, 0.08 + 0.06), (0.14, 0.0, -0.055))
    g = estimate_ground(p, NAMES, FPS)
    c = trial_contacts(p, NAMES, FPS, g)
    assert abs(g.offset_of("l")) <= MAX_OFFSET + 1e-12 and g.offset_of("r") == pytest.approx(0)
    assert c.contact[:, c.sides.index("r")].all() and not c.contact[:, c.sides.index("l")].any()


def test_labels_enter_at_the_floor_leave_above_it_and_a_swing_passes_by():
    gap = np.array([0.1, 0.02, 0.004, 0.0, 0.007, 0.012, 0.004, 0.003, 0.002, 0.0])
    v = np.array([0.0, 0.0, 0.1, 0.1, 0.4, 0.0, 3.0, 0.2, 0.2, 0.2])
    # the other foot stands throughout (the body never loses its support)
    gap2, v2 = np.column_stack([gap, np.zeros(10)]), np.column_stack([v, np.zeros(10)])
    got = label_contacts(gap2, v2, enter=0.005, release=0.005)
    # enter at 2 (on the floor, slow); stay through 7 mm (within 5 + 5); leave at 12 mm; frame 6
    # is on the floor but swinging past at 3 m/s; enter at 7
    assert got[:, 0].tolist() == [False, False, True, True, True, False, False, True, True, True]
    assert got[:, 1].all()
    rolling = np.zeros_like(gap2, bool)
    rolling[1, 0] = True  # a foot rolling on the floor is in contact though its sole is 2 cm up
    assert label_contacts(gap2, v2, enter=0.005, release=0.005, rolling=rolling)[1, 0]
    rolling[0, 0] = True  # ... but not 10 cm up: ROLL_GAP
    assert not label_contacts(gap2, v2, enter=0.005, release=0.005, rolling=rolling)[0, 0]
    # the frame's interval: a sole 8 mm up at the frame but landing before the next one
    assert interval_gap(np.array([0.008, -0.008]))[0] == pytest.approx(0.004)


def test_a_foot_rolling_about_its_heel_is_in_contact_though_its_heel_sphere_is_up():
    """A foot turning toes-up about a pivot 3 cm below its heel sphere (a real heel under the
    humanoid's capsule) at 5 rad/s: the sole's gap grows to 2-5 cm, yet the foot rolls on the
    floor."""
    T = 8
    pivot = np.array([-0.03, 0.1, 0.0])
    ankle0, ball0 = np.array([0.0, 0.1, 0.085]), np.array([0.14, 0.1, 0.03])
    p = np.zeros((T, 6, 3))
    v = np.zeros_like(p)
    w = -5.0  # about +y: toes up
    for t in range(T):
        a = w * t / FPS
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        for j, q in enumerate((ankle0, ball0, ball0 + [0.05, 0, -0.01])):
            r = R @ (q - pivot)
            p[t, j] = pivot + r
            v[t, j] = np.cross([0, w, 0], r)
        p[t, 3:] = _foot((0.0, -0.1, 0.08), (0.14, 0.0, -0.055))
    ground = Ground(0.0)
    roll, centre = rolling_contact(p[:, 0], p[:, 1], v[:, 0], v[:, 1], ground)
    assert roll.all()
    np.testing.assert_allclose(centre[:, [0, 2]], np.tile(pivot[[0, 2]], (T, 1)), atol=1e-9)
    c = motion_contacts(p, NAMES, FPS, ground, velocities=v)
    assert (c.foot_gap[2:, 0] > 0.015).all()
    # in contact while its sole comes within ROLL_GAP of the floor during the frame, not above
    reach = interval_gap(c.gap[:, c.sole.of("l")]).min(axis=1)
    up = reach > ROLL_GAP
    assert up.any() and (~up).sum() >= 2
    np.testing.assert_array_equal(c.contact[:, 0], ~up)


def test_support_does_not_vanish_between_a_push_off_and_a_heel_strike():
    """Double support a centimetre or two above the humanoid's rigid soles: the foot pushing off
    rises slowly, the other comes down; no frame in between is a flight. A foot that lifts or
    moves fast does not hold, and nothing holds a body already in the air."""
    T = 8
    push = np.array([0.0, 0.004, 0.008, 0.012, 0.016, 0.02, 0.03, 0.08])  # [m] rising slowly
    land = np.array([0.12, 0.08, 0.05, 0.03, 0.022, 0.012, 0.004, 0.0])
    gap = np.column_stack([push, land])
    hs = np.column_stack([np.full(T, 0.15), [3.0, 2.0, 1.0, 0.5, 0.3, 0.2, 0.1, 0.1]])
    vs = np.gradient(gap, 1.0 / FPS, axis=0)
    assert gap[3:6].min() > 0.008  # enter + release: without holding, frames 3-5 are flights
    got = label_contacts(gap, hs, enter=0.005, release=0.003, vspeed=vs)
    assert got.any(axis=1).all()  # supported in every frame
    assert got[:6, 0].all() and not got[6:, 0].any() and got[5:, 1].all()
    # the same push-off, but the foot already swinging away fast: a flight in between
    fast = hs.copy()
    fast[:, 0] = 2.0 * HOLD_SPEED
    assert not label_contacts(gap, fast, enter=0.005, release=0.003, vspeed=vs).any(axis=1).all()
    # a body in the air (no contact in the frame before) is not caught by a low, slow foot
    air = label_contacts(gap[2:], hs[2:], enter=0.005, release=0.003, vspeed=vs[2:],
                         initial=[False, False])  # fmt: skip
    assert not air[:4].any()


def test_a_foot_standing_still_a_little_above_the_floor_is_planted_not_one_held_up():
    """A dancer's forefoot standing still 2 cm above the humanoid's sole level is planted; a foot
    held still in the air (6 cm: a one-leg balance) is not, nor one moving."""
    T = 12
    speed = np.full((T, 3), 0.5 * STILL_SPEED)
    speed[:, 2] = 3 * STILL_SPEED
    planted = planted_feet(speed, FPS)
    assert planted[:, :2].all() and not planted[:, 2].any()
    gap = np.tile([0.02, 0.06, 0.02], (T, 1))
    got = label_contacts(gap, np.zeros((T, 3)), enter=0.005, planted=planted, initial=[0, 0, 0])
    assert got[:, 0].all() and not got[:, 1:].any()
    assert HOLD_GAP < 0.06


def _crawl(T, hand_z, hand_speed=0.0):
    """Points of a body on hands and knees: (positions (T, P, 3), names, parents)."""
    names = ("root", "lfemur", "ltibia", "lfoot", "thorax", "lhumerus", "lhand")
    parents = np.array([-1, 0, 1, 2, 0, 4, 5])
    base = np.array([[0.0, 0.0, 0.5], [0.0, 0.1, 0.05], [0.35, 0.1, 0.15], [0.45, 0.1, 0.12],
                     [-0.4, 0.0, 0.5], [-0.45, 0.15, 0.25], [-0.45, 0.15, hand_z]])  # fmt: skip
    p = np.tile(base, (T, 1, 1))
    p[:, 6, 0] += hand_speed * np.arange(T) / FPS
    return p, names, parents


def test_hands_and_knees_on_the_floor_are_ground_contacts():
    ground = Ground(0.0)
    p, names, parents = _crawl(10, hand_z=0.0)
    # the knee (end of the thigh) and the hand rest 1 cm into the floor with 4 cm spheres ...
    p[:, [1, 6], 2] = 0.03
    b = body_contacts(p, names, parents, FPS, ground, radius=np.full(6, 0.04))
    on = dict(zip(b.names, b.contact.all(axis=0), strict=True))
    assert on["lfemur"] and on["lhand"] and not on["root"] and not on["thorax"]
    assert "ltibia" not in b.names and "lfoot" not in b.names  # the feet are the sole's
    assert b.shares() == {"lfemur": 1.0, "lhand": 1.0}
    # ... a hand 10 cm up, or swept past the floor, is not
    q, *_ = _crawl(10, hand_z=0.13)
    q[:, 1, 2] = 0.03
    assert set(body_contacts(q, names, parents, FPS, ground, radius=np.full(6, 0.04))
               .shares()) == {"lfemur"}  # fmt: skip
    q, *_ = _crawl(10, hand_z=0.03, hand_speed=3.0)
    q[:, 1, 2] = 0.03
    assert "lhand" not in body_contacts(q, names, parents, FPS, ground,
                                        radius=np.full(6, 0.04)).shares()  # fmt: skip
    # the forces may act there, on the floor, on the body that carries the point
    feet = motion_contacts(p[:, [2, 3]], ("ltibia", "lfoot"), FPS, ground)
    from dataclasses import replace

    c = replace(feet, body=b)
    pts = dict(c.points(ground, 0))
    np.testing.assert_allclose(pts["lhand"], [-0.45, 0.15, 0.0])
    assert c.supported.all()


def test_a_trial_is_labelled_once_and_clips_are_slices():
    p = _standing(120, z=0.02, noise=0.0005)
    g = estimate_ground(p, NAMES, FPS)
    whole = trial_contacts(p, NAMES, FPS, g)
    part = whole.slice(60, 120)
    np.testing.assert_array_equal(part.contact, whole.contact[60:])
    assert part.sole.centres.shape[0] == 60


def test_contact_metrics_match_a_brute_force_count():
    rng = np.random.default_rng(1)
    p = _standing(30, noise=0.02)
    c = trial_contacts(p, NAMES, FPS, Ground(0.0))
    ref = rng.random(c.contact.shape) < 0.5
    m = contact_metrics(ref, c)
    h, v, own = c.foot_gap, c.foot_speed, c.contact
    T, F = h.shape
    pen = [max(0.0, -x) for x in h.ravel()]
    flo = [max(0.0, h[t, f]) for t in range(T) for f in range(F) if ref[t, f]]
    sk = [v[t, f] for t in range(T) for f in range(F) if ref[t, f]]
    tp = sum(ref[t, f] and own[t, f] for t in range(T) for f in range(F))
    assert m["penetration_mm"] == pytest.approx(1e3 * np.mean(pen))
    assert m["float_mm"] == pytest.approx(1e3 * np.mean(flo)) and m["float_n"] == len(flo)
    assert m["skate_mm_s"] == pytest.approx(1e3 * np.mean(sk)) and m["skate_n"] == len(sk)
    assert m["contact_precision"] == pytest.approx(tp / own.sum())
    assert m["contact_recall"] == pytest.approx(tp / ref.sum())
    empty = contact_metrics(np.zeros_like(ref), c)
    assert empty["float_n"] == 0 and np.isnan(empty["float_mm"])


# ------------------------------------------------------ against MuJoCo's contacts (sim.simulate)

#: CMU walks tracked in simulation (unperturbed "follow" tasks) and their length [s], each short
#: enough that the body stays up (60_01 falls after 3 s).
SIMULATED = (("02", "02_01", 2.8), ("07", "07_04", 3.7), ("35", "35_01", 2.9),
             ("05", "05_01", 4.9), ("16", "16_24", 2.4), ("60", "60_01", 2.5))  # fmt: skip


def test_labels_match_mujocos_contacts_in_simulated_motion(cmu_dir, monkeypatch):
    """Labels from the 30 fps points against MuJoCo's own foot-floor contacts in the same motion
    simulated by sim.simulate (the humanoid tracking CMU walks at 120 Hz, the floor at z = 0
    unknown to the labels): a foot is truly in contact in a frame when MuJoCo reports a force
    between the floor and its foot or toes at any control tick of the frame's interval.
    Precision and recall >= 0.95 per foot, pooled over the walks."""
    import functools

    from sim.simulate import episode_body as body
    from sim.simulate.generate import SynthTask, generate

    # The walks must stay up to be compared: on the default sole-box feet the plain tracker
    # with 0.5 body weight of assistance falls in 3 of these 6 (docs/synthetic.md), so they are
    # simulated on the capsule feet of motion capture, whose contacts the labels describe.
    monkeypatch.setattr(body, "sim_spec", functools.partial(body.sim_spec, soles=False))
    counts = {s: np.zeros(3, int) for s in "lr"}  # true positives, labelled, truly in contact
    for subject, trial, seconds in SIMULATED:
        task = SynthTask(
            "follow", 0, 0, str(cmu_dir / subject / f"{subject}.asf"),
            str(cmu_dir / subject / f"{trial}.amc"), seconds, 120.0, controller="plain", assist=0.5,
        )  # fmt: skip
        clip, record = generate(task)
        assert not record["fell"]
        truth120 = np.asarray(record["labels"]["sim_foot_contact"], bool)  # (ticks, 2)
        pos, vel = clip.positions[::4], clip.velocities[::4]  # the 30 fps frames
        T = len(pos)
        truth = np.stack(
            [[truth120[max(0, 4 * i - 2) : 4 * i + 2, k].any() for i in range(T)] for k in (0, 1)],
            axis=1,
        )
        g = estimate_ground(pos, clip.names, FPS)
        c = trial_contacts(pos, clip.names, FPS, g, vel)
        for k, s in enumerate("lr"):
            lab, tru = c.contact[:, c.sides.index(s)], truth[:, k]
            counts[s] += [int((lab & tru).sum()), int(lab.sum()), int(tru.sum())]
    for s, (tp, n_lab, n_true) in counts.items():
        assert n_true > 100
        assert tp / n_lab >= 0.95, f"{s} precision {tp / n_lab:.3f}"
        assert tp / n_true >= 0.95, f"{s} recall {tp / n_true:.3f}"
