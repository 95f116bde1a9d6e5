"""The foot-locked reference (``sim.simulate.footlock``): in stance each sole held still, flat on
the floor, by its leg's hinges; the root, the rest of the body and the swing away from stance
as they were. The oracle is MuJoCo's forward kinematics of the locked ``qpos``: each sole box's
corners computed here from its pose and half sizes."""

from __future__ import annotations

import pickle
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

import sim.simulate.validate as validate
from sim.errors import UsageError
from sim.model.humanoid import canonical_skeleton
from sim.simulate.footlock import (
    BLEND_S,
    LEG_JOINTS,
    LOCK_SPEED,
    foot_locked,
    lock_intervals,
    stance_intervals,
)
from sim.simulate.model import CONTROL_HZ
from sim.simulate.reference import time_warp

NAMES = ("root", "lfoot", "rfoot", "head")
SIGNS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)


@pytest.fixture(scope="module")
def body():
    return validate.forward_validation(
        canonical_skeleton(), NAMES, controller="plain", contact_reference=True
    )


@pytest.fixture(scope="module")
def walk(trial_on_floor, body):
    """(the contact-consistent reference of 02_01's walk at the control rate, its lock)."""
    ref = body.reference(trial_on_floor(body.model, "02_01"), 120.0)
    return ref, foot_locked(body.model, ref, CONTROL_HZ)


def _soles(model, qpos):
    """(T, 2, 4): per sole box (left, right) the bottom face's centre (x, y) and its lowest
    corner's height, and the box's tilt [rad] from flat, by MuJoCo's kinematics."""
    data = mujoco.MjData(model)
    out = np.empty((len(qpos), 2, 4))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for s, side in enumerate("lr"):
            g = model.geom(f"{side}sole").id
            R = data.geom_xmat[g].reshape(3, 3)
            corners = data.geom_xpos[g] + (SIGNS * model.geom_size[g]) @ R.T
            bottom = data.geom_xpos[g] - R[:, 2] * model.geom_size[g, 2]
            out[t, s] = bottom[0], bottom[1], corners[:, 2].min(), np.arccos(min(1.0, R[2, 2]))
    return out


def test_the_locked_soles_stand_still_flat_on_the_floor(body, walk):
    """Over half the walk's stance (a sole box's lowest corner within 3 cm) is held: the box flat
    (under 1 deg) with its lowest corner within 2 mm of z = 0; over each held run of at least
    0.05 s it stands still (median horizontal speed under 2 mm/s, where the reference slides
    at over 50 mm/s on the same frames)."""
    ref, out = walk
    model = body.model
    before, after = _soles(model, ref), _soles(model, out)
    for s in range(2):
        stance = before[:, s, 2] <= 0.03
        held = stance & (np.abs(after[:, s, 2]) < 0.002) & (after[:, s, 3] < np.radians(1.0))
        assert held.sum() > 0.5 * stance.sum()
        speed = np.linalg.norm(np.gradient(after[:, s, :2], 1 / CONTROL_HZ, axis=0), axis=-1)
        speed0 = np.linalg.norm(np.gradient(before[:, s, :2], 1 / CONTROL_HZ, axis=0), axis=-1)
        runs = [(a + 1, b - 1) for a, b in stance_intervals(held) if b - a >= 6]
        assert len(runs) >= 2
        inner = np.concatenate([np.arange(a, b) for a, b in runs])
        assert np.median(speed0[inner]) > 0.05  # the reference slides
        assert np.median(speed[inner]) < 0.002 and np.percentile(speed[inner], 90) < 0.02


def test_only_the_legs_change_and_the_swing_stays(body, walk):
    """The root and every coordinate but the legs' six hinges are the reference's in every
    frame; a frame whose legs changed is within the blend of a stance frame (a sole box's
    lowest corner within 3 cm), and a swing farther from stance is the reference's exactly."""
    ref, out = walk
    model = body.model
    adr = [model.jnt_qposadr[model.joint(f"{s}{j}").id] for s in "lr" for j in LEG_JOINTS]
    other = np.setdiff1d(np.arange(model.nq), adr)
    np.testing.assert_array_equal(out[:, other], ref[:, other])
    before = _soles(model, ref)
    n = int(round(BLEND_S * CONTROL_HZ))
    for s in range(2):
        near = np.zeros(len(ref), bool)
        for a, b in stance_intervals(before[:, s, 2] <= 0.03):
            near[max(0, a - n) : b + n] = True
        cols = adr[6 * s : 6 * s + 6]
        changed = (out[:, cols] != ref[:, cols]).any(axis=1)
        assert changed.sum() > 0.4 * len(ref) and (~near).sum() > 10
        assert not (changed & ~near).any()


def test_the_legs_stay_in_range_without_jumps(body, walk):
    """Every leg hinge is within its range or no farther out than the reference's (the IK
    fit's own hips go past theirs); the knee changes by less than 0.2 rad per tick (24 rad/s, about a fast kick's
    knee: no knee snapping through a hyper-extension; the reference's own reach 0.13 on the
    22 clips of ``--every 5``); no leg hinge moves faster than the reference's fastest (the IK
    fit twists a foot 0.44 rad in one tick at touch-down) plus 0.05 rad per tick (a blend's
    slope)."""
    ref, out = walk
    model = body.model
    for side in "lr":
        jids = [model.joint(f"{side}{j}").id for j in LEG_JOINTS]
        adr = model.jnt_qposadr[jids]
        lo, hi = model.jnt_range[jids, 0], model.jnt_range[jids, 1]
        captured = ref[:, adr]  # the IK fit's hips overextend: no farther than it
        assert (out[:, adr] >= np.minimum(lo, captured) - 1e-12).all()
        assert (out[:, adr] <= np.maximum(hi, captured) + 1e-12).all()
        jump = np.abs(np.diff(out[:, adr], axis=0)).max(axis=0)
        jump0 = np.abs(np.diff(ref[:, adr], axis=0)).max(axis=0)
        assert jump[3] < 0.2  # the knee
        assert jump.max() <= jump0.max() + 0.05  # the leg's fastest before, and a blend's slope


def test_lock_intervals_trim_the_swing_in_and_push_off():
    """A sole low over the floor for 1 s that sweeps in at 1 m/s for 0.2 s, stands, and leaves
    at 1 m/s for the last 0.2 s is locked in the standing part only; a low pass shorter than
    ``MIN_LOCK_S`` standing is not locked at all."""
    rate = 120.0
    T = 120
    x = np.zeros(T)
    x[:24] = -(24 - np.arange(24)) / rate  # 1 m/s into the stance
    x[96:] = (np.arange(24) + 1) / rate  # 1 m/s out of it
    centres = np.column_stack([x, np.zeros(T), np.full(T, 0.01)])
    (a, b),  = lock_intervals(np.zeros(T), centres, rate)  # fmt: skip
    assert 22 <= a <= 25 and 95 <= b <= 98 and LOCK_SPEED < 1.0
    fast = centres.copy()
    fast[:, 0] = np.arange(T) / rate
    fast[60:63, 0] = fast[60, 0]  # 3 still ticks
    assert lock_intervals(np.zeros(T), fast, rate) == []


def test_the_option_tracks_the_locked_reference_and_measures_as_before(body, walk, monkeypatch):
    """``ForwardValidation(foot_lock=True)``: the tracker is given the locked contact-consistent
    reference; a tracker ending in the lifted reference's states has the same figures with and
    without the option. The option needs the contact-consistent reference and goes to other
    processes."""
    model = body.model
    qpos = walk[0][::4]  # 30 fps
    tracked = {}
    locked = validate.ForwardValidation(model, NAMES, controller="plain", contact_reference=True,
                                        foot_lock=True)  # fmt: skip

    def perfect(model, ref, *, assist_limit, record_every):
        tracked["ref"] = ref
        states = body.reference(qpos, 30.0, tracked["floor"], contact=False)[::record_every]
        return SimpleNamespace(qpos=states, fell=False, fall_frame=-1, unstable=False,
                               joint_torque=np.zeros((len(states), model.nu)))  # fmt: skip

    monkeypatch.setattr(validate, "track", perfect)
    tracked["floor"] = body.floor_of(time_warp(model, qpos, 30.0, 1.0, CONTROL_HZ))
    plain = body.run(qpos, 30.0)
    contact_ref = tracked["ref"]
    figures = locked.run(qpos, 30.0)
    assert figures == plain
    np.testing.assert_array_equal(tracked["ref"], foot_locked(model, contact_ref, CONTROL_HZ))
    assert not np.array_equal(tracked["ref"], contact_ref)
    assert pickle.loads(pickle.dumps(locked)).foot_lock
    assert not pickle.loads(pickle.dumps(body)).foot_lock
    with pytest.raises(UsageError):
        validate.ForwardValidation(model, NAMES, controller="plain", contact_reference=False,
                                   foot_lock=True)  # fmt: skip
