"""Foot holding (``sim.simulate.footholding``): a stance sole that slides costs more than one
held still, the reference costs nothing, the cost is the squared excess speed computed by hand,
and the soles' bottoms and stance agree with the sole boxes' corners."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from sole_tracks import still_soles

from sim.model.humanoid import canonical_skeleton
from sim.simulate.balance import STANCE_HEIGHT
from sim.simulate.footholding import (
    as_slice,
    capture_supported,
    reference_soles,
    slide_cost,
    sole_bottoms,
    sole_ids,
    sole_lowest,
    window_hold_costs,
)
from sim.simulate.footholding import sole_corners as footholding_corners
from sim.simulate.model import CONTROL_HZ, sim_model
from sim.simulate.sampling import CostWeights, search_offsets
from sim.simulate.wholebody_reference import sole_corners

DT = 1.0 / CONTROL_HZ


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


def test_a_sliding_stance_foot_costs_its_squared_excess_speed_a_held_one_nothing():
    K = 12
    ref = still_soles(K)
    stance = np.ones((K, 2), dtype=bool)
    assert slide_cost(ref, ref, stance, DT) == 0.0  # the reference itself
    slid = ref.copy()
    slid[:, 0, 0] += 0.5 * DT * np.arange(K)  # the left sole slides at 0.5 m/s
    # by hand: (K - 1) steps of excess 0.5 m/s on one foot, over K - 1 steps
    assert slide_cost(slid, ref, stance, DT) == pytest.approx(0.25, rel=1e-12)
    faster = ref.copy()
    faster[:, 0, 0] += 1.0 * DT * np.arange(K)
    assert slide_cost(faster, ref, stance, DT) == pytest.approx(1.0, rel=1e-12)
    # no cost where the reference lifts that foot (at either end of a step)
    swing = stance.copy()
    swing[::2, 0] = False
    assert slide_cost(slid, ref, swing, DT) == 0.0
    swing[:, 0] = True
    swing[5, 0] = False  # steps 4 and 5 touch tick 5: 9 of 11 steps count
    assert slide_cost(slid, ref, swing, DT) == pytest.approx(0.25 * 9 / 11, rel=1e-12)


def test_a_dragged_foot_costs_its_squared_speed_a_lifted_one_nothing():
    """Where the reference lifts a foot, a simulated sole that touches the floor (both ends of
    a step) may not move at all: it pays its whole speed squared; one in the air pays nothing,
    whatever its speed."""
    K = 9
    ref = still_soles(K)
    ref[:, 0, 0] += 2.0 * DT * np.arange(K)  # the reference swings its left foot at 2 m/s
    stance = np.ones((K, 2), dtype=bool)
    stance[:, 0] = False
    sim = still_soles(K)
    sim[:, 0, 0] += 0.3 * DT * np.arange(K)  # the simulated left sole moves at 0.3 m/s
    touch = np.zeros((K, 2), dtype=bool)
    assert slide_cost(sim, ref, stance, DT, touch) == 0.0  # in the air
    touch[:, 0] = True  # dragged along the floor
    assert slide_cost(sim, ref, stance, DT, touch) == pytest.approx(0.09, rel=1e-12)
    assert slide_cost(sim, ref, stance, DT) == 0.0  # stance steps only
    touch[:, 1] = True  # the right sole stands, as the reference's: still free
    assert slide_cost(sim, ref, stance, DT, touch) == pytest.approx(0.09, rel=1e-12)
    # on the reference itself nothing, with its own contacts
    assert slide_cost(ref, ref, stance, DT, stance) == 0.0


def test_a_foot_no_faster_than_the_reference_s_costs_nothing():
    """The term asks for no less sliding than the motion itself has: a simulated sole moving
    as fast as (or slower than) the reference's, in any direction, costs nothing."""
    K = 10
    ref = still_soles(K)
    ref[:, 0, 0] += 0.4 * DT * np.arange(K)  # the reference slides at 0.4 m/s along x
    sim = still_soles(K)
    sim[:, 0, 1] += 0.4 * DT * np.arange(K)  # the simulated one as fast along y
    stance = np.ones((K, 2), dtype=bool)
    assert slide_cost(sim, ref, stance, DT) == pytest.approx(0.0, abs=1e-18)
    sim[:, 0, 1] *= 0.5
    assert slide_cost(sim, ref, stance, DT) == 0.0
    assert slide_cost(sim[:1], ref[:1], stance[:1], DT) == 0.0  # one tick: no step


def test_sole_bottoms_and_stance_agree_with_the_sole_boxes_corners(trial_on_floor, model):
    """The bottom centre is the mean of the box's four bottom corners, and a reference sole is
    in stance where its lowest corner is at most STANCE_HEIGHT high (corners from
    ``wholebody_reference.sole_corners``, an independent computation)."""
    ref = trial_on_floor(model, "07_01")[:120]
    ids = sole_ids(model)
    xy, stance = reference_soles(model, ref, ids)
    assert 0.2 < stance.mean() < 1.0  # a walk: both feet down at times, one lifted at others
    data = mujoco.MjData(model)
    for t in range(0, len(ref), 9):
        data.qpos[:] = ref[t]
        mujoco.mj_kinematics(model, data)
        corners = [sole_corners(model, data, g) for g in ids]
        centre = np.array([c.mean(axis=0) for c in corners])
        bottom = sole_bottoms(data.geom_xpos[ids], data.geom_xmat[ids], model.geom_size[ids, 2])
        np.testing.assert_allclose(bottom, centre, atol=1e-12)
        np.testing.assert_allclose(xy[t], centre[:, :2], atol=1e-12)
        low = np.array([c[:, 2].min() for c in corners])
        lowest = sole_lowest(data.geom_xpos[ids], data.geom_xmat[ids], model.geom_size[ids])
        np.testing.assert_allclose(lowest, low, atol=1e-12)
        assert np.array_equal(stance[t], low <= STANCE_HEIGHT)


def test_a_body_without_soles_has_no_foot_holding():
    bare = sim_model(canonical_skeleton(), soles=False)
    assert sole_ids(bare) is None


def test_search_with_foot_holding_is_deterministic_and_another_search(trial_on_floor, model):
    ref = trial_on_floor(model, "07_01")[:48]
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=4)
    a, ra = search_offsets(model, ref, weights=CostWeights(hold=200.0), **kw)
    b, rb = search_offsets(model, ref, weights=CostWeights(hold=200.0), **kw)
    c, _ = search_offsets(model, ref, weights=CostWeights(hold=0.0), **kw)
    assert np.array_equal(a, b) and np.array_equal(ra, rb)
    assert not np.array_equal(a, c)  # the term changes which candidates are kept


def test_many_motions_at_once_cost_what_each_costs_alone():
    rng = np.random.default_rng(0)
    K = 7
    ref = still_soles(K)
    sims = ref + 0.01 * rng.standard_normal((5, K, 2, 2))
    stance = rng.random((K, 2)) > 0.3
    touch = rng.random((5, K, 2)) > 0.5
    many = slide_cost(sims, ref, stance, DT, touch)
    assert many.shape == (5,) and many.max() > 0
    for i in range(5):
        assert many[i] == pytest.approx(slide_cost(sims[i], ref, stance, DT, touch[i]), rel=1e-12)


@pytest.mark.parametrize("ids", [(6, 13), (13, 6), (0, 1), (3, 0), (1, 0)])
def test_as_slice_picks_the_rows_fancy_indexing_picks(ids):
    rows = np.arange(40.0).reshape(20, 2)
    np.testing.assert_array_equal(rows[as_slice(np.array(ids))], rows[list(ids)])


def _box_corners(centre_xy, half=(0.13, 0.045)) -> np.ndarray:
    """(4, 3) the corners of a flat sole on the floor, centred at ``centre_xy``, by hand."""
    (x, y), (a, b) = centre_xy, half
    return np.array([[x + a, y + b, 0], [x + a, y - b, 0], [x - a, y - b, 0], [x - a, y + b, 0]])


def test_the_capture_point_is_inside_the_support_where_hand_computation_puts_it():
    """Soles at (0, 0) and (0, 0.3), 26 x 9 cm; the centre of mass at height g / 9 (omega = 3
    /s): at rest over a sole inside; at rest 0.2 m in front of it outside; over the sole at
    0.3 m/s (capture point 0.1 m ahead, under the half length 0.13) inside, at 0.6 m/s (0.2 m
    ahead) outside; between the soles (in neither box, inside their hull) inside with both
    touching, outside with one; no sole touching: outside."""
    g, dt, K = 9.81, DT, 3
    corners = np.broadcast_to(
        np.stack([_box_corners((0, 0)), _box_corners((0, 0.3))]), (K, 2, 4, 3)
    )
    both = np.ones((K, 2), dtype=bool)

    def inside(xy, v=(0.0, 0.0), touch=both):
        com = np.array([[xy[0] + v[0] * dt * k, xy[1] + v[1] * dt * k, g / 9.0] for k in range(K)])
        return capture_supported(com, corners, touch, dt, g)

    assert inside((0.0, 0.0)).all()
    assert not inside((0.2, 0.0)).any()
    assert inside((0.0, 0.0), v=(0.3, 0.0)).all()
    assert not inside((0.0, 0.0), v=(0.6, 0.0)).any()
    assert inside((0.05, 0.15)).all()  # between the soles
    left_only = both.copy()
    left_only[:, 1] = False
    assert not inside((0.05, 0.15), touch=left_only).any()
    assert inside((0.0, 0.0), touch=left_only).all()
    assert not inside((0.0, 0.0), touch=np.zeros((K, 2), dtype=bool)).any()


def test_a_sliding_foot_costs_nothing_while_the_capture_point_is_outside():
    """With ``supported`` given, a step counts only where it is True at both ends: a sole
    sliding at 0.5 m/s over 12 ticks, unsupported at tick 5, pays for 9 of its 11 steps; all
    supported, what it pays without the mask; none, nothing."""
    K = 12
    ref = still_soles(K)
    stance = np.ones((K, 2), dtype=bool)
    slid = ref.copy()
    slid[:, 0, 0] += 0.5 * DT * np.arange(K)
    up = np.ones(K, dtype=bool)
    assert slide_cost(slid, ref, stance, DT, None, up) == pytest.approx(0.25, rel=1e-12)
    up[5] = False
    assert slide_cost(slid, ref, stance, DT, None, up) == pytest.approx(0.25 * 9 / 11, rel=1e-12)
    assert slide_cost(slid, ref, stance, DT, None, np.zeros(K, dtype=bool)) == 0.0


def test_sole_corners_agree_with_the_whole_body_controller_s(trial_on_floor, model):
    """The bottom corners of the sole boxes (as a set) against
    ``wholebody_reference.sole_corners``, an independent computation, over a walk."""
    ref = trial_on_floor(model, "07_01")[:60]
    ids = sole_ids(model)
    data = mujoco.MjData(model)
    for t in range(0, len(ref), 11):
        data.qpos[:] = ref[t]
        mujoco.mj_kinematics(model, data)
        mine = footholding_corners(data.geom_xpos[ids], data.geom_xmat[ids], model.geom_size[ids])
        for s, g in enumerate(ids):
            theirs = sole_corners(model, data, g)
            d = np.linalg.norm(mine[s][:, None] - theirs[None], axis=-1)
            np.testing.assert_allclose(d.min(axis=1), 0.0, atol=1e-12)
            np.testing.assert_allclose(d.min(axis=0), 0.0, atol=1e-12)


def test_search_with_feet_given_up_is_another_search_and_replays(trial_on_floor, model):
    """``hold_capture`` changes which candidates are kept on a walk (it frees some ticks) and
    the search stays deterministic."""
    ref = trial_on_floor(model, "07_01")[:48]
    kw = dict(samples=6, keep=2, window=12, lookahead=12, seed=4)
    w = CostWeights(hold=200.0, hold_capture=True)
    a, ra = search_offsets(model, ref, weights=w, **kw)
    b, rb = search_offsets(model, ref, weights=w, **kw)
    c, _ = search_offsets(model, ref, weights=CostWeights(hold=200.0), **kw)
    assert np.array_equal(a, b) and np.array_equal(ra, rb)
    assert not np.array_equal(a, c)


def test_a_window_gives_the_feet_up_only_where_asked():
    """Flat soles on the floor (lowest corner at 0), the left sliding at 0.5 m/s, the centre of
    mass 1 m in front of both (its capture point outside the support): held, it pays 0.25;
    released by the capture point, nothing; released only where the reference's capture point
    is inside its support, it pays where the reference's is outside too (the motion itself
    steps there) and nothing where the reference's is inside."""
    S, K = 3, 12
    size = np.array([[0.045, 0.13, 0.01], [0.045, 0.13, 0.01]])
    pos = np.zeros((S, K, 2, 3))
    pos[..., 1, 1] = 0.3
    pos[..., 2] = 0.01  # the box's centre a half height up: its bottom on the floor
    pos[:, :, 0, 0] += 0.5 * DT * np.arange(K)
    mat = np.broadcast_to(np.eye(3).reshape(9), (S, K, 2, 9))
    com = np.broadcast_to([1.0, 0.15, 0.9], (S, K, 3))
    ref_xy = still_soles(K)
    stance = np.ones((K, 2), dtype=bool)
    out = np.zeros(K, dtype=bool)
    records = (pos, mat, com)

    def cost(release, ref_up):
        ref = (ref_xy, stance, ref_up)
        return window_hold_costs(records, size, ref, DT, True, release)

    np.testing.assert_allclose(cost((False, False), out), 0.25, rtol=1e-12)
    np.testing.assert_allclose(cost((True, False), out), 0.0, atol=0)
    np.testing.assert_allclose(cost((True, True), out), 0.25, rtol=1e-12)
    np.testing.assert_allclose(cost((True, True), ~out), 0.0, atol=0)
    inside = np.broadcast_to([0.0, 0.15, 0.9], (S, K, 3))  # over the soles: held anyway
    ref = (ref_xy, stance, ~out)
    held = window_hold_costs((pos, mat, inside), size, ref, DT, True, (True, True))
    np.testing.assert_allclose(held, 0.25, rtol=1e-12)  # a mass at rest over its feet
