"""Swing clearance and stance pivot (``sim.simulate.swingstance``): a sole lower than the
reference's swing sole (capped) pays its squared shortfall, a sole on its support turning
faster than the reference's stance sole pays the squared rate difference (by hand); the
reference itself pays nothing; stopped rollouts, terrain boxes and the heading's wrap are
handled. In the sampler, with the footprints, in tests/test_simulate_footprints.py (every sole
term off is today's search bit for bit, weighted another, deterministic one)."""

from __future__ import annotations

import numpy as np
import pytest
from sole_tracks import reference_sole_boxes, still_soles

from sim.model.humanoid import canonical_skeleton
from sim.simulate.footholding import reference_soles, sole_ids
from sim.simulate.footprints import sole_costs
from sim.simulate.model import sim_model
from sim.simulate.reference import contact_consistent
from sim.simulate.sampling import CostWeights
from sim.simulate.swingstance import (
    CLEARANCE_CAP,
    clearance_cost,
    pivot_cost,
    window_swing_stance_costs,
)
from sim.simulate.terrain import Box, boxes_terrain

SIZE = np.array([[0.045, 0.13, 0.01], [0.045, 0.13, 0.01]])  # sole half sizes [m]


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


def test_a_swing_sole_below_the_reference_s_pays_its_capped_shortfall_squared():
    ref_h = np.array([[0.05, 0.0], [0.02, 0.0], [0.005, 0.0], [0.2, 0.0]])  # (K=4, 2) [m]
    sim_h = np.array([[0.0, 0.0], [0.015, 0.0], [0.0, 0.0], [0.04, 0.0]])
    assert CLEARANCE_CAP == 0.03
    # tick 0: the reference 5 cm up, capped at 3: short 3 cm; tick 1: 2 cm against 1.5; tick 2:
    # the reference at 5 mm stands (within 1 cm): nothing; tick 3: 4 cm clears the cap
    want = (0.03**2 + 0.005**2) / 4
    assert clearance_cost(sim_h, ref_h) == pytest.approx(want, rel=1e-12)
    assert clearance_cost(ref_h, ref_h) == 0.0  # the reference itself
    assert clearance_cost(ref_h + 0.01, ref_h) == 0.0  # higher than the reference: free
    sunk = sim_h.copy()
    sunk[0, 0] = -0.002  # 2 mm into the floor: that too
    assert clearance_cost(sunk, ref_h) == pytest.approx((0.032**2 + 0.005**2) / 4, rel=1e-12)
    stopped = np.stack([sim_h, sim_h])
    stopped[1, 1:] = np.nan  # the second rollout stopped after its first tick
    np.testing.assert_allclose(clearance_cost(stopped, ref_h), [want, 0.03**2 / 4], rtol=1e-12)


def test_a_stance_sole_turning_on_the_floor_pays_its_yaw_rate_squared():
    dt = 0.1
    ref_yaw = np.zeros((4, 2))  # (K + 1 = 4, 2): three steps
    stance = np.ones((4, 2), dtype=bool)
    touch = np.ones((4, 2), dtype=bool)
    sim_yaw = np.zeros((4, 2))
    sim_yaw[:, 0] = [0.0, 0.1, 0.3, 0.3]  # 1, 2 and 0 rad/s
    want = (1.0**2 + 2.0**2 + 0.0) / 3
    assert pivot_cost(sim_yaw, ref_yaw, stance, touch, dt) == pytest.approx(want, rel=1e-12)
    assert pivot_cost(sim_yaw, sim_yaw, stance, touch, dt) == 0.0  # the reference itself
    turned = sim_yaw + 0.7  # a constant heading off the reference's does not pivot
    assert pivot_cost(turned, sim_yaw, stance, touch, dt) == pytest.approx(0.0, abs=1e-20)
    lifted = touch.copy()
    lifted[2, 0] = False  # off the floor at instant 2: steps 1 and 2 do not count
    assert pivot_cost(sim_yaw, ref_yaw, stance, lifted, dt) == pytest.approx(1.0 / 3)
    swing = stance.copy()
    swing[0, 0] = False  # the reference lifts it at the start: step 0 does not count
    assert pivot_cost(sim_yaw, ref_yaw, swing, touch, dt) == pytest.approx(4.0 / 3)
    wrap = np.zeros((4, 2))
    wrap[:, 0] = [3.1, -3.1, -3.1, -3.1]  # across +-pi: a step of 2 pi - 6.2 rad
    step = 2 * np.pi - 6.2
    assert pivot_cost(wrap, ref_yaw, stance, touch, dt) == pytest.approx((step / dt) ** 2 / 3)
    many = np.stack([sim_yaw, turned, wrap])
    np.testing.assert_allclose(
        pivot_cost(many, ref_yaw, stance, np.stack([touch] * 3), dt),
        [pivot_cost(y, ref_yaw, stance, touch, dt) for y in many],
        rtol=1e-12,
    )


def _records(S: int, K: int, lift: float = 0.0) -> tuple:
    """Flat soles 0.3 m apart, their bottoms ``lift`` [m] above z = 0, at K + 1 instants."""
    pos = np.zeros((S, K + 1, 2, 3))
    pos[..., 1, 1] = 0.3
    pos[..., 2] = 0.01 + lift
    mat = np.broadcast_to(np.eye(3).reshape(9), (S, K + 1, 2, 9)).copy()
    return pos, mat


def _turning(mat: np.ndarray, rate: float, dt: float) -> np.ndarray:
    """``mat`` (S, K + 1, 2, 9) with the left soles turning about z at ``rate`` [rad/s]."""
    out = mat.copy()
    for t in range(mat.shape[1]):
        c, s = np.cos(rate * dt * t), np.sin(rate * dt * t)
        out[:, t, 0] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).reshape(9)
    return out


def test_a_window_measures_heights_above_the_floor_or_a_box_and_turns_on_either():
    S, K, dt = 2, 12, 1 / 120
    pos, mat = _records(S, K)
    h_ref = np.zeros((K + 1, 2))
    h_ref[:, 0] = 0.1  # the reference swings its left foot 10 cm up, stands on its right
    stance = h_ref <= 0.04
    ref = (still_soles(K + 1), stance, np.ones(K + 1, dtype=bool), h_ref, np.zeros((K + 1, 2)))
    pos[1, :, 0, 2] += 0.02  # the second rollout lifts its left sole 2 cm: 1 cm short
    got = window_swing_stance_costs((pos, mat), SIZE, ref, None, dt, (100.0, 0.0))
    np.testing.assert_allclose(got, [100 * 0.03**2, 100 * 0.01**2], rtol=1e-12)
    # a 0.3 m box under the left sole: 2 cm above its top is 2 cm up
    box = Box(centre=np.array([0.0, 0.0, 0.15]), half=np.array([0.3, 0.1, 0.15]), yaw=0.0)
    up = pos.copy()
    up[..., 0, 2] += 0.3
    got = window_swing_stance_costs((up, mat), SIZE, ref, boxes_terrain([box]), dt, (100.0, 0))
    np.testing.assert_allclose(got, [100 * 0.03**2, 100 * 0.01**2], rtol=1e-12)
    # pivot: the right sole (the reference's stance) turning at 3 rad/s on the floor pays
    turn = _turning(mat[:, :, ::-1], 3.0, dt)[:, :, ::-1]  # the right sole turns
    got = window_swing_stance_costs((pos, turn), SIZE, ref, None, dt, (0.0, 0.5))
    np.testing.assert_allclose(got, 0.5 * 9.0, rtol=1e-9)
    # the left sole turning pays nothing: the reference does not stand on it
    got = window_swing_stance_costs((pos, _turning(mat, 3.0, dt)), SIZE, ref, None, dt, (0, 0.5))
    np.testing.assert_allclose(got, 0.0, atol=1e-12)
    stopped = turn.copy()
    stopped[1, 5:] = np.nan  # stopped after 4 ticks: 4 of 12 steps count
    got = window_swing_stance_costs((pos, stopped), SIZE, ref, None, dt, (0.0, 0.5))
    np.testing.assert_allclose(got, [4.5, 4.5 * 4 / 12], rtol=1e-9)


def test_the_reference_s_own_soles_cost_nothing_and_a_lowered_swing_sole_pays(
    trial_on_floor, model
):
    ref_qpos = contact_consistent(model, trial_on_floor(model, "07_01")[:61])
    ids = sole_ids(model)
    pos, mat = reference_sole_boxes(model, ref_qpos, ids)
    ref = reference_soles(model, ref_qpos, ids, capture=True)
    size, dt = model.geom_size[ids], 1 / 120
    weights = (1000.0, 1.0)
    assert window_swing_stance_costs((pos, mat), size, ref, None, dt, weights)[0] == 0.0
    h = ref[3][1:]
    swing = h > 0.01
    assert swing.any() and (~swing).any()  # the walk lifts a foot and stands on one
    lowered = pos - np.array([0.0, 0.0, 0.005])  # the whole body 5 mm lower
    want = np.sum(np.maximum(0.0, np.minimum(h, 0.03) - (h - 0.005))[swing] ** 2) / len(h)
    assert want > 0
    got = window_swing_stance_costs((lowered, mat), size, ref, None, dt, (1.0, 0.0))[0]
    assert got == pytest.approx(want, rel=1e-9)


def test_sole_costs_weigh_clearance_and_pivot_and_nothing_else(model):
    K, dt = 12, 1 / 120
    pos, mat = _records(3, K)
    pos[1:, :, 0, 2] += 0.02  # left soles 2 cm up
    mat[2] = _turning(mat[2:, :, ::-1], 2.0, dt)[0, :, ::-1]  # the third's right sole turns
    com = np.zeros((3, K + 1, 3))
    ids = sole_ids(model)
    h_ref = np.zeros((40, 2))
    h_ref[:, 0] = 0.1

    class Prob:  # what sole_costs reads of sampling._Problem
        base = np.zeros((40, 1))
        soles = slice(int(ids[0]), int(ids[1]) + 1, int(ids[1] - ids[0]))
        ref_soles = (still_soles(40), h_ref <= 0.04, np.ones(40, dtype=bool), h_ref, h_ref * 0)

    w = CostWeights(clearance=100.0, pivot=0.25)
    got = sole_costs(model, Prob, w, (8, 8 + K), (pos, mat, com))
    np.testing.assert_allclose(got, [0.09, 0.01, 0.01 + 0.25 * 4.0], rtol=1e-9)
